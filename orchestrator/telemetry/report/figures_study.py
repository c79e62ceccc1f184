"""The study's and the clocks' figures of a report, each from the tables it draws: the detections per day per
receiver (:func:`daily_matrix`, :func:`daily_figure`: a receiver that stopped logging is a row that goes pale), each
receiver's clock offset less its linear trend with its band (:func:`clock_residuals`, :func:`clock_figure`: the
clock breaks marked), the timing noise per receiver (:func:`noise_figure`), the sync tags' leave-one-out errors
(:func:`sync_tags_figure`) and the reference tags' errors (:func:`reference_figure`). The data functions are the
figures' own numbers (the tests check them against the study's files); each figure is an inline PNG
(:mod:`.images`), at most :data:`MAX_PANELS` receivers' panels, sized for a screen.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from sblsim.orchestrator.io.times import utc_seconds
from sblsim.orchestrator.telemetry.report.daily import DAY_S
from sblsim.orchestrator.telemetry.report.folder import StudyFolder
from sblsim.orchestrator.telemetry.report.images import Image, figure_image, new_figure

#: The most receivers' clock panels drawn (those whose offset departs most from its trend) and the most rows of a
#: receivers' figure labelled.
MAX_PANELS = 40
MAX_LABELS = 60
#: A figure's width [in] and the most height of a tall one [in].
WIDTH = 12.5
MAX_HEIGHT = 13.0


def used_receivers(study: StudyFolder) -> pd.DataFrame:
    """``receivers.csv``'s deployments used (all where it has no ``used`` column), in their order."""
    table = study.receivers
    if "used" in table:
        table = table[table["used"].astype(str).str.strip().str.lower() == "true"]
    return table.reset_index(drop=True)


def _window(table: pd.DataFrame, key: str, fill: float) -> np.ndarray:
    """Each deployment's ``start_utc`` or ``end_utc`` [s since 1970], ``fill`` where open or not given."""
    if key not in table:
        return np.full(len(table), fill)
    texts = table[key].astype(str).str.strip().tolist()
    out = np.full(len(texts), fill)
    given = [k for k, text in enumerate(texts) if text and text.lower() not in ("nan", "none")]
    if given:
        out[given] = utc_seconds([texts[k] for k in given], "report", [k + 2 for k in given], key)
    return out


def daily_matrix(study: StudyFolder) -> tuple[list[str], list[str], np.ndarray, np.ndarray] | None:
    """The figure's numbers: the receivers used (``receivers.csv``'s order), the days (``YYYY-MM-DD`` UTC, every day
    from the first to the last with a detection), the kept detections (receivers, days) and whether each receiver
    was deployed during at least part of each day; None where the folder has no daily counts."""
    daily = study.daily
    if daily is None or not len(daily):
        return None
    table = used_receivers(study)
    names = table["receiver"].astype(str).tolist()
    first, last = (pd.Timestamp(d, tz="UTC") for d in (daily["day"].min(), daily["day"].max()))
    days = pd.date_range(first, last, freq="D")
    labels = days.strftime("%Y-%m-%d").tolist()
    counts = np.zeros((len(names), len(days)))
    row = {name: k for k, name in enumerate(names)}
    column = {day: k for k, day in enumerate(labels)}
    for name, day, n in zip(daily["receiver"].astype(str), daily["day"].astype(str), daily["detections"]):
        if name in row and day in column:
            counts[row[name], column[day]] += n
    starts = days.as_unit("s").asi8.astype(float)
    begin, end = _window(table, "start_utc", -np.inf), _window(table, "end_utc", np.inf)
    deployed = (begin[:, None] < starts[None, :] + DAY_S) & (end[:, None] > starts[None, :])
    return names, labels, counts, deployed


def daily_figure(study: StudyFolder) -> Image | None:
    """The kept detections per receiver and day, a colour per count (log), pale red where deployed and silent,
    grey where not deployed (:func:`daily_matrix`); the count written in each cell where the grid is small."""
    from matplotlib.colors import ListedColormap, LogNorm

    found = daily_matrix(study)
    if found is None:
        return None
    names, days, counts, deployed = found
    height = min(MAX_HEIGHT, 1.3 + 0.2 * len(names))
    fig = new_figure(WIDTH, height)
    ax = fig.add_axes([0.12, 1.0 - (height - 0.5) / height, 0.76, (height - 1.1) / height])
    shown = np.where(counts > 0, counts, np.nan)
    background = np.where(deployed & (counts == 0), 1.0, np.where(deployed, np.nan, 0.0))
    ax.imshow(background, aspect="auto", cmap=ListedColormap(["0.85", "#f4a6a6"]), vmin=0, vmax=1,
              interpolation="nearest")
    image = ax.imshow(shown, aspect="auto", cmap="viridis", interpolation="nearest",
                      norm=LogNorm(vmin=1, vmax=max(2.0, float(np.nanmax(shown)))))
    step = max(1, int(np.ceil(len(names) / MAX_LABELS)))
    ax.set_yticks(range(0, len(names), step), names[::step], fontsize=7)
    every = max(1, int(np.ceil(len(days) / 14)))
    ax.set_xticks(range(0, len(days), every), days[::every], fontsize=7, rotation=30, ha="right")
    if len(names) * len(days) <= 400:
        bright = image.norm(np.maximum(counts, 1)) > 0.6  # viridis' yellow end: dark text on it
        for (i, j), n in np.ndenumerate(counts):
            if n > 0:
                ax.text(j, i, f"{n:,.0f}", ha="center", va="center", fontsize=6, color="k" if bright[i, j] else "w")
    ax.set_title("kept detections per receiver and UTC day (pale red: deployed and none logged; grey: not "
                 "deployed)", fontsize=8, loc="left")
    bar = fig.colorbar(image, ax=ax, fraction=0.03, pad=0.01)
    bar.set_label("detections", fontsize=7)
    bar.ax.tick_params(labelsize=7)
    return figure_image(fig, f"detections per day at each of {len(names)} receivers over {len(days)} days")


def clock_residuals(offsets: pd.DataFrame) -> dict[str, list[dict[str, np.ndarray]]]:
    """Each receiver's clock offset less its linear trend, per clock segment: ``time`` [s since 1970] at the
    bins' edges, ``residual_ms`` (the offset [ms] less its least-squares line over the segment's edges) and
    ``band_ms`` (2σ of the offset there [ms]; NaN where ``offsets.csv`` gives no σ)."""
    out: dict[str, list[dict[str, np.ndarray]]] = {}
    sigma = "offset_start_sigma_s" in offsets and "offset_end_sigma_s" in offsets
    segment = offsets["segment"] if "segment" in offsets else pd.Series(np.ones(len(offsets)), index=offsets.index)
    for (name, _), rows in offsets.groupby([offsets["receiver"].astype(str), segment.fillna(1)], sort=False):
        rows = rows.sort_values("start", kind="stable")
        t = np.r_[rows["start"].to_numpy(float), rows["end"].to_numpy(float)[-1:]]
        value = np.r_[rows["offset_start_s"].to_numpy(float), rows["offset_end_s"].to_numpy(float)[-1:]]
        band = np.r_[rows["offset_start_sigma_s"].to_numpy(float), rows["offset_end_sigma_s"].to_numpy(float)[-1:]] \
            if sigma else np.full(len(t), np.nan)
        ok = np.isfinite(t) & np.isfinite(value)
        line = np.polyfit(t[ok] - t[ok][0], value[ok], 1) if ok.sum() >= 2 else np.array([0.0, value[ok].mean()]) \
            if ok.any() else np.zeros(2)
        trend = np.polyval(line, t - (t[ok][0] if ok.any() else 0.0))
        out.setdefault(name, []).append({"time": t, "residual_ms": (value - trend) * 1e3, "band_ms": 2e3 * band})
    return out


def clock_figure(study: StudyFolder) -> tuple[Image | None, list[str]]:
    """Each receiver's offset less its trend with its 2σ band and its clock breaks (:func:`clock_residuals`), a
    panel per receiver (the :data:`MAX_PANELS` departing most); the receivers left out."""
    if study.offsets is None or not len(study.offsets):
        return None, []
    found = clock_residuals(study.offsets)
    size = {n: max(float(np.nanmax(np.abs(s["residual_ms"]))) if len(s["residual_ms"]) else 0.0 for s in parts)
            for n, parts in found.items()}
    names = sorted(found, key=lambda n: -size[n])[:MAX_PANELS]
    left_out = sorted(set(found) - set(names))
    names = [n for n in found if n in names]  # offsets.csv's order
    breaks = (study.summary.get("clocks") or {}).get("clock_breaks") or []
    origin = float(np.nanmin(study.offsets["start"].to_numpy(float)))
    cols = 5 if len(names) > 4 else len(names)
    rows = int(np.ceil(len(names) / cols))
    height = min(MAX_HEIGHT, 0.9 + 1.35 * rows)
    fig = new_figure(WIDTH, height)
    axes = fig.subplots(rows, cols, squeeze=False, sharex=True)
    fig.subplots_adjust(left=0.06, right=0.99, top=1 - 0.45 / height, bottom=0.45 / height, hspace=0.35,
                        wspace=0.28)
    for ax, name in zip(axes.flat, names):
        for part in found[name]:
            days = (part["time"] - origin) / DAY_S
            ax.fill_between(days, part["residual_ms"] - part["band_ms"], part["residual_ms"] + part["band_ms"],
                            color="C0", alpha=0.25, lw=0)
            ax.plot(days, part["residual_ms"], color="C0", lw=1)
        for entry in breaks:
            if isinstance(entry, dict) and str(entry.get("receiver")) == name and entry.get("time_s") is not None:
                ax.axvline((float(entry["time_s"]) - origin) / DAY_S, color="C3", ls="--", lw=1)
        ax.set_title(name, fontsize=8, pad=2)
        ax.tick_params(labelsize=6, labelbottom=True)
        ax.axhline(0, color="0.6", lw=0.5)
    for ax in axes.flat[len(names):]:
        ax.axis("off")
    for ax in axes.flat[max(0, len(names) - cols):len(names)]:
        ax.set_xlabel("days", fontsize=7)
    for ax in axes[:, 0]:
        ax.set_ylabel("[ms]", fontsize=7)
    fig.suptitle("each receiver's clock offset less its linear trend [ms], the band its 2σ; red dashes: a clock "
                 "break", fontsize=8, x=0.01, ha="left")
    return figure_image(fig, f"the clock offsets less their trend of {len(names)} receivers"), left_out


def noise_figure(study: StudyFolder) -> Image | None:
    """The timing noise per receiver [ms] (``study.json``'s ``toa_noise``), and its clock offset's σ where
    ``offsets.csv`` has it, the receivers by their noise."""
    per = (study.summary.get("toa_noise") or {}).get("per_receiver_s") or {}
    if not isinstance(per, dict) or not per:
        return None
    names = sorted(per, key=lambda n: float(per[n]))
    noise = np.array([float(per[n]) for n in names]) * 1e3
    height = min(MAX_HEIGHT, 1.1 + 0.17 * len(names))
    fig = new_figure(WIDTH * 0.7, height)
    ax = fig.add_subplot()
    ax.barh(range(len(names)), noise, color="C0", label="timing noise (toa_sigma_s)")
    offsets = study.offsets
    if offsets is not None and "clock_sigma_s" in offsets:
        clock = offsets.groupby(offsets["receiver"].astype(str))["clock_sigma_s"].first()
        values = np.array([float(clock.get(n, np.nan)) for n in names]) * 1e3
        ax.plot(values, range(len(names)), "o", color="C1", ms=4, label="clock offset's σ (clock_sigma_s)")
    step = max(1, int(np.ceil(len(names) / MAX_LABELS)))
    ax.set_yticks(range(0, len(names), step), names[::step], fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("[ms]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title("each receiver's timing noise, the tracker's weight of its arrivals", fontsize=8, loc="left")
    fig.tight_layout(pad=0.4)
    return figure_image(fig, f"the timing noise of {len(names)} receivers")


def _errors(ax, names: list[str], error: np.ndarray, upper: np.ndarray | None, sigma: np.ndarray | None,
            colours: list[str]) -> None:
    """Horizontal bars of errors [m], a whisker to ``upper`` and a marker at ``sigma``, a row per name."""
    y = np.arange(len(names))
    ax.barh(y, error, color=colours, label="median error")
    if upper is not None:
        ax.errorbar(error, y, xerr=[np.zeros(len(y)), np.clip(upper - error, 0, None)], fmt="none", ecolor="0.3",
                    lw=1, capsize=2, label="to the 90th percentile")
    if sigma is not None:
        ax.plot(sigma, y, "D", color="k", ms=4, label="median σ")
    ax.set_yticks(y, names, fontsize=7)
    ax.set_xlabel("[m]", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.legend(fontsize=7, loc="lower right")


def sync_tags_figure(study: StudyFolder) -> Image | None:
    """Each sync tag's fixes' median error from its surveyed place [m] (to its 90th percentile), its median σ, a
    left-out tag (``leave_one_out``: its arrivals not in the clocks' fit) in its own colour."""
    table = study.sync_tags
    if table is None or "median_error_m" not in table or not len(table):
        return None
    table = table.sort_values("median_error_m", kind="stable", na_position="first")
    left = table["leave_one_out"].astype(str).str.lower().eq("true").to_numpy() if "leave_one_out" in table \
        else np.zeros(len(table), bool)
    fig = new_figure(WIDTH * 0.7, min(MAX_HEIGHT, 1.2 + 0.2 * len(table)))
    ax = fig.add_subplot()
    _errors(ax, table["tag"].astype(str).tolist(), table["median_error_m"].to_numpy(float),
            table["p90_error_m"].to_numpy(float) if "p90_error_m" in table else None,
            table["median_sigma_m"].to_numpy(float) if "median_sigma_m" in table else None,
            ["C2" if k else "C0" for k in left])
    ax.set_title("the sync tags positioned as tags: error from the receiver each sits at (green: left out of the "
                 "clocks' fit)", fontsize=8, loc="left")
    fig.tight_layout(pad=0.4)
    return figure_image(fig, f"the positioning errors of {len(table)} sync tags")


#: The reference tags' table's columns the figure draws, the first of each that the table has.
REFERENCE_ERROR = ("median_error_m", "error_m", "distance_m")
REFERENCE_SIGMA = ("median_sigma_m", "sigma_m")
REFERENCE_UPPER = ("p90_error_m", "p95_error_m")


def reference_columns(table: pd.DataFrame) -> dict[str, str | None]:
    """The reference tags' columns the figure draws: ``error``, ``sigma`` and ``upper`` (None where absent)."""
    def first(names: tuple[str, ...]) -> str | None:
        return next((n for n in names if n in table and table[n].dtype.kind == "f"), None)

    return {"error": first(REFERENCE_ERROR), "sigma": first(REFERENCE_SIGMA), "upper": first(REFERENCE_UPPER)}


def reference_errors(study: StudyFolder) -> pd.DataFrame | None:
    """The figure's numbers: each scored tag of ``reference_tags.csv`` (``tag``, ``kind``) with its ``error``,
    ``sigma`` and ``upper`` [m] (the columns of :func:`reference_columns`, NaN where absent), by error; None where
    the table has no tag or no error column."""
    table = study.reference
    if table is None or not len(table):
        return None
    columns = reference_columns(table)
    if columns["error"] is None:
        return None
    out = pd.DataFrame({"tag": table["tag"].astype(str),
                        "kind": table["kind"].astype(str) if "kind" in table else "",
                        **{key: table[name].to_numpy(float) if name else np.full(len(table), np.nan)
                           for key, name in columns.items()}})
    return out.sort_values("error", kind="stable").reset_index(drop=True)


def reference_figure(study: StudyFolder) -> Image | None:
    """Each scored tag's error from its known position [m] with its σ (:func:`reference_errors`), a reference tag
    and a sync tag left out in their own colours; None where there is none."""
    table = reference_errors(study)
    if table is None:
        return None
    fig = new_figure(WIDTH * 0.7, min(MAX_HEIGHT, 1.2 + 0.22 * len(table)))
    ax = fig.add_subplot()
    _errors(ax, table["tag"].tolist(), table["error"].to_numpy(float),
            table["upper"].to_numpy(float) if table["upper"].notna().any() else None,
            table["sigma"].to_numpy(float) if table["sigma"].notna().any() else None,
            ["C2" if kind == "sync_left_out" else "C4" for kind in table["kind"]])
    ax.set_title("the reference tags (purple) and the sync tags left out (green): error from their known position",
                 fontsize=8, loc="left")
    fig.tight_layout(pad=0.4)
    return figure_image(fig, f"the errors of {len(table)} reference tags")


def summary_value(summary: dict[str, Any], *keys: str) -> Any:
    """``summary[k1][k2]...``, None where a level is missing or not a mapping."""
    value: Any = summary
    for key in keys:
        if not isinstance(value, dict):
            return None
        value = value.get(key)
    return value


__all__ = ["MAX_PANELS", "clock_figure", "clock_residuals", "daily_figure", "daily_matrix", "noise_figure",
           "reference_columns", "reference_errors", "reference_figure", "summary_value", "sync_tags_figure",
           "used_receivers"]

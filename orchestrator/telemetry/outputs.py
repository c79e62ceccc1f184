"""A study's files (:func:`write_study`), for R, QGIS and a reader: ``tracks.csv`` (every tag's rows: ``tag``,
``time_utc``, ``epoch_s``, ``lat``, ``lon``, ``x``, ``y``, ``sigma_x``, ``sigma_y``, ``quality``, ...), ``tags.csv``
(a row per tag), ``receivers.csv`` (every deployment of the sheet in the frame and in latitude and longitude, with
``used``, ``not_used`` and ``detections``: :mod:`sblsim.orchestrator.readers.in_water`), ``study.json`` (the
summary: the files, the frame and its CRS, the detections set aside, the deployments used and not, the clocks, the
tags), ``tracks.geojson`` (RFC 7946: the receivers used as points, each tag's rows not flagged as a line, WGS 84
longitude and latitude; where the frame is known), ``reference_tags.csv`` (the reference tags and the sync tags
left out in turn, scored against their known positions: :mod:`.reference_tags`), ``positions.csv`` (with
``--refine-positions``: the receivers' positions refined from the moving tags, :mod:`.study_positions`), ``map.png``
(:func:`study_map`), the synchronisation made (``sync/``, as ``sblsim sync`` writes it; with the refined positions
its clocks were made on, and their errors, where a refinement was kept) and one folder per tag
(its ``toa.txt``, ``receivers.csv``, ``pings.csv``, ``toa.json`` and its track's files as ``sblsim replay`` writes
them).
"""

from __future__ import annotations

import json
import textwrap
from contextlib import ExitStack, nullcontext
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from sblsim.orchestrator.io.memory import release, spilled
from sblsim.orchestrator.readers.in_water import SAID
from sblsim.orchestrator.sync.outputs import plain
from sblsim.orchestrator.sync.outputs import write as write_sync
from sblsim.orchestrator.telemetry import reference_tags as references
from sblsim.orchestrator.telemetry.report.page import study_report
from sblsim.orchestrator.telemetry.study import StudyOutcome
from sblsim.orchestrator.telemetry.study_positions import sync_positions
from sblsim.orchestrator.telemetry.study_tracks import tag_tracks
from sblsim.orchestrator.tracks.outputs import scale_bar, write

#: The characters of a line of the text beside the map; a receiver's label's offsets from it [pt], tried in turn.
PANEL_WIDTH = 46
LABEL_CORNERS = ((3, 3), (3, -3), (-3, 3), (-3, -3))
#: The most receivers' labels tried (the most detections first): more are not read on a map.
MAX_LABELS = 80


def _heard(outcome: StudyOutcome) -> dict[str, list[str]]:
    """Each tracked tag's receivers: the deployments whose column of its times-of-arrival matrix holds an arrival
    (a matrix written and let go of its rows, :attr:`StudyOutcome.written`: each of its columns, as the study keeps
    only those: :func:`~.tag_rows.heard_columns`)."""
    out = {}
    for folder in outcome.outcomes:
        matrix = outcome.matrices[folder]
        heard = np.isfinite(matrix.toa).any(axis=0) if len(matrix.toa) else np.ones(len(matrix.names), bool)
        out[str(matrix.summary["tag"])] = [n for n, h in zip(matrix.names, heard) if h]
    return out


def geojson(outcome: StudyOutcome) -> dict[str, Any] | None:
    """The receivers used and the tracks as a GeoJSON FeatureCollection (RFC 7946: WGS 84 longitude, latitude);
    None where the positions have no CRS. A receiver is a point with its deployment's fields, ``used`` (true),
    its kept ``detections`` and ``tags_tracked`` (the tracked tags it heard, separated by commas); a track is a
    line of its rows not flagged."""
    features = _features(outcome)
    return None if features is None else {"type": "FeatureCollection", "features": [plain(f) for f in features]}


def _geo_table(outcome: StudyOutcome):
    """The receivers used (``receivers.csv``'s rows with ``used``), or None where the positions have no CRS (no
    GeoJSON)."""
    table = outcome.deployments.written()
    if "used" in table:
        table = table[table["used"].to_numpy(bool)]
    if outcome.deployments.frame is None or not np.isfinite(table["lat"].to_numpy(float)).all():
        return None
    return table


def _features(outcome: StudyOutcome) -> Iterator[dict[str, Any]] | None:
    """:func:`geojson`'s features, a tag's track at a time; None where the positions have no CRS."""
    table = _geo_table(outcome)
    if table is None:
        return None
    return _feature_rows(outcome, table)


def _feature_rows(outcome: StudyOutcome, table) -> Iterator[dict[str, Any]]:
    yield from _receiver_features(outcome, table)
    for tag, rows in tag_tracks(outcome.tracks, outcome.parts):
        feature = _track_feature(tag, rows)
        if feature is not None:
            yield feature


def _receiver_features(outcome: StudyOutcome, table) -> Iterator[dict[str, Any]]:
    """The receivers used as GeoJSON points (:func:`geojson`)."""
    by_receiver: dict[str, list[str]] = {}
    for tag, names in _heard(outcome).items():
        for name in names:
            by_receiver.setdefault(name, []).append(tag)
    for row in table.to_dict("records"):
        yield ({"type": "Feature", "geometry": {"type": "Point", "coordinates": [row["lon"], row["lat"]]},
                         "properties": {"kind": "receiver", "receiver": row["receiver"], "serial": row["serial"],
                                        "station": row["station"], "sync_tag": row["sync_tag"],
                                        "start_utc": row["start_utc"], "end_utc": row["end_utc"], "used": True,
                                        "detections": int(row.get("detections", 0)),
                                        "tags_tracked": ",".join(by_receiver.get(row["receiver"], []))}})


def _track_feature(tag: str, rows) -> dict[str, Any] | None:
    """A tag's rows of ``tracks.csv`` not flagged as a GeoJSON line (:func:`geojson`); None with fewer than two."""
    ok = rows[(rows["quality"] != "flagged") & rows["lat"].notna()]
    if len(ok) < 2:
        return None
    return ({"type": "Feature",
             "geometry": {"type": "LineString",
                          "coordinates": np.c_[ok["lon"].to_numpy(float), ok["lat"].to_numpy(float)]
                          .round(8).tolist()},
             "properties": {"kind": "track", "tag": tag, "rows": int(len(ok)),
                            "flagged_rows_left_out": int((rows["quality"] == "flagged").sum()),
                            "first_utc": ok["time_utc"].iloc[0], "last_utc": ok["time_utc"].iloc[-1]}})


def _short(reason: str) -> str:
    """A refusal's reason as the map's panel lists it: its part before the allowed values, in two lines at most."""
    text = str(reason).split("; allowed:")[0].strip() or "no reason given"
    lines = textwrap.wrap(text, PANEL_WIDTH - 2)
    return "\n  ".join(lines[:2]) + ("…" if len(lines) > 2 else "")


def _panel(outcome: StudyOutcome, labelled: tuple[int, int], lines_free: int) -> str:
    """The text beside the map, under its legend: the deployments used and not, the receivers labelled, each tag
    not tracked with the short reason (as many as ``lines_free`` lines hold, then their count)."""
    s = outcome.deployments.summary()
    lines = [f"deployments: {s['deployments']:,} used" + (f" of {s['in_sheet']:,}" if "in_sheet" in s else "")]
    for cause, count in s.get("not_used", {}).items():
        if cause != "count":
            lines.append(f"  not used, {SAID.get(cause, cause)}: {count:,}")
    if labelled[0] < labelled[1]:
        lines += [f"receivers labelled: {labelled[0]} of {labelled[1]}", "  (the others' labels would overlap)"]
    tags = outcome.tags
    refused = tags[tags["status"] != "tracked"]
    lines += ["", f"tags not tracked: {len(refused)} of {len(tags)}" if len(refused) else "every tag tracked"]
    room = lines_free - len(lines)
    for k, row in enumerate(refused.itertuples(index=False)):
        entry = f"{row.tag if isinstance(row.tag, str) and row.tag else row.transmitter}: {_short(row.reason)}"
        height = entry.count("\n") + 1
        if height + (k + 1 < len(refused)) > room:  # a line kept for the rest's count
            lines.append(f"… and {len(refused) - k} more (tags.csv)")
            break
        lines.append(entry)
        room -= height
    return "\n".join(lines)


def _north(ax, frame, x: float, y: float) -> list:
    """A north arrow in the lower left, pointing to true north at the frame's point ``x``, ``y`` [m] (the grid's
    convergence there, by pyproj); its artists."""
    lat, lon = frame.to_latlon(np.array([x]), np.array([y]))
    nx, ny = frame.from_latlon(lat + 0.01, lon)
    angle = np.arctan2(nx[0] - x, ny[0] - y)
    from matplotlib.transforms import ScaledTranslation

    length = 22.0  # [pt], its tail in the corner
    tip = ax.transAxes + ScaledTranslation(length * np.sin(angle) / 72, length * np.cos(angle) / 72,
                                           ax.figure.dpi_scale_trans)
    arrow = ax.annotate("", xy=(0.04, 0.035), xycoords=tip,
                        xytext=(-length * np.sin(angle), -length * np.cos(angle)), textcoords="offset points",
                        arrowprops={"arrowstyle": "-|>", "color": "k", "lw": 1.2})
    label = ax.annotate("N", xy=(0.04, 0.035), xycoords=tip, xytext=(4 * np.sin(angle), 4 * np.cos(angle)),
                        textcoords="offset points", ha="center", va="bottom", fontsize=9, weight="bold")
    return [arrow, label]


def _thin_labels(ax, renderer, texts: list, fixed: list) -> int:
    """Each receiver's label (in ``texts``' order: the most detections first; at most :data:`MAX_LABELS` tried) put
    at the first of its corners (upper right, lower right, upper left, lower left) where it stays inside the map and
    overlaps no label put before, no receiver's marker and none of the ``fixed`` artists (the scale bar, the north
    arrow), by their extents as matplotlib draws them; removed where none is free. The count kept."""
    half = 2.5 / 72 * ax.figure.dpi  # a marker's half width [px]
    centres = ax.transData.transform(np.array([t.xy for t in texts]).reshape(-1, 2))
    markers = np.column_stack([centres - half, centres + half])  # (n, 4): x0, y0, x1, y1 [px]
    kept = np.array([a.get_window_extent(renderer).extents for a in fixed]).reshape(-1, 4)
    occupied, inside = len(kept), ax.get_window_extent(renderer)

    def free(box: np.ndarray, others: np.ndarray) -> bool:
        return not np.any((box[0] < others[:, 2]) & (others[:, 0] < box[2]) & (box[1] < others[:, 3])
                          & (others[:, 1] < box[3]))

    for k, text in enumerate(texts):
        if k >= MAX_LABELS:
            text.remove()
            continue
        text.set_visible(True)
        for dx, dy in LABEL_CORNERS:
            text.xyann = (dx, dy)
            text.set(ha="left" if dx > 0 else "right", va="bottom" if dy > 0 else "top")
            box = text.get_window_extent(renderer).expanded(1.05, 1.1).extents
            within = inside.x0 <= box[0] and box[2] <= inside.x1 and inside.y0 <= box[1] and box[3] <= inside.y1
            if within and free(box, kept) and free(box, np.delete(markers, k, axis=0)):
                kept = np.vstack([kept, box])
                break
        else:
            text.remove()
    return len(kept) - occupied


def _used(outcome: StudyOutcome):
    """The receivers used (``receivers.csv``'s rows with ``used``), the most detections first."""
    table = outcome.deployments.written()
    if "used" in table:
        table = table[table["used"].to_numpy(bool)]
    if "detections" in table:
        table = table.sort_values("detections", ascending=False, kind="stable")
    return table.reset_index(drop=True)


def _drawn(outcome: StudyOutcome) -> list[tuple[str, np.ndarray, np.ndarray, int]]:
    """Each tag with a row not flagged, in ``tracks.csv``'s order: :func:`_drawn_tag`'s (a tag's rows at a time)."""
    return [d for tag, rows in tag_tracks(outcome.tracks, outcome.parts) if (d := _drawn_tag(tag, rows))]


def _drawn_tag(tag: str, rows) -> tuple[str, np.ndarray, np.ndarray, int] | None:
    """A tag as the map draws it: its tag, its rows not flagged's ``x`` and ``y`` [m] and its rows' count (16 bytes
    of a row kept); None where every row is flagged."""
    ok = rows[rows["quality"] != "flagged"]
    return (tag, ok["x"].to_numpy(float), ok["y"].to_numpy(float), len(rows)) if len(ok) else None


def _draw(ax, outcome: StudyOutcome, table, origin: tuple[float, float], tags: list) -> list:
    """The receivers used (filled where they heard a tag tracked), each tracked tag's rows not flagged (``tags``:
    :func:`_drawn`) and, for up to ten tags, its receivers ringed in its colour; the receivers' labels (returned)."""
    import matplotlib.pyplot as plt

    heard = _heard(outcome)
    rx, ry = table["x_m"].to_numpy(float) - origin[0], table["y_m"].to_numpy(float) - origin[1]
    hearing = table["receiver"].isin(set().union(*heard.values()) if heard else set()).to_numpy()
    for mask, style, said in ((hearing, {"color": "k"}, "receivers used, heard a tag tracked"),
                              (~hearing, {"mfc": "none", "mec": "0.3"}, "receivers used, heard no tag tracked")):
        if mask.any():
            ax.plot(rx[mask], ry[mask], "^", ms=6, zorder=3, label=f"{said} ({int(mask.sum())})", **style)
    colours = plt.get_cmap("tab10").colors
    ringed = len(tags) <= len(colours)
    position = dict(zip(table["receiver"], zip(rx, ry)))
    for k, (tag, x, y, every) in enumerate(tags):
        colour = colours[k % len(colours)]
        ax.plot(x - origin[0], y - origin[1], ".-", ms=2, lw=0.5, color=colour, alpha=0.85,
                label=f"{tag}: {len(x)} of {every} rows, its receivers ringed" if ringed else None)
        if ringed:
            points = np.array([position[n] for n in heard.get(tag, []) if n in position]).reshape(-1, 2)
            ax.plot(points[:, 0], points[:, 1], "o", mfc="none", mec=colour, ms=10 + 3.5 * k, mew=1.0, zorder=2)
    return [ax.annotate(str(name), (x, y), fontsize=6, xytext=(3, 3), textcoords="offset points", zorder=4,
                        visible=False) for name, x, y in zip(table["receiver"], rx, ry)]  # shown where they fit


def study_map(outcome: StudyOutcome, tags: list | None = None):
    """The study on a map (matplotlib): the receivers used, each tracked tag's track (its rows not flagged) and its
    receivers ringed in its colour, labels that do not overlap (the most detections first), a scale bar and a
    north arrow, axes as offsets in metres in the frame from a round origin, the frame and the counts in the
    title (as the console gives them); beside it the legend, the deployments used and not and each tag not
    tracked with its reason. ``tags``: the tracks as :func:`_drawn` gives them (default read from the tags' rows).
    """
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    table = _used(outcome)
    tags = _drawn(outcome) if tags is None else tags
    xs = np.concatenate([table["x_m"].to_numpy(float), *(x for _, x, _, _ in tags)])
    ys = np.concatenate([table["y_m"].to_numpy(float), *(y for _, _, y, _ in tags)])
    finite = np.isfinite(xs) & np.isfinite(ys)
    spans = (np.ptp(xs[finite]), np.ptp(ys[finite])) if finite.any() else (0.0, 0.0)
    width = 7.0 * float(np.clip(spans[0] / spans[1] if spans[1] > 0 else 1.0, 0.75, 1.6))  # the data's shape
    fig, (ax, side) = plt.subplots(1, 2, figsize=(width + 4.2, 8), width_ratios=(width, 3.6))
    origin = tuple(float(np.floor(np.min(v[finite]) / 1000.0) * 1000.0) if finite.any() else 0.0 for v in (xs, ys))
    texts = _draw(ax, outcome, table, origin, tags)
    ax.ticklabel_format(useOffset=False, style="plain")
    ax.xaxis.set_major_locator(MaxNLocator(max(3, int(width / 1.1))))
    ax.tick_params(labelsize=7)
    if finite.any():  # a band below the receivers for the north arrow and the scale bar
        wide, high = max(spans[0], 0.3 * spans[1], 1.0), max(spans[1], 0.3 * spans[0], 1.0)
        ax.set(xlim=(np.min(xs[finite]) - origin[0] - 0.05 * wide, np.max(xs[finite]) - origin[0] + 0.05 * wide),
               ylim=(np.min(ys[finite]) - origin[1] - 0.18 * high, np.max(ys[finite]) - origin[1] + 0.05 * high))
    frame = outcome.summary.get("frame")
    crs = f" ({frame['crs']})" if frame else ""
    ax.set(aspect="equal", xlabel=f"x [m] east of {origin[0]:,.0f}{crs}",
           ylabel=f"y [m] north of {origin[1]:,.0f}{crs}")
    s = outcome.deployments.summary()
    tracked = int((outcome.tags["status"] == "tracked").sum())
    fig.suptitle(f"{tracked} of {len(outcome.tags)} tags tracked (rows not flagged); {s['deployments']:,} of "
                 f"{s.get('in_sheet', s['deployments']):,} deployments used\n"
                 + (f"frame {frame['name']} ({frame['crs']}, {frame['chosen']})" if frame else
                    "a local frame without a CRS (no north)"), fontsize=9, x=0.01, ha="left")
    scale_bar(ax, max(spans) if finite.any() else float("nan"))
    fixed = list(ax.artists)
    if outcome.deployments.frame is not None and len(table):
        fixed += _north(ax, outcome.deployments.frame, float(np.nanmean(table["x_m"])),
                        float(np.nanmean(table["y_m"])))
    side.axis("off")
    legend = side.legend(*ax.get_legend_handles_labels(), loc="upper left", fontsize=7, borderaxespad=0)
    for _ in range(2):  # the second with the ticks and the aspect the first draw settled
        fig.tight_layout()
        fig.canvas.draw()
    box, own = ax.get_position(), side.get_position()  # the panel beside the map, level with its top
    side.set_position([own.x0, box.y0, own.width, box.height])
    renderer = fig.canvas.get_renderer()
    kept = _thin_labels(ax, renderer, texts, fixed)
    below = side.transAxes.inverted().transform(legend.get_window_extent(renderer))[0, 1] - 0.02
    line = 6.5 * 1.25 / 72 * fig.dpi  # a line of the panel's text [px]
    free = int(below * side.get_window_extent(renderer).height / line)
    side.text(0, below, _panel(outcome, (kept, len(texts)), free), transform=side.transAxes, va="top",
              ha="left", fontsize=6.5, family="monospace")
    return fig


def write_study(outcome: StudyOutcome, folder: Path) -> None:
    """The study's files (the module docstring) into ``folder`` (the tags' folders are there already, with their
    matrices): each tracked tag's track files, the synchronisation made, then the study's own files."""
    import matplotlib.pyplot as plt

    release()  # what the study's last steps freed (the reference tags' scores: 0.1 GiB at 13 weeks) handed back first
    for name, tag in outcome.outcomes.items():
        if name not in outcome.written:  # (the others written as they ended)
            write(tag, folder / name)
    if outcome.sync is not None:
        write_sync(outcome.sync, folder / "sync")
        refined = outcome.summary.get("positions") or {}
        if outcome.positions is not None and refined.get("kept"):  # its clocks made on them: the folder's positions
            sync_positions(outcome.positions, refined["survey_sigma_m"]).to_csv(folder / "sync" / "positions.csv",
                                                                               index=False)
    # the synchronisation's row per sync-tag arrival, written, kept on disk while the tracks and the report are
    # made (read back at the end: the outcome the study returns keeps it)
    with spilled(outcome.sync, "residuals", folder) if outcome.sync is not None else nullcontext():
        drawn = _write_tracks(outcome, folder)
        outcome.tags.to_csv(folder / "tags.csv", index=False)
        outcome.deployments.written().to_csv(folder / "receivers.csv", index=False)
        references.table(outcome.summary.get("reference_tags")).to_csv(folder / "reference_tags.csv", index=False)
        if outcome.positions is not None:
            outcome.positions.to_csv(folder / "positions.csv", index=False)
        (folder / "study.json").write_text(json.dumps(plain(outcome.summary), indent=2, allow_nan=False) + "\n")
        fig = study_map(outcome, drawn)
        try:
            fig.savefig(folder / "map.png", dpi=110)
        finally:
            plt.close(fig)
        study_report(outcome, folder)  # report.html (and detections_daily.csv): from the files above


def _write_tracks(outcome: StudyOutcome, folder: Path) -> list:
    """``tracks.csv`` and ``tracks.geojson`` (where the frame has a CRS) in one reading of the tags' rows (each tag's
    own ``track.csv`` read once: :meth:`~.study_tracks.TrackParts.write`), the map's tracks (:func:`_drawn`)
    returned."""
    drawn: list = []
    table = _geo_table(outcome)
    with ExitStack() as files:
        geo, count = None, 0

        def put(feature: dict[str, Any]) -> None:  # as json.dumps writes the whole collection, a feature at a time
            nonlocal count
            geo.write((", " if count else "") + json.dumps(plain(feature), allow_nan=False))
            count += 1

        if table is not None:
            geo = files.enter_context(open(folder / "tracks.geojson", "w"))
            geo.write('{"type": "FeatureCollection", "features": [')
            for feature in _receiver_features(outcome, table):
                put(feature)

        def each(tag: str, rows) -> None:
            feature = None if geo is None else _track_feature(tag, rows)
            if feature is not None:
                put(feature)
            mapped = _drawn_tag(tag, rows)
            if mapped is not None:
                drawn.append(mapped)

        if outcome.parts is not None:  # a tag's rows at a time, from its own file
            outcome.parts.write(folder / "tracks.csv", each)
        else:
            outcome.tracks.to_csv(folder / "tracks.csv", index=False)
            for tag, rows in tag_tracks(outcome.tracks, None):
                each(tag, rows)
        if geo is not None:
            geo.write("]}\n")
    return drawn


__all__ = ["geojson", "study_map", "write_study"]

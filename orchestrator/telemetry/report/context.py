"""What a study's report shows, as its template's values (:func:`page_context`): the study (the files read, the
detections set aside and why, the frame and its CRS, the receivers' map, table and detections per day, the tag sheet
as read), the clocks (their source, breaks, offsets less trend, timing noise, the sync tags' errors), the tags (a row
per tag of ``tags.csv`` linked to its section; each tag's status, true reason, counts, flagged rows by reason, sound
speed and its source, figure), the reference tags where scored, and the warnings and decisions (:mod:`.decisions`).
Numbers are shown as the files hold them, rounded for reading (:func:`shown`); every text is escaped by the template.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
import pandas as pd

from sblsim.orchestrator.readers.in_water import SAID
from sblsim.orchestrator.telemetry.census import REASON_CODES
from sblsim.orchestrator.telemetry.report import figures_study as figures
from sblsim.orchestrator.telemetry.report.decisions import decisions, warnings
from sblsim.orchestrator.telemetry.report.figures_study import summary_value, used_receivers
from sblsim.orchestrator.telemetry.report.figures_tag import flag_counts, tag_figure
from sblsim.orchestrator.telemetry.report.folder import StudyFolder
from sblsim.orchestrator.telemetry.report.images import png_image

#: The tags table's columns: tags.csv's column -> its heading.
TAG_TABLE = {"name": "name", "role": "role", "status": "status", "reason_code": "reason", "detections": "detections",
             "receivers": "receivers", "pings": "pings", "positioned": "positioned", "set_aside": "set aside",
             "not_positioned": "not positioned", "flagged": "flagged", "median_sigma_m": "median σ [m]",
             "sound_speed_m_s": "sound speed [m/s]", "sound_speed_source": "its source"}
#: The receivers table's columns: receivers.csv's column -> its heading.
RECEIVER_TABLE = {"receiver": "receiver", "serial": "serial", "station": "station", "sync_tag": "sync tag",
                  "lat": "lat [°]", "lon": "lon [°]", "z_m": "z [m]", "start_utc": "deployed (UTC)",
                  "end_utc": "recovered (UTC)", "detections": "detections kept"}
#: The most deployments not used listed in the page (the others counted: receivers.csv lists all), and the most
#: tags drawn (those with the most rows positioned: about 0.3 s and 30 kB each; every tag's track.png is in its folder).
MAX_NOT_USED = 500
MAX_TAG_FIGURES = 200
#: An ISO 8601 UTC time as the study's files write it (shown to the second), and the columns shown with 6 decimals.
ISO_TIME = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(\.\d+)?Z")
DEGREES = ("lat", "lon", "truth_lat", "truth_lon")
#: The tag sheet's columns as tags.csv carries them.
SHEET_TABLE = {"transmitter": "transmitter", "name": "name", "role": "role", "motion": "motion",
               "ping_type_stated": "ping type stated"}


def shown(value: Any, decimals: int | None = None) -> str:
    """A cell as the page shows it: a whole number with thousands' commas, another number to 4 significant digits
    (one decimal from 100 on; ``decimals`` where given: latitudes and longitudes), empty for NaN or None, a boolean
    as ``yes``/``no``, an ISO time to the second, anything else as text."""
    if value is None:
        return ""
    if isinstance(value, (bool, np.bool_)):
        return "yes" if value else "no"
    if isinstance(value, (int, np.integer)):
        return f"{int(value):,}"
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value):
            return ""
        if decimals is not None:
            return f"{value:.{decimals}f}"
        if float(value).is_integer() and abs(value) < 1e15:
            return f"{int(value):,}"
        return f"{value:,.1f}" if abs(value) >= 100 else f"{value:.4g}"
    text = str(value)
    if text in ("True", "False"):  # a flag of a table read as text
        return "yes" if text == "True" else "no"
    return text[:19] + "Z" if ISO_TIME.fullmatch(text) else text


def anchor(k: int, tag: str) -> str:
    """A tag's section's id in the page: its row's number and its id's letters (unique, an HTML id's characters)."""
    return f"tag-{k + 1}-" + re.sub(r"[^A-Za-z0-9_-]", "-", tag)[:40]


def _table(frame: pd.DataFrame, columns: dict[str, str]) -> dict[str, Any]:
    """A table's headings and rows of shown cells (the columns the frame has, those empty in every row left out)."""
    keys = [c for c in columns if c in frame]
    rows = [[shown(v, 6 if c in DEGREES else None) for c, v in zip(keys, row)]
            for row in frame[keys].itertuples(index=False)]
    kept = [k for k in range(len(keys)) if any(r[k] for r in rows)] if rows else list(range(len(keys)))
    return {"columns": [columns[keys[k]] for k in kept], "rows": [[r[k] for k in kept] for r in rows]}


def _pairs(items: list[tuple[str, Any]]) -> list[tuple[str, str]]:
    """Key-value rows of a facts table, those without a value left out."""
    return [(k, shown(v)) for k, v in items if v is not None and shown(v) != ""]


def _study(study: StudyFolder) -> dict[str, Any]:
    s = study.summary
    d, r = s.get("detections") or {}, s.get("receivers") or {}
    reasons = d.get("reasons") if isinstance(d.get("reasons"), dict) else {}
    aside = [("outside a deployment (before, after, on deck between two)", reasons.get("outside_deployment")),
             ("at serials not in the receivers file", reasons.get("receiver_not_in_table")),
             ("of sync tags out of the water", reasons.get("sync_tag_outside_deployment"))]
    per_serial = reasons.get("per_serial") if isinstance(reasons.get("per_serial"), dict) else {}
    not_used = r.get("not_used") if isinstance(r.get("not_used"), dict) else {}
    files = [("detections", _pairs([("file", d.get("file")), ("format", d.get("format")), ("rows", d.get("rows")),
                                    ("used", d.get("used")), ("set aside", d.get("set_aside")),
                                    ("duplicates", d.get("duplicates")),
                                    ("columns ignored", ", ".join(map(str, d.get("ignored_columns") or [])) or None),
                                    ("first (UTC)", d.get("first_utc")), ("last (UTC)", d.get("last_utc"))])),
             ("receivers", _pairs([("file", r.get("file")), ("deployments in the file", r.get("in_sheet")),
                                   ("deployments used", r.get("deployments")), ("receivers", r.get("receivers")),
                                   ("redeployed", ", ".join(map(str, r.get("redeployed") or [])) or None)]
                                  + [(f"not used: {SAID.get(k, k)}", v) for k, v in not_used.items() if k != "count"])),
             ("tag sheet", _pairs([("file", summary_value(s, "tag_sheet", "file")),
                                   ("transmitters", summary_value(s, "tag_sheet", "transmitters"))])
              or [("file", "none: every detected tag that is not a sync tag, its ping type inferred")])]
    frame = s.get("frame") if isinstance(s.get("frame"), dict) else None
    receivers = used_receivers(study)
    others = study.receivers[study.receivers["used"].astype(str).str.strip().str.lower() != "true"] \
        if "used" in study.receivers else None
    sheet = study.tags.drop_duplicates("transmitter")
    return {"files": files, "set_aside": [(k, shown(v)) for k, v in aside if v],
            "per_serial": sorted(((str(k), shown(v)) for k, v in per_serial.items()), key=lambda kv: kv[0]),
            "frame": _pairs([(k, frame.get(k)) for k in ("name", "crs", "chosen", "scale_factor", "scale_note",
                                                        "latlon")]) if frame else [],
            "times": s.get("times"),
            "map": png_image(study.map_png, "the study's map: the receivers used and each tag's track")
            if study.map_png else None,
            "daily": figures.daily_figure(study),
            "receivers": _table(receivers, RECEIVER_TABLE),
            "not_used": None if others is None or not len(others) else
            {"count": len(others), "table": _table(others.head(MAX_NOT_USED),
                                                   {"receiver": "receiver", "serial": "serial", "station": "station",
                                                    "start_utc": "deployed (UTC)", "end_utc": "recovered (UTC)",
                                                    "not_used": "why not used"})},
            "sheet": _table(sheet, SHEET_TABLE)}


def _clocks(study: StudyFolder) -> dict[str, Any]:
    s = study.summary
    c = s.get("clocks") if isinstance(s.get("clocks"), dict) else {}
    noise = s.get("toa_noise") if isinstance(s.get("toa_noise"), dict) else {}
    breaks = [b for b in (c.get("clock_breaks") or []) if isinstance(b, dict)]
    figure, left_out = figures.clock_figure(study)
    sync = study.sync_tags
    columns = {"tag": "sync tag", "receiver": "at receiver", "fixes": "fixes", "median_error_m": "median error [m]",
               "p90_error_m": "90th percentile [m]", "median_sigma_m": "median σ [m]", "nees_mean": "mean NEES",
               "leave_one_out": "left out of the fit"}
    return {"facts": _pairs([("source", c.get("source")), ("reference receiver", c.get("reference_receiver")),
                             ("receivers synchronised", c.get("receivers")),
                             ("not synchronised", ", ".join(map(str, c.get("not_synchronised") or [])) or None),
                             ("bins [h]", c.get("bin_hours")),
                             ("median |residual| [m]", c.get("median_abs_residual_m")),
                             ("sync tags' median error [m]", c.get("sync_tags_median_error_m")),
                             ("synchronisation given", c.get("folder")),
                             ("timing noise", noise.get("source")),
                             ("timing noise, median [ms]", None if noise.get("sigma_s") is None
                              else float(noise["sigma_s"]) * 1e3)]),
            "breaks": [[shown(b.get(k)) for k in ("receiver", "time_utc", "size_s", "size_sigma_s", "segment_before",
                                                  "segment_after", "synchronised")] for b in breaks],
            "figure": figure, "left_out": left_out, "noise": figures.noise_figure(study),
            "sync_figure": figures.sync_tags_figure(study),
            "sync_table": None if sync is None else _table(sync, columns)}


def _tag_section(k: int, row: dict[str, Any], study: StudyFolder, drawn: bool) -> dict[str, Any]:
    tag = shown(row.get("tag")) or shown(row.get("transmitter"))
    code = shown(row.get("reason_code"))
    counts = _pairs([(label, row.get(key)) for key, label in (
        ("detections", "detections"), ("receivers", "receivers that heard it"), ("pings", "pings"),
        ("pings_at_once", "pings heard by enough receivers at once"), ("positioned", "positioned"),
        ("set_aside", "set aside (no pings of the stated interval)"), ("not_positioned", "not positioned"),
        ("not_positioned_why", "not positioned, why"), ("flagged", "flagged"), ("median_sigma_m", "median σ [m]"),
        ("time_resolution_s", "times' resolution [s]"), ("first_utc", "first row (UTC)"),
        ("last_utc", "last row (UTC)"))])
    section = {"anchor": anchor(k, tag), "tag": tag, "name": shown(row.get("name")), "role": shown(row.get("role")),
               "status": shown(row.get("status")), "code": code, "meaning": REASON_CODES.get(code, ""),
               "reason": shown(row.get("reason")), "counts": counts, "flags": [], "facts": [], "figure": None,
               "undrawn": False}
    if row.get("status") != "tracked":
        return section
    summary = study.tag_summaries.get(tag, {})
    speed = summary.get("sound_speed") if isinstance(summary.get("sound_speed"), dict) else {}
    ping = summary.get("ping_type") if isinstance(summary.get("ping_type"), dict) else {}
    section["facts"] = _pairs([
        ("sound speed [m/s]", row.get("sound_speed_m_s")), ("its source", row.get("sound_speed_source")),
        ("how", speed.get("method")), ("its σ [m/s]", speed.get("sigma_m_s")),
        ("ping type", row.get("ping_type")), ("the sheet's", row.get("ping_type_stated")),
        ("burst interval [s]", " to ".join(f"{float(v):.4g}" for v in ping.get("burst_interval_s") or []) or None),
        ("depth", summary_value(summary, "depth", "source")),
        ("timing noise", summary_value(summary, "toa_noise", "source")),
        ("motion model", summary_value(summary, "motion", "model")), ("track", row.get("track"))])
    section["flags"] = [(reason, f"{n:,}") for reason, n in flag_counts(study, tag).items()]
    section["figure"] = tag_figure(study, tag) if drawn else None
    section["undrawn"] = not drawn
    return section


def _tags(study: StudyFolder) -> dict[str, Any]:
    tags = study.tags
    rows = tags.to_dict("records")
    keys = [c for c in TAG_TABLE if c in tags and any(shown(r.get(c)) for r in rows)]  # none empty in every row
    table = [{"anchor": anchor(k, shown(r.get("tag")) or shown(r.get("transmitter"))),
              "tag": shown(r.get("tag")) or shown(r.get("transmitter")),
              "cells": [shown(r.get(c)) for c in keys], "tracked": r.get("status") == "tracked"}
             for k, r in enumerate(rows)]
    codes = tags.loc[tags["status"] != "tracked", "reason_code"].astype(str).value_counts()
    positioned = tags["positioned"].to_numpy(float) if "positioned" in tags else np.zeros(len(tags))
    tracked = np.flatnonzero((tags["status"] == "tracked").to_numpy())
    drawn = set(tracked[np.argsort(-np.nan_to_num(positioned[tracked]), kind="stable")][:MAX_TAG_FIGURES].tolist())
    return {"columns": [TAG_TABLE[c] for c in keys], "rows": table,
            "numeric": [c in tags and tags[c].dtype.kind == "f" for c in keys],
            "reasons": [(code, f"{n:,}", REASON_CODES.get(code, "")) for code, n in codes.items()],
            "sections": [_tag_section(k, r, study, k in drawn) for k, r in enumerate(rows)],
            "max_figures": MAX_TAG_FIGURES}


#: The reference tags' table's columns shown (reference_tags.csv has them all).
REFERENCE_TABLE = {"tag": "tag", "kind": "kind", "truth": "known position", "error_m": "error [m]",
                   "sigma_m": "σ [m]", "nees": "NEES", "beyond_sigma": "beyond its σ", "rows": "rows",
                   "flagged": "flagged", "verdict": "verdict", "scored_by": "scored by",
                   "single_fix_median_error_m": "single fixes' error [m]",
                   "in_sync": "in the sync", "inside_array": "inside the array"}


def _reference(study: StudyFolder) -> dict[str, Any] | None:
    """The reference tags and the sync tags left out in turn: pooled (``study.json``'s ``reference_tags``), per tag
    (``reference_tags.csv``) and drawn; None where neither has a tag."""
    pooled = study.summary.get("reference_tags")
    pooled = pooled if isinstance(pooled, dict) else {}
    table = study.reference
    if (table is None or not len(table)) and not any(isinstance(pooled.get(k), dict)
                                                     for k in ("reference", "sync_left_out")):
        return None
    groups = []
    for key, title in (("reference", "reference tags, pooled"), ("sync_left_out", "sync tags left out, pooled"),
                       ("still", "still tags together, pooled")):
        value = pooled.get(key)
        if isinstance(value, dict):
            groups.append((title, _pairs([(k, ", ".join(map(str, v)) if isinstance(v, list) else v)
                                          for k, v in value.items() if not isinstance(v, dict)])))
    return {"groups": groups, "figure": figures.reference_figure(study),
            "not_scored": [(shown(m.get("tag")), shown(m.get("why"))) for m in pooled.get("not_scored") or []
                           if isinstance(m, dict)],
            "table": None if table is None or not len(table) else _table(table, REFERENCE_TABLE)}


def page_context(study: StudyFolder) -> dict[str, Any]:
    """The template's values (the module docstring)."""
    s = study.summary
    tags = study.tags
    tracked = tags[tags["status"] == "tracked"]
    head = _pairs([("tags tracked", f"{len(tracked):,} of {len(tags):,}"),
                   ("rows positioned", tracked["positioned"].sum() if "positioned" in tracked else None),
                   ("rows flagged", tracked["flagged"].sum() if "flagged" in tracked else None),
                   ("detections used", summary_value(s, "detections", "used")),
                   ("deployments used", summary_value(s, "receivers", "deployments")),
                   ("clocks", summary_value(s, "clocks", "source")),
                   ("frame", summary_value(s, "frame", "name") or "a local frame without a CRS"),
                   ("from", summary_value(s, "detections", "first_utc")),
                   ("to", summary_value(s, "detections", "last_utc"))])
    reference = _reference(study)
    sections = [("study", "The study"), ("receivers", "The receivers"), ("clocks", "The clocks"),
                ("tags", "The tags")] + ([("reference-tags", "The reference tags")] if reference else []) \
        + [("warnings", "Warnings and decisions")]
    return {"name": study.name, "head": head, "sections": sections, "study": _study(study), "clocks": _clocks(study),
            "tags": _tags(study), "reference": reference, "warnings": warnings(study),
            "decisions_rows": [[d["what"], d["taken"], d["how"], d["option"]] for d in decisions(study)],
            "title": shown(summary_value(s, "detections", "file")) or study.name}


__all__ = ["MAX_NOT_USED", "MAX_TAG_FIGURES", "anchor", "page_context", "shown"]

"""A report's warnings and decisions: every warning ``sblsim track`` printed (the study's notes, the receivers
file's notes, each tag's and each reference tag's warning as the console says it:
:func:`~sblsim.orchestrator.telemetry.study_report.tag_lines`, ``reference_lines``)
and every value the study took that its user could have given, with how it was taken and the option that sets it
(the frame, the clocks and their bins, the timing noise, the water's depth, each tag's sound speed, ping type and
depth, which tags were tracked), from ``study.json``, ``tags.csv`` and the tags' ``summary.json``
(:func:`warnings`, :func:`decisions`).
"""

from __future__ import annotations

import re
from collections import Counter
from typing import Any

from sblsim.models.tracking.timing import SIGMA_TOA
from sblsim.orchestrator.io.frames import CHOSEN_GIVEN, CHOSEN_UTM
from sblsim.orchestrator.telemetry.report.figures_study import summary_value
from sblsim.orchestrator.telemetry.report.folder import StudyFolder
from sblsim.orchestrator.telemetry.study_clocks import TOO_COARSE, UNHEARD
from sblsim.orchestrator.telemetry.study_offsets import FITTED, misfit
from sblsim.orchestrator.telemetry.study_positions import lines as position_lines
from sblsim.orchestrator.telemetry.study_report import reference_lines, tag_lines

#: The options that set a tag's sound speed (``sblsim track``'s).
SPEED_OPTIONS = "--sound-speed, --sound-speed-file, or --temperature with --salinity (or --temperature-file)"
#: tags.csv's columns :func:`~sblsim.orchestrator.telemetry.study_report.tag_lines` reads.
LINE_COLUMNS = ("tag", "transmitter", "status", "reason_code", "reason", "detections", "pings", "positioned",
                "set_aside", "not_positioned", "not_positioned_why", "flagged", "median_sigma_m", "ping_type",
                "ping_type_stated", "sound_speed_m_s", "sound_speed_source", "first_utc", "last_utc")


def _text(value: Any) -> str:
    return "" if value is None else str(value)


def warnings(study: StudyFolder) -> list[dict[str, str]]:
    """Every warning of the study, each as ``source`` (where it was said) and ``text``: ``study.json``'s notes (the
    console's ``note:`` lines), the receivers file's notes, the receivers not synchronised, the clocks' fit's misfit
    (:func:`~sblsim.orchestrator.telemetry.study_offsets.misfit`), a refinement of the positions not taken, and each
    tag's warning line as the console printed it."""
    s = study.summary
    out = [{"source": "study", "text": _text(note)} for note in (s.get("notes") or [])]
    out += [{"source": "receivers file", "text": _text(note)}
            for note in (summary_value(s, "receivers", "notes") or [])]
    try:  # as the console said them (a folder of an earlier sblsim may have fewer of their fields)
        scored = reference_lines(s.get("reference_tags"))
    except (KeyError, TypeError, ValueError, AttributeError):
        scored = []
    out += [{"source": "reference tags", "text": re.sub(r"^(sblsim: warning: |note: )", "", line)}
            for line, warning in scored if warning]
    try:
        refined = position_lines(s.get("positions"))
    except (KeyError, TypeError, ValueError, AttributeError):
        refined = []
    out += [{"source": "positions", "text": line.removeprefix("warning: ")} for line, warning in refined if warning]
    missing = summary_value(s, "clocks", "not_synchronised") or []
    if missing:
        out.append({"source": "clocks", "text": f"not synchronised: {', '.join(map(str, missing))} (their detections "
                                                "are not positioned)"})
    try:  # the clocks' fit from the tags' pings leaving more than the noise (as the console warned)
        unheld = misfit(s)
    except (KeyError, TypeError, ValueError, AttributeError):
        unheld = None
    if unheld:
        out.append({"source": "clocks", "text": unheld})
    tags = study.tags
    if set(LINE_COLUMNS) <= set(tags.columns):
        table = tags.assign(**{c: tags[c].fillna("").astype(str) for c in tags if tags[c].dtype == object})
        out += [{"source": "tags", "text": line.removeprefix("sblsim: warning: ")}
                for line, warning in tag_lines(table) if warning]
    return out


def _said(source: str, default: bool) -> str:
    return f"{source} (the default)" if default else f"{source} (given)"


def _frame(s: dict[str, Any]) -> dict[str, str]:
    frame = s.get("frame")
    if not isinstance(frame, dict):
        return {"what": "frame", "taken": "a local frame without a CRS (no latitude and longitude out)",
                "how": "the receivers file's x_m, y_m without --crs", "option": "--crs (the positions' CRS)"}
    chosen = _text(frame.get("chosen"))
    return {"what": "frame", "taken": f"{frame.get('name')} ({frame.get('crs')})",
            "how": "given (--frame)" if chosen == CHOSEN_GIVEN else _said(chosen, chosen == CHOSEN_UTM),
            "option": "--frame EPSG:… (a metric CRS); --crs for the positions' own"}


def _clocks(s: dict[str, Any]) -> list[dict[str, str]]:
    clocks = s.get("clocks") or {}
    source = _text(clocks.get("source"))
    if source == "given":
        return [{"what": "clocks", "taken": f"the synchronisation of {clocks.get('folder')}", "how": "given",
                 "option": "--sync DIR"}]
    if source == "synchronised here":
        return [{"what": "clocks", "taken": f"synchronised here against {clocks.get('reference_receiver')}",
                 "how": "the default: the deployments' sync tags", "option": "--sync DIR (a synchronisation made "
                                                                            "before: sblsim sync --out DIR)"},
                {"what": "synchronisation bins", "taken": f"{clocks.get('bin_hours')} h", "how": "as given, else 1 h",
                 "option": "--bin-hours H"}]
    if source == FITTED:
        return [{"what": "clocks", "taken": f"fitted from the moving tags' pings against "
                                           f"{clocks.get('reference_receiver')}",
                 "how": "the default where the clocks taken as logged were off (no sync tag heard by two "
                        "receivers: the pings left out fit the fitted ones better)",
                 "option": "the deployments' sync tags (transmitter column) or --sync DIR"}]
    why = ("the sync tags' times are too coarse to synchronise" if source == TOO_COARSE else
           "one receiver" if "one receiver" in source else "no sync tag heard by two receivers" if source == UNHEARD
           else "no deployment has a sync tag")
    if clocks.get("checked"):
        why += "; " + ("the tags' pings fit them as well as clocks fitted from them"
                       if (clocks["checked"] or {}).get("held_out") else "not checked against the tags' pings")
    return [{"what": "clocks", "taken": "as logged", "how": f"the default: {why}",
             "option": "the deployments' sync tags (transmitter column) or --sync DIR"}]


def _noise(s: dict[str, Any]) -> dict[str, str]:
    noise = s.get("toa_noise") or {}
    source = _text(noise.get("source"))
    sigma = noise.get("sigma_s")
    shown = f"{float(sigma) * 1e3:.3g} ms" if isinstance(sigma, (int, float)) else "?"
    how = {"synchronisation": "the default: each receiver's from the synchronisation's residuals (median shown)",
           "assumed": f"the default: the tracker's {SIGMA_TOA * 1e3:g} ms (nothing measured it)",
           "given": "given"}.get(source, source or "not said")
    return {"what": "timing noise (TOA σ)", "taken": shown, "how": how, "option": "--toa-sigma S"}


def _water(s: dict[str, Any]) -> dict[str, str]:
    water = s.get("water_depth") or {}
    source = _text(water.get("source"))
    if source == "given":
        return {"what": "water depth", "taken": f"{water.get('water_depth_m')} m", "how": "given",
                "option": "--water-depth M"}
    if source == "bottom_depth":
        per = water.get("per_tag_m") or {}
        return {"what": "water depth", "taken": f"per tag ({len(per)} tags)", "how": "the default: "
                + _text(water.get("rule")), "option": "--water-depth M"}
    return {"what": "water depth", "taken": "none (a tag's depth is not bounded by the bottom)",
            "how": "the default: the receivers file gives no bottom_depth", "option": "--water-depth M"}


def _counted(values: list[str]) -> str:
    return "; ".join(f"{value}: {n:,} tag{'s' if n > 1 else ''}" for value, n in Counter(values).most_common())


def _tags(study: StudyFolder) -> list[dict[str, str]]:
    """The decisions of each tracked tag, counted over the tags: sound speed, ping type, depth."""
    tags = study.tags
    tracked = tags[tags["status"] == "tracked"]
    out = []
    if "sound_speed_source" in tracked and len(tracked):
        sources = tracked["sound_speed_source"].astype(str).tolist()
        given = all(source in ("given", "measured series") for source in sources)
        out.append({"what": "sound speed", "taken": _counted(sources),
                    "how": "given" if given else "the default: calibrated from each tag's pings (a fallback from the "
                                                 "water's temperature and salinity where they do not determine it)",
                    "option": SPEED_OPTIONS})
    if "ping_type_stated" in tracked and len(tracked):
        stated = tracked["ping_type_stated"].astype(str)
        inferred = stated.str.startswith("inferred")
        if inferred.any():
            kinds = tracked.loc[inferred, "ping_type"].astype(str).tolist() if "ping_type" in tracked else []
            out.append({"what": "ping type", "taken": _counted(kinds) or "inferred",
                        "how": "the default: inferred from the pings (the tag sheet states none)",
                        "option": "the tag sheet's ping_type with min_delay and max_delay, interval or burst_sequence "
                                  "(--tags)"})
    depths = [_text(summary_value(study.tag_summaries.get(str(t), {}), "depth", "source"))
              for t in tracked.get("tag", [])]
    depths = [d for d in depths if d]
    if depths:
        out.append({"what": "tag depth", "taken": _counted(depths),
                    "how": "the default: a depth sensor's readings where the tag sheet converts them, else estimated "
                           "in 3-D, none in 2-D",
                    "option": "the receivers file's instrument_depth or z_m (3-D); the tag sheet's sensor_type, "
                              "sensor_slope, sensor_intercept"})
    chosen = "the tag sheet's animal and reference tags" if study.summary.get("tag_sheet") else \
        "every detected tag that is not a sync tag (no tag sheet)"
    out.append({"what": "tags tracked", "taken": f"{len(tags):,} asked", "how": f"as --tag names them, else {chosen}",
                "option": "--tag IDS; --tags SHEET"})
    return out


def decisions(study: StudyFolder) -> list[dict[str, str]]:
    """Every value the study took that its user could have given: ``what``, ``taken`` (the value), ``how`` (the
    default and its source, or given) and ``option`` (what sets it)."""
    s = study.summary
    return [_frame(s), *_clocks(s), _noise(s), _water(s), *_tags(study)]


__all__ = ["SPEED_OPTIONS", "decisions", "warnings"]

"""A telemetry study's clocks (:func:`study_clocks`): a synchronisation's folder given (its ``offsets.csv``, its
refined positions and their errors where it has them); else synchronised here from the deployments' sync tags
(:func:`~sblsim.orchestrator.sync.run.synchronise`); else, where no deployment has a sync tag, no two receivers hear
one or the times are too coarse, taken as logged (said).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.sync.emissions import SyncTagsUnheard
from sblsim.models.sync.resolution import RoundingError
from sblsim.orchestrator.io.arguments import real_argument
from sblsim.orchestrator.readers.deployments import Deployments
from sblsim.orchestrator.readers.limits import MAX_HYDROPHONES, SOUND_SPEED_RANGE
from sblsim.orchestrator.readers.receivers_file import SURVEY_SIGMA_RANGE
from sblsim.orchestrator.sync.clocks import logged_clocks, offsets_clocks, read_clocks, read_positions, with_positions
from sblsim.orchestrator.sync.estimated_speed import estimated_speed
from sblsim.orchestrator.sync.run import NEVER_HEARD, synchronise
from sblsim.orchestrator.sync.segments import NOT_SYNCHRONISED
from sblsim.orchestrator.sync.taken_survey import folder_position_sigmas, folder_survey, read_sync_json

#: The most windows a synchronisation's folder may say (a year in windows of an hour).
MAX_WINDOWS = 10_000
#: The clocks' source where the sync tags' times were rounded too coarsely to synchronise them.
TOO_COARSE = "as logged (times too coarse to synchronise)"
#: The clocks' source where the deployments' sync tags are not heard by two receivers (the detections hold none of them,
#: or each is heard by its own receiver alone).
UNHEARD = "as logged (no sync tag heard)"
#: The clocks' source where no deployment names a sync tag.
NO_SYNC_TAG = "as logged (no sync tag)"
#: The clocks' source where they are synchronised here from the deployments' sync tags.
SYNCHRONISED_HERE = "synchronised here"
#: The clocks' source where they are a synchronisation's folder given (``--sync DIR``).
GIVEN = "given"


def study_clocks(sync_dir: Path | None, assigned, deployments: Deployments, sound_speed: float | None,
                 series: tuple[np.ndarray, np.ndarray] | None, bin_hours: float, notes: list[str],
                 survey_sigma: float | None = None, take_seen: bool = True, release_rows: bool = False):
    """A study's clocks (:mod:`sblsim.orchestrator.telemetry.study`, step 2): the clocks, the receivers table they go
    with, what was done, and the synchronisation made here (or None); ``survey_sigma`` [m] the survey's stated
    error, in the sync tags' NEES (:func:`~sblsim.orchestrator.sync.run.synchronise`; none stated: the error its
    residuals show, taken where seen unless ``take_seen`` is False); ``release_rows``: ``assigned``'s rows emptied
    once the synchronisation has taken its arrivals from them (the study reads them no more).

    Raises
    ------
    ModelError
        A synchronisation that cannot be made, or a folder's files refused (one line).
    """
    table = assigned.hydrophones
    if sync_dir is not None:
        clocks = read_clocks(sync_dir)
        refined = read_positions(sync_dir)
        table, _ = with_positions(table, refined)
        missing = sorted(set(table["receiver"]) - set(clocks.receivers))
        # the survey error its synchronisation saw and took, as one made here would; on refined positions, each one's
        each = None if refined is None else folder_position_sigmas(sync_dir, table["receiver"].astype(str).tolist())
        read = read_sync_json(sync_dir)  # (once: its survey error and its speed)
        taken = None if refined is not None else folder_survey(sync_dir, read)
        return clocks, table, {"source": GIVEN, "folder": str(sync_dir), "reference_receiver": clocks.reference(),
                               "receivers": len(clocks.receivers),
                               "not_synchronised": missing,
                               "positions": "refined (positions.csv)" if refined is not None else "the table's"} | (
            {} if taken is None else {"survey_sigma_m": taken, "survey_sigma_from": "seen"}) | (
            {} if each is None else {"position_sigma_m": each}) | folder_speed(sync_dir, read), None
    rounded = unheard = None
    if (table["sync_tag"] != "").any() and len(table) > 1:
        try:
            outcome = synchronise(assigned.detections, table, sound_speed, series, bin_hours,
                                  receivers_file=deployments.source, alternatives=deployments.alternatives(),
                                  survey_sigma=survey_sigma, take_seen=take_seen, release_rows=release_rows)
        except RoundingError as exc:  # no clock can be synchronised: each tag says what that allows
            rounded = str(exc)
        except SyncTagsUnheard as exc:  # the sync tags named, none heard by two receivers: as with none named
            unheard = exc.reason
        else:
            s = outcome.summary
            notes.extend(s.get("warnings", []))  # each clock break found, in one line
            # why a receiver is not synchronised, and the sync tags nobody heard (one mistyped, or dead)
            notes.extend(n for n in s.get("notes", []) if n.startswith((NOT_SYNCHRONISED, NEVER_HEARD)))
            info = {"source": SYNCHRONISED_HERE, "reference_receiver": s["reference_receiver"],
                    "receivers": len(s["synchronised"]), "not_synchronised": s["not_synchronised"],
                    "clock_breaks": s["clock_breaks"],
                    "median_abs_residual_m": s["median_abs_residual_m"], "bin_hours": bin_hours,
                    "sync_tags_median_error_m": (s["sync_tags"] or {}).get("median_error_m"),
                    "survey_error": s.get("survey_error"), "survey_sigma_m": s.get("survey_sigma_m"),
                    "survey_sigma_from": s.get("survey_sigma_from")}
            info |= estimated_speed(s)
            if "windows" in s:  # a season fitted window by window (sblsim.models.sync.windows)
                info["windows"] = s["windows"]
            return offsets_clocks(outcome.offsets), table, info, outcome
    named = sorted(set(table["sync_tag"]) - {""})
    first, last = assigned.kept_span()
    alone = len(table) == 1  # one receiver: no other clock to synchronise it against (and nothing to position)
    notes.append(note := f"the clocks are taken as logged, not synchronised: {rounded}" if rounded else
                 "one receiver: its clock is taken as logged (no other to synchronise it against)" if alone else
                 f"the clocks are taken as logged (synchronised already), not synchronised: {unheard} (the "
                 f"deployments' {len(named)} sync tags: {', '.join(named[:6])}{', ...' if len(named) > 6 else ''}); "
                 "give the raw detections with the sync tags' or --sync DIR where they are not" if unheard else
                 "no deployment has a sync tag: the receivers' clocks are taken as logged (synchronised already); "
                 "give the deployments' sync tags (transmitter column) or --sync DIR where they are not")
    source = (TOO_COARSE if rounded else "as logged (one receiver)" if alone else UNHEARD if unheard
              else NO_SYNC_TAG)
    return logged_clocks(table["receiver"].tolist(), float(np.floor(first)), float(np.ceil(last))), \
        table, {"source": source, "receivers": int(len(table)), "not_synchronised": [], "note": note}, None


def folder_speed(folder: Path, read: tuple[dict | None, str] | None = None) -> dict:
    """The sound speed a synchronisation's ``folder`` (``--sync DIR``) estimated and its σ, as :func:`estimated_speed`
    gives them where the synchronisation is made here, from its ``sync.json`` read as anyone's
    (:func:`~sblsim.orchestrator.sync.taken_survey.read_sync_json`; ``read``: as it gave it already, else read
    here): the numbers taken checked in their ranges, nothing else in it read; nothing where the folder has no
    ``sync.json`` or its speed was given.

    Raises
    ------
    ModelError
        ``sync.json`` refused, or a number it holds for the speed outside its range (one line naming it).
    """
    data, shown = read_sync_json(folder) if read is None else read
    speed = None if data is None else data.get("sound_speed")
    if not isinstance(speed, dict) or speed.get("source") != "estimated" or speed.get("sound_speed_sigma_m_s") is None:
        return {}
    low, high = SOUND_SPEED_RANGE
    c = real_argument(speed.get("sound_speed_m_s"), f"{shown} sound_speed.sound_speed_m_s", low, high, "m/s")
    fit = real_argument(speed["sound_speed_sigma_m_s"], f"{shown} sound_speed.sound_speed_sigma_m_s", 0.0,
                        high - low, "m/s")
    seen = data.get("survey_error") if isinstance(data.get("survey_error"), dict) else {}
    checked = {"seen": seen.get("seen") is True}
    for key, high, unit in (("speed_scale_sigma_per_m", 1.0, "1/m"), ("survey_sigma_se_m", 1e300, "m"),
                            ("survey_sigma_m", SURVEY_SIGMA_RANGE[1], "m")):
        if seen.get(key) is not None:
            checked[key] = real_argument(seen[key], f"{shown} survey_error.{key}", 0.0, high, unit)
    taken = data.get("survey_sigma_m")
    where = f"{shown} survey_sigma_m"
    if isinstance(taken, dict):  # each receiver's
        if len(taken) > MAX_HYDROPHONES:
            raise ModelError(f"{where}: {len(taken)} receivers; allowed: at most {MAX_HYDROPHONES}")
        taken = {k: real_argument(v, f"{where}[{str(k)[:40]!r}]", *SURVEY_SIGMA_RANGE, "m") for k, v in taken.items()}
    elif taken is not None:
        taken = real_argument(taken, where, *SURVEY_SIGMA_RANGE, "m")
    spread, windows = _folder_windows(data, speed, shown)
    return estimated_speed({"sound_speed": {"source": "estimated", "sound_speed_m_s": c, "sound_speed_sigma_m_s": fit,
                                            "windows_spread_m_s": spread},
                            "survey_sigma_m": taken, "survey_error": checked, "windows": windows})


def _folder_windows(data: dict, speed: dict, shown: str) -> tuple[float | None, dict | None]:
    """A season's windows' speeds in a folder's ``sync.json`` (``data``; its ``sound_speed`` ``speed``), each number
    checked in its range (:func:`folder_speed`): the windows' spread [m/s] and their edges [s since 1970 UTC], speeds
    and σ [m/s]; None, None where it has none.

    Raises
    ------
    ModelError
        A number outside its range, edges not increasing or not one more than the speeds (one line naming it).
    """
    windows = data.get("windows")
    if not isinstance(windows, dict) or speed.get("windows_spread_m_s") is None or "sound_speed_m_s" not in windows:
        return None, None
    low, high = SOUND_SPEED_RANGE
    spread = real_argument(speed["windows_spread_m_s"], f"{shown} sound_speed.windows_spread_m_s", 0.0, high - low,
                           "m/s")
    where = f"{shown} windows"
    each = [windows.get(k) if isinstance(windows.get(k), list) else [] for k in
            ("edges", "sound_speed_m_s", "sound_speed_sigma_m_s")]
    if not 2 <= len(each[0]) <= MAX_WINDOWS + 1 or len(each[1]) != len(each[0]) - 1 or len(each[2]) != len(each[1]):
        raise ModelError(f"{where}: {len(each[0])} edges, {len(each[1])} speeds and {len(each[2])} sigmas; allowed: "
                         f"one more edge than speeds and sigmas, at most {MAX_WINDOWS} windows")
    edges = [real_argument(v, f"{where}.edges", 0.0, 1e11, "s") for v in each[0]]
    if not all(b > a for a, b in zip(edges, edges[1:])):
        raise ModelError(f"{where}.edges: not increasing; allowed: the windows' edges in time order")
    return spread, {"edges": edges,
                    "sound_speed_m_s": [real_argument(v, f"{where}.sound_speed_m_s", low, high, "m/s")
                                        for v in each[1]],
                    "sound_speed_sigma_m_s": [None if v is None else real_argument(
                        v, f"{where}.sound_speed_sigma_m_s", 0.0, high - low, "m/s") for v in each[2]]}


def taken_survey(stated: float | None, refine: bool, info: dict) -> float | dict[str, float] | None:
    """The receivers' survey error [m per horizontal axis] a study's σ take: the one ``stated`` (0: none, the
    positions taken as exact), else, without the refinement (``refine``: its prior is the survey's), a given folder's
    refined positions' errors by receiver (``info``: :func:`study_clocks`' summary, its ``position_sigma_m``) or the
    error the synchronisation saw in its residuals and took (its ``survey_sigma_from`` ``"seen"``), else None
    (exact)."""
    if stated is not None:
        return None if stated == 0 else stated
    if refine:
        return None
    if info.get("position_sigma_m"):
        return dict(info["position_sigma_m"])
    return float(info["survey_sigma_m"]) if info.get("survey_sigma_from") == "seen" else None


__all__ = ["GIVEN", "NO_SYNC_TAG", "SYNCHRONISED_HERE", "TOO_COARSE", "UNHEARD", "folder_speed",
           "study_clocks", "taken_survey"]

"""A tag's row of ``tags.csv`` (``sblsim track``): every ping of it counted once, ``pings`` = ``positioned`` +
``set_aside`` + ``not_positioned``, the pings not positioned counted by why (``not_positioned_why``), and
``tracked`` only with a row positioned (:func:`tracked_row`); the counts of a tag none of whose pings is positioned
(:func:`unpositioned`); the tag's matrix as written for the tracker, a column per receiver that heard it
(:func:`heard_columns`).

A tracked tag's pings not positioned are those before the ping the tracker starts from (``before_track_start``: its
first position needs a ping heard by ``dim + 2`` receivers at once) and those its track holds no estimate of
(``no_estimate``); a tag whose track positions none is no track (``refused``, ``no_position``): its rows are in no
output but its row of ``tags.csv``.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from sblsim.models.tracking.strays import SET_ASIDE_REASON
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.sync.toa import ToaOutcome, header_line
from sblsim.orchestrator.telemetry.census import code_of


def unpositioned(pings: int, at_once: int = 0, code: str | None = None) -> dict[str, Any]:
    """A tag's counts in ``tags.csv`` where none of its ``pings`` is positioned (``code``: why, where known)."""
    return {"pings": int(pings), "pings_at_once": int(at_once), "positioned": 0, "set_aside": 0,
            "not_positioned": int(pings), "not_positioned_why": f"{code} {int(pings)}" if code and pings else "",
            "flagged": 0}


def heard_columns(matrix: ToaOutcome) -> ToaOutcome:
    """A tag's matrix with the columns of the receivers that heard it only (the tracker drops the others; a column
    per deployment of a network's sheet would make a line of thousands of cells its reader refuses)."""
    heard = np.flatnonzero(np.isfinite(matrix.toa).any(axis=0))
    if len(heard) == len(matrix.names):
        return matrix
    names = [matrix.names[k] for k in heard]
    summary = matrix.summary | {"receivers": names, "toa_header": header_line(names)}
    if summary.get("toa_sigma_s"):
        summary["toa_sigma_s"] = {n: summary["toa_sigma_s"][n] for n in names}
    return replace(matrix, toa=matrix.toa[:, heard], names=names, positions=matrix.positions[heard],
                   summary=summary, toa_sigma=None if matrix.toa_sigma is None else matrix.toa_sigma[heard],
                   clock_sigma=None if matrix.clock_sigma is None else matrix.clock_sigma[heard],
                   clock_mean=None if matrix.clock_mean is None else matrix.clock_mean[heard],
                   rounding=None if matrix.rounding is None else matrix.rounding[heard])


def tracked_row(result, elapsed: float, row: dict[str, Any]) -> dict[str, Any]:
    """A tag's ``tags.csv`` fields from its tracking's outcome (or the one line of its refusal; ``row``: its fields
    so far): every ping positioned, set aside or not positioned with why (before the track's start, no estimate);
    ``tracked`` only with a row positioned."""
    if isinstance(result, str):
        return {"status": "refused", "reason": result, "reason_code": code_of(result), "wall_time_s": elapsed} | \
            unpositioned(row["pings"], row["pings_at_once"], code_of(result))
    s = result.summary
    main = s["track"]
    track = result.track
    pings = int(s["pings"])
    rows = result.estimates[result.estimates["estimator"] == main]
    aside = (rows["quality_reason"] == SET_ASIDE_REASON).to_numpy()
    placed = ~aside & np.isfinite(rows[["x", "y"]].to_numpy(float)).all(axis=1)
    at = rows["ping"].to_numpy()[placed]
    missing = np.setdiff1d(np.arange(pings), rows["ping"].to_numpy()[placed | aside])
    before = int((missing < at.min()).sum()) if len(at) else len(missing)
    why = {"before_track_start": before, "no_estimate": len(missing) - before}
    counts = {"pings": pings, "positioned": int(placed.sum()), "set_aside": int(aside.sum()),
              "not_positioned": len(missing), "not_positioned_why": "; ".join(f"{k} {v}" for k, v in why.items() if v)}
    if not placed.any():
        need = int(s["dimensions"]) + 1
        reason = (f"the tracker positioned none of its {pings:,} pings ({int(aside.sum()):,} set aside as no pings of "
                  f"the stated interval; {row['pings_at_once']:,} heard by {need} receivers or more at once): its "
                  f"start, a ping heard by {need + 1} receivers at once that the others agree with, was not found")
        return counts | {"status": "refused", "reason_code": "no_position", "reason": reason,
                         "not_positioned_why": f"no_position {len(missing)}" if len(missing) else "",
                         "wall_time_s": elapsed}
    flagged = int(s["flagged"].get(main, 0)) - int(aside.sum())
    sigma = np.hypot(track["sigma_x"].to_numpy(float), track["sigma_y"].to_numpy(float))
    ok = (track["quality"] != "flagged").to_numpy() & np.isfinite(sigma)
    times = track["epoch_s"].to_numpy(float)[placed] if "epoch_s" in track else np.array([])
    return counts | {"status": "tracked", "reason": "", "reason_code": "", "flagged": flagged,
                     "share_flagged": flagged / int(placed.sum()),
                     "two_places": (s.get("two_places") or {}).get("warning", ""),
                     "median_sigma_m": float(np.median(sigma[ok])) if ok.any() else float("nan"),
                     "ping_type": s["ping_type"]["type"], "track": main,
                     "sound_speed_m_s": s["sound_speed"]["sound_speed_m_s"],
                     "sound_speed_source": s["sound_speed"]["source"],
                     "first_utc": iso_utc(times[:1])[0] if len(times) else "",
                     "last_utc": iso_utc(times[-1:])[0] if len(times) else "", "wall_time_s": s["wall_time_s"]}


__all__ = ["heard_columns", "tracked_row", "unpositioned"]

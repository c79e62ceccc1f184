"""Every proposed design confirmed by Monte Carlo: what a vehicle gets where the design's map predicts.

* **Static vehicles** (:func:`static_check`): at the work area's worst point (the largest DRMS among the points
  with a fix of direct rays) and at its median point, a vehicle held still for a few cycles,
  ``monte_carlo.replicates`` runs of the design's scenario with the ``lsq`` receiver (a fix from each cycle's latest
  measurements and the depth, no motion model: what the map describes), its fixes after the first cycle; the
  horizontal (or 3-D) RMS error of those fixes against the map's DRMS there. A ratio outside
  ``1 ± monte_carlo.tolerance_pct`` is flagged (``confirmed`` false), never hidden. The share of the runs'
  cycles whose own packets give a fix (:func:`fresh_fix_cycles`: at least the system's packets of a fix received
  among the cycle's slots, every lane of a delivery counted) is reported beside the predicted availability, the
  probability of just that.
* **A path** (:func:`path_check`): the scenario's receiver on a straight path across the work area (through its
  centre, North to South, at the first depth, at :data:`PATH_SPEED`, at most :data:`PATH_SLOTS` sampling times
  long), ``monte_carlo.path_replicates`` runs (:func:`sblsim.orchestrator.montecarlo.compare.compare`): its RMS
  error, NEES and PCRB beside the map's RMS along the path. A filter averages cycles and a moving vehicle's
  measurements are of different instants, so this is what a receiver makes of the design, not a check of the map.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.acoustics.channel.lanes import lane_name
from sblsim.models.design.criteria import ECHO_LIMIT
from sblsim.orchestrator.cosim.plan import with_replicates
from sblsim.orchestrator.cosim.run import run_batch
from sblsim.orchestrator.design.judgement import Design
from sblsim.orchestrator.design.resolution import Resolved, plan_of
from sblsim.orchestrator.maps import point_accuracy
from sblsim.orchestrator.montecarlo.compare import compare

#: The path's speed [m/s] (an AUV's transit).
PATH_SPEED = 2.0
#: The longest path, in sampling times.
PATH_SLOTS = 100


def checked_points(design: Design, resolved: Resolved) -> list[tuple[str, np.ndarray]]:
    """The worst and the median point of a design's map over the work area, named: among the points with a fix
    whose ranges are the direct rays' (:data:`~sblsim.models.design.criteria.ECHO_LIMIT`), where the map predicts
    the fix."""
    dimensions = resolved.sections["prescription"]["dimensions"]
    drms = design.values["drms" if dimensions == "horizontal" else "drms_3d"]
    finite = np.flatnonzero(np.isfinite(drms) & (design.values["echo"] <= ECHO_LIMIT))
    if finite.size == 0:
        return []
    worst = finite[np.argmax(drms[finite])]
    order = finite[np.argsort(drms[finite], kind="stable")]
    median = order[(len(order) - 1) // 2]
    points = [("worst", resolved.points[worst])]
    if median != worst:
        points.append(("median", resolved.points[median]))
    return points


def static_check(design: Design, resolved: Resolved, where: str, point: np.ndarray) -> dict:
    """A static vehicle's fixes at ``point`` (N, E, D [m]) against the design's map there (module docstring).

    Returns
    -------
    dict
        ``point`` (its name), ``east_m``, ``north_m``, ``depth_m``, ``predicted_drms_m``, ``simulated_drms_m``,
        ``ratio`` (simulated over predicted), ``confirmed``, ``fixes``, ``predicted_availability``,
        ``simulated_availability`` (the share of the runs' complete cycles whose own packets give a fix,
        :func:`fresh_fix_cycles`: what ``predicted_availability`` predicts).
    """
    mc = resolved.sections["monte_carlo"]
    horizontal = resolved.sections["prescription"]["dimensions"] == "horizontal"
    n, e, d = (float(v) for v in point)
    probe = plan_of(resolved, design.items)
    slots = 1 if probe.system.measures_direction else design.candidate.count
    period = float(probe["simulation"]["sampling_time"])
    warm = (slots + 2) * period  # every transducer heard once, and the flight of the last
    duration = warm + mc["cycles"] * slots * period
    plan = plan_of(resolved, [*design.items, "simulation.receiver=lsq", "target.trajectory=file",
                              f"target.waypoints=0 {n!r} {e!r} {d!r}; 100 {n!r} {e!r} {d!r}",
                              f"simulation.duration={duration!r}"])
    predicted = point_accuracy(plan, np.array([[n, e, d]]))
    predicted_drms = float(predicted["drms" if horizontal else "drms_3d"][0])
    ts = run_batch(with_replicates(plan, range(mc["replicates"])), "local", timeseries=True).timeseries
    seq = ts["packet_seq"].to_numpy()
    first = np.r_[True, ts["replicate"].to_numpy()[1:] != ts["replicate"].to_numpy()[:-1]]
    new = (seq != np.r_[0, seq[:-1]]) & ~first & (seq > 0) & ts["packet_valid"].to_numpy(bool)
    estimated = np.isfinite(ts[["est_x", "est_y", "est_z"]].to_numpy()).all(axis=1)  # NaN: no fix yet, not a fix
    rows = ts[new & (ts["time"].to_numpy() > warm) & estimated]
    error = rows[["est_x", "est_y", "est_z"]].to_numpy() - rows[["true_x", "true_y", "true_z"]].to_numpy()
    if horizontal:
        error = error[:, :2]
    simulated = float(np.sqrt(np.mean(np.sum(error ** 2, axis=1)))) if len(rows) else math.nan
    ratio = simulated / predicted_drms if np.isfinite(predicted_drms) and predicted_drms > 0 else math.nan
    fresh, complete = fresh_fix_cycles(ts, slots, probe.system.fix_packets)
    return {"point": where, "east_m": e, "north_m": n, "depth_m": d, "predicted_drms_m": predicted_drms,
            "simulated_drms_m": simulated, "ratio": ratio,
            "confirmed": bool(np.isfinite(ratio) and abs(ratio - 1.0) <= mc["tolerance_pct"] / 100.0),
            "fixes": int(len(rows)), "predicted_availability": float(predicted["availability"][0]),
            "simulated_availability": fresh / complete if complete else math.nan}


def fresh_fix_cycles(ts: pd.DataFrame, slots: int, fix_packets: int) -> tuple[int, int]:
    """The cycles of a run's time series whose own packets give a fix, and its complete cycles.

    A cycle is ``slots`` successive slots of the channel's counter (slot k of cycle ``(k − 1) // slots``: every
    transducer's once, :mod:`sblsim.models.acoustics.core`); it is complete where every one of its packets was
    delivered (received or lost) before the run ended, and it gives a fix where at least ``fix_packets`` of them
    were received from distinct transducers: the event whose probability the availability map gives
    (:func:`sblsim.orchestrator.maps.availability_map`), ranges of earlier cycles not counted. Every lane of a
    delivery is read (``lane2_packet_seq`` ..., where the run recorded them): two packets arriving within one
    sampling time are both counted.

    Parameters
    ----------
    ts : DataFrame
        A run's time series (:func:`~sblsim.orchestrator.cosim.run.run_batch`): ``replicate``, ``packet_seq``,
        ``packet_valid``, ``beacon_id`` and the later lanes' same columns where recorded.
    slots, fix_packets : int
        The slots of a cycle and the packets of one cycle a fix needs
        (:attr:`~sblsim.models.systems.System.fix_packets`).

    Returns
    -------
    fresh, complete : int
        Over all replicates.
    """
    parts = []
    for prefix in ["", *(lane_name(m, "") for m in range(2, LANES + 1))]:
        if prefix + "packet_seq" not in ts:
            continue
        part = ts[["replicate", prefix + "packet_seq", prefix + "beacon_id", prefix + "packet_valid"]]
        parts.append(part.set_axis(["replicate", "seq", "beacon", "valid"], axis=1))
    packets = pd.concat(parts, ignore_index=True)
    # a packet shows on the outputs until the next delivery: each slot once, whichever steps and lanes held it
    packets = packets[packets["seq"] > 0].drop_duplicates(["replicate", "seq"])
    packets = packets.assign(cycle=(np.rint(packets["seq"]).astype(np.int64) - 1) // slots)
    heard = packets[packets["valid"].to_numpy(float) > 0.5]
    delivered = packets.groupby(["replicate", "cycle"]).size()
    complete = delivered.index[delivered.to_numpy() == slots]
    fixes = heard.groupby(["replicate", "cycle"])["beacon"].nunique().reindex(complete, fill_value=0)
    return int(np.count_nonzero(fixes.to_numpy() >= fix_packets)), int(len(complete))


def path_check(design: Design, resolved: Resolved) -> list[dict]:
    """The scenario's receiver on a path across the work area (module docstring): one row, ``receiver``, ``runs``,
    ``length_m`` (the path's), ``rms_e_tot_m`` (the receiver's RMS 3-D error over the runs), ``pcrb_rms_m`` (None
    where the run has no finite bound), ``nees`` and ``map_rms_drms_m`` (the
    map's RMS 3-D DRMS along the path: the one-round fix's prediction)."""
    mc = resolved.sections["monte_carlo"]
    low, high = resolved.area.bounds()
    centre = [float(v) for v in (low + high) / 2.0]
    depth = float(resolved.depths[0])
    probe = plan_of(resolved, design.items)
    inside = resolved.points[np.isclose(resolved.points[:, 2], depth)]
    across = inside[np.isclose(inside[:, 1], inside[np.argmin(np.abs(inside[:, 1] - centre[1])), 1]), 0]
    length = min(float(np.ptp(across)), PATH_SPEED * PATH_SLOTS * float(probe["simulation"]["sampling_time"]))
    start, end = centre[0] + length / 2.0, centre[0] - length / 2.0
    duration = length / PATH_SPEED
    waypoints = f"0 {start!r} {centre[1]!r} {depth!r}; {duration!r} {end!r} {centre[1]!r} {depth!r}"
    plan = plan_of(resolved, [*design.items, "target.trajectory=file", f"target.waypoints={waypoints}",
                              f"simulation.duration={duration!r}"])
    row = next(compare([plan], replicates=mc["path_replicates"]).itertuples())
    along = np.column_stack([np.linspace(start, end, 101), np.full(101, centre[1]), np.full(101, depth)])
    drms = np.asarray(point_accuracy(plan, along)["drms_3d"], float)
    fixed = np.isfinite(drms)  # none where no point of the path is positioned (a work area out of reach): null
    return [{"receiver": row.receiver, "runs": int(row.runs), "length_m": length, "rms_e_tot_m": float(row.rms_e_tot),
             "pcrb_rms_m": float(row.pcrb_rms) if np.isfinite(row.pcrb_rms) else None, "nees": float(row.nees),
             "map_rms_drms_m": float(np.sqrt(np.mean(drms[fixed] ** 2))) if fixed.any() else None}]


def confirm(design: Design, resolved: Resolved) -> None:
    """The design's Monte Carlo checks (module docstring), into ``design.monte_carlo`` and ``design.path``."""
    design.monte_carlo = [static_check(design, resolved, name, point)
                          for name, point in checked_points(design, resolved)]
    design.path = path_check(design, resolved) if resolved.sections["monte_carlo"]["path"] else []


__all__ = ["PATH_SLOTS", "PATH_SPEED", "checked_points", "confirm", "fresh_fix_cycles", "path_check", "static_check"]

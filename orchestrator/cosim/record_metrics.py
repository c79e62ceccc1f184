"""A batch's metrics from its record: every run's metrics row and the position bound per step, in one compiled pass
over the recorded outputs (:func:`sblsim.orchestrator.cosim.metrics.run_metrics`), the runs whose system steps a bound
of its own (USBL's, a ranging system's with error states) taking that one, compiled, in place of the pass's range
bound; the later lanes of a delivery read where they were recorded.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from sblsim.fmus import compiled_metrics
from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.acoustics.channel.lanes import lane_name
from sblsim.models.bound import FIXED
from sblsim.models.columns import LANE_METRIC_INPUTS, TIMESERIES_COLUMNS, lane_source
from sblsim.orchestrator.cosim.metrics import (
    METRIC_INPUTS,
    bound_rms,
    errors,
    lane_slots,
    new_pings,
    run_flags,
    run_metrics,
    slots,
)
from sblsim.orchestrator.cosim.plan import RunPlan

#: The recorded outputs :func:`sblsim.orchestrator.cosim.metrics.run_flags` reads (all among the metrics' inputs).
FLAG_INPUTS = ("packet_seq", "packet_valid", "beacon_id", "gated", "instr_valid", "true_x", "true_y")


def _metrics(plans: Sequence[RunPlan], rec: dict, replicates: list[int],
             with_bound: bool) -> tuple[pd.DataFrame, np.ndarray | None]:
    """The metrics row of every run (and the PCRB per step) from the recorded floats, in one compiled pass
    (the runs whose system steps a bound of its own, :func:`_system_bound`, take that one in place of the pass's
    range bound: USBL's, or a ranging system's with error states)."""
    dt = plans[0].sampling_time
    parameters = [p.bound for p in plans]
    fixed = np.array([[dt] + [p[k] for k in FIXED[1:]] for p in parameters])  # (B, 8)
    arms = np.stack([p.lever_arms for p in plans], axis=0)  # (B, n, 3)
    system = plans[0].system
    own = np.array([system.own_bound(p) for p in parameters])  # the runs that step the system's own bound
    lanes = _recorded_lanes(rec, _lane_sources({}))
    values, bound = run_metrics({**{name: rec[TIMESERIES_COLUMNS[name]] for name in METRIC_INPUTS}, **lanes},
                                fixed, arms, with_bound and not own.all())
    if own.any():
        chosen = np.flatnonzero(own)
        theirs = _system_bound(system, rec, None if own.all() else chosen, dt, [parameters[i] for i in chosen],
                               arms[chosen])
        if with_bound:
            bound = np.empty((theirs.shape[0], len(plans))) if bound is None else bound
            bound[:, chosen] = theirs
        values["pcrb_rms"] = np.asarray(values["pcrb_rms"], dtype=float).copy()
        position = {kind: np.stack([np.asarray(rec[TIMESERIES_COLUMNS[f"{kind}_{a}"]], dtype=float)[:, chosen]
                                    for a in "xyz"], axis=-1) for kind in ("true", "est")}
        estimated = np.isfinite(errors(position["true"], position["est"])).all(axis=-1)  # the steps e_tot_rms takes
        values["pcrb_rms"][chosen] = bound_rms(theirs, estimated)
    spread = np.array([p.horizontal_spread for p in plans])
    flags = run_flags({**{name: rec[TIMESERIES_COLUMNS[name]] for name in FLAG_INPUTS}, **lanes}, spread,
                      arms.shape[1])
    return pd.DataFrame({"replicate": replicates, **values, **flags}), bound


def _system_bound(system, rec: dict, chosen: np.ndarray | None, dt: float, parameters: Sequence[dict],
                  arms: np.ndarray) -> np.ndarray:
    """The position PCRB (N, B) [m] of runs that step the system's own bound (USBL's,
    :func:`sblsim.models.systems.usbl_bound.pcrb`; a ranging system's with error states,
    :func:`sblsim.models.error_bound.error_pcrb`), compiled (:func:`sblsim.fmus.compiled_metrics.system_pcrb`): its
    per-run inputs :attr:`~sblsim.models.systems.System.bound_fixed` from the bound's parameters, its per-step
    inputs :attr:`~sblsim.models.systems.System.bound_steps` from the record (``true_*``, the position the
    packet carries, the transmitting beacon's lever arm ``arms`` (B, n, 3), the slot and whether the packet was
    received, and the system's :attr:`~sblsim.models.systems.System.bound_columns`: USBL's attitude of the packet's
    direction), of the runs ``chosen`` among the record's columns (None: all of them)."""
    def column_of(source: str) -> np.ndarray:
        values = np.asarray(rec[source], dtype=float)
        return values if chosen is None else values[:, chosen]

    column = {name: column_of(TIMESERIES_COLUMNS[name])
              for name in ("true_x", "true_y", "true_z", "packet_seq", "packet_valid", "beacon_id", "beacon_x",
                           "beacon_y", "beacon_z")}
    received = (column["packet_valid"] > 0.5) & (np.rint(column["beacon_id"]) >= 1)
    slot, fresh = slots(np.rint(column["packet_seq"]), received)
    index = np.clip(np.rint(column["beacon_id"]).astype(int) - 1, 0, arms.shape[1] - 1)  # (N, B)
    arm = arms[np.arange(arms.shape[0])[None, :], index]  # (N, B, 3): the transmitting beacon's
    sources = {**{f"true_{a}": column[f"true_{a}"] for a in "xyz"},
               **{f"{kind}_{a}": column[f"beacon_{a}"] for kind in ("transceiver", "beacon") for a in "xyz"},
               **{f"arm_{a}": arm[..., k] for k, a in enumerate("xyz")}, "slot": slot, "received": fresh,
               **{name: column_of(source) for name, source in system.bound_columns.items() if source in rec}}
    per_run = {"dt": np.full(len(parameters), dt), **{k: np.array([p[k] for p in parameters])
                                                      for k in system.bound_fixed[1:]}}
    fixed = np.ascontiguousarray(np.stack([per_run[k] for k in system.bound_fixed], axis=1))
    # the later lanes of a delivery (recorded where a step delivered two packets): each lane's packet in place of
    # lane 1's, at the same true position
    recorded = _recorded_lanes(rec, _lane_sources(system.bound_columns))
    lanes = {name: column_of(source) for name, source in _lane_sources(system.bound_columns).items()
             if name in recorded}
    lane_steps, lane_new = [], []
    taken = lane_slots(lanes, arms.shape[1])
    # the first packet of each ping of an inverted LBL, in the order the receivers take them (every lane's)
    pinged = new_pings([column["packet_seq"]] + [lanes[f"lane{m}_packet_seq"] for m, _, _ in taken],
                       [slot] + [new for _, new, _ in taken], arms.shape[1])
    sources["new_ping"] = pinged[0]
    for (m, new, heard), first in zip(taken, pinged[1:]):
        on_lane = {name[len(f"lane{m}_"):]: values for name, values in lanes.items() if name.startswith(f"lane{m}_")}
        index = np.clip(np.rint(on_lane["beacon_id"]).astype(int) - 1, 0, arms.shape[1] - 1)
        arm = arms[np.arange(arms.shape[0])[None, :], index]
        mine = {**sources, **{f"{kind}_{a}": on_lane[f"beacon_{a}"] for kind in ("transceiver", "beacon")
                              for a in "xyz"},
                **{f"arm_{a}": arm[..., k] for k, a in enumerate("xyz")}, "slot": new, "received": heard,
                "new_ping": first, **{name: on_lane[name] for name in system.bound_columns if name in on_lane}}
        lane_steps.append(np.stack([np.asarray(mine[k], dtype=float) for k in system.bound_steps], axis=-1))
        lane_new.append(new)
    steps = np.ascontiguousarray(np.stack([np.asarray(sources[k], dtype=float) for k in system.bound_steps],
                                          axis=-1))
    if not lane_steps:
        return compiled_metrics.system_pcrb(arms.shape[1], fixed, steps)
    return compiled_metrics.system_pcrb(arms.shape[1], fixed, steps, np.stack(lane_steps), np.stack(lane_new))


def _recorded_lanes(rec: Mapping[str, np.ndarray], sources: Mapping[str, str]) -> dict[str, np.ndarray]:
    """The lanes' columns (``sources``: name -> recorded output) of each later lane whose every column was recorded
    (a run records them all where a step delivered two packets, lane 2's counter alone where not; a replay the
    lanes it used)."""
    out = {}
    for m in range(2, LANES + 1):
        mine = {name: source for name, source in sources.items() if name.startswith(f"lane{m}_")}
        if mine and all(source in rec for source in mine.values()):
            out.update({name: rec[source] for name, source in mine.items()})
    return out


def _lane_sources(own_columns: Mapping[str, str]) -> dict[str, str]:
    """The recorded outputs of the later lanes of a delivery that the metrics (and a system's own bound, whose
    columns of the packet are ``own_columns``: name -> source) read: lane column name -> ``component.variable``."""
    out = {name: f"acoustics.{name}" for name in LANE_METRIC_INPUTS}
    out.update({lane_name(m, name): lane_source(m, source) for m in range(2, LANES + 1)
                for name, source in own_columns.items()})
    return out

__all__ = ["FLAG_INPUTS"]

"""One scenario run, or a batch of runs stepped together: build the system on an engine, simulate, the record as the
diver sees it (the receiver's latency), its metrics (:mod:`sblsim.orchestrator.cosim.record_metrics`) and its time
series; the run's files are written by :mod:`sblsim.orchestrator.cosim.run_output`."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.acoustics.channel.lanes import check_in_flight, lane_name, lane_of
from sblsim.models.columns import LANE_COLUMNS, OPTIONAL_COLUMNS, TIMESERIES_COLUMNS, lane_source
from sblsim.models.declarations import ModelError
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.config import turnaround
from sblsim.orchestrator.cosim.connections import (
    Connection,
    check_connections,
    default_connections,
)
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.handles import DTYPES, ComponentHandle, cast_column
from sblsim.orchestrator.cosim.limits import check_steps
from sblsim.orchestrator.cosim.master import RecordBuffer, simulate
from sblsim.orchestrator.cosim.metrics import METRIC_INPUTS, errors
from sblsim.orchestrator.cosim.plan import RunPlan, as_plan, with_replicates
from sblsim.orchestrator.cosim.record_metrics import _lane_sources, _metrics
from sblsim.orchestrator.io.progress import Progress, ProgressSpec, progress_of

#: A system's time series adds its own columns after :data:`TIMESERIES_COLUMNS`
#: (:attr:`sblsim.models.systems.System.timeseries_columns`: USBL's direction of arrival and array attitude).


@dataclass
class RunRecord:
    """Outcome of one (batched) run.

    Attributes
    ----------
    config : dict
        Resolved configuration (read-only: the plan's).
    engine : str
        ``local`` or ``fmu``.
    timeseries : pandas.DataFrame
        One row per replicate and step (columns :data:`TIMESERIES_COLUMNS`, a USBL run's
        a system's own columns, ``time`` [s], ``replicate`` and the errors ``e_*``, ``instr_e_*`` [m]).
    metrics : pandas.DataFrame
        One row per replicate: the metrics of :mod:`sblsim.orchestrator.cosim.metrics`.
    steps : int
        Macro steps per replicate.
    wall_time : float
        Wall-clock time of the simulation [s].
    step_time : dict
        Component -> wall-clock time spent in its ``doStep`` calls [s], all runs of the batch.
    plan : RunPlan or None
        The plan that ran (:mod:`sblsim.orchestrator.cosim.plan`; its ``config`` is :attr:`config`).
    """

    config: dict
    engine: str
    timeseries: pd.DataFrame
    metrics: pd.DataFrame
    steps: int
    wall_time: float
    step_time: dict[str, float] = field(default_factory=dict)
    plan: RunPlan | None = None


def distinct_plans(plans: Sequence[RunPlan]) -> list[RunPlan]:
    """The runs' distinct plans, one per design cell: the replicates of a cell share every section but their
    ``run.replicate`` (:func:`with_replicates`)."""
    return list({(tuple(id(v) for s, v in p.config.items() if s != "run"),
                  tuple((k, v) for k, v in p.config["run"].items() if k != "replicate")): p
                 for p in plans}.values())


def merge_params(plans: Sequence[RunPlan], component: str, accepted: frozenset[str] | None = None,
                 distinct: Sequence[RunPlan] | None = None) -> tuple[dict[str, Any], np.ndarray]:
    """Parameters of one component for a batch of runs, one plan per run (a configuration: its plan is made).

    The FMU parameters of the first run (:meth:`sblsim.orchestrator.cosim.plan.RunPlan.component_parameters`);
    a numeric parameter whose value differs between runs (a factor of a batch
    spanning several design cells) becomes an array of shape (B,). The values
    are each run's parameters as its plan resolved them: those tied to a key of
    another section (``acoustics.beaufort`` from ``platform.beaufort``,
    :data:`sblsim.orchestrator.cosim.config.KEY_TIES`) and those the model derives
    from its keys (the absorption at ``acoustics.frequency``, the eigenray
    table) follow their run. Only the seed keys and numeric FMU parameters may
    differ; text, tables' shapes and configuration-only keys must be the same in
    every run of a batch. ``accepted`` names the parameters of the handle
    (default: the model's); ``distinct`` are the runs' :func:`distinct_plans`
    when the caller has them (one batch, several components).

    Returns
    -------
    params : dict
        Parameters without ``replicate``.
    replicates : ndarray of int, shape (B,)
        ``run.replicate`` of each run.

    Raises
    ------
    ModelError
        If the runs differ in a key a batch must share.
    """
    plans = [as_plan(p) for p in plans]
    first = plans[0]
    params = first.component_parameters(component, accepted)
    params.pop("replicate", None)
    replicates = np.array([p.replicate for p in plans], dtype=np.int64)
    distinct = distinct_plans(plans) if distinct is None else distinct
    section = first.config.get(component, {})
    for key, value in section.items():  # a configuration-only key (it makes tables or files)
        if key not in params and any(d.config[component][key] != value for d in distinct[1:]):
            raise ModelError(f"{component}.{key}: must be the same for every run of a batch")
    missing = object()
    for key, value in params.items():
        if all(d.parameters[component].get(key, missing) == value for d in distinct[1:]):
            continue
        if isinstance(value, str) or any(key not in d.parameters[component] for d in distinct[1:]):
            raise ModelError(f"{component}.{key}: must be the same for every run of a batch")
        params[key] = np.asarray([p.parameters[component][key] for p in plans])
    return params, replicates


def run(cfg: RunPlan | dict, engine: str = "local", replicates: Sequence[int] | None = None,
        fmu_dir: Path | str | None = None, handles: dict[str, ComponentHandle] | None = None,
        progress: ProgressSpec | Progress = False, connections: Sequence[Connection] | None = None) -> RunRecord:
    """Simulate a resolved configuration on an engine.

    Parameters
    ----------
    cfg : RunPlan or dict
        The run's plan (:func:`sblsim.orchestrator.cosim.plan.make_plan`); a configuration is resolved into its plan
        once.
    engine : {'local', 'fmu'}
    replicates : sequence of int, optional
        Replicates to run (stepped together on the local engine, one after the
        other on the fmu engine); default ``[run.replicate]``.
    fmu_dir : path, optional
        Directory of the built FMUs (fmu engine).
    handles : dict, optional
        Re-usable handles from :func:`make_handles` (FMUs are then reset, not
        re-instantiated); closed by the caller.
    progress : bool, 'auto', callable or Progress
        Report the steps done (:class:`sblsim.orchestrator.io.progress.Progress`; a unit is one step of one
        replicate); default silent.
    connections : sequence of Connection, optional
        As for :func:`run_batch`.

    Returns
    -------
    RunRecord

    Raises
    ------
    ModelError
        On a connection that does not match the components, or invalid parameters.
    """
    plan = as_plan(cfg)
    replicates = list(replicates) if replicates is not None else [plan.replicate]
    return run_batch(with_replicates(plan, replicates), engine, fmu_dir, handles, progress, connections=connections)


def run_batch(cfgs: Sequence[RunPlan], engine: str = "local", fmu_dir: Path | str | None = None,
              handles: dict[str, ComponentHandle] | None = None, progress: ProgressSpec | Progress = False,
              timeseries: bool = True, connections: Sequence[Connection] | None = None,
              records: RecordBuffer | None = None) -> RunRecord:
    """Simulate a batch of runs, one plan each.

    The runs may differ in the seed keys (cell, replicate) and in the
    parameters the cores accept per replicate (``batched_parameters``); they
    must share the simulation section and everything else. The local engine
    steps them all together; FMUs (the fmu engine, or a user's receiver FMU)
    step them one at a time (B = 1).
    Each run's numbers are the same whatever batch it is part of. The
    receiver's recorded outputs are delayed by ``receiver.latency``
    (:func:`apply_latency`, which the runs of a batch share) before the
    metrics and the time series are computed from them.

    Parameters
    ----------
    cfgs : sequence of RunPlan
        The runs' plans, B ≥ 1 (:func:`with_replicates`; a configuration given instead is resolved into its
        plan).
    engine, fmu_dir, handles, progress
        As for :func:`run`.
    timeseries : bool
        Build the per-step time series (else only the metrics' inputs are
        recorded and :attr:`RunRecord.timeseries` is empty).
    connections : sequence of Connection, optional
        The system's connections (default :func:`default_connections`; an
        SSP package brings its own).
    records : RecordBuffer, optional
        Memory for the compiled master loop's record, kept by a caller that runs batch after batch (a
        campaign worker): re-used, it saves allocating and first touching it each time. The result does
        not refer to it (its tables are copies). Default: new memory.

    Returns
    -------
    RunRecord
        For the first plan, with one metrics row per run (in order).

    Raises
    ------
    ModelError
        If the runs differ where a batch cannot, their record would not fit in memory
        (:func:`sblsim.orchestrator.cosim.limits.check_steps`), or as for :func:`run`.
    """
    plans = [as_plan(c) for c in cfgs]
    first = plans[0]
    sim = first.config["simulation"]
    if any(p.config["simulation"] != sim for p in plans):
        raise ModelError("simulation: every run of a batch needs the same simulation settings")
    n_beacons = first.n_beacons
    T = first.sampling_time
    n_steps = check_steps(first.duration, T, len(plans), timeseries)  # before any work: the record must fit
    own = handles is None
    if own:
        handles = make_handles(engine, fmu_dir, n_beacons, dict(first.sources),
                               fmi_version=int(sim["fmi_version"]), early_return=first.master == "event")
    if first.master == "event" and not any(getattr(h, "early_return", False) for h in handles.values()):
        if own:
            close_handles(handles)
        raise ModelError("simulation.master: event needs the fmu engine on FMI 3.0 FMUs, whose channel returns "
                         "early at an arrival (--engine fmu --fmi-version 3)")
    try:
        connections = list(connections) if connections is not None else default_connections(n_beacons)
        lane_less = _lane_less(handles, n_beacons)
        if lane_less:  # a user's receiver without the later lanes of a delivery: lane 1 alone
            connections = [c for c in connections if not (c.destination == "receiver" and c.input in lane_less)]
        check_connections(connections, {name: h.ports for name, h in handles.items()})
        rates = first.rates
        own_columns = first.system.bound_columns  # what the system's own bound reads besides (USBL's doa_*)
        record = None if timeseries else [TIMESERIES_COLUMNS[c] for c in METRIC_INPUTS] + list(own_columns.values())
        lanes = list(_lane_sources(own_columns).values())
        batched = all(h.batched for h in handles.values())
        groups = [plans] if batched else [[p] for p in plans]
        bar, own_bar = progress_of(progress, n_steps * len(plans), f"{first.scenario} ({engine})")
        start = time.perf_counter()
        recs, replicates, timing, overruns = [], [], {}, []
        try:
            for group in groups:
                distinct = distinct_plans(group)
                for name, handle in handles.items():
                    params, reps = merge_params(group, name, handle.parameters, distinct)
                    handle.setup(params, reps)
                advance = partial(_advance, bar, len(group)) if bar.active else None
                recs.append(simulate(handles, connections, rates, T, n_steps,
                                     record=None if record is None else record + [LANE_SENTINEL], timing=timing,
                                     progress=advance, algorithm=first.master,
                                     buffer=records if len(groups) == 1 else None))
                crowded = np.any(recs[-1][LANE_SENTINEL])  # a step delivered two packets
                if lane_less and crowded:
                    raise ModelError(f"simulation.receiver: {first.sources['receiver']} has no inputs for the later "
                                     "lanes of a delivery (lane2_packet_seq ...), and packets arrived two in a step "
                                     "in this run: it would lose them; give it those inputs (docs/interop.md) or a "
                                     "shorter simulation.sampling_time")
                if record is not None and crowded:  # the same runs again (the same numbers), recording the lanes
                    for name, handle in handles.items():
                        handle.setup(*merge_params(group, name, handle.parameters, distinct))
                    recs[-1] = simulate(handles, connections, rates, T, n_steps, record=record + lanes,
                                        algorithm=first.master)
                _check_in_flight(handles, group)
                overruns.extend(slot_overrun(handles, len(group)))
                replicates.extend(reps.tolist())
        finally:
            if own_bar:
                bar.close()
        wall = time.perf_counter() - start
    finally:
        if own:
            close_handles(handles)
    if len(recs) == 1:
        rec = recs[0]
    else:  # a lane recorded in one group only: no packet on it in the others
        keys = list(dict.fromkeys(k for r in recs for k in r))
        rec = {k: (recs[0][k] if k == "time" else np.concatenate(
            [r[k] if k in r else np.zeros_like(r[LANE_SENTINEL]) for r in recs], axis=1)) for k in keys}
    rec = apply_latency(rec, first.latency_steps)  # what the diver sees; the runs of a batch share it
    metrics, bound = _metrics(plans, rec, replicates, with_bound=timeseries)
    metrics["slot_overrun"] = overruns
    if timeseries:
        types = {f"{c}.{p.name}": p.type for c, h in handles.items() for p in h.ports}
        rec = {k: (v if k == "time" else cast_column(v, DTYPES[types[k]])) for k, v in rec.items()}
        frame = _timeseries(rec, replicates, n_steps, bound)
    else:
        frame = pd.DataFrame()
    result = RunRecord(first.config, engine, frame, metrics, n_steps, wall, plan=first)
    result.step_time = timing
    return result


def _check_in_flight(handles: dict, cfgs: Sequence[dict]) -> None:
    """Refuse the runs whose channel had more packets in flight than it holds (its ``overflow_travel_time``
    output, never reset in a run: :func:`sblsim.models.acoustics.core.check_in_flight`), before anything of
    them is written.

    Raises
    ------
    ModelError
        The one line of :func:`~sblsim.models.acoustics.core.check_in_flight`, for the longest flight refused.
    """
    channel = handles.get("acoustics")
    if channel is None or "overflow_travel_time" not in channel.output_names:
        return
    refused = channel.output_vector()[channel.output_names.index("overflow_travel_time")]
    if np.any(refused > 0.0):  # the runs of a batch share the sampling time; name the longest turnaround of them
        jitter = max(c["acoustics"]["turnaround_sigma"] if c["acoustics"]["ranging"] == "twtt" else 0.0 for c in cfgs)
        check_in_flight(cfgs[0]["simulation"]["sampling_time"], max(turnaround(c) for c in cfgs),
                        float(np.max(refused)), jitter)



def slot_overrun(handles: dict, width: int) -> list[float]:
    """Per run of a batch of ``width``: the longest time from a slot's transmit epoch to the last heard arrival of
    its exchange beyond the slot [s] (the channel's ``slot_overrun`` output, detection by signal-to-noise; 0:
    none, and for a channel without it)."""
    channel = handles.get("acoustics")
    if channel is None or "slot_overrun" not in channel.output_names:
        return [0.0] * width
    values = np.asarray(channel.output_vector()[channel.output_names.index("slot_overrun")], dtype=float)
    return np.broadcast_to(values, (width,)).tolist()


def _advance(bar: Progress, width: int, steps: int) -> None:
    """``steps`` macro steps of ``width`` replicates stepped together are done."""
    bar.update(steps * width)


#: The receiver's outputs a latency does not delay: diagnostics of the slot they judge, not what a diver sees.
UNDELAYED = ("receiver.nis", "receiver.gated")


def apply_latency(columns: dict[str, np.ndarray], steps: int) -> dict[str, np.ndarray]:
    """The record as the diver sees it with the receiver's processing latency (``receiver.latency``).

    Every recorded output of the receiver the diver sees (``receiver.*``: estimates, covariance, the
    instrumentation fix) at step k is replaced by the one at step k − ``steps``; before step ``steps`` the
    diver sees the receiver's first recorded row. The receiver's own diagnostics of each slot
    (:data:`UNDELAYED`: its NIS and gate decision) stay paired with the slot they judged, and the other
    components' outputs and ``time`` are left as they are.

    Parameters
    ----------
    columns : dict
        ``"component.variable"`` -> array of shape (n_steps, B), and ``"time"`` (:func:`simulate`'s record).
    steps : int
        The latency in steps of the record (:attr:`sblsim.orchestrator.cosim.plan.RunPlan.latency_steps`), ≥ 0.

    Returns
    -------
    dict
        A new dict with new arrays for the receiver's outputs (``columns`` itself when ``steps`` is 0).
    """
    if steps <= 0:
        return columns
    n_steps = len(columns["time"])
    source = np.maximum(np.arange(n_steps) - steps, 0)  # the row each step shows
    return {k: (v[source] if k.startswith("receiver.") and k not in UNDELAYED else v) for k, v in columns.items()}


def _lane_less(handles: Mapping[str, Any], n_beacons: int) -> set[str]:
    """The inputs of the later lanes of a delivery the run's receiver lacks (a user's FMU may have none of them:
    :func:`~sblsim.orchestrator.cosim.connections.check_interface`); empty for a receiver with them all."""
    receiver = handles.get("receiver")
    if receiver is None:
        return set()
    inputs = {p.name for p in receiver.ports if p.causality == "input"}
    wanted = {c.input for c in default_connections(n_beacons) if c.destination == "receiver"}
    return {name for name in wanted - inputs if lane_of(name)}



#: The record that says whether a run used the later lanes of a delivery (lane 2 fills first).
LANE_SENTINEL = f"acoustics.{lane_name(2, 'packet_seq')}"


def _timeseries(rec: dict, replicates: list[int], n_steps: int, bound: np.ndarray) -> pd.DataFrame:
    """The per-step table, replicate-major (all steps of replicate 0, then replicate 1, ...)."""
    batch = len(replicates)
    # every column (one a user's FMU may lack, OPTIONAL_COLUMNS: where recorded)
    cols = {name: rec[source] for name, source in TIMESERIES_COLUMNS.items()
            if source in rec or name not in OPTIONAL_COLUMNS}
    for system in SYSTEMS.values():  # a system's own columns (USBL's direction of arrival), where recorded
        if system.timeseries_columns and all(source in rec for source in system.timeseries_columns.values()):
            cols.update({name: rec[source] for name, source in system.timeseries_columns.items()})
    # the lanes of a delivery a run used (a packet arrived after another in one step), each lane's columns (and a
    # system's own, where recorded)
    for m in range(2, LANES + 1):
        seq = rec.get(LANE_COLUMNS[lane_name(m, "packet_seq")])
        if seq is None or not np.any(seq):
            break  # lanes fill in order: none later either
        cols.update({name: rec[source] for name, source in LANE_COLUMNS.items() if name.startswith(f"lane{m}_")})
        for system in SYSTEMS.values():
            cols.update({lane_name(m, name): rec[lane_source(m, source)]
                         for name, source in system.timeseries_columns.items() if lane_source(m, source) in rec})
    truth = np.stack([cols[f"true_{a}"] for a in "xyz"], axis=-1)
    est_err = errors(truth, np.stack([cols[f"est_{a}"] for a in "xyz"], axis=-1))
    # no fix at a step (instr_valid false, instr_* 0): the step has no instrumentation error
    fix = np.where(np.asarray(cols["instr_valid"], bool)[..., None],
                   np.stack([cols[f"instr_{a}"] for a in "xyz"], axis=-1), np.nan)
    instr_err = errors(truth, fix)
    table = {"replicate": np.repeat(np.asarray(replicates)[None, :], n_steps, axis=0),
             "time": np.repeat(rec["time"][:, None], batch, axis=1)}
    table.update(cols)
    table["pcrb"] = bound
    for k, name in enumerate(("e_x", "e_y", "e_z", "e_tot")):
        table[name] = est_err[..., k]
        table[f"instr_{name}"] = instr_err[..., k]
    return pd.DataFrame({k: np.asarray(v).T.reshape(-1) for k, v in table.items()})

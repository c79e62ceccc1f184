"""``sblsim replay``: a receiver run on a recorded log (:mod:`sblsim.orchestrator.logs.receiver_log` reads it) as the
master steps it in a run.

Which row the receiver is shown in each communication step, and where the replay starts and ends, is
:mod:`sblsim.orchestrator.logs.schedule`'s (its "Timing"); the configuration it runs with,
:mod:`sblsim.orchestrator.logs.configuration`'s. The receiver's times are taken from the start time (a log with
Unix times runs as one starting near 0); the time series records them as
the log has them. ``receiver.latency`` delays the receiver's recorded outputs
as a run's (:func:`sblsim.orchestrator.cosim.run.apply_latency`).

A truth track (``time_s, n_m, e_m, d_m``) is interpolated linearly at the
end of every macro step, as a run records its truth; steps outside its span
have no truth and no errors (they are counted).
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.acoustics.channel.lanes import lane_name, lane_of
from sblsim.models.acoustics.channel.pinger import ping_intervals
from sblsim.models.columns import LANE_COLUMNS, lane_source
from sblsim.models.declarations import ModelError
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cosim.config import to_toml
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.handles import DTYPES, cast_column
from sblsim.orchestrator.cosim.metrics import FLAG_NAMES, RUN_METRICS, errors, slots
from sblsim.orchestrator.cosim.plan import RunPlan, as_plan
from sblsim.orchestrator.cosim.record_metrics import _metrics
from sblsim.orchestrator.cosim.run import (
    TIMESERIES_COLUMNS,
    UNDELAYED,
    RunRecord,
    merge_params,
)
from sblsim.orchestrator.cosim.run_output import summary
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.logs.receiver_log import (
    Log,
    read_log,
)
from sblsim.orchestrator.logs.schedule import schedule
from sblsim.orchestrator.logs.truth_track import read_truth

# --------------------------------------------------------------------------- the replay

@dataclass
class ReplayRecord:
    """Outcome of a replay.

    Attributes
    ----------
    config : RunPlan
        The plan the receiver ran with (reads as its resolved configuration).
    engine : str
    timeseries : pandas.DataFrame
        One row per macro step: ``time`` [s] (the log's clock), ``log_row`` (where in the log the row the
        step shows is), the receiver's inputs and outputs as a run records them, and with a truth track
        ``true_*``, ``pcrb`` and the errors ``e_*``, ``instr_e_*`` (NaN outside its span).
    summary : dict
        ``summary.json``: a run's keys (errors ``null`` without a truth track), ``log`` and ``truth``.
    """

    config: RunPlan
    engine: str
    timeseries: pd.DataFrame
    summary: dict[str, Any]


def system_inputs(log: Log) -> dict[str, np.ndarray]:
    """The receiver's inputs of the columns the log's system adds (USBL's direction of arrival): input name ->
    values (N,)."""
    if log.system_values is None:
        return {}
    return {source: log.system_values[:, j] for j, source in enumerate(log.system_columns.values())}


def _row_values(log: Log, rel: np.ndarray, start: float) -> dict[str, np.ndarray]:
    """The receiver's inputs of every row by name, each (N,); ``rel`` the rows' arrivals from the start ``start``
    [s]."""
    packet = log.beacon > 0
    # the transmit epoch from the start: the arrival itself where the log gives none (as the schedule has it)
    sent = np.where(log.transmit == log.time, rel, log.transmit - start)
    return {"packet_seq": np.arange(1, len(rel) + 1, dtype=float), "beacon_id": log.beacon.astype(float),
            "packet_valid": packet.astype(float), "tx_time": sent, "rx_time": rel, "range": log.range,
            "beacon_x": log.beacon_ned[:, 0], "beacon_y": log.beacon_ned[:, 1], "beacon_z": log.beacon_ned[:, 2],
            "depth": log.depth, **system_inputs(log)}


def _inputs(values: dict[str, np.ndarray], names: Sequence[str]):
    """``vector(rows)``: the receiver's input vector (n_in,) that shows the log's ``rows`` (LANES, −1: none) on the
    lanes of a delivery, the depth of the newest of them; ``values`` the rows' inputs by name (:func:`_row_values`).

    Raises
    ------
    ModelError
        An input of the receiver a log does not have.
    """
    where = []  # per input: (lane index, its field)
    for n in names:
        lane = lane_of(n)
        m, field_name = lane if lane else (1, n)
        if field_name not in values or (lane and field_name == "depth"):
            raise ModelError(f"receiver: input {n!r} is not in a log")
        where.append((m - 1, field_name))

    def vector(rows: np.ndarray) -> np.ndarray:
        newest = rows[rows >= 0][-1]
        return np.array([values[f][newest] if f == "depth" else (values[f][rows[m]] if rows[m] >= 0 else 0.0)
                         for m, f in where])
    return vector


def replay(log: Log, cfg: RunPlan | dict, engine: str = "local", fmu_dir: Path | str | None = None,
           truth: tuple[np.ndarray, np.ndarray] | None = None) -> ReplayRecord:
    """Step the configuration's receiver on a log (module docstring).

    Parameters
    ----------
    log : Log
        From :func:`~sblsim.orchestrator.logs.receiver_log.read_log` with the configuration's beacon count.
    cfg : RunPlan or dict
        The plan (the receiver, its parameters, T, the rate ratio, the master; a configuration: its plan is made
        once).
    engine : {'local', 'fmu'}
    fmu_dir : path, optional
    truth : (time, ned), optional
        From :func:`read_truth`.

    Raises
    ------
    ModelError
        A truth track that covers no step; as :func:`~sblsim.orchestrator.logs.schedule.schedule` and
        :func:`sblsim.orchestrator.cosim.engines.make_handles`.
    """
    cfg = as_plan(cfg)
    T, ratio = cfg.sampling_time, cfg.ekf_rate_ratio
    lead = 0.0
    if "toa" in cfg.system.ranging:  # an inverted LBL's first ping: an interval of its pinger after the start
        lead = float(ping_intervals(cfg["acoustics"], cfg.n_beacons, T)[0]) - T
    plan = schedule(log, T, ratio, cfg.master == "jacobi", lead)
    rel_times = 0.0 + T * np.arange(1, plan.steps + 1)  # the end of each macro step, as the master records it
    times = plan.start + rel_times
    true = np.full((plan.steps, 3), np.nan)
    if truth is not None:
        t_truth = truth[0] - plan.start
        true = np.stack([np.interp(rel_times, t_truth, truth[1][:, a], left=np.nan, right=np.nan)
                         for a in range(3)], axis=1)
        if not np.isfinite(true[:, 0]).any():
            raise ModelError(f"--truth: its times ({truth[0][0]:.10g} … {truth[0][-1]:.10g} s) cover no step of "
                             f"the log ({times[0]:.10g} … {times[-1]:.10g} s); are they on the log's clock?")
    values = _row_values(log, plan.rel, plan.start)  # every row's inputs, by name
    handles = make_handles(engine, fmu_dir, cfg.n_beacons, {"receiver": cfg.sources["receiver"]})
    handle = handles["receiver"]
    start = time.perf_counter()
    try:
        params, replicates = merge_params([cfg], "receiver", handle.parameters)
        handle.setup(params, replicates, 0.0)
        inputs = _inputs(values, handle.input_names)
        outputs = np.empty((plan.steps, len(handle.output_names)))
        sub = T / ratio
        current = np.full(LANES, -1)
        for k in range(plan.steps):
            t = 0.0 + k * T
            for j in range(ratio):
                rows = plan.fed[k * ratio + j]
                if not np.array_equal(rows, current):
                    handle.set_input_vector(inputs(rows)[:, None])
                    current = rows
                handle.do_step(t + j * sub, sub)
            outputs[k] = handle.output_vector()[:, 0]
        types = {p.name: p.type for p in handle.ports}
        names = list(handle.output_names)
    finally:
        close_handles(handles)
    wall = time.perf_counter() - start
    delay = cfg.latency_steps
    if delay:  # what the diver sees, as a run records it (sblsim.orchestrator.cosim.run.apply_latency)
        source = np.maximum(np.arange(plan.steps) - delay, 0)
        for k, name in enumerate(names):
            if f"receiver.{name}" not in UNDELAYED:
                outputs[:, k] = outputs[source, k]
    out = {n: cast_column(outputs[:, k], DTYPES[types[n]]) for k, n in enumerate(names)}
    shown = plan.shown[:, 0]
    rows = np.where(shown >= 0, shown, 0)
    none = shown < 0

    def packet(values: np.ndarray, empty: float = 0.0) -> np.ndarray:
        return np.where(none, empty, values[rows])

    lanes = {}  # the later lanes a delivery used: each lane's packet as a run records it
    for m in range(2, LANES + 1):
        on = plan.shown[:, m - 1]
        if not np.any(on >= 0):
            break
        lane_rows, empty = np.where(on >= 0, on, 0), on < 0
        lanes.update({lane_name(m, name): np.where(empty, 0.0, values[name][lane_rows])
                      for name in values if name != "depth"})
        lanes[lane_name(m, "tx_time")] = np.where(empty, 0.0, log.transmit[lane_rows])
        lanes[lane_name(m, "rx_time")] = np.where(empty, 0.0, log.time[lane_rows])
        for name, kind in (("packet_seq", np.int64), ("beacon_id", np.int64), ("packet_valid", bool)):
            lanes[lane_name(m, name)] = lanes[lane_name(m, name)].astype(kind)

    columns: dict[str, np.ndarray] = {
        "time": times, "replicate": np.zeros(plan.steps, dtype=np.int64),
        "log_row": np.array([log.where[r] if r >= 0 else "" for r in shown], dtype=object),
        **{f"true_{a}": true[:, k] for k, a in enumerate("xyz")},
        **{n: out[n] for n in names if n.startswith(("est_", "instr_"))},
        "packet_seq": np.where(none, 0, shown + 1).astype(np.int64),
        "beacon_id": packet(log.beacon).astype(np.int64), "packet_valid": packet(log.beacon > 0, False),
        "tx_time": packet(log.transmit), "rx_time": packet(log.time), "range": packet(log.range),
        **{f"beacon_{a}": packet(log.beacon_ned[:, k]) for k, a in enumerate("xyz")},
        "depth": packet(log.depth),
    }
    columns.update({name: packet(values) for name, values in system_inputs(log).items()})
    columns.update(lanes)
    columns.update({n: out[n] for n in names if n not in columns})
    frame = pd.DataFrame(columns)
    result = RunRecord(cfg.config, engine, frame, pd.DataFrame(), plan.steps, wall, plan=cfg)
    metrics, truth_steps = _replay_metrics(cfg, frame)
    frame["pcrb"] = metrics.pop("__pcrb")
    for name in ("e_x", "e_y", "e_z", "e_tot"):
        frame[name] = metrics.pop(f"__{name}")
        frame[f"instr_{name}"] = metrics.pop(f"__instr_{name}")
    result.metrics = pd.DataFrame([{"replicate": 0, **metrics}])
    s = summary(result)
    if truth is None:
        s.update({k: None for k in ("diverged", "beyond_geometry", "max_distance")})
    s.update(duration=float(plan.steps * T), start_time=float(plan.start), end_time=float(times[-1]))
    s["log"] = {"file": log.path.name, **log.counts, "used": int(plan.used.size),
                "depth_only": int((log.beacon[plan.used] == 0).sum()),
                "same_step": plan.same_step, "not_reached": plan.not_reached,
                "typical_gap_s": log.typical_gap, "longest_gap_s": log.longest_gap[0],
                "longest_gap_before": log.longest_gap[1],
                "ignored_columns": log.ignored}
    s["truth"] = None if truth is None else {"steps": int(truth_steps), "steps_without": int(plan.steps - truth_steps)}
    return ReplayRecord(cfg, engine, frame, s)


def _replay_metrics(cfg: RunPlan, frame: pd.DataFrame) -> tuple[dict, int]:
    """The metrics of a replay: a run's, over the steps the truth track covers (contiguous), and the per-step
    PCRB and errors (keys ``__*``, NaN outside); without truth only those that need none."""
    n = len(frame)
    covered = np.flatnonzero(np.isfinite(frame["true_x"].to_numpy()))
    values: dict[str, Any] = {k: math.nan for k in RUN_METRICS}
    values.update({k: math.nan for k in FLAG_NAMES})
    for name in ("__pcrb", "__e_x", "__e_y", "__e_z", "__e_tot", "__instr_e_x", "__instr_e_y", "__instr_e_z",
                 "__instr_e_tot"):
        values[name] = np.full(n, np.nan)
    received = frame["packet_valid"].to_numpy(bool) & (frame["beacon_id"].to_numpy() >= 1)
    _, fresh = slots(frame["packet_seq"].to_numpy()[:, None], received[:, None])
    gated = frame["gated"].to_numpy(bool)
    started = frame["packet_seq"].to_numpy() > 0
    values["updates"] = int((fresh[:, 0] & ~gated).sum())
    values["fix_steps"] = int(frame["instr_valid"].to_numpy(bool).sum())
    values["nis_mean"] = float(frame["nis"].to_numpy()[started].mean()) if started.any() else math.nan
    values["gated_pct"] = 100.0 * float((fresh[:, 0] & gated).sum()) / fresh.sum() if fresh.any() else math.nan
    if covered.size == 0:
        return values, 0
    block = slice(int(covered[0]), int(covered[-1]) + 1)
    own = {name: source for system in SYSTEMS.values() for name, source in system.bound_columns.items()}
    own.update({lane_name(m, name): lane_source(m, source)
                for m in range(2, LANES + 1) for name, source in own.items()})
    rec = {column: frame[name].to_numpy()[block, None].astype(float)
           for name, column in {**TIMESERIES_COLUMNS, **LANE_COLUMNS, **own}.items() if name in frame}
    metrics, bound = _metrics([cfg], rec, [0], with_bound=True)
    row = metrics.iloc[0]
    values.update({k: row[k] for k in metrics.columns if k != "replicate"})
    values["__pcrb"][block] = bound[:, 0]
    truth = frame[["true_x", "true_y", "true_z"]].to_numpy()
    est = frame[["est_x", "est_y", "est_z"]].to_numpy()
    fix = np.where(frame["instr_valid"].to_numpy(bool)[:, None], frame[["instr_x", "instr_y", "instr_z"]].to_numpy(),
                   np.nan)
    e, ie = errors(truth, est), errors(truth, fix)
    for k, name in enumerate(("e_x", "e_y", "e_z", "e_tot")):
        values[f"__{name}"] = e[:, k]
        values[f"__instr_{name}"] = ie[:, k]
    return values, covered.size


def write_replay(result: ReplayRecord, out_dir: Path | str) -> Path:
    """Write ``summary.json``, ``config.toml``, ``timeseries.parquet`` and the figures atomically.

    With a truth track the figures of a run (over the steps it covers); without, ``trajectory_xy.png`` of
    the estimate and the instrumentation fixes.
    """
    import matplotlib.pyplot as plt

    from sblsim.orchestrator.io.plots import plot_trajectory_xy, save_run_figures

    out_dir = Path(out_dir)
    receiver = result.config.receiver_label
    title = f"replay of {result.summary['log']['file']}, {receiver} ({result.engine})"
    with staged_directory(out_dir) as tmp:
        (tmp / "summary.json").write_text(json.dumps(result.summary, indent=2, allow_nan=False) + "\n")
        (tmp / "config.toml").write_text(to_toml(result.config))
        result.timeseries.to_parquet(tmp / "timeseries.parquet", index=False)
        ts = result.timeseries
        covered = ts[np.isfinite(ts["true_x"].to_numpy())]
        if len(covered):
            save_run_figures(covered, tmp, title=title, receiver=receiver)
        else:
            fig, ax = plt.subplots(figsize=(6.5, 6))
            plot_trajectory_xy(ts, ax, receiver).suptitle(f"Track, {title} (no truth track)")
            fig.savefig(tmp / "trajectory_xy.png", dpi=120, bbox_inches="tight")
            plt.close(fig)
    return out_dir


def replay_files(plan: RunPlan, log: Path, truth: Path | None, engine: str, fmu_dir: str | Path | None,
                 prepare: Callable[[], Path | None]) -> tuple[ReplayRecord, Path | None]:
    """A replay of a plan on the files (``sblsim.replay`` and ``sblsim replay``): read the log and the truth track,
    ``prepare()`` the output folder (None: nothing is written), replay and write; the record and the folder."""
    data = read_log(log, plan.n_beacons, plan.system, plan["acoustics"]["sound_speed_assumed"], plan["acoustics"])
    track = read_truth(truth) if truth is not None else None
    target = prepare()
    result = replay(data, plan, engine, fmu_dir, track)
    if target is not None:
        write_replay(result, target)
    return result, target


def replay_lines(summary: dict[str, Any], plan: RunPlan, source: str, log: Path, truth: Path | None
                 ) -> tuple[list[str], list[str]]:
    """What ``sblsim replay LOG`` prints of a replay's ``summary``: the lines before the metrics, and the warnings
    for standard error after them (``source``: where the configuration came from; ``log``, ``truth``: the files as
    given)."""
    s, c = summary, summary["log"]
    sim = plan["simulation"]
    lines = [f"replay of {log} on the {s['engine']} engine (receiver {s['receiver']}, configuration {source}): "
             f"{s['steps']} steps of {sim['sampling_time']:g} s from {s['start_time']:.10g} s in "
             f"{s['wall_time']:.2f} s"]
    skipped = c["duplicate"] + c["unknown_beacon"] + c["same_step"] + c["not_reached"]
    lines.append(
        f"  log: {c['rows']} rows, {c['used']} used ({c['depth_only']} depth readings only), {skipped} skipped "
        f"({c['duplicate']} duplicated, {c['unknown_beacon']} with an unknown beacon id, {c['same_step']} in a step "
        f"that used {LANES} newer rows" + (f", {c['not_reached']} after the last step" if c["not_reached"] else "")
        + f"), {c['out_of_order']} out of order (sorted); rows every {c['typical_gap_s']:.6g} s (median), the "
        f"longest gap {c['longest_gap_s']:.6g} s"
        + (f" (before its {c['longest_gap_before']})" if c["longest_gap_s"] > 1.5 * c["typical_gap_s"] else "")
        + (f"; ignored columns: {', '.join(c['ignored_columns'])}" if c["ignored_columns"] else ""))
    if truth is not None:
        t = s["truth"]
        lines.append(f"  truth: {truth}, interpolated at {t['steps']} of {s['steps']} steps"
                     + (f" ({t['steps_without']} outside its span: no errors there)" if t["steps_without"] else ""))
    warnings = []
    if c["same_step"]:
        warnings.append(
            f"sblsim: warning: {c['same_step']} rows of the log fell in a step that used {LANES} newer rows (at most "
            f"{LANES} rows per step of {sim['sampling_time'] / sim['ekf_rate_ratio']:g} s, on the lanes of a "
            "delivery): a smaller simulation.sampling_time or a larger simulation.ekf_rate_ratio (--set) uses them")
    if truth is not None and s["diverged"]:
        warnings.append(f"sblsim: warning: the {s['receiver']} receiver diverged: its numbers mean nothing; see "
                        "error_bounds.png")
    if s["updates"] == 0:
        warnings.append(f"sblsim: warning: the {s['receiver']} receiver never made a fix: no row of the log brought "
                        "a range it used")
    return lines, warnings


__all__ = ["ReplayRecord", "replay", "replay_files", "replay_lines", "write_replay"]

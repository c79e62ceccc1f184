"""``sblsim budget``: each error source's share of the position error of one configuration.

The measure is the mean squared error of the receiver's position, per run
``MSE = e_tot_rms²`` (the mean of e_tot² over the run's steps), averaged
over the replicates 0 … N − 1 (docs/model.md, "Error budget"):

* ``total`` = MSE with every error source as configured (all on);
* ``floor`` = MSE with every source of :data:`SOURCES` off: what the receiver
  makes of perfect measurements (its own lag and start-up, and the staleness
  of ranges held for up to one sampling time, which no switch removes
  without changing the step count);
* ``contribution_i`` = MSE(all on) − MSE(all on but source i off);
* ``remainder`` = total − floor − Σ contribution_i: the interactions (errors
  that do not add in the mean square), so that
  ``floor + Σ contribution_i + remainder = total`` exactly;
* ``share_i`` = contribution_i / total, and ``rms`` = sqrt(max(contribution_i, 0)) [m].

Every configuration of a budget runs the same replicates with the same seed.
Each random stream is keyed by its purpose (:mod:`sblsim.models.philox`), so
switching one source to zero leaves every other random number of a run
unchanged (common random numbers): the paired per-replicate differences
are far less noisy than two independent estimates, and their standard error
(``se``, of the mean over the replicates) is the one given. The receiver is
the same in every run of a budget: its section is resolved once, all
sources on, and kept (its R does not follow a switched-off source, as
the ties of :mod:`sblsim.orchestrator.cosim.config` would have it).

A source that is already zero in the configuration (its switched-off
configuration equals the configured one) contributes exactly 0 and is not
run (``off in this configuration``); a source the system does not use (the
survey error of an SBL) runs and contributes exactly 0, every run unchanged
(``no effect``).
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.config import (
    ConfigError,
    parse_override,
    scenario_system,
    to_toml,
)
from sblsim.orchestrator.cosim.limits import check_replicates
from sblsim.orchestrator.cosim.master import RecordBuffer
from sblsim.orchestrator.cosim.plan import RunPlan, as_plan, load_plan, make_plan, thaw, with_replicates
from sblsim.orchestrator.cosim.run import run_batch
from sblsim.orchestrator.cosim.systems import compared
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.io.progress import Progress, ProgressSpec

#: Error source -> (what it is, the ``--set`` overrides that switch it off). A value ``{section.key}`` is that
#: key's value in the configured (all-on) configuration.
SOURCES: dict[str, tuple[str, tuple[str, ...]]] = {
    "gps": ("GPS error of the platform position", ("platform.gps_sigma=0",)),
    "imu_noise": ("IMU attitude noise", ("platform.imu_sigma_deg=0",)),
    "imu_bias": ("IMU attitude bias and gyro-bias drift", ("platform.imu_bias_deg=0", "platform.imu_gyro_bias=0")),
    "imu_scale_misalignment": ("IMU scale factor and axis misalignment",
                               ("platform.imu_scale_factor_ppm=0", "platform.imu_misalignment_deg=0")),
    "waves": ("wave motion of the platform (Beaufort sea state)", ("platform.beaufort=0",)),
    "range_noise": ("white range noise (with its growth with range, acoustics.range_k)",
                    ("acoustics.sigma_range=0", "acoustics.range_k=0")),
    "sound_speed": ("true sound speed other than the assumed one",
                    ("acoustics.sound_speed_profile=constant",
                     "acoustics.sound_speed_true={acoustics.sound_speed_assumed}")),
    "clock_drift": ("receiver clock drift", ("acoustics.clock_drift_ppm=0",)),
    "moving_ocean": ("the moving ocean: the sound speed's smooth change in time (nadir total delay)",
                     ("acoustics.ntd_sigma_ppm=0",)),
    "multipath": ("multipath: ranges from a reflected path (outliers, or the surface and sea-floor eigenrays)",
                  ("acoustics.outlier_pct=0", "acoustics.water_depth=0")),
    "ambient_noise": ("ambient noise: arrivals missed and timing and angle noise grown below the reference SNR",
                      ("acoustics.source_level=250",)),
    "packet_loss": ("lost packets", ("acoustics.loss_pct=0",)),
    "depth_sensor": ("depth-sensor noise", ("target.depth_sigma=0",)),
    "survey": ("LBL transponders' survey error", ("platform.survey_sigma=0",)),
    "installation": ("transducer installation error", ("platform.installation_sigma=0",)),
    "turnaround_jitter": ("two-way ranging: turnaround jitter", ("acoustics.turnaround_sigma=0",)),
    "ping_jitter": ("inverted LBL: the pinger's interval jitter (its emission epochs a random walk)",
                    ("acoustics.ping_jitter=0",)),
    "usbl_angle": ("USBL direction-of-arrival noise", ("platform.usbl_angle_sigma_deg=0",)),
    "usbl_misalignment": ("USBL array misalignment", ("platform.usbl_misalignment_deg=0",)),
    "latency": ("the receiver's processing latency (the diver sees an older estimate)", ("receiver.latency=0",)),
    "profile_error": ("profile error: the receiver's sound-speed profile other than the true one",
                      ("receiver.sound_speed_profile=acoustics",)),
}
#: Sources that exist only for a receiver that ranges with its own profile (``receiver.sound_speed_profile`` not
#: ``assumed``): a receiver of the single assumed speed has them off (its error is the ``sound_speed`` source).
PROFILE_SOURCES = frozenset({"profile_error"})
#: Sources that exist only with detection by signal-to-noise (``acoustics.detection = "snr"``); a source level
#: of 250 dB re 1 µPa at 1 m hears every eigenray there is, at the configured accuracy.
SNR_SOURCES = frozenset({"ambient_noise"})

DEFAULT_REPLICATES = 500
#: Status of a source in a budget.
ON, NO_EFFECT, OFF = "on", "no effect", "off in this configuration"
COLUMNS = ("source", "description", "status", "contribution", "se", "share", "rms")

_REFERENCE = re.compile(r"^\{(\w+)\.(\w+)\}$")


def switched_off(cfg: RunPlan | dict[str, dict], overrides: Sequence[str]) -> RunPlan:
    """The plan of the configuration ``cfg`` with ``overrides`` applied and its receiver kept.

    The overrides go into a copy of the resolved configuration, whose plan is
    made (:func:`~sblsim.orchestrator.cosim.plan.make_plan`: it is resolved again, once): every receiver key is then
    given, so no tie retunes the
    receiver (its R stays the configured one, e.g. when ``acoustics.sigma_range``
    is 0); only a receiver key an override names changes.

    Raises
    ------
    ConfigError
        If an override names a key the configuration does not have, or a value outside its range.
    """
    raw = thaw(cfg)
    receiver = dict(cfg["receiver"])
    for item in overrides:
        section, name, value = parse_override(item)
        if section not in raw or name not in raw[section]:
            raise ConfigError(f"{section}.{name}: not a key of this configuration")
        if isinstance(value, str) and _REFERENCE.match(value):
            ref_section, ref_name = _REFERENCE.match(value).groups()
            value = cfg[ref_section][ref_name]
        raw[section][name] = value
        if section == "receiver":
            receiver[name] = value
    out = make_plan(raw)
    if out["receiver"] != receiver or out["simulation"] != cfg["simulation"]:  # the ties above: never
        raise ModelError("budget: switching a source off changed the receiver or the simulation settings")
    return out


@dataclass
class Budget:
    """The error budget of one configuration.

    Attributes
    ----------
    label : str
        What the budget is of (the scenario, or ``KEY = VALUE`` of a comparison).
    config : RunPlan
        The plan of the configuration, every source on (reads as the configuration).
    replicates : int
    total, total_se, floor, floor_se, remainder, remainder_se : float
        [m²]; the standard errors of the mean over the replicates (the remainder's from its per-replicate
        values).
    table : pandas.DataFrame
        One row per source (:data:`COLUMNS`), largest contribution first, the sources the configuration
        has off last.
    diverged : int
        Runs of the budget whose receiver diverged (their numbers mean nothing).
    runs : int
        Runs made (configurations run × replicates).
    wall_time : float
        [s].
    """

    label: str
    config: RunPlan
    replicates: int
    total: float
    total_se: float
    floor: float
    floor_se: float
    remainder: float
    remainder_se: float
    table: pd.DataFrame
    diverged: int
    runs: int
    wall_time: float
    differences: dict[str, np.ndarray]

    def first(self) -> list[str]:
        """The sources to improve first: the largest contribution if it is significant (above 2 se), with
        every other that it does not exceed by 2 se of their paired difference (empty: none significant)."""
        on = self.table[self.table["status"] == ON]
        if on.empty or not on.iloc[0]["contribution"] > 2.0 * on.iloc[0]["se"]:
            return []
        top = str(on.iloc[0]["source"])
        out = [top]
        for name in on["source"].iloc[1:]:
            gap = self.differences[top] - self.differences[name]
            if not np.mean(gap) > 2.0 * _se(gap):
                out.append(str(name))
        return out


def _pm(value: float, se: float, total: float, spec: str = ".3g") -> str:
    """``value ± se`` [m²]; a standard error at rounding level (below 1e-12 of the total) shows as 0."""
    shown = 0.0 if abs(se) <= 1e-12 * abs(total) else se
    return f"{value:{spec}} ± {shown:.2g}"


def _se(values: np.ndarray) -> float:
    return float(np.std(values, ddof=1) / math.sqrt(len(values))) if len(values) > 1 else math.nan


def budget(cfg: RunPlan | dict[str, dict], replicates: int = DEFAULT_REPLICATES, label: str | None = None,
           bar=None, records: RecordBuffer | None = None) -> Budget:
    """The error budget of a configuration (module docstring).

    Parameters
    ----------
    cfg : RunPlan or dict
        The plan of the configuration, every source as configured (a configuration: its plan is made once).
    replicates : int
        Runs per configuration (replicates 0 … N − 1 of ``run.seed``).
    label : str, optional
        Default the scenario.
    bar : Progress, optional
        Advanced by every step of every replicate of every configuration run
        (:class:`sblsim.orchestrator.io.progress.Progress`).
    records : RecordBuffer, optional
        Record memory re-used from batch to batch.

    Raises
    ------
    ConfigError, ModelError
        On a source that cannot be switched off in this configuration (nothing is run); a configuration whose
        receiver has no estimate in a replicate (it heard nothing, made no fix: its error is not a number).
    """
    check_budget_replicates(replicates)
    start = time.perf_counter()
    cfg = as_plan(cfg)
    names = SOURCES
    off, floor_cfg = _switches(cfg)
    records = records if records is not None else RecordBuffer()
    done: list[tuple[RunPlan, np.ndarray, int]] = []  # (plan, per-replicate MSE, diverged runs)

    def mse(c: RunPlan, what: str) -> np.ndarray:
        for other, values, _ in done:
            if other == c:  # the same configuration: the same runs
                return values
        result = run_batch(with_replicates(c, range(replicates)), "local", timeseries=False, records=records,
                           progress=bar if bar is not None else False)
        m = result.metrics
        values = m["e_tot_rms"].to_numpy(dtype=float) ** 2
        if not np.isfinite(values).all():  # a receiver without a fix has no estimate: no error to share out
            raise ModelError(_no_estimate(label or cfg.scenario, c, what, m))
        done.append((c, values, int(m["diverged"].sum())))
        return values

    on = mse(cfg, "every source on")
    floor = mse(floor_cfg, "every source off")
    rows, differences = [], {}
    for name, (description, _) in names.items():
        if off[name] == cfg:
            rows.append((name, description, OFF, 0.0, 0.0))
            continue
        without = mse(off[name], f"{name} off")
        d = on - without
        differences[name] = d
        status = NO_EFFECT if not np.any(d) else ON
        rows.append((name, description, status, float(np.mean(on) - np.mean(without)), _se(d)))
    total, floor_mean = float(np.mean(on)), float(np.mean(floor))
    contributions = [r[3] for r in rows]
    remainder = total - floor_mean - math.fsum(contributions)
    per_replicate = on - floor - (np.sum(list(differences.values()), axis=0) if differences else 0.0)
    table = pd.DataFrame([{"source": n, "description": desc, "status": s, "contribution": c, "se": se,
                           "share": c / total if total > 0 else math.nan, "rms": math.sqrt(max(c, 0.0))}
                          for n, desc, s, c, se in rows], columns=list(COLUMNS))
    rank = table["status"].map({ON: 0, NO_EFFECT: 1, OFF: 2})
    table = (table.assign(_rank=rank, _size=-table["contribution"]).sort_values(["_rank", "_size"], kind="stable")
             .drop(columns=["_rank", "_size"]).reset_index(drop=True))
    return Budget(label or cfg.scenario, cfg, replicates, total, _se(on), floor_mean, _se(floor),
                  remainder, _se(per_replicate), table, sum(d for _, _, d in done), len(done) * replicates,
                  time.perf_counter() - start, differences)


def _no_estimate(label: str, plan: RunPlan, what: str, metrics: pd.DataFrame) -> str:
    """The one line of a budget refused because a configuration's receiver had no estimate in some replicates
    (``what``: which configuration of the budget, e.g. ``every source on``): whether it heard nothing (no update),
    the system and the settings that decide what is heard."""
    none = ~np.isfinite(metrics["e_tot_rms"].to_numpy(dtype=float))
    unheard = none & (metrics["updates"].to_numpy() == 0)
    a = plan["acoustics"]
    if a["detection"] == "snr":
        setting = (f"acoustics.detection snr, acoustics.source_level = {a['source_level']:g} dB re 1 µPa at 1 m, "
                   f"acoustics.detection_threshold = {a['detection_threshold']:g} dB")
    else:
        setting = f"acoustics.detection fixed, acoustics.loss_pct = {a['loss_pct']:g} %"
    verb = "heard nothing" if unheard.sum() == none.sum() else "had no estimate"
    return (f"budget: {label}: the {plan.receiver_label} receiver {verb} with {what} (platform.system "
            f"{plan['platform']['system']}, {setting}): {int(none.sum())} of its {len(none)} replicates made no fix "
            f"({int(unheard.sum())} without a single update) and have no estimate, so no error to share out; "
            "allowed: a configuration whose receiver hears its beacons (sblsim run shows its updates); nothing "
            "written")


#: The switched-off plans of the plans of this process's budgets, by the plan's id: (plan, switches); each plan's
#: switches are made once (:func:`configurations` checks them, :func:`budgets` counts and runs them).
_SWITCHED: dict[int, tuple[RunPlan, tuple[dict[str, RunPlan], RunPlan]]] = {}
_KEEP = 64


def _switches(cfg: RunPlan) -> tuple[dict[str, RunPlan], RunPlan]:
    """Each source's switched-off plan, and the floor's (every source off): made once per plan."""
    kept = _SWITCHED.get(id(cfg))
    if kept is not None and kept[0] is cfg:
        return kept[1]
    names = {name: _overrides(cfg, name, overrides) for name, (_, overrides) in SOURCES.items()}
    off = {name: switched_off(cfg, overrides) for name, overrides in names.items()}
    switches = off, switched_off(cfg, [o for overrides in names.values() for o in overrides])
    if len(_SWITCHED) >= _KEEP:
        _SWITCHED.pop(next(iter(_SWITCHED)))
    _SWITCHED[id(cfg)] = (cfg, switches)
    return switches


def _overrides(cfg: RunPlan, name: str, overrides: tuple[str, ...]) -> tuple[str, ...]:
    """The overrides that switch the source ``name`` off in ``cfg``: none (the source is off) for a profile
    source of a receiver that ranges with the single assumed speed (or declares no profile), and for a source of
    detection by signal-to-noise with fixed detection."""
    if name in PROFILE_SOURCES and cfg["receiver"].get("sound_speed_profile", "assumed") == "assumed":
        return ()
    if name in SNR_SOURCES and cfg["acoustics"]["detection"] != "snr":
        return ()
    return overrides


def planned(cfg: RunPlan | dict[str, dict]) -> int:
    """How many configurations a budget of ``cfg`` runs: all on, the floor and each source that is on, the
    same configuration once."""
    cfg = as_plan(cfg)
    off, floor = _switches(cfg)
    distinct: list[RunPlan] = []
    for c in (cfg, floor, *(c for c in off.values() if c != cfg)):
        if not any(c == d for d in distinct):
            distinct.append(c)
    return len(distinct)


def check_budget_replicates(replicates: int) -> None:
    """Refuse a budget's replicate count outside [2, :data:`~sblsim.orchestrator.cosim.limits.MAX_REPLICATES`]: its
    standard errors need two."""
    check_replicates(replicates, 2, "the standard errors need two")


def configurations(scenario: str | Path, overrides: Sequence[str] = (), seed: int | None = None,
                   receiver: str | None = None,
                   compare: tuple[str, list[str]] | None = None) -> list[tuple[str, RunPlan]]:
    """The plans of a budget, or of one budget per compared value: (label, plan), each resolved once with its
    switched-off plans.

    ``receiver`` sets ``simulation.receiver``; a compared ``platform.system`` starts, as in ``sblsim compare
    --systems``, from its :attr:`~sblsim.models.systems.System.compare_defaults` with the overrides over them
    (:func:`~sblsim.orchestrator.cosim.systems.system_overrides`).

    Raises
    ------
    ConfigError, ModelError
        On a bad key or value (the message names it), or a source that cannot be switched off; nothing is
        run.
    """
    items = [*overrides, *([f"simulation.receiver={receiver}"] if receiver is not None else [])]
    if compare is None:
        out = [(Path(str(scenario)).stem, load_plan(scenario, items, seed=seed))]
    else:
        key, values = compare
        out = [(f"{key} = {value}", load_plan(scenario, items_of, seed=seed))
               for value, items_of in zip(values, compared(key, values, items, scenario_system(scenario)))]
    for _, cfg in out:  # every switch is checked before any run
        _switches(cfg)
    return out


def budgets(configs: Sequence[tuple[str, RunPlan]], replicates: int = DEFAULT_REPLICATES,
            progress: ProgressSpec = False) -> list[Budget]:
    """The budget of every plan (:func:`configurations`), each of the replicates 0 … N − 1.

    ``progress`` reports the steps of every run (:class:`sblsim.orchestrator.io.progress.Progress`); default
    silent."""
    check_budget_replicates(replicates)
    configs = [(label, as_plan(cfg)) for label, cfg in configs]
    steps = sum(planned(cfg) * cfg.n_steps for _, cfg in configs)
    records = RecordBuffer()
    with Progress(steps * replicates, "budget", "step", progress) as bar:
        return [budget(cfg, replicates, label, bar, records) for label, cfg in configs]


def lines(b: Budget) -> list[str]:
    """The printed lines of a budget: one per source, largest first, then the floor, remainder and total."""
    width = max(len(n) for n in b.table["source"]) + 1

    def share(value: float) -> str:
        return f"{100 * value / b.total:5.1f} %" if b.total > 0 else "   n/a"

    out = []
    for r in b.table.itertuples():
        if r.status == OFF:
            out.append(f"  {r.source + ':':<{width}} off in this configuration")
        elif r.status == NO_EFFECT:
            out.append(f"  {r.source + ':':<{width}} 0 (no effect: every run unchanged)")
        else:
            out.append(f"  {r.source + ':':<{width}} {_pm(r.contribution, r.se, b.total)} m² "
                       f"({share(r.contribution)}), RMS {r.rms:.3f} m")
    out.append(f"  {'floor:':<{width}} {_pm(b.floor, b.floor_se, b.total)} m² ({share(b.floor)}): the receiver "
               "with every source off")
    out.append(f"  {'remainder:':<{width}} {_pm(b.remainder, b.remainder_se, b.total)} m² ({share(b.remainder)}): "
               "interactions")
    out.append(f"  {'total:':<{width}} {_pm(b.total, b.total_se, b.total)} m² (RMS e_tot {math.sqrt(b.total):.3f} m)")
    return out


def advice(b: Budget) -> str:
    """One sentence: which source to improve first."""
    first = b.first()
    if not first:
        return ("No source contributes more than twice its standard error: the error is the receiver's floor "
                "and the interactions (or more replicates are needed).")
    rows = [b.table[b.table["source"] == n].iloc[0] for n in first]
    if len(rows) == 1:
        return (f"Improve {first[0]} ({rows[0]['description']}) first: switched off, it removes "
                f"{100 * rows[0]['share']:.0f} % of the mean squared error.")
    named = ", ".join(f"{r['source']} ({100 * r['share']:.0f} %)" for r in rows[:-1])
    return (f"Improve {named} or {rows[-1]['source']} ({100 * rows[-1]['share']:.0f} %) first: their contributions "
            "to the mean squared error are equal within two standard errors of their paired difference.")


def table(budgets: Sequence[Budget], key: str | None = None) -> pd.DataFrame:
    """The rows of ``budget.csv``: every source, then floor, remainder and total (with the compared value
    first when ``key`` is given)."""
    frames = []
    for b in budgets:
        extra = pd.DataFrame([
            {"source": "floor", "description": "every source off", "status": "", "contribution": b.floor,
             "se": b.floor_se},
            {"source": "remainder", "description": "interactions", "status": "", "contribution": b.remainder,
             "se": b.remainder_se},
            {"source": "total", "description": "every source on", "status": "", "contribution": b.total,
             "se": b.total_se}])
        extra["share"] = extra["contribution"] / b.total if b.total > 0 else math.nan
        extra["rms"] = np.sqrt(np.maximum(extra["contribution"], 0.0))
        frame = pd.concat([b.table, extra], ignore_index=True)
        if key is not None:
            frame.insert(0, key, b.label.split(" = ", 1)[1])
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def _cell(row: Any, total: float) -> str:
    if row["status"] == OFF:
        return "off"
    if row["status"] == NO_EFFECT:
        return "0 (no effect)"
    return f"{_pm(row['contribution'], row['se'], total)} ({100 * row['contribution'] / total:.1f} %)"


def markdown(budgets: Sequence[Budget], key: str | None = None) -> str:
    """The budget as Markdown: one table (a column per compared value), the total, floor and remainder, and
    which source to improve first."""
    if len(budgets) == 1:
        b = budgets[0]
        lines_ = ["| source | what | contribution [m²] (± se) | share | RMS [m] |", "|---|---|---|---|---|"]
        for _, r in b.table.iterrows():
            if r["status"] == ON:
                value = _pm(r["contribution"], r["se"], b.total, ".4g")
                lines_.append(f"| {r['source']} | {r['description']} | {value} | {100 * r['share']:.1f} % "
                              f"| {r['rms']:.3f} |")
            else:
                lines_.append(f"| {r['source']} | {r['description']} | {r['status']} | 0 % | 0 |")
        lines_ += ["", *_summary(b), "", advice(b)]
        return "\n".join(lines_) + "\n"
    order = _order(budgets)
    head = "| source | " + " | ".join(b.label.split(" = ", 1)[1] for b in budgets) + " |"
    lines_ = [f"Contribution to the MSE [m²] (± se) and share, per {key}:", "", head,
              "|---|" + "---|" * len(budgets)]
    for name in order:
        cells = [_cell(b.table[b.table["source"] == name].iloc[0], b.total) for b in budgets]
        lines_.append(f"| {name} | " + " | ".join(cells) + " |")
    for what, attr in (("floor", "floor"), ("remainder", "remainder"), ("total", "total")):
        cells = [_pm(getattr(b, attr), getattr(b, attr + "_se"), b.total)
                 + (f" ({100 * getattr(b, attr) / b.total:.1f} %)" if what != "total" else
                    f" (RMS {math.sqrt(b.total):.3f} m)") for b in budgets]
        lines_.append(f"| **{what}** | " + " | ".join(cells) + " |")
    lines_.append("")
    lines_ += [f"{b.label}: {advice(b)}" for b in budgets]
    return "\n".join(lines_) + "\n"


def _summary(b: Budget) -> list[str]:
    share = (lambda v: f"{100 * v / b.total:.1f} %") if b.total > 0 else (lambda v: "n/a")
    return [f"* total: {_pm(b.total, b.total_se, b.total, '.4g')} m² (RMS e_tot {math.sqrt(b.total):.3f} m), every "
            "source on",
            f"* floor: {_pm(b.floor, b.floor_se, b.total, '.4g')} m² ({share(b.floor)}), every source off: the "
            "receiver's own lag, start-up and the staleness of held ranges",
            f"* remainder: {_pm(b.remainder, b.remainder_se, b.total, '.4g')} m² ({share(b.remainder)}): "
            "interactions, total − floor − Σ contributions"]


def _order(budgets: Sequence[Budget]) -> list[str]:
    """The sources, by their largest share in any budget (the ones off everywhere last)."""
    best: dict[str, float] = {}
    for b in budgets:
        for _, r in b.table.iterrows():
            share = r["share"] if r["status"] == ON and math.isfinite(r["share"]) else -1.0
            best[r["source"]] = max(best.get(r["source"], -1.0), share)
    return sorted(best, key=lambda n: -best[n])


def plot(budgets: Sequence[Budget], title: str):
    """Horizontal bars of the shares of the total MSE (± 2 se), the floor and the remainder, one panel per
    budget."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    order = [n for n in _order(budgets)
             if any(b.table.loc[b.table["source"] == n, "status"].iloc[0] == ON for b in budgets)]
    names = [*order, "remainder", "floor"]
    fig, axes = plt.subplots(1, len(budgets), figsize=(4.2 * len(budgets) + 2.0, 0.35 * len(names) + 1.8),
                             squeeze=False, sharey=True)
    y = np.arange(len(names))[::-1]
    for ax, b in zip(axes[0], budgets):
        scale = 100.0 / b.total if b.total > 0 else math.nan
        values, errors, colors, notes = [], [], [], []
        for n in names:
            if n in ("remainder", "floor"):
                values.append(getattr(b, n) * scale)
                errors.append(2.0 * getattr(b, f"{n}_se") * scale)
                colors.append("0.6")
                notes.append(f"{values[-1]:.1f} %")
            else:
                r = b.table[b.table["source"] == n].iloc[0]
                values.append(r["contribution"] * scale)
                errors.append(2.0 * r["se"] * scale)
                colors.append("tab:red")
                notes.append(f"{values[-1]:.1f} %" if r["status"] == ON else {OFF: "off"}.get(r["status"], r["status"]))
        ax.barh(y, values, xerr=errors, color=colors, capsize=3, alpha=0.85)
        for k, (value, error, note) in enumerate(zip(values, errors, notes)):
            if math.isfinite(value):
                ax.annotate(note, (max(value, 0.0) + error, y[k]), textcoords="offset points", xytext=(4, -3),
                            fontsize=7, color="k" if note.endswith("%") else "0.5")
        ax.margins(x=0.12)
        ax.axvline(0.0, color="k", lw=0.8)
        ax.set_yticks(y, names)
        ax.set_xlabel("share of the total MSE [%] (± 2 se)")
        ax.set_title(f"{b.label}\ntotal {b.total:.3g} m² (RMS {math.sqrt(b.total):.3f} m)", fontsize=9)
        ax.grid(True, axis="x", alpha=0.3)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def _config_name(b: Budget, many: bool) -> str:
    if not many:
        return "config.toml"
    value = re.sub(r"[^A-Za-z0-9._-]", "_", b.label.split(" = ", 1)[1])
    return f"config_{value}.toml"


def write(budgets: Sequence[Budget], out: Path | str, title: str, key: str | None = None) -> Path:
    """Write ``budget.csv``, ``budget.md``, ``budget.png`` and the all-on configuration (``config.toml``, or
    ``config_VALUE.toml`` per compared value) into ``out`` atomically; return ``out``."""
    import matplotlib.pyplot as plt

    with staged_directory(out) as tmp:
        table(budgets, key).to_csv(tmp / "budget.csv", index=False)
        (tmp / "budget.md").write_text(f"{title}\n\n{markdown(budgets, key)}", encoding="utf-8")
        fig = plot(budgets, title)
        fig.savefig(tmp / "budget.png", dpi=120, bbox_inches="tight")
        plt.close(fig)
        for b in budgets:
            (tmp / _config_name(b, key is not None)).write_text(to_toml(b.config), encoding="utf-8")
    return Path(out)


def title(scenario: str, budgets: Sequence[Budget], overrides: Sequence[str] = ()) -> str:
    """The heading of a budget's outputs: scenario, receiver, replicates, seed and overrides."""
    cfg = budgets[0].config
    receivers = sorted({b.config.receiver_label for b in budgets})
    return (f"{scenario}: error budget of the {', '.join(receivers)} receiver, {budgets[0].replicates} replicates "
            f"per configuration, seed {cfg['run']['seed']}" + (f", {' '.join(overrides)}" if overrides else ""))


__all__ = ["COLUMNS", "DEFAULT_REPLICATES", "SOURCES", "Budget", "advice", "budget",
           "budgets", "check_budget_replicates", "configurations", "lines", "markdown", "planned", "plot",
           "switched_off", "table", "title", "write"]

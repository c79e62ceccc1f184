"""Simulated calibration surveys: ``sblsim calibrate box-in|CONFIG.toml [--replicates N]``.

A simulated survey is a TOML file (the built-in ``box-in``, :data:`SIMULATED_SURVEYS`, or the user's
``CONFIG.toml``) with three optional tables: ``[survey]`` (:data:`sblsim.models.calibration.boxin.SURVEY_VARIABLES`: the
pattern, the transponder, the turnaround, the TWTT noise, the sound speed and its error, the seed),
``[platform]`` (the platform's GNSS and attitude errors and lever arm,
:data:`sblsim.models.calibration.boxin.PLATFORM_KEYS`, with the platform's names, units, ranges and defaults) and
``[solver]`` (:data:`sblsim.orchestrator.surveys.calibrate.SOLVER_KEYS`). Each replicate is simulated
(:func:`sblsim.models.calibration.boxin.simulate`), written as a calibration log (checked like any log,
:func:`sblsim.orchestrator.surveys.log.check_frame`) and solved like a recorded one
(:func:`sblsim.orchestrator.surveys.calibrate.calibrate`); its errors are taken against the truth, its NEES
with the solver's covariance, and the horizontal bound of the pattern from the CRB
(:func:`sblsim.models.calibration.crb`).

The solver is told the true sound speed plus ``survey.sound_speed_error_mps`` (``solver.sound_speed_mps`` is
not set by hand here) and, unless ``solver.twtt_sigma_s`` is given, the simulation's own TWTT noise
(turnaround jitter and measurement noise together). A moving ocean (``survey.ntd_sigma_s``, its time scale and
gradient) delays every reply; ``solver.perturbation`` solves it (the bound is then that of the positions with
the perturbation's unknowns), or leaves it in the residuals.

The survey error an LBL design takes (``platform.survey_sigma``, one sigma for the three axes) is
:func:`survey_sigma`: the replicates' RMS error per axis when there are several, else the calibration's own
1-sigma per axis (both the root mean square over North, East and Up). It is suggested (``lbl_set``) only when the
study agrees with its Cramér-Rao bound within :data:`BOUND_AGREEMENT_FACTOR` (:func:`bound_agreement`).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.calibration import boxin, crb
from sblsim.models.declarations import ModelError, Variable
from sblsim.orchestrator.io import tomlfile
from sblsim.orchestrator.io.progress import Progress
from sblsim.orchestrator.surveys.calibrate import (
    SOLVER_KEYS,
    Calibration,
    Survey,
    calibrate,
    check_solver,
    solver_defaults,
    solver_value,
)
from sblsim.orchestrator.surveys.log import LOG_COLUMNS, SurveyLog, check_frame

_FOLDER = files("sblsim.orchestrator.surveys")
#: The built-in simulated surveys: name -> its TOML file's name in this package.
SIMULATED_SURVEYS = {"box-in": "box-in.toml"}
#: The largest CONFIG.toml read [bytes].
MAX_CONFIG_BYTES = 1 << 20
#: The replicates accepted.
REPLICATES_RANGE = (1, 100_000)
#: The transponder's id in a simulated log.
TRANSPONDER_ID = "1"
#: A study's horizontal error (the replicates' RMS, or one calibration's 1-sigma) and its Cramér-Rao bound must agree
#: within this factor, either way, for a survey sigma to be suggested from it (:func:`bound_agreement`).
BOUND_AGREEMENT_FACTOR = 3.0
#: Columns of ``replicates.parquet``.
REPLICATE_COLUMNS = ("replicate", "id", "e_n_m", "e_e_m", "e_u_m", "nees", "pcrb_h_m")


def sections() -> dict[str, dict[str, Variable]]:
    """The simulation's keys by table: ``survey`` and ``platform`` (``solver`` is :data:`SOLVER_KEYS`)."""
    return {"survey": {v.name: v for v in boxin.SURVEY_VARIABLES}, "platform": boxin.platform_variables()}


def is_simulated(source: str) -> bool:
    """Whether ``source`` names a simulated survey: a built-in one or a ``.toml`` file."""
    return source in SIMULATED_SURVEYS or source.lower().endswith(".toml")


@dataclass
class SimulatedSurvey:
    """A simulated survey's settings, checked.

    Attributes
    ----------
    name : str
        The built-in name or the file's stem.
    survey, platform : dict
        The values of every key of :func:`sections` (defaults filled).
    solver : dict
        The solver's settings (``sound_speed_mps`` and, unless given, ``twtt_sigma_s`` are set per replicate).
    given : set of str
        The solver's keys given in the file or by ``--set``.
    """

    name: str
    survey: dict
    platform: dict
    solver: dict
    given: set = field(default_factory=set)


def _read(source: str) -> tuple[str, dict]:
    if source in SIMULATED_SURVEYS:
        return source, tomlfile.loads(_FOLDER.joinpath(SIMULATED_SURVEYS[source]).read_text(encoding="utf-8"))
    path = Path(source)
    if path.exists() and not path.is_file():  # a directory, a pipe or a device: never opened
        raise ModelError(f"calibrate: {source[:80]!r} is not a regular file; give a survey CONFIG.toml")
    try:
        with open(path, "rb") as handle:  # a missing file or a refused read fails here
            data = handle.read(MAX_CONFIG_BYTES + 1)
    except FileNotFoundError:
        raise ModelError(f"calibrate: no such file {source[:80]!r}; give a built-in survey "
                         f"({', '.join(SIMULATED_SURVEYS)}) or a survey CONFIG.toml") from None
    except OSError as exc:
        raise ModelError(f"calibrate: {source[:80]!r} cannot be read ({exc.strerror})") from None
    if len(data) > MAX_CONFIG_BYTES:
        raise ModelError(f"calibrate: {source[:80]!r} is larger than {MAX_CONFIG_BYTES} bytes; a survey "
                         "CONFIG.toml is a few lines")
    try:
        return path.stem, tomlfile.loads(data.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ModelError(f"calibrate: {source[:80]!r} is not valid TOML ({str(exc)[:120]})") from None


def _solver_value(name: str, value: Any) -> Any:
    if name not in SOLVER_KEYS:
        raise ModelError(f"solver.{name[:40]}: unknown key; the keys: " + ", ".join(f"solver.{k}" for k in SOLVER_KEYS))
    if name == "sound_speed_mps":
        raise ModelError("solver.sound_speed_mps: a simulated survey's solver takes the true sound speed plus "
                         "survey.sound_speed_error_mps [m/s]; set that one")
    return solver_value(name, value)


def load_simulated(source: str, overrides: list[str] | None = None) -> SimulatedSurvey:
    """A simulated survey from a built-in name or a CONFIG.toml, with ``--set TABLE.KEY=VALUE`` items.

    Parameters
    ----------
    source : str
        A name of :data:`SIMULATED_SURVEYS` or a ``.toml`` file.
    overrides : list of str
        ``survey.KEY=VALUE``, ``platform.KEY=VALUE`` or ``solver.KEY=VALUE`` (the value read as TOML).

    Raises
    ------
    ModelError
        One line: a file that cannot be read or is not TOML, an unknown table or key, a value outside its range
        (naming the key, the allowed range and the unit).
    """
    name, raw = _read(source)
    tables = sections()
    values: dict[str, dict] = {"survey": {}, "platform": {}, "solver": {}}
    for table, content in raw.items():
        if table not in values:
            raise ModelError(f"{table[:40]}: unknown table of a simulated survey; the tables: survey, platform, "
                             "solver")
        if not isinstance(content, dict):
            raise ModelError(f"{table[:40]}: expected a table [{table[:40]}]")
        values[table].update(content)
    for item in overrides or []:
        if "=" not in item:
            raise ModelError(f"--set: expected TABLE.KEY=VALUE, got {item[:60]!r}")
        key, text = (s.strip() for s in item.split("=", 1))
        table, _, sub = key.partition(".")
        if table not in values or not sub:
            raise ModelError(f"--set: {key[:60]!r} is not a key of a simulated survey; give survey.KEY, "
                             "platform.KEY or solver.KEY")
        try:
            values[table][sub] = tomlfile.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            values[table][sub] = text  # text, refused below unless a text key takes it
    out = {}
    for table, declared in tables.items():
        unknown = sorted(set(values[table]) - set(declared))
        if unknown:
            raise ModelError(f"{table}.{unknown[0][:40]}: unknown key; the keys: "
                             + ", ".join(f"{table}.{k}" for k in declared))
        out[table] = {k: v.coerce(values[table].get(k, v.start), f"{table}.{k}") for k, v in declared.items()}
    solver = solver_defaults()
    for key, value in values["solver"].items():
        solver[key] = _solver_value(key, value)
    return SimulatedSurvey(name, out["survey"], out["platform"], check_solver(solver), set(values["solver"]))


def replicate(sim: SimulatedSurvey, k: int) -> tuple[Survey, boxin.Simulated]:
    """Replicate ``k`` simulated and written as a calibration log, ready for
    :func:`sblsim.orchestrator.surveys.calibrate.calibrate`."""
    s = boxin.simulate(sim.survey, sim.platform, k)
    m = s.measured
    n = len(m)
    frame = pd.DataFrame({"ping": np.arange(n, dtype=np.int64), "transponder": [TRANSPONDER_ID] * n,
                          "t_tx_s": s.t_tx})
    for prefix, points, sigma in (("tx", m.tx, m.tx_sigma), ("rx", m.rx, m.rx_sigma)):
        if prefix == "rx":
            frame["t_rx_s"] = s.t_rx
        for j, axis in enumerate("enu"):
            frame[f"{prefix}_{axis}_m"] = points[:, j]
        for j, axis in enumerate("enu"):
            frame[f"{prefix}_sigma_{axis}_m"] = sigma[:, j]
    frame["twtt_s"] = m.twtt
    frame = frame[list(LOG_COLUMNS)]
    log: SurveyLog = check_frame(frame, [f"ping {p}" for p in range(n)], f"{sim.name} replicate {k}")
    log.counts["ignored_columns"] = []
    solver = dict(sim.solver)
    solver["sound_speed_mps"] = solver_value("sound_speed_mps", s.assumed_sound_speed)
    if "twtt_sigma_s" not in sim.given:
        solver["twtt_sigma_s"] = s.twtt_sigma
    survey = Survey(sim.name, log, [TRANSPONDER_ID], s.apriori, solver, None, "simulated",
                    f"simulated {sim.survey['pattern']} survey {sim.name}, replicate {k}")
    return survey, s


@dataclass
class Outcome:
    """One solved replicate: its calibration and its row of ``replicates.parquet``."""

    calibration: Calibration
    simulated: boxin.Simulated
    row: dict


def solve_replicate(sim: SimulatedSurvey, k: int, progress: Any = False) -> Outcome:
    """Simulate and solve replicate ``k``: errors against the truth, NEES, the horizontal CRB (``progress``: of a
    moving-ocean solve, :func:`~sblsim.orchestrator.surveys.solution.calibrate`)."""
    survey, s = replicate(sim, k)
    result = calibrate(survey, progress)
    t = result.solution["transponders"][0]
    error_enu = np.array([t["e_m"], t["n_m"], t["u_m"]]) + s.apriori[0] - s.truth[0]
    if len(result.segments) == 1:
        covariance = result.segments[0][3].covariance[:3, :3]
    else:
        covariance = np.diag([t["sigma_e_m"] ** 2, t["sigma_n_m"] ** 2, t["sigma_u_m"] ** 2])
    try:
        nees = float(error_enu @ np.linalg.solve(covariance, error_enu))
    except np.linalg.LinAlgError:
        nees = float("nan")
    solved = result.segments[0][3].perturbation  # the bound of the perturbation solved (a search's choice)
    bound = crb(s.true, s.truth, s.sound_speed, solve_sound_speed=sim.solver["solve_sound_speed"],
                twtt_sigma=s.twtt_sigma, perturbation=None if solved is None else solved.settings)
    row = {"replicate": k, "id": TRANSPONDER_ID, "e_n_m": float(error_enu[1]), "e_e_m": float(error_enu[0]),
           "e_u_m": float(error_enu[2]), "nees": nees, "pcrb_h_m": float(math.sqrt(bound[0, 0] + bound[1, 1]))}
    return Outcome(result, s, row)


def survey_sigma(solution: dict, table: pd.DataFrame | None = None) -> tuple[float, str]:
    """The survey error per axis an LBL design takes (``platform.survey_sigma`` [m]) and what it is.

    With several replicates: the RMS of their errors over the three axes,
    :math:`\\sqrt{\\overline{e_n^2 + e_e^2 + e_u^2}/3}`; else the calibration's own 1-sigma,
    :math:`\\sqrt{(\\sigma_n^2 + \\sigma_e^2 + \\sigma_u^2)/3}` (of the first transponder).
    """
    if table is not None and len(table) > 1:
        e2 = (table["e_n_m"] ** 2 + table["e_e_m"] ** 2 + table["e_u_m"] ** 2).to_numpy()
        return float(np.sqrt(np.mean(e2) / 3.0)), f"the RMS error per axis of {len(table)} replicates"
    t = solution["transponders"][0]
    value = math.sqrt((t["sigma_n_m"] ** 2 + t["sigma_e_m"] ** 2 + t["sigma_u_m"] ** 2) / 3.0)
    return value, "the calibration's own 1-sigma per axis (RMS of North, East, Up)"


def bound_agreement(solution: dict, table: pd.DataFrame | None = None) -> dict:
    """Whether a study's horizontal error agrees with its Cramér-Rao bound within :data:`BOUND_AGREEMENT_FACTOR`.

    With several replicates the measured error is their horizontal RMS error against the truth and the bound the
    RMS of their horizontal bounds (``solution["replicates"]``); with one, the calibration's horizontal 1-sigma
    :math:`\\sqrt{\\sigma_e^2 + \\sigma_n^2}` against that replicate's bound. A bound far from the Monte Carlo (or
    from the solver's sigma) means the solver's model is not the simulation's (an ocean left out, correlated GNSS
    errors) or that the survey does not determine what is solved (a gradient from one circle): neither number is a
    survey error to design with.

    Returns
    -------
    dict
        ``measured_h_m``, ``bound_h_m`` [m], ``ratio`` (measured over bound; None when the bound is not a positive
        finite number), ``agrees``, ``measured`` (what was measured).
    """
    if table is not None and len(table) > 1:
        r = solution["replicates"]
        measured, bound = r["rms_h_m"], r["pcrb_h_m"]
        what = f"the horizontal RMS error of {len(table)} replicates"
    else:
        t = solution["transponders"][0]
        measured, bound = math.hypot(t["sigma_e_m"], t["sigma_n_m"]), solution["errors"][0]["pcrb_h_m"]
        what = "the calibration's horizontal 1-sigma"
    ratio = measured / bound if math.isfinite(bound) and bound > 0.0 and math.isfinite(measured) else None
    agrees = ratio is not None and 1.0 / BOUND_AGREEMENT_FACTOR <= ratio <= BOUND_AGREEMENT_FACTOR
    return {"measured_h_m": measured, "bound_h_m": bound, "ratio": ratio, "agrees": agrees, "measured": what}


def run_simulated(sim: SimulatedSurvey, replicates: int | None = None, progress: Any = False
                  ) -> tuple[Calibration, pd.DataFrame | None]:
    """Replicate 0 solved (with the truth, its errors and the bound in its solution), and with ``replicates``
    the table of :data:`REPLICATE_COLUMNS` of replicates ``0 .. replicates - 1``.

    Raises
    ------
    ModelError
        ``replicates`` outside :data:`REPLICATES_RANGE`, or a replicate the solver cannot solve.
    """
    if replicates is not None:
        lo, hi = REPLICATES_RANGE
        if isinstance(replicates, bool) or not isinstance(replicates, int) or not lo <= replicates <= hi:
            raise ModelError(f"--replicates: {replicates!r} is outside the allowed range [{lo}, {hi}]")
    count = replicates or 1
    rows, first = [], None
    if count == 1 and sim.solver["perturbation"] != "none":  # one moving-ocean solve: its iterations' progress
        first = solve_replicate(sim, 0, progress)
        rows.append(first.row)
    else:
        with Progress(count, "calibrate", "replicate", progress) as bar:
            for k in range(count):
                outcome = solve_replicate(sim, k)
                first = first or outcome
                rows.append(outcome.row)
                bar.update()
    table = pd.DataFrame(rows, columns=list(REPLICATE_COLUMNS)) if replicates is not None else None
    result, s = first.calibration, first.simulated
    solution = result.solution
    solution["simulation"] = {"survey": sim.survey, "platform": sim.platform, "replicate": 0}
    solution["truth"] = [{"id": TRANSPONDER_ID, "e_m": float(s.truth[0, 0]), "n_m": float(s.truth[0, 1]),
                          "u_m": float(s.truth[0, 2])}]
    solution["errors"] = [{k: first.row[k] for k in REPLICATE_COLUMNS if k != "replicate"}]
    if table is not None:
        e = table[["e_n_m", "e_e_m", "e_u_m"]].to_numpy()
        solution["replicates"] = {
            "count": len(table),
            "rms_n_m": float(np.sqrt(np.mean(e[:, 0] ** 2))), "rms_e_m": float(np.sqrt(np.mean(e[:, 1] ** 2))),
            "rms_u_m": float(np.sqrt(np.mean(e[:, 2] ** 2))),
            "rms_h_m": float(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2))),
            "pcrb_h_m": float(np.sqrt(np.mean(table["pcrb_h_m"].to_numpy() ** 2))),
            "nees_mean": float(np.nanmean(table["nees"].to_numpy())),
        }
    value, what = survey_sigma(solution, table)
    solution["survey_sigma_m"] = value
    solution["survey_sigma_from"] = what
    agreement = bound_agreement(solution, table)
    solution["bound_agreement"] = agreement
    solution["lbl_set"] = f"platform.survey_sigma={value:.4g}" if agreement["agrees"] else None
    if not agreement["agrees"]:
        apart = None if agreement["ratio"] is None else max(agreement["ratio"], 1.0 / agreement["ratio"])
        factor = ("an undefined factor" if apart is None else
                  f"a factor {apart:.3g}" if apart < 1000.0 else f"a factor {apart:,.0f}")
        result.warnings.append(
            f"{agreement['measured']} ({agreement['measured_h_m']:.4g} m) and its Cramér-Rao bound "
            f"({agreement['bound_h_m']:.4g} m) disagree by {factor}, more than {BOUND_AGREEMENT_FACTOR:g}: the "
            "solver's model is not the simulation's (an ocean or correlated GNSS errors left out) or the survey does "
            "not determine what it solves; no survey sigma is suggested from this study")
    return result, table


__all__ = ["BOUND_AGREEMENT_FACTOR", "MAX_CONFIG_BYTES", "Outcome", "REPLICATES_RANGE", "REPLICATE_COLUMNS",
           "SIMULATED_SURVEYS", "SimulatedSurvey", "TRANSPONDER_ID", "bound_agreement", "is_simulated",
           "load_simulated", "replicate", "run_simulated", "sections", "solve_replicate", "survey_sigma"]

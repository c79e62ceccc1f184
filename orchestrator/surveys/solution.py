"""A calibration survey solved (:func:`calibrate`): each segment by the calibration solver
(:mod:`sblsim.models.calibration`: the least-squares solution, the moving ocean's, or the search among its
candidates), the segments combined, the running solution beside them, and the numbers of ``solution.json`` and the
tables of the other files (:class:`Calibration`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from sblsim.fmus.compiled_functions import compiled_exact_points
from sblsim.models.acoustics.sound_speed import profile_table
from sblsim.models.calibration import (
    RUNNING_AGREEMENT_SIGMA,
    EigenRay,
    LegModel,
    Perturbation,
    Solution,
    StraightRay,
    combine,
    running,
    running_disagreement,
    select,
    solve,
)
from sblsim.models.calibration.ocean import bases_of
from sblsim.models.calibration.perturbation import effective_scale
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.progress import Progress, ProgressSpec
from sblsim.orchestrator.surveys.harmonic_mean import harmonic_mean_speed
from sblsim.orchestrator.surveys.settings import SEARCH_KEYS, _instant
from sblsim.orchestrator.surveys.survey import Survey

#: Columns of ``ntd.csv``: one row per reply (its segment, ping, transponder, mid-time [s, POSIX], the nadir angle's
#: cosine, the nadir-normalised TWTT residual of the legs less the gradients' part [s], the perturbation's nadir
#: delay [s] and what remains [s], the sound speed's change the delay means [m/s], used).
NTD_COLUMNS = ("segment", "ping", "transponder", "t_s", "nadir_cosine", "observed_s", "ntd_s", "residual_s",
               "sound_speed_change_mps", "used")
#: Columns of ``running.csv``: one row per reply the running solution takes and per transponder (the
#: estimate after that reply: offsets from the a-priori position [m], local frame of the a-priori point, and
#: their 1-sigma; the reply's innovation [m], its 1-sigma [m] and its NIS [1]).
RUNNING_COLUMNS = ("segment", "reply", "ping", "transponder", "t_tx_s", "id", "e_m", "n_m", "u_m", "sigma_e_m",
                   "sigma_n_m", "sigma_u_m", "sound_speed_mps", "innovation_m", "innovation_sigma_m", "nis")


@dataclass
class Calibration:
    """A solved survey: its segments' solutions, the combination, the tables and numbers written."""

    survey: Survey
    segments: list[tuple[str, str, np.ndarray, Solution]]
    solution: dict
    residuals: pd.DataFrame
    #: The running solution, :data:`RUNNING_COLUMNS` (None with ``solver.running = false``).
    running: pd.DataFrame | None = None
    #: The perturbation of each reply, :data:`NTD_COLUMNS` (None without one).
    ntd: pd.DataFrame | None = None
    #: The search's candidates (:func:`sblsim.models.calibration.select`, with their ``segment``; None without).
    search: pd.DataFrame | None = None
    #: What the user must know about the solution (one line each; ``sblsim calibrate`` prints them as warnings).
    warnings: list[str] = field(default_factory=list)


def _windows(survey: Survey) -> list[tuple[str, str, np.ndarray]]:
    f = survey.log.frame
    t = f["t_tx_s"].to_numpy()
    near = np.hypot(f["tx_e_m"].to_numpy(), f["tx_n_m"].to_numpy()) <= survey.solver["distance_limit_m"]
    if not survey.solver["segments"]:
        return [("", "", np.flatnonzero(near))]
    out = []
    for k, (a, b) in enumerate(survey.solver["segments"]):
        start, end = _instant(a, f"solver.segments[{k}]"), _instant(b, f"solver.segments[{k}]")
        out.append((a, b, np.flatnonzero((t >= start) & (t < end) & near)))
    return out


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x**2))) if len(x) else float("nan")


def leg_model(survey: Survey) -> tuple[LegModel | None, np.ndarray | None]:
    """The legs' model of a survey's settings and, for a straight ray through a profile, each transponder's
    harmonic-mean speed [m/s].

    ``propagation = "straight"`` without a profile: None (a straight ray at ``sound_speed_mps``); with one:
    :class:`~sblsim.models.calibration.StraightRay` at each transponder's harmonic mean of the profile from
    ``harmonic_mean_start_depth_m`` to its depth (:attr:`Survey.depth_m`, or ``surface_u_m`` less its Up), the
    model's
    :func:`~sblsim.orchestrator.surveys.harmonic_mean.harmonic_mean_speed`; ``propagation = "ray"``:
    :class:`~sblsim.models.calibration.EigenRay` through the profile (its solve compiled in the local engine's
    library when a C compiler can build it; else evaluated by casadi, some 15 times slower).

    Returns
    -------
    legs : LegModel or None
        The leg model for :func:`~sblsim.models.calibration.solve` (None: its default straight ray).
    speeds : numpy.ndarray, shape (k,), or None
        Each transponder's harmonic-mean speed [m/s] (straight rays through a profile only).

    Raises
    ------
    ModelError
        ``ray`` without a profile, an unknown or unreadable profile, a transponder not below the start depth.
    """
    s = survey.solver
    table = profile_of(survey)
    if table is None:
        if s["propagation"] == "ray":
            raise ModelError("solver.sound_speed_profile: propagation = \"ray\" needs a profile (e.g. ctd:NCL1)")
        return None, None
    if s["propagation"] == "ray":
        # the eigenray solve compiled in the local engine's library when a compiler builds it (once per cache)
        return EigenRay(table, s["sound_speed_mps"], s["surface_u_m"], compiled_exact_points(),
                        earth_radius=s["earth_radius_m"], transducer_depth=s["transducer_depth_m"]), None
    start = s["harmonic_mean_start_depth_m"]
    speeds = []
    depths = survey.depth_m if survey.depth_m is not None else s["surface_u_m"] - survey.apriori[:, 2]
    for name, depth in zip(survey.ids, depths):
        if depth <= start:
            raise ModelError(f"solver.harmonic_mean_start_depth_m: transponder {name} at {depth:g} m is not below "
                             f"the start depth {start:g} m")
        speeds.append(harmonic_mean_speed(start, depth, s["sound_speed_profile"] or table))
    speeds = np.array(speeds)
    return StraightRay(s["sound_speed_mps"] / speeds), speeds


def profile_of(survey: Survey) -> np.ndarray | None:
    """The profile of a survey's settings: ``solver.sound_speed_profile``'s table, else the survey's own (SeaGap),
    else None.

    Raises
    ------
    ModelError
        An unknown or unreadable profile, or one without a table.
    """
    profile = survey.solver["sound_speed_profile"]
    if not profile:
        return survey.profile
    table = profile_table(profile, "", 15.0, 35.0, field="solver.sound_speed_profile")
    if table.shape[0] == 0:
        raise ModelError(f"solver.sound_speed_profile: {profile[:40]!r} has no table; give a cast such as ctd:NCL1")
    return table


def calibrate(survey: Survey, progress: ProgressSpec = False) -> Calibration:
    """Solve every segment of a survey and combine them.

    Parameters
    ----------
    survey : Survey
    progress : bool, 'auto', 'log' or callable
        Report the Gauss-Newton iterations of a moving-ocean solve or search
        (:class:`sblsim.orchestrator.io.progress.Progress`; their number is not known ahead).

    Returns
    -------
    Calibration

    Raises
    ------
    ModelError
        A segment without enough replies (named), more bases than a segment's pings determine (``solver.n_bases``
        or ``solver.knot_interval``, checked for every segment and candidate before any is solved), or replies that
        do not determine the unknowns.
    """
    legs, harmonic = leg_model(survey)
    candidates = perturbations(survey)
    windows = []
    for k, (a, b, rows) in enumerate(_windows(survey)):
        what = f"segment {k + 1} [{a}, {b})" if a else "the log"
        replies = survey.log.replies(survey.ids, rows)
        if len(replies):
            for candidate in candidates:
                bases_of(candidate, replies.t_tx, replies.t_rx, what, prefix="solver.")
        windows.append((k, a, b, rows, what, replies))
    bar = Progress(0, f"calibrate {survey.name} (the moving ocean)", "iteration", progress if candidates else False)
    with bar:
        segments, runs, nis, apart, searches, tables = _solve_windows(survey, windows, candidates, legs,
                                                                      bar.update if bar.active else None)
    residuals = pd.concat(tables, ignore_index=True)
    return _combined(survey, segments, runs, nis, apart, searches, residuals, candidates, harmonic)


def _solve_windows(survey: Survey, windows: list, candidates: list[Perturbation], legs: LegModel | None,
                   step) -> tuple[list, list, list, list, list, list]:
    """Each window's solution (a search's, the least squares', a moving ocean's), its running solution and its
    rows of ``residuals.csv``; ``step(1)`` after each Gauss-Newton iteration of a moving-ocean solve."""
    s = survey.solver
    f = survey.log.frame
    segments, tables, runs, nis, apart, searches = [], [], [], [], [], []
    for k, a, b, rows, what, replies in windows:
        if len(candidates) > 1:
            sol, table = select(replies, survey.apriori, s["sound_speed_mps"], candidates, rigid=s["rigid"],
                                outlier_factor=s["outlier_factor"], legs=legs, what=what, criterion=s["criterion"],
                                progress=step)
            searches.append(pd.DataFrame(table).assign(segment=k + 1))
        else:
            sol = solve(replies, survey.apriori, s["sound_speed_mps"], rigid=s["rigid"],
                        solve_sound_speed=s["solve_sound_speed"], outlier_factor=s["outlier_factor"],
                        twtt_sigma=s["twtt_sigma_s"], legs=legs, what=what,
                        perturbation=candidates[0] if candidates else None, progress=step)
        segments.append((a, b, rows, sol))
        if s["running"] and not candidates:  # the running solution has no perturbation model
            frame, distance, sigmas = _running(survey, k + 1, rows, replies, sol, legs, what)
            runs.append(frame)
            nis.append(frame["nis"].to_numpy()[::len(survey.ids)])
            j = int(np.argmax(sigmas))
            apart.append((float(sigmas[j]), float(np.max(distance)), survey.ids[j], what, float(np.mean(nis[-1]))))
        part = f.iloc[rows][["ping", "transponder", "t_tx_s", "tx_e_m", "tx_n_m", "rx_e_m", "rx_n_m"]].copy()
        part.insert(0, "segment", k + 1)
        part["residual_s"] = sol.residual_s
        part["residual_m"] = sol.residual_m
        part["weight_per_m2"] = sol.weight
        part["elevation_deg"] = np.degrees(sol.elevation)
        part["azimuth_deg"] = np.degrees(sol.azimuth) % 360.0
        part["used"] = sol.used
        tables.append(part)
    return segments, runs, nis, apart, searches, tables


def _combined(survey: Survey, segments: list, runs: list, nis: list, apart: list, searches: list,
              residuals: pd.DataFrame, candidates: list[Perturbation], harmonic: np.ndarray | None) -> Calibration:
    """The segments combined: ``solution.json``'s numbers, the running solution's check, the tables."""
    s = survey.solver
    f = survey.log.frame
    combined = combine([seg[3] for seg in segments])
    used = residuals[residuals["used"]]
    rejected = residuals[~residuals["used"]]
    w = used["weight_per_m2"].to_numpy()
    speeds = [seg[3].sound_speed for seg in segments]
    solution = {
        "survey": survey.name,
        "title": survey.title,
        "format": survey.format,
        "origin": survey.origin,
        "sound_speed_mps": float(np.mean(speeds)),
        "solver": {k: (list(map(list, v)) if k == "segments" else v) for k, v in s.items()},
        "transponders": [
            {"id": name,
             "n_m": float(combined.position[j, 1] - survey.apriori[j, 1]),
             "e_m": float(combined.position[j, 0] - survey.apriori[j, 0]),
             "u_m": float(combined.position[j, 2] - survey.apriori[j, 2]),
             "sigma_n_m": float(combined.sigma[j, 1]), "sigma_e_m": float(combined.sigma[j, 0]),
             "sigma_u_m": float(combined.sigma[j, 2]),
             "scatter_n_m": _finite(combined.scatter[j, 1]), "scatter_e_m": _finite(combined.scatter[j, 0]),
             "scatter_u_m": _finite(combined.scatter[j, 2]),
             "apriori_e_m": float(survey.apriori[j, 0]), "apriori_n_m": float(survey.apriori[j, 1]),
             "apriori_u_m": float(survey.apriori[j, 2]),
             **({"sound_speed_mps": float(harmonic[j])} if harmonic is not None else {})}
            for j, name in enumerate(survey.ids)],
        "segments": [
            {"start": a, "end": b, "id": name,
             "n_m": float(sol.offset[j, 1]), "e_m": float(sol.offset[j, 0]), "u_m": float(sol.offset[j, 2]),
             "sigma_n_m": float(sol.sigma[j, 1]), "sigma_e_m": float(sol.sigma[j, 0]),
             "sigma_u_m": float(sol.sigma[j, 2]),
             "pings_used": int(f.iloc[rows[sol.used]]["ping"].nunique()),
             "pings_rejected": int(f.iloc[rows[~sol.used]]["ping"].nunique()),
             "sound_speed_mps": sol.sound_speed,
             "twtt_residual_rms_s": _rms(sol.residual_s[sol.used]),
             "variance_factor": sol.variance_factor, "converged": sol.converged}
            for a, b, rows, sol in segments for j, name in enumerate(survey.ids)],
        "determination": _determination(segments),
        "twtt_residual_rms_s": _rms(used["residual_s"].to_numpy()),
        "twtt_residual_wrms_s": float(np.sqrt(np.sum(w * used["residual_s"].to_numpy() ** 2) / np.sum(w))),
        "pings_used": int(used["ping"].nunique()),
        "pings_rejected": int(rejected["ping"].nunique()),
        "replies_used": len(used),
        "replies_rejected": len(rejected),
        "log": {"rows": survey.log.counts["rows"], "pings": survey.log.counts["pings"],
                "replies_per_transponder": survey.log.counts["transponders"],
                "replies_in_no_segment": int(len(f) - residuals.drop_duplicates(["ping", "transponder"]).shape[0]),
                "ignored_columns": survey.log.counts.get("ignored_columns", [])},
    }
    warnings = []
    if runs:
        values = np.concatenate(nis)
        worst = max(apart)
        solution["running"] = {"replies": len(values), "nis_mean": float(np.mean(values)),
                               "prior_sigma_m": s["running_prior_sigma_m"], "iterated": s["running_iterated"],
                               "passes": s["running_passes"],
                               "largest_distance_from_least_squares_m": max(a[1] for a in apart),
                               "agrees_with_least_squares": worst[0] <= RUNNING_AGREEMENT_SIGMA}
        if worst[0] > RUNNING_AGREEMENT_SIGMA:
            warnings.append(f"the running solution of {worst[3]} ends {worst[1]:.4g} m from the least-squares "
                            f"solution (transponder {worst[2]} {worst[0]:.3g} sigma apart, more than "
                            f"{RUNNING_AGREEMENT_SIGMA:g}; mean NIS {worst[4]:.3g}, 1 when consistent): it did not "
                            "converge from the a-priori positions, so running.csv is no solution (solution.json "
                            "is); give it more passes (solver.running_passes) or a-priori positions nearer the truth")
    solution.update(_perturbation_keys(survey, segments, combined))
    ntd = _ntd_table(survey, segments) if candidates else None
    search = pd.concat(searches, ignore_index=True) if searches else None
    return Calibration(survey, segments, solution, residuals, pd.concat(runs, ignore_index=True) if runs else None,
                       ntd=ntd, search=search, warnings=warnings)


def perturbations(survey: Survey) -> list[Perturbation]:
    """The perturbations a survey's settings solve: none (``solver.perturbation = "none"``), one, or the candidates
    of a search (the product of the lists among :data:`SEARCH_KEYS`).

    GARPOS's characteristic travel time is twice the transponders' mean depth (:attr:`Survey.depth_m`, or
    ``surface_u_m`` less their Up) over the profile's depth-averaged speed (its trapezoidal mean over its rows;
    ``sound_speed_mps`` without a profile), as GARPOS takes it.

    Raises
    ------
    ModelError
        A list among GARPOS's keys with ``perturbation = "ntd"``, more than 500 candidates, or the profile's errors.
    """
    s = survey.solver
    if s["perturbation"] == "none":
        return []
    lists = {k: (s[k] if isinstance(s[k], list) else [s[k]]) for k in SEARCH_KEYS}
    if s["perturbation"] == "ntd":
        for key in SEARCH_KEYS[1:]:
            if len(lists[key]) > 1:
                raise ModelError(f"solver.{key}: a list searches GARPOS's hyperparameters (perturbation = garpos); "
                                 "SeaGap's NTD searches n_bases")
    count = math.prod(len(v) for v in lists.values())
    if count > 500:
        raise ModelError(f"solver: {count} candidates in the search (the product of the lists of "
                         f"{', '.join(SEARCH_KEYS)}); at most 500")
    t0 = 0.0
    if s["perturbation"] == "garpos":
        table = profile_of(survey)
        depths = survey.depth_m if survey.depth_m is not None else s["surface_u_m"] - survey.apriori[:, 2]
        speed = s["sound_speed_mps"] if table is None or len(table) < 2 else \
            float(np.sum(0.5 * (table[1:, 1] + table[:-1, 1]) * np.diff(table[:, 0])) / (table[-1, 0] - table[0, 0]))
        t0 = 2.0 * float(np.mean(depths)) / speed
    common = {"kind": s["perturbation"], "knot_interval": s["knot_interval"], "gradient": s["gradient"],
              "reject_sigma": s["reject_sigma"], "earth_radius": s["earth_radius_m"], "t0": t0}
    return [Perturbation(n_bases=n, log_lambda0=l0, log_grad_lambda=lg, mu_t=mt, mu_mt=mm, **common)
            for n in lists["n_bases"] for l0 in lists["log_lambda0"] for lg in lists["log_grad_lambda"]
            for mt in lists["mu_t"] for mm in lists["mu_mt"]]


def _perturbation_keys(survey: Survey, segments: list, combined) -> dict:
    """``solution.json``'s keys of the array and the perturbation: ``array_displacement`` (the rigid shift, or the
    transponders' mean offset with their sigmas taken as independent; the formal and the realistic 1-sigma),
    ``n_bases``, ``aic``, ``bic``, ``abic`` (summed over segments: the criteria of their joint model), ``gradient``
    (the deep gradient's East and North: SeaGap's constants [s], the mean of GARPOS's coefficients [1/km]) and
    ``shallow_gradient``."""
    fits = [seg[3].perturbation for seg in segments]
    offset = combined.position - survey.apriori
    scales = [_realistic(seg[3]) for seg in segments]
    scale = float(np.sqrt(np.mean(np.square(scales))))
    if survey.solver["rigid"]:
        mean, sd = offset[0], combined.sigma[0]
    else:
        mean, sd = offset.mean(axis=0), np.sqrt(np.sum(combined.sigma**2, axis=0)) / len(offset)
    out = {"array_displacement": {**{f"{a}_m": float(mean[j]) for j, a in enumerate("enu")},
                                  **{f"sigma_{a}_m": float(sd[j]) for j, a in enumerate("enu")},
                                  **{f"sigma_realistic_{a}_m": float(sd[j] * scale) for j, a in enumerate("enu")}},
           "realistic_sigma_scale": scale}
    if fits[0] is None:
        return {**out, "n_bases": None, "aic": None, "bic": None, "abic": None, "gradient": None}

    def total(name: str) -> float | None:
        values = [getattr(fit, name) for fit in fits]
        return None if values[0] is None else float(np.sum(values))

    def gradient(name: str) -> dict | None:
        if name not in fits[0].gradient:
            return None
        values = np.mean([np.mean(fit.gradient[name].reshape(2, -1), axis=1) for fit in fits], axis=0)
        return {"e": float(values[0]), "n": float(values[1])}

    bases = [fit.n_bases for fit in fits]
    return {**out, "n_bases": bases[0] if len(set(bases)) == 1 else bases, "aic": total("aic"), "bic": total("bic"),
            "abic": total("abic"), "gradient": gradient("deep"), "shallow_gradient": gradient("shallow"),
            "perturbation": {"kind": fits[0].settings.kind, "parameters": [fit.parameters for fit in fits]}}


def _determination(segments: list) -> dict:
    """``solution.json``'s ``determination``: of the segment whose normal matrix is worst conditioned, its condition
    number equilibrated to a unit diagonal and its positions' largest correlation with another unknown (a speed
    scale, the perturbation's bases or gradients; :mod:`sblsim.models.calibration.determination`), and each
    segment's."""
    dets = [seg[3].determination for seg in segments]
    rows = [d.as_dict() for d in dets]
    worst = max(range(len(dets)), key=lambda k: (dets[k].max_correlation or 0.0, dets[k].condition))
    return {**rows[worst], "segment": worst + 1, "segments": rows}


def _realistic(sol: Solution) -> float:
    """The realistic sigma's factor of a segment (:func:`~sblsim.models.calibration.perturbation.effective_scale` of
    its used residuals in time order)."""
    if sol.perturbation is not None:
        return sol.perturbation.effective_scale
    return effective_scale(sol.residual_s[sol.used])


def _ntd_table(survey: Survey, segments: list) -> pd.DataFrame:
    """The rows of :data:`NTD_COLUMNS`, every segment's replies.

    The sound speed's change of a reply's delay :math:`\\delta` is that of a uniform water column,
    :math:`\\delta V = -V\\,\\delta/T_v`, :math:`T_v = T\\cos\\xi` its nadir two-way time, :math:`V` the solver's
    speed (for GARPOS this is its :math:`\\gamma V`)."""
    f = survey.log.frame
    parts = []
    for k, (_, _, rows, sol) in enumerate(segments, start=1):
        fit = sol.perturbation
        src = f.iloc[rows]
        nadir = src["twtt_s"].to_numpy() * fit.mapping
        parts.append(pd.DataFrame({
            "segment": k, "ping": src["ping"].to_numpy(), "transponder": src["transponder"].to_numpy(),
            "t_s": fit.mid_time, "nadir_cosine": fit.mapping, "observed_s": fit.observed, "ntd_s": fit.delay,
            "residual_s": fit.observed - fit.delay, "sound_speed_change_mps": -sol.sound_speed * fit.delay / nadir,
            "used": sol.used}))
    return pd.concat(parts, ignore_index=True)[list(NTD_COLUMNS)]


def _running(survey: Survey, segment: int, rows: np.ndarray, replies, sol: Solution, legs: LegModel | None,
             what: str) -> tuple[pd.DataFrame, np.ndarray, np.ndarray]:
    """The running solution of a segment's replies that :func:`~sblsim.models.calibration.solve` kept, in
    transmit-time order, as rows of :data:`RUNNING_COLUMNS`, and how far it ends from ``sol``
    (:func:`~sblsim.models.calibration.running_disagreement`)."""
    s = survey.solver
    f = survey.log.frame
    kept = np.flatnonzero(sol.used)
    kept = kept[np.argsort(f["t_tx_s"].to_numpy()[rows[kept]], kind="stable")]
    run = running(replies.subset(kept), survey.apriori, s["sound_speed_mps"], rigid=s["rigid"],
                  solve_sound_speed=s["solve_sound_speed"], twtt_sigma=s["twtt_sigma_s"], legs=legs,
                  prior_sigma=s["running_prior_sigma_m"], iterated=s["running_iterated"],
                  passes=s["running_passes"], what=what)
    n, k = len(kept), len(survey.ids)
    source = f.iloc[rows[kept]]
    offset = run.position - survey.apriori[None]
    rep = np.repeat
    frame = pd.DataFrame({
        "segment": segment, "reply": rep(np.arange(n), k), "ping": rep(source["ping"].to_numpy(), k),
        "transponder": rep(source["transponder"].to_numpy(), k), "t_tx_s": rep(source["t_tx_s"].to_numpy(), k),
        "id": np.tile(np.asarray(survey.ids, dtype=object), n),
        "e_m": offset[:, :, 0].ravel(), "n_m": offset[:, :, 1].ravel(), "u_m": offset[:, :, 2].ravel(),
        "sigma_e_m": run.position_sigma[:, :, 0].ravel(), "sigma_n_m": run.position_sigma[:, :, 1].ravel(),
        "sigma_u_m": run.position_sigma[:, :, 2].ravel(), "sound_speed_mps": rep(run.sound_speed, k),
        "innovation_m": rep(run.innovation, k), "innovation_sigma_m": rep(np.sqrt(run.innovation_variance), k),
        "nis": rep(run.nis, k)}, columns=list(RUNNING_COLUMNS))
    return (frame, *running_disagreement(run, sol))


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


__all__ = ["Calibration", "NTD_COLUMNS", "RUNNING_COLUMNS", "calibrate", "leg_model", "perturbations", "profile_of"]

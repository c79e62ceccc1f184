"""A study's receivers' positions refined from its own pings (``sblsim track --refine-positions``): the moving tags'
pings pooled with the sync tags' emissions (:func:`~sblsim.models.tracking.receiver_positions.refine_receivers`): the
tags' places, each receiver's horizontal shift and the offset its clock keeps from a synchronisation made on wrong
positions at each of its bins' edges (the sync tags' emissions, both directions of each pair of receivers, tell a
clock from a place), and the sound speed where the tags' was calibrated from their pings (it took up the positions'
error), the surveyed positions the prior (``--survey-sigma``), each receiver's timing noise its own residuals' (the
synchronisation's took up the positions' error).

Taken only where the data say it helps: the moving tags' pings of each block of the record left out in turn fit the
array refined without them better than the surveyed one (:func:`~sblsim.models.tracking.held_out.held_out`),
and only for the receivers the pings determine (the rest keep the survey's). The study is then made again on the
refined positions (the clocks synchronised on them, every tag tracked again), the positions refined again from it
until they settle (:data:`ROUNDS`), and kept only where its reference tags and the sync tags left out in turn are not
worse than on the surveyed positions (:func:`verdict`): both studies' errors are said. The reference tags' pings are
never in the refinement (they are the check). A translation or a rotation of the whole array changes no time of
arrival, nor its scale where the sound speed is fitted too: those stay the survey's.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.held_out import HELD_OUT_GAIN, held_out
from sblsim.models.tracking.receiver_positions import refine_receivers
from sblsim.models.tracking.survey_root import frame_conditioned
from sblsim.orchestrator.sync.taken_survey import position_errors

#: The rounds at most of a refinement (each: the study made again on the positions, its clocks synchronised on
#: them, and the positions refined again from its tracks), and the largest change of a receiver's refined position
#: [m] from one round to the next at which they stop.
ROUNDS, ROUND_TOLERANCE = 4, 0.05
#: The prior σ [1] of the sound speed's scale fitted with the positions where the tags' sound speeds were calibrated
#: from their pings (1 %: 15 m/s).
SPEED_SIGMA = 0.01
#: The most a refined study's pooled reference or left-out sync-tag median error may exceed the survey's study's
#: [1] and still be kept (the two studies' own noise on the same tags).
WORSE_TOLERANCE = 0.05


@dataclass
class StudyRefinement:
    """The receivers' positions refined from a study's moving tags (:func:`refine_study`).

    Attributes
    ----------
    positions : pandas.DataFrame
        ``positions.csv``: per deployment ``receiver``, the refined ``x``, ``y`` [m], the survey's ``survey_x``,
        ``survey_y`` [m], ``shift_x``, ``shift_y``, ``shift_m`` [m], ``sigma_x``, ``sigma_y`` [m] (the fit's; NaN
        where not refined), ``sigma_ratio`` [1] (the posterior σ in the array's shape over the survey's, worst
        direction), ``arrivals`` (its arrivals in the fit), ``refined`` and ``reason`` (why not).
    summary : dict
        ``study.json``'s ``positions``: what was fitted, the held-out check, and (after :func:`verdict`) the reference
        and sync tags' errors on both arrays and whether the refined one was kept.
    covariance : numpy.ndarray or None
        (2R, 2R) [m²] the receivers' horizontal position errors (x then y, in ``positions``' order) in the survey's
        frame (:func:`~sblsim.models.tracking.survey_root.frame_conditioned` of the fit's): the moving tags' consider
        terms on the refined positions take them, correlated as the fit made them.
    """

    positions: pd.DataFrame
    summary: dict[str, Any]
    covariance: np.ndarray | None = None

    def errors(self) -> tuple[list[str], np.ndarray] | None:
        """The receivers' names and :attr:`covariance`, as a track takes them (``survey_covariance``)."""
        return None if self.covariance is None else (self.positions["receiver"].astype(str).tolist(),
                                                      self.covariance)

    @property
    def helps(self) -> bool:
        """The held-out pings fit the refined array better and it moves a receiver."""
        return bool(self.summary["held_out"]["helps"] and self.positions["refined"].any())

    def deployments(self, deployments, assigned):
        """The deployments and the assigned detections' hydrophones at the refined positions."""
        shift = self.positions.set_index("receiver")[["shift_x", "shift_y"]]  # from the survey
        table = deployments.table.copy()
        moved = shift.reindex(table["receiver"]).fillna(0.0).to_numpy(float)
        table[["x", "y"]] = table[["x", "y"]].to_numpy(float) + moved
        hydrophones = assigned.hydrophones.copy()
        moved = shift.reindex(hydrophones["receiver"]).fillna(0.0).to_numpy(float)
        hydrophones[["x", "y"]] = hydrophones[["x", "y"]].to_numpy(float) + moved
        return replace(deployments, table=table), replace(assigned, hydrophones=hydrophones)


def pooled(matrix, column: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """A tag's times-of-arrival matrix over the study's receivers (``column``: each name's column): its times of
    arrival (P, R) [s] on its own origin (NaN where not heard) and each ping's time (P,) [s since 1970 UTC] (its first
    arrival's; inf where none)."""
    toa = np.full((len(matrix.toa), len(column)), np.nan)
    toa[:, [column[n] for n in matrix.names]] = matrix.toa
    return toa, np.nanmin(np.where(np.isfinite(toa), toa, np.inf), axis=1) + matrix.origin


def _pings(outcomes: dict[str, Any], matrices: dict[str, Any], folders: list[str], names: list[str]):
    """The moving tags' pings pooled over the study's receivers: times of arrival (P, R) [s] (each tag's on its own
    origin: every ping has its own emission time), each ping's place on its track (P, dim) [m] (NaN where the
    track has none), its sound speed (P,) [m/s], each receiver's timing noise (R,) [s], the tags used and each
    ping's time (P,) [s since 1970 UTC] (its first arrival's)."""
    column = {n: k for k, n in enumerate(names)}
    parts, places, speeds, used, times = [], [], [], [], []
    sigma = np.full(len(names), np.nan)
    for folder in folders:
        matrix, outcome = matrices[folder], outcomes[folder]
        toa, first = pooled(matrix, column)
        at = [column[n] for n in matrix.names]
        dim = matrix.positions.shape[1]
        estimates = outcome.estimates
        main = estimates[estimates["estimator"] == outcome.summary["track"]].dropna(subset=["x", "y"])
        place = np.full((len(toa), dim), np.nan)
        axes = ["x", "y", "z"][:dim]
        if all(a in main for a in axes):
            place[main["ping"].to_numpy(int)] = main[axes].to_numpy(float)
        noise = matrix.toa_sigma if matrix.toa_sigma is not None else np.full(
            len(matrix.names), float(np.median(np.atleast_1d(outcome.summary["sigma_toa_s"]))))
        sigma[at] = np.where(np.isfinite(sigma[at]), sigma[at], noise)
        parts.append(toa)
        times.append(first)
        places.append(place)
        speeds.append(np.full(len(toa), float(outcome.summary["sound_speed"]["sound_speed_m_s"])))
        used.append(matrix.summary["tag"])
    sigma = np.where(np.isfinite(sigma), sigma, np.nanmedian(sigma) if np.isfinite(sigma).any() else 1.5e-4)
    return np.vstack(parts), np.vstack(places), np.concatenate(speeds), sigma, used, np.concatenate(times)


def sync_pings(residuals: pd.DataFrame | None, hydrophones: pd.DataFrame, names: list[str]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The sync tags' emissions as the synchronisation heard them (its ``residuals``: ``receiver``, ``tag``,
    ``emission``, ``time_sync`` on the reference clock, ``kept``), each from the receiver its tag sits at
    (``hydrophones``' ``sync_tag``): times of arrival (Q, R) [s] over ``names`` (on the earliest's origin), each
    one's receiver (Q,) and its time (Q,) [s since 1970 UTC] (its first arrival's); None where there are none."""
    if residuals is None or not len(residuals):
        return None
    home = {str(t): str(r) for r, t in zip(hydrophones["receiver"], hydrophones["sync_tag"], strict=True) if t}
    column = {n: k for k, n in enumerate(names)}
    rows = residuals[residuals["kept"].astype(bool) & residuals["tag"].astype(str).isin(home)
                     & residuals["receiver"].astype(str).isin(column)]
    rows = rows[rows["tag"].astype(str).map(home).isin(column)]
    if not len(rows):
        return None
    emission, at = np.unique(rows["tag"].astype(str) + "#" + rows["emission"].astype(str), return_inverse=True)
    toa = np.full((len(emission), len(names)), np.nan)
    times = rows["time_sync"].to_numpy(float)
    toa[at, rows["receiver"].astype(str).map(column).to_numpy(int)] = times - times.min()
    source = np.zeros(len(emission), int)
    source[at] = rows["tag"].astype(str).map(home).map(column).to_numpy(int)
    return toa, source, np.nanmin(toa, axis=1) + times.min()


def refine_study(outcomes: dict[str, Any], matrices: dict[str, Any], moving: list[str], deployments,
                 survey_sigma: float, held: dict[str, Any] | None = None,
                 anchored: tuple[np.ndarray, ...] | None = None, edges: np.ndarray | None = None
                 ) -> StudyRefinement:
    """The receivers' positions refined from the moving tags' tracks (the module docstring).

    Parameters
    ----------
    outcomes : dict
        Each tracked tag's :class:`~sblsim.orchestrator.tracks.outcome.TrackOutcome`, by its folder.
    matrices : dict
        Each tag's times-of-arrival matrix (:class:`~sblsim.orchestrator.sync.toa.ToaOutcome`), by its folder.
    moving : list of str
        The folders of the tags tracked as moving (animals; never a reference tag).
    deployments : Deployments
        The study's deployments (their surveyed positions).
    survey_sigma : float
        [m] the survey's σ per horizontal axis.
    held : dict, optional
        An earlier round's held-out check (its ``summary["held_out"]``), taken instead of checking again (a round on
        the clocks synchronised on refined positions: :func:`~sblsim.orchestrator.telemetry.study.run_study`).
    anchored : tuple of numpy.ndarray, optional
        The sync tags' emissions as :func:`sync_pings` gives them: fitted with the moving tags' pings, each
        receiver's clock offset with its position (both directions of a pair of receivers heard).
    edges : numpy.ndarray, optional
        (K + 1,) [s since 1970 UTC] the synchronisation's bins' edges: each receiver's clock offset fitted at each
        (linear between them, as the synchronisation's clocks are: the error wrong positions leave in them changes
        from bin to bin with the sync tags a receiver hears); None: one constant offset per receiver.

    Returns
    -------
    StudyRefinement

    Raises
    ------
    ModelError
        No moving tag tracked, or none heard by four receivers at once (one line).
    """
    if not moving:
        raise ModelError("refine positions: no moving tag was tracked (the reference tags are the check, never in "
                         "the refinement); allowed: a study with a moving tag heard by four receivers at once, or "
                         "the surveyed positions (without --refine-positions)")
    table = deployments.table
    names = [str(n) for n in table["receiver"]]
    axes = ["x", "y", "z"][:matrices[moving[0]].positions.shape[1]]
    receivers = table[axes].to_numpy(float)
    toa, places, c, sigma, tags, times = _pings(outcomes, matrices, moving, names)
    biases = anchored is not None  # the clocks' offsets the synchronisation left, told apart by its sync tags
    # a sound speed calibrated from the pings on the surveyed positions took up their error: fitted with them
    calibrated = all(str(outcomes[f].summary["sound_speed"]["source"]).startswith(("calibrated", "fallback"))
                     for f in moving)
    speed = SPEED_SIGMA if calibrated else None
    edges = edges if biases else None
    fit = refine_receivers(toa, receivers, places, c, sigma, survey_sigma, biases=biases, anchored=anchored,
                           speed_sigma=speed, times=times, edges=edges, rescale=True)
    if held is None:
        check = held_out(toa, receivers, places, c, sigma, survey_sigma, biases=biases, anchored=anchored,
                         speed_sigma=speed, times=times, edges=edges, rescale=True)
        held = {"survey_chi2_per_dof": check.surveyed, "refined_chi2_per_dof": check.refined, "pings": check.pings,
                "folds": check.folds.tolist(), "helps": check.helps,
                "rule": f"the refined array's median chi2 per degree of freedom of the pings left out at most "
                        f"{1 - HELD_OUT_GAIN:g} of the survey's, and lower in most blocks"}
    cov = fit.covariance
    sx, sy = np.sqrt(np.maximum(np.diag(cov)[0::2], 0.0)), np.sqrt(np.maximum(np.diag(cov)[1::2], 0.0))
    refined = fit.determined & held["helps"]
    reason = np.where(fit.arrivals == 0, "not heard by a moving tag with three others at once",
                      np.where(~fit.determined, [f"its posterior sigma {r:.2f} of the survey's in the array's shape "
                                                 "(needs < 0.5)" for r in fit.sigma_ratio],
                               np.where(refined, "", "the held-out pings fit the refined array no better")))
    at = receivers[:, :2] + np.where(refined[:, None], fit.shift, 0.0)
    source = np.where(refined, "moving tags' pings", "survey")
    positions = pd.DataFrame({
        "receiver": names, "x": at[:, 0], "y": at[:, 1], "survey_x": receivers[:, 0], "survey_y": receivers[:, 1],
        "shift_x": at[:, 0] - receivers[:, 0], "shift_y": at[:, 1] - receivers[:, 1],
        "shift_m": np.hypot(at[:, 0] - receivers[:, 0], at[:, 1] - receivers[:, 1]), "source": source,
        "sigma_x": np.where(refined, sx, np.nan), "sigma_y": np.where(refined, sy, np.nan),
        "sigma_ratio": fit.sigma_ratio, "arrivals": fit.arrivals.astype(int),
        "fitted_shift_m": np.hypot(fit.fitted[:, 0], fit.fitted[:, 1]), "refined": refined, "reason": reason})
    moved = positions[positions["refined"]]
    summary = {"sync_emissions": fit.anchored,
               "clock_offsets_fitted": biases,
               "clock_offset_knots": int(fit.bias.shape[1]) if biases else 0,
               "timing_noise": "each receiver's from its own residuals in the fit (median absolute, studentised)",
               "sound_speed": ({"fitted": True, "scale": fit.speed_scale, "scale_sigma": fit.speed_scale_sigma,
                                "why": "the tags' sound speeds were calibrated from their pings on the surveyed "
                                       "positions; the array's scale is then the survey's (a gauge)"}
                               if calibrated else {"fitted": False, "why": "given or measured: the array's scale is "
                                                                           "the pings'"}),
        "survey_sigma_m": survey_sigma, "tags": tags, "pings": fit.pings, "receivers": len(names),
        "determined": int(fit.determined.sum()), "refined": int(refined.sum()),
        "median_shift_m": float(moved["shift_m"].median()) if len(moved) else 0.0,
        "largest_shift_m": float(moved["shift_m"].max()) if len(moved) else 0.0,
        "largest_shift_receiver": str(moved.loc[moved["shift_m"].idxmax(), "receiver"]) if len(moved) else "",
        "converged": fit.converged, "iterations": fit.iterations,
        "held_out": held,
        "gauge": "a translation or a rotation of the whole array changes no time of arrival: the survey's kept"}
    try:  # the errors in the survey's frame, for the moving tags' consider terms (none: each one's σ alone)
        framed = frame_conditioned(receivers[:, :2], cov, scale=speed is not None)
    except ModelError:  # the array's gauge without variance (receivers at one place)
        framed = None
    return StudyRefinement(positions, summary, framed)


def _errors(references: dict[str, Any] | None) -> dict[str, float | None]:
    """The pooled reference tags' and left-out sync tags' median errors [m] of a study's ``reference_tags``."""
    references = references or {}
    return {key: (references.get(key) or {}).get("median_error_m") for key in ("reference", "sync_left_out")}


def verdict(refinement: StudyRefinement, surveyed: dict[str, Any] | None, refined: dict[str, Any] | None) -> bool:
    """Whether the study on the refined positions is kept: none of its pooled reference tags' and left-out sync
    tags' median errors more than :data:`WORSE_TOLERANCE` above the survey's study's (both written in the summary's
    ``checks``, and ``kept``)."""
    before, after = _errors(surveyed), _errors(refined)
    worse = [k for k in before if before[k] is not None and after[k] is not None
             and after[k] > (1.0 + WORSE_TOLERANCE) * before[k]]
    refinement.summary["checks"] = {k: {"survey_m": before[k], "refined_m": after[k]} for k in before}
    refinement.summary["kept"] = not worse
    refinement.summary["worse"] = worse
    if worse:  # the survey's positions stand: positions.csv says so, with what the pings would have moved
        p = refinement.positions
        why = f"the {' and '.join(worse)} errors are worse on the refined positions (study.json's positions.checks)"
        p.loc[p["refined"], "reason"] = why
        p[["x", "y"]] = p[["survey_x", "survey_y"]].to_numpy()
        p[["shift_x", "shift_y", "shift_m"]] = 0.0
        p[["sigma_x", "sigma_y"]] = np.nan
        p["source"] = "survey"
        p["refined"] = False
    return not worse


#: The folder a study on refined positions is made in, in the study's own (moved over the survey's when kept).
REFINED_FOLDER = ".refined"


def _moving(outcome) -> list[str]:
    """The folders of a study's tags tracked as moving (never a reference tag)."""
    return [row["folder"] for row in outcome.tags.to_dict("records")
            if row["status"] == "tracked" and row["role"] != "reference" and row["motion"] == "moving"]


def position_sigmas(positions: pd.DataFrame, survey_sigma: float) -> dict[str, float]:
    """Each receiver's position's error in a study on refined positions [m per axis], by its name
    (:func:`~sblsim.orchestrator.sync.taken_survey.position_errors`: ``sigma_ratio`` × ``survey_sigma`` where the
    pings refined it, ``survey_sigma`` where not)."""
    return position_errors(positions["receiver"].tolist(), positions["sigma_ratio"], positions["refined"],
                           survey_sigma)


def sync_positions(positions: pd.DataFrame, survey_sigma: float) -> pd.DataFrame:
    """A kept refinement's ``positions.csv`` (:class:`StudyRefinement`) as ``sblsim sync --refine-positions``
    writes its own (``serial``, ``x_m``, ``y_m``, ``table_x_m``, ``table_y_m``, ``refined``, ``position_sigma_m``:
    :func:`position_sigmas`), for the study's ``sync/`` folder, whose clocks were synchronised on these positions:
    ``sblsim toa`` and a study given that folder (``--sync``) take them and their errors."""
    return pd.DataFrame({"serial": positions["receiver"].astype(str).to_numpy(), "x_m": positions["x"].to_numpy(),
                         "y_m": positions["y"].to_numpy(), "table_x_m": positions["survey_x"].to_numpy(),
                         "table_y_m": positions["survey_y"].to_numpy(),
                         "refined": positions["refined"].to_numpy(bool),
                         "position_sigma_m": list(position_sigmas(positions, survey_sigma).values())})


def refined_study(outcome, again: Callable, deployments, assigned, survey_sigma: float, workdir: Path,
                  tags_folder: str):
    """A study (:class:`~sblsim.orchestrator.telemetry.study.StudyOutcome`) made again by ``again(deployments,
    assigned, sigmas, errors)`` (into ``workdir``'s :data:`REFINED_FOLDER`; ``sigmas`` each receiver's position's
    error, :func:`position_sigmas`; ``errors`` their joint covariance, :meth:`StudyRefinement.errors`) on the
    receivers' positions refined from its moving tags
    where the held-out pings say it helps, in rounds, and kept where its reference and left-out sync tags are not
    worse (the module docstring); its tags' folders (``tags_folder``) moved over the first study's where kept. The
    study returned says what was done (``summary["positions"]``; ``positions``: ``positions.csv``)."""
    names = [str(n) for n in deployments.table["receiver"]]

    def anchored(study):
        return None if study.sync is None else sync_pings(study.sync.residuals, assigned.hydrophones, names)

    def edges(study):  # the synchronisation's bins' edges [s since 1970 UTC]: its clocks' knots
        fit = None if study.sync is None else study.sync.fit
        return None if fit is None or len(fit.edges) < 2 else np.asarray(fit.edges, float) + study.sync.origin

    try:
        refinement = refine_study(outcome.outcomes, outcome.matrices, _moving(outcome), deployments, survey_sigma,
                                  anchored=anchored(outcome), edges=edges(outcome))
    except ModelError as exc:  # said in a warning (lines)
        outcome.summary["positions"] = {"kept": False, "reason": str(exc)}
        return outcome
    if not refinement.helps:
        refinement.summary["kept"] = False
        outcome.summary["positions"], outcome.positions = refinement.summary, refinement.positions
        return outcome
    # the study made again on the refined positions (its clocks synchronised on them), the positions refined again
    # from its tracks, in rounds until they settle
    rounds = []
    while True:
        shutil.rmtree(workdir / REFINED_FOLDER, ignore_errors=True)
        second = again(*refinement.deployments(deployments, assigned), position_sigmas(refinement.positions,
                                                                                     survey_sigma),
                       refinement.errors())
        rounds.append({"median_shift_m": refinement.summary["median_shift_m"],
                       "largest_shift_m": refinement.summary["largest_shift_m"]})
        if len(rounds) == ROUNDS:
            break
        try:
            following = refine_study(second.outcomes, second.matrices, _moving(second), deployments, survey_sigma,
                                     refinement.summary["held_out"], anchored(second), edges(second))
        except ModelError:
            break
        change = float(np.hypot(*(following.positions[["x", "y"]].to_numpy()
                                  - refinement.positions[["x", "y"]].to_numpy()).T).max())
        rounds[-1]["change_after_m"] = change
        if change < ROUND_TOLERANCE:
            break
        refinement = following
    refinement.summary["rounds"] = rounds
    kept = verdict(refinement, outcome.summary["reference_tags"], second.summary["reference_tags"])
    chosen = second if kept else outcome
    if kept:  # the refined study's tags' folders in the study's place
        shutil.rmtree(workdir / tags_folder, ignore_errors=True)
        if (workdir / REFINED_FOLDER / tags_folder).exists():
            (workdir / REFINED_FOLDER / tags_folder).rename(workdir / tags_folder)
    shutil.rmtree(workdir / REFINED_FOLDER, ignore_errors=True)
    chosen.deployments = deployments  # receivers.csv: the deployments as read (positions.csv the refined)
    chosen.summary["positions"], chosen.positions = refinement.summary, refinement.positions
    return chosen


def lines(summary: dict[str, Any] | None) -> list[tuple[str, bool]]:
    """The console's lines of a refinement (a warning where the survey's positions were kept)."""
    if not summary:
        return []
    if "held_out" not in summary:  # nothing to refine from
        return [(f"warning: positions not refined: {summary.get('reason', '')}", True)]
    held = summary["held_out"]
    done = "refined" if summary.get("kept") else "the pings would move"
    head = (f"positions: {summary['refined']} of {summary['receivers']} receivers {done} from {len(summary['tags'])} "
            f"moving tags' {summary['pings']:,} pings (survey sigma {summary['survey_sigma_m']:g} m)")
    out = [(head + (f", median shift {summary['median_shift_m']:.2f} m, largest {summary['largest_shift_m']:.2f} m "
                    f"({summary['largest_shift_receiver']})" if summary["refined"] else ""), False),
           (f"  held-out pings' chi2 per degree of freedom: {held['survey_chi2_per_dof']:.3g} on the surveyed "
            f"positions, {held['refined_chi2_per_dof']:.3g} on the refined", False)]
    for key, label in (("reference", "reference tags'"), ("sync_left_out", "sync tags' (left out)")):
        got = (summary.get("checks") or {}).get(key) or {}
        if got.get("survey_m") is not None and got.get("refined_m") is not None:
            out.append((f"  {label} median error: {got['survey_m']:.2f} m before the refinement, "
                        f"{got['refined_m']:.2f} m after", False))
    if not summary.get("kept", False):
        named = {"reference": "reference tags'", "sync_left_out": "left-out sync tags'"}
        why = ("the held-out pings fit the refined array no better" if not held["helps"] or not summary["refined"]
               else f"the {' and '.join(named[k] for k in summary.get('worse') or [])} errors are worse on it")
        out.append((f"warning: positions not refined: {why}; the survey's positions kept (positions.csv says "
                    "what the pings would move)", True))
    return out


__all__ = ["REFINED_FOLDER", "ROUNDS", "ROUND_TOLERANCE", "SPEED_SIGMA", "StudyRefinement", "WORSE_TOLERANCE", "lines",
           "pooled", "position_sigmas", "refine_study", "refined_study", "sync_pings", "verdict"]

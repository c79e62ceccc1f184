"""A study's clocks taken as logged, checked against its moving tags' own pings before any tag is tracked, and
fitted from them where they are off.

A study whose deployments name no sync tag, or whose sync tags no two receivers hear (a network's extract of a tag
project), has its clocks taken as logged (:func:`~sblsim.orchestrator.telemetry.study_clocks.study_clocks`). A
receiver's clock set from a computer at deployment is off by milliseconds to seconds and drifts, and a millisecond is
a metre and a half of range: tracked on such clocks, a tag's fixes are off by tens of metres with a σ of one or two
(the clocks' error is in no σ), or, seconds off, a ping's arrivals split and its tag is refused for a false reason.
So, the tags' matrices made and none tracked:

1. where two receivers' clocks disagree by more than the time the sound takes across the array (the lags of their
   detections of the same tags), they are aligned from those lags (:func:`aligned`,
   :mod:`~sblsim.models.sync.coarse_lags`), to within that time;
2. each receiver's offset from the clocks the matrices were made on, linear in time between knots (the study's first
   and last detection and every :data:`~sblsim.models.sync.knots.WINDOW` between, or the coarse alignment's windows,
   :mod:`~sblsim.models.sync.knots`; a stretch of too few pings one), is fitted with the moving tags' pings'
   places and emission times, each ping from its own fix (in 3-D at the depth its tracker takes:
   :func:`held_heights`) (:func:`fit_clocks`;
   :func:`~sblsim.models.tracking.receiver_positions.refine_receivers`: each offset a range bias with a broad prior,
   the positions held at the survey's, a ping heard by four receivers or more, the sound speed's scale fitted with
   them where none is given), one receiver's clock the time base (an offset common to every clock moves no
   position);
3. the fitted clocks are taken where every fourth ping, left out of the fit in turn, is fixed better with them than
   with the clocks the matrices were made on (:func:`~sblsim.models.tracking.held_out.held_out`); the matrices are
   then made again on them and the clocks fitted again, in rounds, until the pings left out say no more
   (:func:`fitted_study`); a receiver the pings tie no closer than :data:`MAX_CLOCK_SIGMA` is not synchronised;
4. the tags are tracked once, on the clocks fitted (``study.json`` ``clocks.source`` :data:`FITTED`) or, where no
   fit helps, as logged (``clocks.checked`` says what the pings left out showed); :func:`said` gives the notes.

This is an array synchronised from its own tags' pings where it has no sync tag (the pings as a self-calibration's:
Triggs et al., "Bundle adjustment — a modern synthesis", LNCS 1883, 1999, § 6.1). A still tag's pings alone tie no
clock (its place and the offsets trade); a clock that jumps is not followed.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.models.sync.coarse_lags import coarse_offsets
from sblsim.models.sync.knots import knot_counts, knot_times, merged, spread_pings
from sblsim.models.tracking.calibration import MAX_SIGMA
from sblsim.models.tracking.depth import plane_prior
from sblsim.models.tracking.fix import fix_pings
from sblsim.models.tracking.held_out import HELD_OUT_GAIN, held_out
from sblsim.models.tracking.receiver_positions import refine_receivers
from sblsim.models.tracking.sound_speed import DEFAULT_SOUND_SPEED, fallback_prior
from sblsim.models.tracking.timing import SIGMA_TOA
from sblsim.orchestrator.sync.clocks import Clocks, logged_clocks
from sblsim.orchestrator.telemetry.clock_stretches import sparse_stretches, stretches_said
from sblsim.orchestrator.telemetry.study_clocks import GIVEN, NO_SYNC_TAG, SYNCHRONISED_HERE, UNHEARD
from sblsim.orchestrator.telemetry.study_positions import pooled
from sblsim.orchestrator.tracks.depth import undetermined_depth
from sblsim.orchestrator.tracks.tracker import DEPTH_SIGMA

#: The clocks' sources whose clocks are fitted from the tags' pings (no sync tag named, or none heard by two
#: receivers), and the source of clocks so fitted.
FITTED_FROM = (NO_SYNC_TAG, UNHEARD)
FITTED = "fitted from the tags' pings"
#: The prior σ [s] of a clock's offset from its time as logged at the study's first and last detection: a receiver
#: set from a computer at deployment and corrected for its drift at offload (a VR2W's clock drifts by seconds a month).
CLOCK_PRIOR = 1.0
#: The σ [m] the receivers' positions are held at in the fit (the survey's: not refined here) and the σ [s] of the
#: time base's clock (its offset 0).
HELD_SIGMA, BASE_SIGMA = 0.01, 1e-7
#: The prior σ [1] of the sound speed's scale fitted with the clocks where the study gives none (5 % of
#: :data:`~sblsim.models.tracking.sound_speed.DEFAULT_SOUND_SPEED`: 75 m/s, fresh to salt water).
SPEED_PRIOR = 0.05
#: The slowest sound speed [m/s] and a margin [s] of the time the sound takes across the array, and the largest lag [s]
#: between two clocks looked for (a coarse alignment's windows, and the fine fit's knots, are
#: :data:`~sblsim.models.sync.knots.WINDOW` apart).
SLOWEST, CROSSING_MARGIN, MAX_LAG = 1400.0, 0.05, 120.0
#: The most pings fitted (heard by four receivers or more; a season's spread over its windows, never fewer than
#: :data:`~sblsim.models.sync.knots.WINDOW_PINGS` from a window that holds as many:
#: :func:`~sblsim.models.sync.knots.spread_pings`): 20,000 pings of 20 receivers tie each clock to a few
#: microseconds, and a fit's cost is linear in them.
MAX_PINGS = 20_000
#: The rounds at most of the fit (each: the study made again on the clocks fitted, and they fitted again from it).
ROUNDS = 4
#: The most a fitted clock's offset σ [s] may be (its median over the clock's knots) for it to be taken: a clock the
#: pings tie to the time base no better is not synchronised.
MAX_CLOCK_SIGMA = 1e-3
#: The fewest clocks the pings must tie within :data:`MAX_CLOCK_SIGMA` for the fit to be taken (a position needs
#: four receivers at once).
MIN_TIED = 4
#: The median χ² per degree of freedom of the pings left out above which the clocks' fit is said to leave more than
#: the timing noise (:func:`misfit`; a consistent fix's median is below 1 whatever its degrees of freedom, the
#: simulated studies' 0.47 to 0.84; receivers 2 m off (σ per axis) gave 3.98 on one draw, its tracks' NEES 160-230).
MISFIT = 2.0
#: The most a clock's offset σ [s] may be in a round of the fit (:func:`fitted_study`: a round's fixes on clocks
#: still off tie them more loosely than the last's; at ±0.2 s a first round's reached 10 ms): one tied more loosely
#: (its arrivals would split the pings it hears) is left out of the next round.
LOOSE_SIGMA = 5e-2


@dataclass
class ClockFit:
    """The clocks fitted from a study's moving tags' pings (:func:`fit_clocks`): ``clocks`` (the receivers the pings
    tie to the time base, each one's offset at the study's first and last detection), ``summary`` (``study.json``'s
    ``clocks``) and ``helps`` (the held-out pings fit them better than the clocks the study was made on)."""

    clocks: Clocks
    summary: dict[str, Any]
    helps: bool


def fits(source: str) -> bool:
    """Whether clocks of this source (``study.json`` ``clocks.source``) are checked against the tags' pings."""
    return source in FITTED_FROM


def aligned(clocks: Clocks, info: dict[str, Any], assigned, table) -> tuple[Clocks, dict[str, Any]]:
    """Clocks taken as logged (``clocks``, ``info`` their summary: :func:`fits`) aligned coarsely from the tags the
    receivers hear together where two of them disagree by more than the time the sound takes across the array
    (:func:`~sblsim.models.sync.coarse_lags.coarse_offsets`: each pair's lag where its detections' differences pile
    up, the receivers' offsets by least squares in windows of :data:`~sblsim.models.sync.knots.WINDOW` s, the
    receiver with the most detections the time base), the start of the fine fit (:func:`fit_clocks`); else as they
    are. A receiver no pair ties to the time base is left out (not synchronised). ``assigned`` the detections at
    their deployments, ``table`` the receivers (``receiver``, ``x``, ``y``, ``sync_tag``)."""
    if not fits(info["source"]):
        return clocks, info
    names = [str(n) for n in table["receiver"]]
    frame = assigned.detections.frame
    frame = frame[~frame["tag"].isin(set(table["sync_tag"]) - {""})]  # (none heard by two receivers)
    xy = table[["x", "y"]].to_numpy(float)
    crossing = float(np.linalg.norm(xy[:, None] - xy[None], axis=2).max()) / SLOWEST + CROSSING_MARGIN
    index = frame["receiver"].map({n: k for k, n in enumerate(names)})
    frame, receiver = frame[index.notna()], index.dropna().to_numpy(np.int64)
    if not len(frame) or len(names) < 2:
        return clocks, info
    time = frame["time"].to_numpy(float)
    span = clocks.edges[0], clocks.edges[-1]
    edges = knot_times(span)
    base = int(np.bincount(receiver, minlength=len(names)).argmax())
    lags = coarse_offsets(receiver, pd.factorize(frame["tag"])[0], time, len(names), edges, MAX_LAG, crossing, base)
    if lags.largest_lag <= crossing:  # the clocks as logged agree to within a crossing: the fine fit's to say
        return clocks, info
    tied = np.isfinite(lags.offsets).any(axis=1)
    knots = np.array([np.interp(lags.centres, lags.centres[np.isfinite(o)], o[np.isfinite(o)]) if t else
                      np.zeros(len(lags.centres)) for o, t in zip(lags.offsets, tied)])
    at = lags.centres if len(lags.centres) > 1 else np.array(span)
    knots = knots if len(lags.centres) > 1 else np.repeat(knots, 2, axis=1)
    kept = np.flatnonzero(tied)
    coarse = Clocks([names[k] for k in kept], at, knots[kept])
    summary = {"largest_lag_s": lags.largest_lag, "crossing_s": crossing, "pairs": lags.pairs,
               "windows": len(lags.centres), "time_base": names[base],
               "not_tied": [n for n, t in zip(names, tied) if not t]}
    return coarse, info | {"coarse": summary}


def fit_clocks(outcome, deployments, span: tuple[float, float], on: Clocks | None = None,
               sound_speed: float | None = None, toa_sigma: float | None = None) -> ClockFit:
    """The receivers' clocks fitted from a study's moving tags' pings (the module docstring), before any is tracked.

    Parameters
    ----------
    outcome : StudyOutcome
        The study made on the clocks ``on`` (its moving tags' matrices: each ping starts from its own fix).
    deployments : Deployments
        Its deployments (the receivers' surveyed positions, fitted in the horizontal plane: in 3-D each ping held at
        its tracker's depth, :func:`held_heights`, within the water depth ``study.json``'s ``water_depth`` gave its
        tracker).
    span : tuple of float
        [s since 1970 UTC] the study's first and last detection: the clocks' first and last knots
        (:func:`~sblsim.models.sync.knots.knot_times`: a knot every :data:`~sblsim.models.sync.knots.WINDOW`
        between, :func:`~sblsim.models.sync.knots.merged` where the pings are few).
    on : Clocks, optional
        The clocks the study was made on (a coarse alignment's or an earlier round's fit, with their knots): the
        offsets fitted are added to theirs. None: as logged.
    sound_speed : float, optional
        [m/s] the study's (else :data:`~sblsim.models.tracking.sound_speed.DEFAULT_SOUND_SPEED`, its scale fitted
        with the clocks with a prior σ of :data:`SPEED_PRIOR`: the positions held, the pings' ranges set it).
    toa_sigma : float, optional
        [s] the arrivals' timing noise to start from (else :data:`~sblsim.models.tracking.timing.SIGMA_TOA`; each
        receiver's is then its own residuals').

    Returns
    -------
    ClockFit

    Raises
    ------
    ModelError
        No moving tag's matrix made, or none heard by four receivers at once (one line).
    """
    moving = [row["folder"] for row in outcome.tags.to_dict("records") if isinstance(row["folder"], str)
              and row["folder"] in outcome.matrices and row["role"] != "reference" and row["motion"] == "moving"]
    if not moving:
        animals = outcome.tags[(outcome.tags["role"] != "reference") & (outcome.tags["motion"] == "moving")]
        codes = animals["reason_code"].fillna("").astype(str).value_counts()
        raise ModelError("no moving tag's pings to fit from, " + (
            "every moving tag refused (" + ", ".join(f"{c} {n}" for c, n in codes.items() if c) + ")" if len(animals)
            else "only reference tags (a check, never in the fit)"))
    dim = outcome.matrices[moving[0]].positions.shape[1]
    names = [str(n) for n in deployments.table["receiver"]]
    receivers = deployments.table[["x", "y", "z"][:dim]].to_numpy(float)
    column = {n: k for k, n in enumerate(names)}
    speed = DEFAULT_SOUND_SPEED if sound_speed is None else float(sound_speed)
    sigma = SIGMA_TOA if toa_sigma is None else toa_sigma
    # each tag's pings on its own origin (every ping has its own emission time); in 3-D at the depth its tracker
    # takes (the fit is in the horizontal plane: each ping's depth held)
    parts = [pooled(outcome.matrices[folder], column) for folder in moving]
    toa, times = np.vstack([p[0] for p in parts]), np.concatenate([p[1] for p in parts])
    times = np.where(np.isfinite(times), times, span[0])
    owner = np.concatenate([np.full(len(p[0]), i) for i, p in enumerate(parts)])  # each ping's tag, its row there
    local = np.concatenate([np.arange(len(p[0])) for p in parts])
    grid = knot_times(span) if on is None else on.edges
    usable = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= 4)  # (a season's: MAX_PINGS of them, spread by window)
    keep = usable[spread_pings(times[usable], grid, MAX_PINGS)]
    toa, times, owner, local = toa[keep], times[keep], owner[keep], local[keep]
    heights = None if dim == 2 else np.full(len(toa), np.nan)
    for i in np.unique(owner) if heights is not None else []:  # (the pings kept alone fixed)
        heights[owner == i] = held_heights(outcome.matrices[moving[i]], outcome.summary.get("water_depth"), speed,
                                           sigma, local[owner == i])
    # the receivers these pings reach alone (a network's thousand others: not synchronised)
    reached = np.flatnonzero(np.isfinite(toa).any(axis=0)) if len(toa) else np.arange(len(names))
    unreached = [names[k] for k in np.setdiff1d(np.arange(len(names)), reached)]
    names, receivers, toa = [names[k] for k in reached], receivers[reached], toa[:, reached]
    # (every ping kept is heard by four or more: the clocks ``on`` put on this one's at the end)
    edges = merged(grid, times)  # (the grid's knots between which the pings fitted are enough to fit a clock)
    near = knot_counts(np.isfinite(toa), times, edges)  # (R, K + 1) the arrivals touching each knot
    base = int(np.argmax(np.isfinite(toa).sum(axis=0)))
    # the time base: the receiver heard most in the pings fitted; at a knot its arrivals do not reach (no
    # deployment spans a redeployed array's season), the one heard most there (a common offset moves no position)
    bases = np.where(near[base] > 0, base, near.argmax(axis=0))
    prior = np.full((len(names), len(edges)), CLOCK_PRIOR * speed)
    prior[bases, np.arange(len(edges))] = BASE_SIGMA * speed
    kwargs = {"biases": True, "times": times, "edges": edges, "rescale": True, "bias_sigma": prior,
              "speed_sigma": SPEED_PRIOR if sound_speed is None else None}
    places = np.full((len(toa), dim), np.nan)  # each ping from its own fix (at its depth in 3-D)
    if heights is not None:
        places[:, 2] = heights
    fit = refine_receivers(toa, receivers, places, speed, sigma, HELD_SIGMA, **kwargs)  # refused in one line
    check = held_out(toa, receivers, places, speed, sigma, HELD_SIGMA, **kwargs, clocks=True)
    fitted = speed * fit.speed_scale  # [m/s] (the speed given where not fitted)
    # [s]: a range bias is its clock's offset; its σ the median over the knots its arrivals touch (a knot at a
    # stretch it hears little; a deployment's knots outside its own time tied by the prior alone)
    mine = (near > 0) | (near == 0).all(axis=1, keepdims=True)
    spread = np.array([np.median(s[m]) for s, m in zip(fit.bias_sigma, mine)]) / fitted
    taken = (fit.arrivals > 0) & (spread <= LOOSE_SIGMA)  # (one tied more loosely than MAX_CLOCK_SIGMA: :func:`tied`)
    taken[bases] = True
    # each clock at the grid's knots: the offset fitted, linear between the fit's knots, added to the clocks the study
    # was made on (their receivers alone); less the time base's at each of the fit's knots (linear between them: an
    # offset common to every clock moves no position)
    knots = np.array([np.interp(grid, edges, k) for k in fit.bias / fitted])
    if on is not None:
        taken &= np.isin(names, on.receivers)
        knots = knots + np.array([on.knots[on.receivers.index(n)] if n in on.receivers else np.zeros(len(grid))
                                  for n in names])
    at = knots[:, np.searchsorted(grid, edges)]  # (R, K + 1) at the fit's knots (the grid's own: merged keeps them)
    common = at[bases, np.arange(len(edges))]
    knots, at = knots - np.interp(grid, edges, common), at - common
    kept = np.flatnonzero(taken)
    clocks = Clocks([names[k] for k in kept], grid, knots[kept], clock_sigma=np.where(kept == base, 0.0,
                                                                                      spread[kept]))
    others = kept[kept != base]  # (the clocks taken but the time base's)
    reach = np.where(mine, np.abs(at), 0.0)  # (the knots a deployment's own arrivals touch)
    largest = kept[int(np.argmax(reach[kept].max(axis=1)))]
    summary = {"source": FITTED, "reference_receiver": names[base], "receivers": len(kept),
               "not_synchronised": [n for n, t in zip(names, taken) if not t] + unreached, "tags": [
                   outcome.matrices[f].summary["tag"] for f in moving], "pings": int(fit.pings),
               "largest_offset_s": float(reach[largest].max()), "largest_offset_receiver": names[largest],
               "offsets_s": {names[k]: knots[k].tolist() for k in kept}, "knot_times_s": grid.tolist(),
               "fitted_knot_times_s": edges.tolist(), "sparse_stretches": sparse_stretches(
                   edges, grid, times, at[others], mine[others], fit.bias_sigma[others] / fitted, sigma),
               "offset_sigma_s": {names[k]: float(spread[k]) for k in others},
               "sound_speed_m_s": fitted, "sound_speed_sigma_m_s": speed * fit.speed_scale_sigma if sound_speed is None
               else None,
               "time_base_by_knot": [names[b] for b in bases[np.abs(grid[:, None] - edges).argmin(axis=1)]]
               if (bases != base).any() else None,
               "held_out": {"logged_chi2_per_dof": check.surveyed, "fitted_chi2_per_dof": check.refined,
                            "pings": check.pings, "folds": check.folds.tolist(), "helps": check.helps,
                            "rule": f"the fitted clocks' median chi2 per degree of freedom of the pings left out at "
                                    f"most {1 - HELD_OUT_GAIN:g} of the clocks' the study was made on, and lower in "
                                    f"most blocks"},
               "converged": fit.converged}
    return ClockFit(clocks, summary, check.helps)


def interpolated(info: dict[str, Any]) -> list[tuple[float, float]]:
    """The stretches [s since 1970 UTC] (start, end) across which clocks fitted from the tags' pings (``info``:
    ``study.json``'s ``clocks``) are linear and bend, seen elsewhere, more than the timing noise
    (:func:`~sblsim.orchestrator.telemetry.clock_stretches.sparse_stretches`): a moving tag's rows in them are
    flagged ``clocks_interpolated`` (the tracker's option of that name); none where the clocks are not so fitted."""
    if info.get("source") != FITTED:
        return []
    return [(s["start_s"], s["end_s"]) for s in info.get("sparse_stretches") or [] if s.get("rows_flagged")]


def study_speed(info: dict[str, Any]) -> tuple[float, float] | None:
    """The study's own sound speed [m/s] and its σ [m/s] where its clocks were fitted with the speed's scale, from
    its tags' pings (:func:`fit_clocks`) or its sync tags' arrivals (synchronised here or in a folder given, no speed
    given: :func:`~sblsim.orchestrator.sync.run.synchronise`) (``info``: ``study.json``'s ``clocks``), each tag's
    fallback in place of the default's (:func:`~sblsim.orchestrator.tracks.speed.sound_speed_stage`): its σ the
    fit's with the most a tag's own calibration is taken at (:data:`~sblsim.models.tracking.calibration.MAX_SIGMA`,
    in quadrature: one speed for the season, and the sync tags' paths near the bottom, stand for the water a tag's
    pings crossed no better than the weakest calibration; a season's windows' own σ where they rescale each tag's
    arrivals, ``sound_speed_windows_sigma_m_s``); None otherwise, or where that σ is not below the default's."""
    fitted = info.get("source") in (FITTED, SYNCHRONISED_HERE, GIVEN)  # (a season's windows: each tag rescaled)
    sigma = info.get("sound_speed_windows_sigma_m_s", info.get("sound_speed_sigma_m_s")) if fitted else None
    sigma = None if sigma is None else float(np.hypot(sigma, MAX_SIGMA))
    return None if sigma is None or not sigma < fallback_prior()[1] else (float(info["sound_speed_m_s"]), sigma)


def fitted_options(info: dict[str, Any], moving: bool) -> dict[str, Any]:
    """A tag's tracking options from the study's clocks fitted (``info``: ``study.json``'s ``clocks``), each where
    there is one (none for clocks taken as logged): a moving tag's ``clocks_interpolated`` (:func:`interpolated`),
    every tag's ``study_speed`` (:func:`study_speed`) and a season's ``study_speed_series`` (its windows' speeds)."""
    bent, speed, windows = interpolated(info) if moving else [], study_speed(info), info.get("sound_speed_windows")
    return ({"clocks_interpolated": bent} if bent else {}) | ({"study_speed": speed} if speed else {}) | (
        {"study_speed_series": windows} if speed and windows else {})


def held_heights(matrix, water: dict[str, Any] | None, c: float, sigma: float,
                 rows: np.ndarray | None = None) -> np.ndarray:
    """(P,) [m, z up] the height each of a tag's pings is held at in a 3-D study's clock fit: its depth sensor's
    reading (``pings.csv``'s ``depth_m``) where it has one, else its own fix's with the prior its tracker takes
    (:mod:`~sblsim.orchestrator.tracks.depth`: receivers in one plane hold it at mid-water, or at their mean depth;
    a depth the arrivals do not determine, at the receivers' mean; the water's depth, ``study.json``'s
    ``water_depth`` (``water``: given, or each tag's as the study handed it to its tracker, ``per_tag_m``: the
    deepest bottom of the receivers that heard it), and the surface bounding it), else the prior's (a fix with no
    arrival to spare, or none: the receivers' mean where no prior is taken). ``matrix`` the tag's (its ``positions``
    (R, 3) [m], its ``summary``'s ``tag``), at the sound speed ``c`` [m/s] and a timing noise ``sigma`` [s];
    ``rows`` (P,) the pings asked (None: every one; a tag's decision of its prior on these alone)."""
    water = water or {}
    deepest = water.get("water_depth_m") if water.get("source") == "given" else \
        (water.get("per_tag_m") or {}).get(matrix.summary["tag"])
    positions = np.asarray(matrix.positions, float)
    prior = plane_prior(positions, deepest, DEPTH_SIGMA)  # (at least a depth reading's σ, as the tracker's)
    rows = np.arange(len(matrix.toa)) if rows is None else np.asarray(rows, np.int64)
    toa = matrix.toa[rows]
    fixed = _fix(toa, positions, c, sigma, prior)
    if prior is None:  # the arrivals' depth, where they determine it (else the receivers' mean), in the water
        fx, _, fc, used, _ = fixed
        prior = undetermined_depth(None, fx, fc, used.sum(axis=1), positions, deepest)
        fixed = fixed if prior is None else _fix(toa, positions, c, sigma, prior)
    fallback = -prior.depth if prior is not None else float(positions[:, 2].mean())
    # a fix with no arrival to spare (four, its depth free) says nothing of its depth: the prior's, or the receivers'
    told = np.isfinite(fixed[0][:, 2]) & (fixed[3].sum(axis=1) >= (4 if prior is not None else 5))
    height = np.clip(np.where(told, fixed[0][:, 2], fallback), -np.inf if deepest is None else -deepest, 0.0)
    readings = matrix.pings["depth_m"].to_numpy(float)[rows] if "depth_m" in matrix.pings and \
        len(matrix.pings) == len(matrix.toa) else np.full(len(rows), np.nan)
    return np.where(np.isfinite(readings), -readings, height)


def _fix(toa, positions, c, sigma, prior):
    """Each ping's fix (no gate: the clocks may be off), its depth with ``prior`` where one is taken."""
    depth = None if prior is None else np.full(len(toa), prior.depth)
    return fix_pings(toa, positions, c, sigma, gate=np.inf, depth=depth,
                     depth_sigma=DEPTH_SIGMA if prior is None else prior.sigma)


def fitted_study(outcome, again: Callable[[tuple | None, bool], Any], deployments, span: tuple[float, float],
                 workdir: Path, tags_folder: str, sound_speed: float | None = None,
                 toa_sigma: float | None = None) -> tuple[Any, tuple | None]:
    """A study whose clocks are taken as logged (:func:`fits`), its tags' matrices made and none tracked
    (``outcome``), checked against its moving tags' pings (:func:`fit_clocks`) and made again by ``again(clocks,
    untracked)`` (``clocks`` the clocks and their summary) on the clocks fitted from them where the held-out pings
    say they help, fitted again from the matrices made on them until the pings left out say the clocks help no more
    (:data:`ROUNDS` at most: a round's pings, fixed on better clocks, tie them closer), the receivers tied no closer
    than :data:`MAX_CLOCK_SIGMA` left out; then tracked once (on the clocks as logged where no fit helps), its tags'
    folders (``tags_folder`` in ``workdir``) made anew, its ``clocks`` saying what was done (``rounds``, or
    ``checked``: :func:`said`). Returns the study and the clocks it was tracked on, with their summary."""
    fitted, rounds, checked, taken, first = None, [], None, [], outcome
    logged = {key: outcome.summary["clocks"].get(key) for key in ("source", "note", "coarse")}  # (said again)
    start = outcome.clocks if "coarse" in outcome.summary["clocks"] else None  # (aligned coarsely: :func:`aligned`)
    while len(rounds) < ROUNDS:
        try:
            fit = fit_clocks(outcome, deployments, span, start if fitted is None else fitted[0], sound_speed,
                             toa_sigma)
        except ModelError as exc:  # none to fit from, or the last round's clocks left none: the clocks before it
            fitted = taken[-2] if len(taken) > 1 else None
            checked = None if fitted is not None else {"fitted": False, "reason": str(exc) if not taken else
                                                       f"the clocks fitted left no pings to fit again ({exc})"}
            break
        held = fit.summary["held_out"]
        rounds.append({"chi2_per_dof_before": held["logged_chi2_per_dof"],
                       "chi2_per_dof_after": held["fitted_chi2_per_dof"], "taken": fit.helps})
        if not fit.helps:
            checked = None if fitted is not None else fit.summary | {"source": "as logged", "fitted": False}
            break
        fitted = (fit.clocks, fit.summary | {"rounds": rounds, "as_logged": logged})
        taken.append(fitted)
        outcome = again(fitted, True)
    if fitted is not None:
        loose = tied(fitted[0], fitted[1]["offset_sigma_s"])
        if len(fitted[0].receivers) - len(loose) < MIN_TIED:  # too few pings to tie the clocks: as they were
            checked = {"fitted": False, "reason": f"the pings tie {len(fitted[0].receivers) - len(loose)} of the "
                                                  f"receivers' clocks within {MAX_CLOCK_SIGMA * 1e3:g} ms (fewer "
                                                  f"than {MIN_TIED})"}
            fitted = None
        elif loose:
            fitted = (_without(fitted[0], loose), fitted[1] | {
                "not_synchronised": fitted[1]["not_synchronised"] + loose, "loosely_tied": loose,
                "receivers": fitted[1]["receivers"] - len(loose)})
    if fitted is None:  # the clocks as logged, checked (aligned coarsely and no fit: never tracked on those)
        clocks = first.clocks if start is None else logged_clocks([str(n) for n in deployments.table["receiver"]],
                                                                  float(np.floor(span[0])), float(np.ceil(span[1])))
        fitted = (clocks, first.summary["clocks"] | ({"checked": checked} if checked else {}))
    shutil.rmtree(workdir / tags_folder, ignore_errors=True)
    study = again(fitted, False)
    if fitted[1].get("coarse") and fitted[1]["source"] != FITTED:  # the clocks as logged split its pings
        split_reasons(study.tags, fitted[1]["coarse"]["largest_lag_s"])
    return study, fitted


#: The reasons a tag is refused that clocks seconds apart make (a ping's arrivals split, its steps false).
SPLIT_CODES = ("too_few_receivers_at_once", "interval_contradicted", "interval_unknown", "no_position")


def split_reasons(tags: pd.DataFrame, lag: float) -> None:
    """``tags.csv``'s refused rows whose reason (:data:`SPLIT_CODES`) clocks disagreeing by up to ``lag`` [s] make,
    positioned on the clocks as logged (no fit tied them): each reason names those clocks as its cause, in place."""
    rows = (tags["status"] == "refused") & tags["reason_code"].isin(SPLIT_CODES)
    tags.loc[rows, "reason"] = tags.loc[rows, "reason"].astype(str) + (
        f"; the receivers' clocks as logged disagree by up to {_seconds(lag)} (their detections of the same tags) "
        f"and no fit from the moving tags' pings ties them: they split a ping's arrivals; allowed: the raw "
        f"detections with the sync tags' or --sync DIR")


def _seconds(value: float) -> str:
    """A duration [s] in milliseconds below a second, else in seconds."""
    return f"{value * 1e3:.3g} ms" if abs(value) < 1.0 else f"{value:.3g} s"


def said(info: dict[str, Any]) -> list[str]:
    """The study's notes of its clocks taken as logged, checked against its tags' pings (``info``: ``study.json``'s
    ``clocks`` as :func:`fitted_study` leaves them)."""
    if info["source"] == FITTED:
        return [n for n in (info["as_logged"].get("note"), note(info)) if n]
    out = [info["note"]] if info.get("note") else []
    checked, coarse = info.get("checked") or {}, info.get("coarse")
    if "reason" in checked:
        out.append(f"the clocks taken as logged are not checked against the tags' pings: {checked['reason']}")
    if coarse:  # aligned coarsely, not fitted: taken as logged (a ping's arrivals split), never on those
        out.append(f"the receivers' clocks as logged disagree by up to {coarse['largest_lag_s']:.3g} s (their "
                   f"detections of the same tags), and no fit from the moving tags' pings ties them: the tags are "
                   f"positioned on the clocks as logged, whose offsets split a ping's arrivals; give the raw "
                   f"detections with the sync tags' or --sync DIR")
    return out


def misfit(summary: dict[str, Any]) -> str | None:
    """The warning where the moving tags' pings left out fit the clocks they were tracked on (``summary``:
    ``study.json``'s; its ``clocks`` fitted or checked) with a median χ² per degree of freedom above :data:`MISFIT`:
    more than the timing noise explains (the receivers' positions off, the noise larger than taken), which the
    tracks' σ hold only where a survey error stated covers it; else None."""
    info = summary["clocks"]
    held = info.get("held_out") if info["source"] == FITTED else (info.get("checked") or {}).get("held_out")
    # (the clocks tracked on: the fitted, or those as logged where the fit did not help)
    chi2 = None if not held else held["fitted_chi2_per_dof" if info["source"] == FITTED else "logged_chi2_per_dof"]
    if chi2 is None or chi2 <= MISFIT:
        return None
    noise = (summary.get("toa_noise") or {}).get("sigma_s")
    return (f"the moving tags' pings left out fit the clocks with chi2 per degree of freedom {chi2:.3g} at the "
            f"timing noise taken"
            + (f" ({noise * 1e3:.3g} ms)" if isinstance(noise, float) else "") + ": more than the noise explains, the "
            "receivers' positions off or the timing noise larger; the tracks' σ hold it only where the survey's "
            "error stated (--survey-sigma M, per axis) or the timing noise (--toa-sigma S) covers it")


def tied(clocks: Clocks, sigma: dict[str, float]) -> list[str]:
    """The receivers of ``clocks`` whose offset's σ (``sigma`` [s] by receiver: a fit's on these clocks, the last)
    exceeds :data:`MAX_CLOCK_SIGMA` (its median over the knots its arrivals touch): tied to the time base too loosely
    to be taken."""
    return [n for n in clocks.receivers if sigma.get(n, 0.0) > MAX_CLOCK_SIGMA]


def _without(clocks: Clocks, names: list[str]) -> Clocks:
    """``clocks`` less the receivers ``names``."""
    keep = [k for k, n in enumerate(clocks.receivers) if n not in names]
    return Clocks([clocks.receivers[k] for k in keep], clocks.edges, clocks.knots[keep],
                  clock_sigma=clocks.clock_sigma[keep])


def note(summary: dict[str, Any]) -> str:
    """The study's note of clocks fitted from its tags' pings (:func:`fitted_study`'s summary, with its rounds)."""
    rounds = [r for r in summary["rounds"] if r["taken"]]
    untaken = summary["not_synchronised"]
    return (f"the receivers' clocks, taken as logged, were off: fitted from {len(summary['tags'])} moving tags' "
            f"{summary['pings']:,} pings against {summary['reference_receiver']} in {len(rounds)} "
            f"round{'s' if len(rounds) > 1 else ''} (largest offset {_seconds(summary['largest_offset_s'])}, "
            f"{summary['largest_offset_receiver']}; the pings "
            f"left out fit them with chi2 per degree of freedom {rounds[-1]['chi2_per_dof_after']:.3g}, the clocks "
            f"{'aligned coarsely' if summary['as_logged'].get('coarse') else 'as logged'} "
            f"{rounds[0]['chi2_per_dof_before']:.3g})" + (
                f"; not synchronised (no ping heard with three others ties its clock, or too loosely), its "
                f"detections not used: {', '.join(untaken[:12])}{', ...' if len(untaken) > 12 else ''}"
                if untaken else "") + stretches_said(summary.get("sparse_stretches") or []))


__all__ = ["CLOCK_PRIOR", "ROUNDS", "ClockFit", "FITTED", "FITTED_FROM", "aligned", "fit_clocks", "fits",
           "fitted_options", "fitted_study", "held_heights", "interpolated", "misfit", "note", "said", "split_reasons",
           "study_speed"]

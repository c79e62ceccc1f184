"""A still tag (``motion`` ``stationary``; a reference tag; a sync tag left out of the synchronisation): one position
for all its pings, pooled from its arrivals
(:mod:`sblsim.models.tracking.stationary`) with the sound speed's change over its record fitted beside it
(:mod:`sblsim.models.tracking.speed_change`), the consider covariance of the errors pooling does not average (the
receivers' survey, the receivers' clock offsets, the sound speed's where its change is not fitted, and what the
receivers' jackknife shows beyond the fit's own covariance), and the verdict of whether, and from when, it moved
(:mod:`sblsim.models.tracking.still`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking import still as sv
from sblsim.models.tracking.timing import SIGMA_TOA

#: The fewest trusted single-ping fixes whose wander the verdict tests
#: (:func:`~sblsim.models.tracking.still.still_verdict`: two segments of
#: :data:`~sblsim.models.tracking.still.MIN_SEGMENT`): with fewer, whether the tag moved is unchecked, and said so
#: (the verdict ``unchecked``), not called still.
UNCHECKED_BELOW = 2 * sv.MIN_SEGMENT
#: The least share of its arrivals a still tag's one place explains (each within the robust fit's kept residual at the
#: timing noise taken: :func:`explained_share`; its two places', where its fixes say it moved once: the still part's
#: and where it went, each share weighed by its part's arrivals). Where fewer, the tag is
#: neither still nor moved once: ``moving`` where its fixes say it moved or lie in an order in time its error terms do
#: not make (:func:`~sblsim.models.tracking.still.wanders`), else ``unchecked`` (it moved where its few trusted fixes
#: cannot tell it from their errors, or its timing noise is several times the one taken). A still tag's place explains
#: all its arrivals but its reflections (0.84 to 1.0 on the boats' reference and sync tags, at least 0.91 where a
#: receiver hears a reflection 30 % of the time), a tag moved once half way 0.79 over its record and its two places
#: all of it, a random walk of 2 m a ping on a bent canal's four receivers 0.36 to 0.49 (0.42 to 0.51 its still part's
#: place, before a change its fixes found; its two places 0.42); a still tag whose timing noise is 7 times the stated
#: 0.65, 10 times 0.53 to 0.55, 15 times 0.42 to 0.44.
MIN_EXPLAINED = 0.5


def stationary_track(toa: np.ndarray, positions: np.ndarray, c: float, fixes: np.ndarray,
                     sigma_toa: float | np.ndarray = SIGMA_TOA):
    """A stationary tag's pooled fix (:func:`~sblsim.models.tracking.stationary.stationary_fix`) from the median of
    its single-ping fixes ``fixes`` (m, dim) [m], else the receivers' centroid; ``sigma_toa`` the timing noise [s]
    (one, or each receiver's).

    Raises
    ------
    ModelError
        Too few receivers heard it (one line).
    """
    from sblsim.models.tracking.stationary import stationary_fix

    return stationary_fix(toa, positions, c, sigma_toa, _start(positions, fixes))


def changing_track(toa: np.ndarray, positions: np.ndarray, c: float, fixes: np.ndarray,
                   sigma_toa: float | np.ndarray = SIGMA_TOA):
    """A still tag's pooled fix with the sound speed's change over its record fitted beside it
    (:func:`~sblsim.models.tracking.speed_change.speed_change_fix`), from the same start as
    :func:`stationary_track`.

    Raises
    ------
    ModelError
        Too few receivers heard it (one line).
    """
    from sblsim.models.tracking.speed_change import speed_change_fix

    return speed_change_fix(toa, positions, c, sigma_toa, _start(positions, fixes))


def _start(positions: np.ndarray, fixes: np.ndarray) -> np.ndarray:
    """A pooled fit's start: the median of the single-ping fixes (m, dim) [m], else the receivers' centroid."""
    finite = np.isfinite(fixes).all(axis=1)
    return np.median(fixes[finite], axis=0) if finite.any() else positions.mean(axis=0)


def stationary_consider(toa: np.ndarray, positions: np.ndarray, c: float, pooled, survey: np.ndarray | None,
                        speed_sigma: float | None, sigma_toa: float | np.ndarray = SIGMA_TOA,
                        clock_sigma: np.ndarray | None = None, sensitivity: np.ndarray | None = None
                        ) -> np.ndarray | None:
    """A stationary tag's pooled position's consider covariance (dim, dim) [m²] of the errors pooling does not
    average: the receivers' survey ``survey`` (n,) [m per axis], the sound speed's ``speed_sigma`` [m/s] and the
    receivers' clock offsets' ``clock_sigma`` (n,) [s] (a synchronisation's own uncertainty of each receiver's offset,
    NaN where not known: taken as 0), each a constant bias of one receiver's arrivals
    (:func:`~sblsim.models.tracking.stationary.bias_sensitivity`, or ``sensitivity`` where already made); None where
    none is known."""
    from sblsim.models.tracking.stationary import bias_sensitivity

    clock = None if clock_sigma is None else np.nan_to_num(np.asarray(clock_sigma, float), nan=0.0)
    if survey is None and not speed_sigma and (clock is None or not clock.any()):
        return None
    S = bias_sensitivity(toa, positions, c, sigma_toa, pooled) if sensitivity is None else sensitivity
    B = np.zeros((len(positions), len(positions)))
    if survey is not None:  # a still tag's range to receiver i is off by u_i · δr_i, of variance σ_i² (|u_i| = 1)
        B += np.diag(np.asarray(survey, float) ** 2 / c**2)
    if clock is not None:  # receiver i's arrivals all off by its offset's error, independent between receivers
        B += np.diag(clock**2)
    if speed_sigma:  # the travel time ρ_i / c off by −ρ_i δc / c² at every receiver at once
        rho = np.linalg.norm(pooled.position[None, :] - positions, axis=1)
        B += float(speed_sigma) ** 2 * np.outer(rho, rho) / c**4
    return S @ B @ S.T


def survey_gains(toa: np.ndarray, positions: np.ndarray, c: float, pooled,
                 sigma_toa: float | np.ndarray = SIGMA_TOA, sensitivity: np.ndarray | None = None) -> np.ndarray:
    """How each receiver's survey error moves a stationary tag's pooled position: ``G_i = ∂p / ∂δr_i`` (n, dim, 2)
    [m/m], ``δr_i`` the horizontal offset of receiver i's position as given from its true one.

    The fit ranges to the position given, ``|p − r_i − δr_i| ≈ |p − r_i| − u_i · δr_i`` (``u_i`` the unit vector from
    the receiver to the tag), so its arrivals look late by ``u_i · δr_i / c`` and the position moves by
    ``S_i u_iᵀ δr_i / c`` (:func:`~sblsim.models.tracking.stationary.bias_sensitivity`'s column ``S_i``): the
    first-order consider sensitivity (Tapley, Schutz & Born, *Statistical Orbit Determination*, Elsevier 2004,
    § 6.3). ``Σ_i σ_i² G_i G_iᵀ`` is :func:`stationary_consider`'s survey term; a still tag scored against receiver
    k's surveyed position, itself off by the same ``δr_k``, errs by ``Σ_i G_i δr_i − δr_k``: its covariance has
    ``−σ_k² (G_k + G_kᵀ)`` besides (:func:`place_score`'s ``cross``): a tag heard near its own receiver moves with
    that receiver's position along their line (``G_k`` of rank about one, a third to two thirds along it on the
    boats' reference tags), and that share of the receiver's error is no error of the score. ``sensitivity``: the
    ``S`` already made for this fit."""
    from sblsim.models.tracking.stationary import bias_sensitivity

    S = bias_sensitivity(toa, positions, c, sigma_toa, pooled) if sensitivity is None else sensitivity
    diff = pooled.position[None, :] - positions
    unit = diff / np.maximum(np.linalg.norm(diff, axis=1), 1e-9)[:, None]
    return np.einsum("di,ij->idj", S, unit[:, :2]) / c


def receivers_term(toa: np.ndarray, positions: np.ndarray, c: float, pooled,
                   sigma_toa: float | np.ndarray) -> np.ndarray:
    """What the receivers' errors did to the pooled position (dim, dim) [m²]: the receivers' jackknife
    (:func:`~sblsim.models.tracking.stationary.receiver_jackknife`), added to the pooled fit's covariance and the
    consider terms where it exceeds the fit's own covariance (:func:`_place`). It sees what they cannot: a reflection
    on one receiver's path, a clock or a survey worse than stated; added rather than merged with the consider terms
    (a jackknife of 6 to 20 receivers falls short of its variance as often as not)."""
    from sblsim.models.tracking.stationary import receiver_jackknife

    return receiver_jackknife(toa, positions, c, sigma_toa, pooled)[1]


def split_ping(toa: np.ndarray, positions: np.ndarray, c: float, sigma: np.ndarray, first: np.ndarray,
               second: np.ndarray, dof: float | None = None) -> int:
    """Where a still tag that moved once went from its first place to its second among the pings ``toa`` (k, n) [s]
    between its last still trusted fix and its first moved one (pings without a trusted fix: heard by too few
    receivers, or a fix the quality check set aside): the row ``s`` (0 ≤ s ≤ k) from which the pings' arrivals fit
    ``second`` (dim,) [m] better than ``first`` (dim,) [m] in their Student-t cost summed, the rows before ``s`` at
    the first place and the rest at the second (a change point of the arrivals' own likelihood: Hinkley, Biometrika
    57(1), 1970). Each ping's cost at a place: its arrivals' ``(ν + 1) ln(1 + z² / ν)``, ``z`` the time of arrival
    less the range over ``c`` [m/s], less the ping's emission time (their mean weighed by ``1 / σ_i²``), over the
    receiver's ``sigma`` (n,) [s]. A ping heard by one receiver fits both places alike; of equal costs the earliest
    split is taken (those rows flagged: no arrival says they stayed). ``dof``: ν (None: the robust smoother's
    :data:`~sblsim.models.tracking.smoother_cost.ROBUST_DOF`)."""
    from sblsim.models.tracking.smoother_cost import ROBUST_DOF
    from sblsim.models.tracking.stationary import _centred, _geometry

    dof = ROBUST_DOF if dof is None else dof
    toa = np.asarray(toa, float)
    heard = np.isfinite(toa)
    y = np.where(heard, toa, 0.0)
    w = np.where(heard, 1.0 / sigma**2, 0.0)

    def cost(place: np.ndarray) -> np.ndarray:  # (k,)
        z = np.where(heard, _centred(_geometry(y, positions, c, place)[1], w), 0.0) / sigma
        return np.where(heard, (dof + 1.0) * np.log1p(z**2 / dof), 0.0).sum(axis=1)

    at_first, at_second = cost(np.asarray(first, float)), cost(np.asarray(second, float))
    totals = np.concatenate([[0.0], np.cumsum(at_first)]) + np.concatenate([np.cumsum(at_second[::-1])[::-1], [0.0]])
    return int(np.argmin(totals))


@dataclass(frozen=True)
class StillTag:
    """A still tag's rows (:func:`still_tag`): the ``pings`` (rows of the TOA matrix) with an emission, their
    ``emissions`` [s], each row's ``places`` (dim,) [m] and ``covariances`` (the pooled fit's own) and ``consider``
    terms [m²], the arrivals each row kept (``heard``), the rows that ``moved`` (from the change on), whether its
    motion is ``unchecked`` (fewer trusted fixes than the verdict tests: :data:`UNCHECKED_BELOW`), the ``summary``
    (``summary.json``'s ``motion``) and the times of arrival (m, n) [s] less the sound speed's change fitted at its
    place (or places), each row of the record (``corrected``: the times given where no change was fitted)."""

    pings: np.ndarray
    emissions: np.ndarray
    places: np.ndarray
    covariances: np.ndarray
    consider: np.ndarray
    heard: np.ndarray
    moved: np.ndarray
    unchecked: bool
    summary: dict[str, Any]
    corrected: np.ndarray | None = None


def explained_share(pooled, heard: np.ndarray) -> float:
    """The share of a still tag's arrivals its one place ``pooled`` explains: of those ``heard`` (m, n), the ones its
    robust fit kept (weight :data:`~sblsim.models.tracking.smoother.ROBUST_KEPT_WEIGHT` or more, the weights settled
    at the place: a normalised residual within ``√((ν + 1) / w − ν)``, 6.1 σ of the timing noise at ν =
    :data:`~sblsim.models.tracking.smoother_cost.ROBUST_DOF`, each ping's emission time the Student-t location of its
    arrivals); NaN where none was heard."""
    from sblsim.models.tracking.smoother import ROBUST_KEPT_WEIGHT

    heard = np.asarray(heard, bool)
    return float(np.mean(pooled.weights[heard] >= ROBUST_KEPT_WEIGHT)) if heard.any() else float("nan")


class _Place(NamedTuple):
    """One place of a still tag (:func:`_place`): its pooled ``fit``, the consider terms and the receivers' term
    summed ``consider`` (dim, dim) [m²], the receivers' term's DRMS ``spread`` [m], the survey's ``gains``
    (:func:`survey_gains`), the speed's change fitted ``changed`` [m/s] (its least and largest; None where the record
    is too short to fit it), the share of the arrivals the place explains ``explained`` (:func:`explained_share`)
    and the rows' times of arrival less the speed's change ``corrected`` [s]."""

    fit: Any
    consider: np.ndarray
    spread: float
    gains: np.ndarray
    changed: list | None
    explained: float
    corrected: np.ndarray


def _place(toa, positions, c, fixes, rows, sigma_toa, survey, speed_sigma, clock_sigma) -> _Place:
    """One place of a still tag from the pings ``rows``: its pooled fit with the sound speed's change fitted beside
    it (:func:`changing_track`), the consider terms and the gains from one bias sensitivity, all on the times of
    arrival less the speed's change."""
    from sblsim.models.tracking.stationary import bias_sensitivity

    fitted = changing_track(toa[rows], positions, c, fixes[rows], sigma_toa)
    pooled, y = fitted.fix, fitted.corrected
    S = bias_sensitivity(y, positions, c, sigma_toa, pooled)
    # the speed fitted (its mean too): its error is in the fit's covariance, no consider term
    held = stationary_consider(y, positions, c, pooled, survey, None if fitted.knots else speed_sigma, sigma_toa,
                               clock_sigma, S)
    spread = receivers_term(y, positions, c, pooled, sigma_toa)
    gains = survey_gains(y, positions, c, pooled, sigma_toa, S)
    beyond = _beyond(spread, pooled.covariance)  # what the jackknife sees beyond the fit's own covariance
    return _Place(pooled, beyond + (0.0 if held is None else held), float(np.sqrt(np.trace(spread))), gains,
                  fitted.speed_range(c) if fitted.knots else None, explained_share(pooled, np.isfinite(y)), y)


def _moved_once(toa, positions, c, fx, sigma_toa, survey, speed_sigma, clock_sigma, sigma, last, first, drifted):
    """A still tag that moved once after its last still trusted fix ``last`` (its first moved one ``first``): the
    split (the first row at its second place; the rows between the two given to the place their arrivals fit,
    :func:`split_ping`, where it stepped; every one moved where it ``drifted``: its second place, the drift's mean,
    fits none of them), its first place from the rows before the split and its second from the rest (each
    :class:`_Place`; the second None where too few receivers heard it there)."""
    rows = np.arange(len(toa))
    before = _place(toa, positions, c, fx, rows[:last + 1], sigma_toa, survey, speed_sigma, clock_sigma)
    split = last + 1
    if first > last + 1 and not drifted:  # the rows between the two trusted fixes: each side's place from its own
        try:
            went = stationary_track(toa[first:], positions, c, fx[first:], sigma_toa).position
        except ModelError:  # too few receivers heard it after: the rows between flagged
            went = None
        if went is not None:
            split += split_ping(toa[last + 1:first], positions, c, sigma, before.fit.position, went)
    if split != last + 1:
        before = _place(toa, positions, c, fx, rows[:split], sigma_toa, survey, speed_sigma, clock_sigma)
    try:  # where it went: the pooled fit of the rows from the split
        gone = _place(toa, positions, c, fx, rows[split:], sigma_toa, survey, speed_sigma, clock_sigma)
    except ModelError:
        gone = None
    return split, before, gone


def _two_places_explained(toa: np.ndarray, split: int, first: float, second: float | None) -> float:
    """The share of a moved tag's arrivals its two places explain (:func:`explained_share`: ``first`` of the rows of
    ``toa`` (m, n) before ``split``, ``second`` of the rest), each weighed by its arrivals; the first's alone where
    the second is None (not fitted) or NaN. A tag that went from one place to another (a reference tag dragged, a
    dead fish) has both explain their arrivals; an animal whose fixes find a still part does not."""
    heard = np.isfinite(np.asarray(toa, float)).sum(axis=1)
    h1, h2 = float(heard[:split].sum()), float(heard[split:].sum())
    if second is None or not np.isfinite(second) or h2 == 0:
        return first
    return (first * h1 + second * h2) / (h1 + h2)


def _beyond(spread: np.ndarray, own: np.ndarray) -> np.ndarray:
    """The receivers' jackknife ``spread`` (dim, dim) [m²] beyond a fit's ``own`` covariance: the positive part of
    their difference (its eigenvalues below 0 set to 0), so that ``own`` plus it is at least each of the two in every
    direction. Each refit without a receiver moves by the arrivals' own noise too, which ``own`` already holds."""
    values, vectors = np.linalg.eigh(spread - own)
    return (vectors * values.clip(0.0, None)) @ vectors.T


def _rows(fit, rows: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """A pooled fit's emission times and arrivals kept (weight :data:`ROBUST_KEPT_WEIGHT` or more) on the record's
    rows ``rows`` of m, NaN and 0 elsewhere."""
    from sblsim.models.tracking.smoother import ROBUST_KEPT_WEIGHT

    emissions, kept = np.full(m, np.nan), np.zeros(m, int)
    emissions[rows] = fit.emissions
    kept[rows] = (fit.weights >= ROBUST_KEPT_WEIGHT).sum(axis=1)
    return emissions, kept


def still_tag(toa: np.ndarray, positions: np.ndarray, c: float, fixes: tuple, trusted: np.ndarray,
              sigma_toa: float | np.ndarray, survey: np.ndarray | None, speed: dict,
              clock_sigma: np.ndarray | None, clock_mean: np.ndarray | None = None,
              rounding: np.ndarray | float | None = None) -> StillTag:
    """A still tag (``motion`` ``stationary``): its pooled place, and whether it moved beyond what its error terms
    let its fixes wander (:func:`~sblsim.models.tracking.still.still_verdict`, with the single-ping fixes' order test
    :func:`~sblsim.models.tracking.stationary.moved` as a second input: a change the fixes' order in time does not
    show is none). The slow errors: each receiver's clock offset's ``clock_sigma`` [s], the sound speed's change over
    the record (:data:`~sblsim.models.tracking.still.SPEED_WANDER`, or the calibration's stretches' spread where
    larger), and a reflection at each receiver as large as its timing noise as the fixes show it. A tag that moved
    keeps its first place on the rows before the change and its second place (where it went) on the rows from the
    split (the pings between its last still trusted fix and its first moved one given to the place their arrivals
    fit: :func:`split_ping`; all of them moved where it drifted off: ``change.drift``), those flagged; one that moved
    the whole time keeps one place, every row flagged (an animal). One whose place explains fewer than
    :data:`MIN_EXPLAINED` of its arrivals (:func:`explained_share`; its two places, where it moved once) is not called
    still or moved: it moved the whole time where its fixes say it
    moved or lie in an order its error terms do not make (an animal whose few trusted fixes scatter far beyond their
    covariance), else ``unchecked``. With fewer than :data:`UNCHECKED_BELOW` trusted fixes nothing tells whether it
    moved: ``unchecked`` (its rows are flagged by the caller), not still.

    Parameters
    ----------
    toa : ndarray, (m, n)
        [s].
    positions : ndarray, (n, dim)
        [m].
    c : float
        [m/s].
    fixes : tuple
        The single-ping fixes ``(positions (m, dim), emissions (m,), covariances (m, dim, dim), used (m, n))``.
    trusted : ndarray of bool, (m,)
    sigma_toa : float or ndarray, (n,)
        [s].
    survey : ndarray, (n,), or None
        The receivers' survey error [m].
    speed : dict
        The sound speed's summary (``sigma_m_s``, ``stretches_m_s`` where calibrated).
    clock_sigma : ndarray, (n,), or None
        [s] each receiver's clock offset's error at a ping (the verdict's slow errors: one fix sees one bin's).
    clock_mean : ndarray, (n,), or None
        [s] that error averaged over the tag's arrivals at the receiver (the places' consider term: the pooled pings
        share the average, :func:`~sblsim.models.sync.mean_offset.mean_offset_sigma`); None or NaN: ``clock_sigma``.
    rounding : ndarray, (n,), float or None
        [s] each receiver's logged times' rounding σ (``q / √12``,
        :func:`~sblsim.models.sync.resolution.rounding_sigma`; 0 or None: not known). At a still tag the
        receivers' arrivals keep their places on the time grid for as long as the clocks take to drift across a
        quantum (hours): while they round alike the fixes scatter far less than the rounding's σ, and more later,
        so the fixes' dispersion in the verdict is at least the rounding's share of their timing noise (the
        arrivals' mean of ``(rounding / σ_toa)²``, :func:`~sblsim.models.tracking.still.still_verdict`'s
        ``white_floor``); and the clocks synchronised from the sync tags' rounded times keep such errors for hours
        too, so each receiver's rounding σ is a slow error of the verdict beside its clock's. The boats' times cut
        to tenths of a second had 3 of the 9 left-out sync tags called moved or moving (736 of 2,311 emissions
        flagged); taking it, none.

    Raises
    ------
    ModelError
        Too few receivers heard the tag (one line).
    """
    from sblsim.models.tracking.stationary import PERMUTATIONS, moved

    fx, fe, fc, fused = fixes
    m, n = toa.shape
    sigma = np.broadcast_to(np.asarray(sigma_toa, float), (n,))
    clock = np.zeros(n) if clock_sigma is None else np.nan_to_num(np.asarray(clock_sigma, float))
    # the places' clock term: averaged over the arrivals where known
    clock_held = clock_sigma if clock_mean is None else np.where(np.isfinite(clock_mean), clock_mean, clock)
    stretches = np.asarray(speed.get("stretches_m_s") or [], float)
    wander = max(sv.SPEED_WANDER, float(np.std(stretches, ddof=1)) if len(stretches) > 1 else 0.0)
    speed_sigma = speed.get("sigma_m_s")
    rows = np.arange(m)
    pooled, extra, spread, gains, changed, explained, corrected = _place(toa, positions, c, fx, rows, sigma_toa,
                                                                         survey, speed_sigma, clock_held)
    rho = np.linalg.norm(pooled.position[None, :] - positions, axis=1)
    used = np.asarray(fused, bool) & np.asarray(trusted, bool)[:, None]
    # the times' rounding a slow error too (as the clocks synchronised from rounded times carry it)
    rounded = np.broadcast_to(np.nan_to_num(np.asarray(0.0 if rounding is None else rounding, float)), (n,))
    slow = sv.slow_covariance(positions, pooled.position, c, used, sigma,
                              np.diag(clock**2 + rounded**2) + wander**2 * np.outer(rho, rho) / c**4)
    multipath = sv.slow_covariance(positions, pooled.position, c, used, sigma, np.diag(sigma**2))
    # the rounding's share of the fixes' timing noise, their dispersion's floor (over the arrivals used)
    floor = float(np.sum(used * (rounded / sigma) ** 2) / max(used.sum(), 1)) if rounded.any() else 0.0
    # a place that explains too few of its arrivals: whether its fixes lie in an order their errors do not make
    verdict = sv.still_verdict(fx, fc, fe, trusted, slow, multipath, order_test=explained < MIN_EXPLAINED,
                               white_floor=min(floor, 1.0))
    count, ratio, ordered = moved(fx, fe, trusted)
    went, throughout = verdict.change is not None and ordered, verdict.throughout
    places_tried = 1
    if went and not throughout:  # its still part (the rows to its last still trusted fix) and where it went
        last, first = int(verdict.order[verdict.change - 1]), int(verdict.order[verdict.change])
        args = (toa, positions, c, fx, sigma_toa, survey, speed_sigma, clock_held)
        split, before, gone = _moved_once(*args, sigma, last, first, verdict.drifted)
        explained = _two_places_explained(toa, split, before.explained, None if gone is None else gone.explained)
        places_tried = 2
    # no one place (the still part's and where it went, where it moved): it moved the whole time where its fixes say
    # it moved or wander, else unchecked
    scattered = verdict.fixes >= UNCHECKED_BELOW and (not went or not throughout) and explained < MIN_EXPLAINED
    throughout = throughout or (scattered and went)
    went = went or (scattered and throughout)
    unchecked = verdict.fixes < UNCHECKED_BELOW or (scattered and not throughout)
    emissions, kept = _rows(pooled, rows, m)
    places = np.repeat(pooled.position[None], m, axis=0)
    own, held = np.repeat(pooled.covariance[None], m, axis=0), np.repeat(extra[None], m, axis=0)
    after, change = np.zeros(m, bool) | (went and throughout), None
    if went and not throughout:  # the rows from the split moved
        change = {"last_still_ping": last, "first_moved_ping": first, "time_s": float(fe[first]),
                  "drift": verdict.drifted}
        after[split:] = True
        pooled, extra, spread, gains, changed, _, corrected = before
        corrected = np.vstack([corrected, toa[split:] if gone is None else gone.corrected])
        emissions[:], kept[:] = _rows(pooled, rows[:split], m)
        places[:split], own[:split], held[:split] = pooled.position, pooled.covariance, extra
        change["split_ping"] = split
        if gone is None:  # too few receivers heard it there: its fixes' median
            change |= {"second_place": np.nanmedian(fx[split:], axis=0).tolist(), "second_place_sigma_m": None,
                       "second_place_explained_share": None}
        else:
            moved_emissions, moved_kept = _rows(gone.fit, rows[split:], m)
            emissions[split:], kept[split:] = moved_emissions[split:], moved_kept[split:]
            places[split:], own[split:], held[split:] = gone.fit.position, gone.fit.covariance, gone.consider
            change |= {"second_place": gone.fit.position.tolist(),
                       "second_place_sigma_m": float(np.sqrt(np.trace((gone.fit.covariance + gone.consider)[:2, :2]))),
                       "second_place_explained_share": _number(gone.explained)}
        change["distance_m"] = float(np.linalg.norm(np.asarray(change["second_place"])[:2] - pooled.position[:2]))
    kp = np.flatnonzero(np.isfinite(emissions))
    if change is not None:
        change["rows_moved"] = int(after[kp].sum())
    scale = verdict.white_scale if np.isfinite(verdict.white_scale) else 1.0
    said = "unchecked" if unchecked else "moving" if went and throughout else "moved" if went else "still"
    summary = {"verdict": said,
               "trusted_fixes": verdict.fixes, "dispersion": _number(verdict.white_scale),
               "dispersion_floor": min(floor, 1.0),  # the times' rounding's share of the timing noise
               "explained_share": _number(explained), "places_explaining": places_tried, "scattered": bool(scattered),
               "step_statistic": _number(verdict.statistic), "threshold": _number(verdict.threshold),
               "level": sv.LEVEL, "slow_time_s": sv.SLOW_TIME_S, "speed_wander_m_s": wander,
               "detectable_step_m": [_number(x) for x in verdict.detectable],
               "slow_sigma_m": np.sqrt(np.clip(np.linalg.eigvalsh(slow + scale * multipath), 0.0, None))[::-1].tolist(),
               "receivers_jackknife_m": spread, "speed_change_m_s": changed, "change": change,
               "place": pooled.position.tolist(), "covariance": (pooled.covariance + extra).tolist(),
               "survey_gains": gains.tolist()}
    return StillTag(kp, emissions[kp], places[kp], own[kp], held[kp], kept[kp], after[kp], unchecked,
                    {"still": summary, "moved": bool(went),
                     "moved_test": {"trusted_fixes": count, "successive_ratio": _number(ratio),
                                    "permutations": PERMUTATIONS, "in_order": bool(ordered)}}, corrected)


def _number(x: float) -> float | None:
    """A float for JSON: None where not finite."""
    return float(x) if np.isfinite(x) else None


def place_score(still: dict[str, Any], truth: np.ndarray, known: np.ndarray,
                cross: np.ndarray | None = None) -> tuple[np.ndarray, float, float, float]:
    """A still tag's place (``still``: :func:`still_tag`'s ``summary["still"]``, its ``place`` and ``covariance``)
    against a known position ``truth`` (≥ 2,) [m] of horizontal covariance ``known`` (2, 2) [m²]: its offset ``e``
    (2,) [m], the error ``|e|`` [m], σ (the root trace of the offset's covariance) [m] and the 2-D NEES
    ``eᵀ C⁻¹ e``, ``C = P + Q − X − Xᵀ``. ``cross`` ``X`` (2, 2) [m²] is the covariance of the place's error with the
    known position's, where both come from one survey: a tag scored against receiver k's position as surveyed, whose
    place the same survey error moved, ``X = G_k Σ_k`` (:func:`survey_gains`' ``G_k``, ``Σ_k`` that receiver's survey
    covariance); without it a tag heard at its own receiver counts that receiver's survey error twice."""
    P = np.asarray(still["covariance"], float)[:2, :2] + known
    if cross is not None:
        P = P - cross - cross.T
    e = np.asarray(still["place"], float)[:2] - np.asarray(truth, float)[:2]
    return e, float(np.hypot(*e)), float(np.sqrt(np.trace(P))), float(e @ np.linalg.solve(P, e))


def survey_cross(still: dict[str, Any], k: int, survey: np.ndarray) -> np.ndarray | None:
    """:func:`place_score`'s ``cross`` (2, 2) [m²] for a still tag (``still``: its summary, with ``survey_gains``)
    scored against the position of its receiver ``k`` (its index among the tracked receivers) as surveyed, of survey
    covariance ``survey`` (2, 2) [m²]; None where the summary has no gains (written before them)."""
    gains = still.get("survey_gains")
    if gains is None:
        return None
    return np.asarray(gains, float)[k, :2] @ np.asarray(survey, float)


__all__ = ["MIN_EXPLAINED", "UNCHECKED_BELOW", "StillTag", "changing_track", "explained_share", "place_score",
           "receivers_term", "stationary_consider",
           "stationary_track", "split_ping", "still_tag", "survey_cross", "survey_gains"]

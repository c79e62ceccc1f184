"""A stationary tag (a sync tag, a reference tag, a dead fish): one position for all its pings, the pings pooled.

Every ping k has its own emission time ``t_k``; the position ``p`` is shared:

    ``min over p, t_1..t_m  Σ_(k,i) heard (ν + 1) ln(1 + z_ki² / ν)``,
    ``z_ki = (toa_ki − t_k − ‖p − r_i‖ / c) / σ_toa``,

the robust smoother's Student-t error of each arrival (:data:`~sblsim.models.tracking.smoother_cost.ROBUST_DOF`).
Solved by iteratively reweighted Gauss-Newton with the emission times eliminated: at fixed weights, each ``t_k`` is
the weighted mean of its arrivals' ``toa_ki − ‖p − r_i‖ / c``, so the position's normal equations are those of the
arrivals centred per ping (the Schur complement of the arrowhead system; Triggs et al., "Bundle adjustment — a modern
synthesis", 1999, § 6.1), a dim × dim solve per iteration whatever the number of pings. The covariance is the inverse
of the arrivals' observed information (:func:`~sblsim.models.tracking.smoother_cost.observed_information`) in the same
reduced form.

Units: seconds [s], metres [m].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.smoother_cost import ROBUST_DOF, observed_information
from sblsim.models.tracking.toa import checked_sigma, per_receiver

#: Gauss-Newton iterations at most, and the step [m] below which the position has converged.
ITERATIONS = 100
TOLERANCE = 1e-6


@dataclass(frozen=True)
class StationaryFix:
    """What :func:`stationary_fix` returns: ``position`` (dim,) [m], its ``covariance`` (dim, dim) [m²], each ping's
    ``emissions`` (m,) [s] (NaN for a ping nobody heard), the arrivals' ``weights`` (m, n) (0 where not heard),
    the ``pings`` that had arrivals and the Gauss-Newton ``iterations``."""

    position: np.ndarray
    covariance: np.ndarray
    emissions: np.ndarray
    weights: np.ndarray
    pings: int
    iterations: int


def _per_ping(w: np.ndarray, sigma_toa: float | np.ndarray) -> np.ndarray:
    """The weights (m, n) of each ping's emission time over its arrivals: the arrivals' own ``w``, over ``σ_i²``
    where the timing noise is each receiver's (one σ for all: ``w`` as it is, the mean the same)."""
    return w / np.asarray(sigma_toa, float) ** 2 if per_receiver(sigma_toa) else w


def _centred(values: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``values`` (m, n[, dim]) less their per-ping weighted mean over the heard arrivals (weights ``w`` (m, n), 0
    where not heard)."""
    total = np.maximum(w.sum(axis=1), 1e-300)
    if values.ndim == 3:
        return values - (np.einsum("mn,mnd->md", w, values) / total[:, None])[:, None, :]
    return values - ((w * values).sum(axis=1) / total)[:, None]


def _geometry(y: np.ndarray, receivers: np.ndarray, c: float, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At position ``p`` (dim,) [m]: each receiver's unit vector from it over ``c`` (n, dim) [s/m], and each arrival's
    emission time (m, n) [s] of the times of arrival ``y`` (0 where not heard)."""
    diff = p[None, :] - receivers
    d = np.linalg.norm(diff, axis=1)
    return diff / np.maximum(d, 1e-9)[:, None] / c, y - d[None, :] / c


def _information(heard: np.ndarray, unit: np.ndarray, emitted: np.ndarray, w: np.ndarray, sigma_toa: np.ndarray,
                 dof: float) -> tuple[np.ndarray, np.ndarray]:
    """The arrivals' observed information (m, n) at the normalised residuals the weights ``w`` leave (each ping's
    emission time their weighted mean), and the position's rows (m, n, dim) centred per ping with it [1/m]."""
    r = np.where(heard, _centred(emitted, _per_ping(w, sigma_toa)), 0.0) / sigma_toa
    info = np.where(heard, observed_information(r, dof), 0.0)
    J = np.where(heard[..., None], _centred(np.broadcast_to(-unit, heard.shape + (unit.shape[1],)),
                                            _per_ping(info, sigma_toa)), 0.0) / _columns(sigma_toa)
    return info, J


def checked_start(heard: np.ndarray, receivers: np.ndarray, start: np.ndarray) -> np.ndarray:
    """A pooled fit's first position (dim,) [m], a copy, checked with the arrivals ``heard`` (m, n).

    Raises
    ------
    ModelError
        Fewer than dim + 1 receivers heard the tag, or the start is not (dim,) and finite (one line).
    """
    dim = receivers.shape[1]
    if heard.any(axis=0).sum() < dim + 1:
        raise ModelError(f"stationary tag: {int(heard.any(axis=0).sum())} receivers heard it; allowed: at least "
                         f"{dim + 1}")
    p = np.asarray(start, float).copy()
    if p.shape != (dim,) or not np.isfinite(p).all():
        raise ModelError(f"stationary tag: a start of shape {p.shape} or not finite; allowed: ({dim},), finite")
    return p


def settled(heard: np.ndarray, emitted: np.ndarray, w: np.ndarray, sigma_toa: float | np.ndarray,
            dof: float) -> tuple[np.ndarray, np.ndarray]:
    """The arrivals' normalised residuals and Student-t weights (m, n) at a place, each ping's emission time the
    weighted mean of its arrivals' ``emitted`` (m, n) [s] (IRLS of the Student-t location from the weights ``w``, to
    its fixed point; 0 where not ``heard``)."""
    for _ in range(50):
        r = np.where(heard, _centred(emitted, _per_ping(w, sigma_toa)), 0.0) / sigma_toa
        new = np.where(heard, (dof + 1.0) / (dof + r**2), 0.0)
        if np.abs(new - w).max() < 1e-12:
            break
        w = new
    return np.where(heard, _centred(emitted, _per_ping(w, sigma_toa)), 0.0) / sigma_toa, w


def emission_times(emitted: np.ndarray, w: np.ndarray, sigma_toa: float | np.ndarray) -> np.ndarray:
    """Each ping's emission time (m,) [s]: its arrivals' ``emitted`` (m, n) [s] averaged with the weights ``w``
    (over ``σ_i²`` where the timing noise is each receiver's); NaN for a ping nobody heard."""
    wp = _per_ping(w, sigma_toa)
    total = wp.sum(axis=1)
    return np.where(total > 0, (wp * emitted).sum(axis=1) / np.where(total > 0, total, 1.0), np.nan)


def stationary_fix(toa: np.ndarray, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray, start: np.ndarray,
                   dof: float = ROBUST_DOF) -> StationaryFix:
    """The position of a stationary tag from all its pings (module docstring).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        [m].
    c : float
        Sound speed [m/s].
    sigma_toa : float or ndarray, (n,)
        [s]: one, or each receiver's.
    start : ndarray, (dim,)
        The first position [m] (e.g. the median of the single-ping fixes).
    dof : float
        ν.

    Returns
    -------
    StationaryFix

    Raises
    ------
    ModelError
        Fewer than dim + 1 receivers heard the tag, or the start is not finite.
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    heard = np.isfinite(toa)
    n, dim = receivers.shape
    p = checked_start(heard, receivers, start)
    sigma_toa = checked_sigma(sigma_toa, n)
    y = np.where(heard, toa, 0.0)

    w = heard.astype(float)

    iterations = 0
    for _ in range(ITERATIONS):
        iterations += 1
        unit, emitted = _geometry(y, receivers, c, p)
        r, w = settled(heard, emitted, w, sigma_toa, dof)
        J = np.where(heard[..., None], _centred(np.broadcast_to(-unit, heard.shape + (dim,)), _per_ping(w, sigma_toa)),
                     0.0) / _columns(sigma_toa)
        normal = np.einsum("mn,mni,mnj->ij", w, J, J)
        gradient = np.einsum("mn,mni,mn->i", w, J, r)
        step = np.linalg.lstsq(normal, -gradient, rcond=None)[0]
        p = p + step
        if np.abs(step).max() < TOLERANCE:
            break
    unit, emitted = _geometry(y, receivers, c, p)
    _, w = settled(heard, emitted, w, sigma_toa, dof)
    info, J = _information(heard, unit, emitted, w, sigma_toa, dof)
    covariance = np.linalg.pinv(np.einsum("mn,mni,mnj->ij", info, J, J))
    return StationaryFix(p, 0.5 * (covariance + covariance.T), emission_times(emitted, w, sigma_toa), w,
                         int(heard.any(axis=1).sum()), iterations)


def bias_sensitivity(toa: np.ndarray, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray,
                     fix: StationaryFix,
                     dof: float = ROBUST_DOF) -> np.ndarray:
    """How a constant time bias at each receiver moves a stationary tag's pooled position: the columns of
    ``∂p / ∂β_i`` [m/s].

    An error common to all the pings of one receiver is not averaged away by pooling them: the receiver's survey
    error (its range to a still tag is the same every ping), its clock offset's error and the sound speed's error
    (``−ρ_i δc / c²``, different at each receiver) are each such a bias ``β_i`` of its arrivals. At the solution
    the estimating equations ``Σ J ψ(z) = 0`` hold (``ψ`` the Student-t score), so a bias moves the position by
    ``δp = −(Σ Jᵀ ψ' J)⁻¹ Σ Jᵀ ψ' δz`` (the M-estimator's influence: Huber & Ronchetti, *Robust Statistics*, Wiley
    2009, § 6.2), ``ψ'`` the observed information, ``(Σ Jᵀ ψ' J)⁻¹`` the fix's covariance, ``δz = β_i / σ_toa`` at
    receiver i's arrivals; a bias common to every receiver moves only the emission times (the rows centred per
    ping). Given the biases' covariance B (n, n) [s²], the position's consider covariance is ``S B Sᵀ`` (Tapley,
    Schutz & Born, *Statistical Orbit Determination*, Elsevier 2004, § 6.3).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        [m].
    c : float
        [m/s]: that of the fix.
    sigma_toa : float or ndarray, (n,)
        [s]: that of the fix (one, or each receiver's).
    fix : StationaryFix
        :func:`stationary_fix`'s result on the same data.
    dof : float
        ν.

    Returns
    -------
    ndarray, (dim, n)
        S [m/s].
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    heard = np.isfinite(toa)
    sigma_toa = checked_sigma(sigma_toa, len(receivers))
    unit, emitted = _geometry(np.where(heard, toa, 0.0), receivers, c, fix.position)
    info, J = _information(heard, unit, emitted, fix.weights, sigma_toa, dof)
    return -fix.covariance @ np.einsum("mn,mni->in", info, J) / sigma_toa


#: The Gauss-Newton iterations of each refit of :func:`receiver_jackknife` (from the pooled position, its weights
#: held).
JACKKNIFE_ITERATIONS = 5


def receiver_jackknife(toa: np.ndarray, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray,
                       fix: StationaryFix) -> tuple[np.ndarray, np.ndarray]:
    """The pooled position refitted without each receiver in turn, and the delete-a-group jackknife's covariance
    of the position from them (dim, dim) [m²].

    Pooling averages each arrival's own noise, not what is the same at every ping of one receiver (its survey, its
    clock offset's error, a reflection on its path): the spread of the positions that leave one receiver out measures
    what such errors do to the position, whatever their source (Efron & Stein, Ann. Stat. 9(3), 1981; receivers as
    the groups of a delete-a-group jackknife: Kott, "The delete-a-group jackknife", J. Off. Stat. 17(4), 2001):
    ``(g − 1) / g Σ (p_(i) − p̄)(p_(i) − p̄)ᵀ`` over the g receivers that heard the tag. Each refit holds the
    pooled fit's robust weights and takes :data:`JACKKNIFE_ITERATIONS` Gauss-Newton steps from its position (a
    receiver near the tag moves it by metres where its linear sensitivity says centimetres: the range's cone).

    Parameters
    ----------
    toa, receivers, c, sigma_toa
        As :func:`stationary_fix` took them.
    fix : StationaryFix
        Its result.

    Returns
    -------
    positions : ndarray, (g, dim)
        [m], one per receiver that heard the tag (in the receivers' order).
    covariance : ndarray, (dim, dim)
        [m²]; zeros with fewer than dim + 2 receivers (a refit without one has no arrival to spare).
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    heard = np.isfinite(toa)
    n, dim = receivers.shape
    sigma_toa = checked_sigma(sigma_toa, n)
    y = np.where(heard, toa, 0.0)
    used = np.flatnonzero(heard.any(axis=0))
    out = []
    for i in used:
        w = fix.weights.copy()
        w[:, i] = 0.0
        kept = heard & (w > 0)
        p = fix.position.copy()
        for _ in range(JACKKNIFE_ITERATIONS):
            unit, emitted = _geometry(y, receivers, c, p)
            wp = _per_ping(w, sigma_toa)
            r = np.where(kept, _centred(emitted, wp), 0.0) / sigma_toa
            J = np.where(kept[..., None], _centred(np.broadcast_to(-unit, heard.shape + (dim,)), wp), 0.0) \
                / _columns(sigma_toa)
            step = np.linalg.lstsq(np.einsum("mn,mni,mnj->ij", w, J, J), -np.einsum("mn,mni,mn->i", w, J, r),
                                   rcond=None)[0]
            p = p + step
            if np.abs(step).max() < TOLERANCE:
                break
        out.append(p)
    positions = np.array(out).reshape(len(used), dim)
    if len(used) < dim + 2:
        return positions, np.zeros((dim, dim))
    d = positions - positions.mean(axis=0)
    return positions, (len(used) - 1) / len(used) * d.T @ d


def _columns(sigma_toa: float | np.ndarray) -> float | np.ndarray:
    """The timing noise as a divisor of the arrivals' Jacobians (m, n, dim): the one value, or (n, 1) per
    receiver."""
    return np.asarray(sigma_toa, float)[:, None] if per_receiver(sigma_toa) else sigma_toa


#: The permutations of :func:`moved`'s test, and its level: the tag moved where the fixes' order is more orderly than
#: in every permutation (p = 1 / (PERMUTATIONS + 1) = 0.001).
PERMUTATIONS = 999
#: The fewest trusted fixes the test takes (fewer: undecided), and the most (every j-th in time beyond: a still
#: tag's fixes stay in no order, a moving tag's in order).
MIN_FIXES = 10
MAX_FIXES = 5000


def moved(fixes: np.ndarray, times: np.ndarray, trusted: np.ndarray, seed: int = 0) -> tuple[int, float, bool]:
    """Whether the trusted single-ping fixes (:func:`~sblsim.models.tracking.quality.trusted_fixes`) lie in an order
    in time: a permutation test, one input of a still tag's verdict (:func:`~sblsim.models.tracking.still.still_verdict`
    decides: a still tag's fixes wander slowly with the water's sound speed, in an order this test alone calls
    motion, for every real still tag). Fixes with independent errors scatter about the
    position in no order (their errors are the pings' own), so successive fixes lie as far apart as any two; of a
    moving one successive fixes lie close. The statistic is the median distance between successive fixes over the
    median distance of the fixes from their median, a robust form of von Neumann's ratio of the mean square successive
    difference to the variance (von Neumann, Ann. Math. Stat. 12(4), 1941; √2 for independent Gaussian errors, near
    0 for a track): robust to a few gross fixes, and free of the fixes' covariances (which a clock synchronisation's
    residual errors leave too tight on real data: Lake Hald's tow and the Norwegian fjord's sync tags, docs). Its
    null distribution is that of the same fixes in random orders (a permutation test under exchangeability; Good,
    *Permutation, Parametric and Bootstrap Tests of Hypotheses*, Springer 2005, § 3): the tag moved where the ratio
    is below that of all :data:`PERMUTATIONS` orders (``numpy.random.default_rng(seed)``).

    Parameters
    ----------
    fixes : ndarray, (m, ≥2)
        The single-ping fixes [m], NaN where none.
    times : ndarray, (m,)
        Their times [s] (the order of the test).
    trusted : ndarray of bool, (m,)

    Returns
    -------
    tuple
        The trusted fixes, the ratio (NaN with fewer than :data:`MIN_FIXES`; of every j-th in time beyond
        :data:`MAX_FIXES`), and whether they lie in order.
    """
    fixes = np.asarray(fixes, float)[:, :2]
    k = np.flatnonzero(np.asarray(trusted, bool) & np.isfinite(fixes).all(axis=1) & np.isfinite(times))
    if len(k) < MIN_FIXES:
        return len(k), float("nan"), False
    k = k[np.argsort(np.asarray(times, float)[k], kind="stable")]
    p = fixes[k[::-(-len(k) // MAX_FIXES)]]
    spread = float(np.median(np.linalg.norm(p - np.median(p, axis=0), axis=1)))
    if not spread > 0:
        return len(k), float("nan"), False

    def ratio(q: np.ndarray) -> np.ndarray:  # (..., g, 2) -> (...,)
        return np.median(np.linalg.norm(np.diff(q, axis=-2), axis=-1), axis=-1) / spread

    observed = float(ratio(p))
    rng = np.random.default_rng(seed)
    lowest = np.inf
    for start in range(0, PERMUTATIONS, 100):  # 100 orders at a time: (100, g, 2) at most
        orders = np.argsort(rng.random((min(100, PERMUTATIONS - start), len(p))), axis=1)
        lowest = min(lowest, float(ratio(p[orders]).min()))
    return len(k), observed, bool(observed < lowest)


__all__ = ["ITERATIONS", "JACKKNIFE_ITERATIONS", "MAX_FIXES", "MIN_FIXES", "PERMUTATIONS", "TOLERANCE", "StationaryFix",
           "bias_sensitivity", "checked_start", "emission_times", "moved", "receiver_jackknife", "settled",
           "stationary_fix"]

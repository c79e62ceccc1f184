"""The single-ping fix: each ping alone, its position and emission time by Gauss-Newton least squares.

Needs dim + 1 receivers; the receiver with the largest normalised residual is dropped while it fails the χ² test of
one arrival (:data:`GATE_ONE`) and redundancy remains (a late multipath arrival). A record's pings are fixed together,
:data:`FIX_CHUNK` at a time (each Gauss-Newton iteration one numpy pass over a chunk: each ping's fix its own).

References
----------
Kay, *Fundamentals of Statistical Signal Processing: Estimation Theory*, Prentice Hall 1993, § 8.9 (Gauss-Newton
for nonlinear least squares); Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to Tracking and
Navigation*, Wiley 2001, § 5.4 (the χ² gate).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.tracking.depth import checked_depth
from sblsim.models.tracking.toa import _evaluate_pings, checked_sigma, per_receiver, reference_sigma

#: χ²(1) quantile of probability 0.999: the gate of one time of arrival.
GATE_ONE = 10.828


#: Iterations of a single-ping Gauss-Newton fix.
FIX_ITERATIONS = 30


#: A start on a receiver is moved off it by this share of the array's span on each horizontal axis.
START_OFFSET = 0.01


#: Pings :func:`fix_pings` fixes together: a chunk's arrays stay in the processor's cache (each ping's fix is its
#: own, the same whatever the chunk).
FIX_CHUNK = 8192


@dataclass
class Fix:
    """A single-ping fix: position [m] (dim,), emission time [s], covariance of ``(p, t_e)`` (dim + 1, dim + 1)
    [m², m·s, s²], the receivers used (n,) and the normalised residuals' sum of squares."""

    position: np.ndarray
    emission: float
    covariance: np.ndarray
    used: np.ndarray
    chi2: float


def single_ping_fix(toa: np.ndarray, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray,
                    guess: np.ndarray | None = None, gate: float = GATE_ONE) -> Fix | None:
    """The least-squares fix of one ping from its times of arrival, the emission time unknown (TOA/TDOA).

    Gauss-Newton on ``Σ_i ((toa_i − t_e − ‖p − r_i‖/c) / σ_i)²`` with step halving; while the ping keeps at least
    dim + 2 receivers, the one with the largest squared normalised residual is dropped when that exceeds
    ``gate`` (multipath arrivals are late) and the fix is made again.

    Parameters
    ----------
    toa : ndarray, (n,)
        Times of arrival [s]; NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    c : float
        Sound speed [m/s].
    sigma_toa : float or ndarray, (n,)
        Standard deviation of a time of arrival [s]: one for every receiver, or each receiver's own (the
        arrivals weighed by ``1 / σ_i²``).
    guess : ndarray, (dim,), optional
        Start position [m] (default between the first receiver to hear and the centroid of those heard).
    gate : float
        χ²(1) threshold of one residual.

    Returns
    -------
    Fix or None
        None when fewer than dim + 1 receivers heard the ping or the iteration failed.
    """
    positions, emissions, covariances, used, chi2 = fix_pings(
        np.asarray(toa, float)[None, :], receivers, c, sigma_toa, None if guess is None else np.asarray(guess)[None],
        gate)
    if not np.isfinite(emissions[0]):
        return None
    return Fix(positions[0], float(emissions[0]), covariances[0], used[0], float(chi2[0]))


def fix_pings(toa: np.ndarray, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray,
              guesses: np.ndarray | None = None,
              gate: float = GATE_ONE, depth: np.ndarray | None = None, depth_sigma: float = 0.3,
              survey_sigma: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`single_ping_fix` of every ping at once (one evaluation per Gauss-Newton iteration for all pings).

    A tag's depth-sensor reading (``depth``) is one more measurement of the ping, ``z = −depth`` with standard
    deviation ``depth_sigma`` (the receivers' z up): a ping with a reading is fixed from dim receivers. The
    receivers' survey error (``survey_sigma``) enters the covariance as a consider covariance: receiver i's position
    error δr_i moves the fix by ``−S_i δr_i``, ``S_i = C Jᵢᵀ J_p,i / σ²`` (C the fix's covariance, J_i its arrival's
    row, J_p,i that row's position part), so ``C + Σ_i σ_i² S_i S_iᵀ`` (Tapley, Schutz & Born, *Statistical Orbit
    Determination*, Elsevier 2004, § 6.3).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    c, sigma_toa, gate
        As :func:`single_ping_fix`.
    guesses : ndarray, (m, dim), optional
        Start positions [m].
    depth : ndarray, (m,), optional
        The tag's depth-sensor reading per ping [m], positive down, NaN where none; needs receivers in 3-D.
    depth_sigma : float
        Its standard deviation [m].
    survey_sigma : ndarray, (n,), optional
        Each receiver's survey error per axis [m] (standard deviation; None: exact).

    Returns
    -------
    positions : ndarray, (m, dim)
        [m]; NaN where a ping has no fix (fewer than dim + 1 receivers, or no convergence).
    emissions : ndarray, (m,)
        [s]; NaN likewise.
    covariances : ndarray, (m, dim + 1, dim + 1)
        Of ``(p, t_e)`` [m², m·s, s²].
    used : ndarray of bool, (m, n)
        The arrivals each fix used.
    chi2 : ndarray, (m,)
        Sum of the squared normalised residuals of the arrivals.

    Raises
    ------
    ModelError
        A depth given with receivers in 2-D, or not one per ping; a timing noise not one value or one per receiver.
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    m, (n, dim) = len(toa), receivers.shape
    depth = checked_depth(depth, m, dim)
    sigma_toa = checked_sigma(sigma_toa, n)
    if m <= FIX_CHUNK:
        return _fix_chunk(toa, receivers, c, sigma_toa, guesses, gate, depth, depth_sigma, survey_sigma)
    out = (np.empty((m, dim)), np.empty(m), np.empty((m, dim + 1, dim + 1)), np.empty((m, n), bool), np.empty(m))
    for lo in range(0, m, FIX_CHUNK):
        rows = slice(lo, lo + FIX_CHUNK)
        part = _fix_chunk(toa[rows], receivers, c, sigma_toa, None if guesses is None else np.asarray(guesses)[rows],
                          gate, None if depth is None else depth[rows], depth_sigma, survey_sigma)
        for whole, piece in zip(out, part):
            whole[rows] = piece
    return out


def _fix_chunk(toa, receivers, c, sigma_toa, guesses, gate, depth, depth_sigma, survey_sigma):
    """:func:`fix_pings` of a chunk of pings (its arguments checked). With a timing noise per receiver each arrival's
    row is weighed by ``σ / σ_i`` (σ the receivers' median, :func:`~sblsim.models.tracking.toa.reference_sigma`), so
    that the sums below, in units of σ, are those of the arrivals' own noise."""
    m, (n, dim) = len(toa), receivers.shape
    relative = np.asarray(reference_sigma(sigma_toa) / sigma_toa) if per_receiver(sigma_toa) else None
    sigma_toa = reference_sigma(sigma_toa)
    used = np.isfinite(toa)
    known = np.zeros(m, bool) if depth is None else np.isfinite(depth)
    valid = used.sum(axis=1) + known >= dim + 1
    positions = np.full((m, dim), np.nan)
    emissions = np.full(m, np.nan)
    covariances = np.full((m, dim + 1, dim + 1), np.nan)
    chi2 = np.full(m, np.nan)
    rows = np.flatnonzero(valid)
    if not len(rows):
        return positions, emissions, covariances, used & valid[:, None], chi2
    filled = np.where(used, toa, 0.0)
    first = np.argmin(np.where(used, toa, np.inf), axis=1)
    centroid = (used[:, :, None] * receivers[None]).sum(axis=1) / np.maximum(used.sum(axis=1), 1)[:, None]
    p = 0.5 * (receivers[first] + centroid) if guesses is None else np.array(guesses, float)
    # a start on a receiver has no gradient (its range's derivative is 0 / 0): the first receiver heard at the
    # centroid of those heard, a receiver at the middle of a symmetric array, started Gauss-Newton nowhere; moved off
    # it horizontally by START_OFFSET of the array's span
    span = max(float(np.ptp(receivers, axis=0).max()), 1.0)
    on = (np.linalg.norm(p[:, None, :] - receivers[None], axis=-1) < 1e-9 * span).any(axis=1)
    p[on, :2] += START_OFFSET * span
    # a depth reading: the height z = −depth one more measurement, in the arrivals' units (its row weighed by
    # σ_toa / depth_sigma), and the start at it
    height = np.where(known, -np.nan_to_num(depth) if depth is not None else 0.0, 0.0)
    if known.any():
        p[known, 2] = height[known]
    te = toa[np.arange(m), first] - np.linalg.norm(p - receivers[first], axis=1) / c
    p, te = p[rows], te[rows]
    prior = (height, known, sigma_toa / depth_sigma) if known.any() else None
    active = rows
    for _ in range(n + 1):  # outlier rounds: the worst residual dropped while it fails the gate and redundancy remains
        p_a, te_a, J, res = _gauss_newton_pings(toa[active], filled[active], used[active], receivers, c, p, te,
                                                None if prior is None else (prior[0][active], prior[1][active],
                                                                            prior[2]), relative)
        positions[active], emissions[active] = p_a, te_a
        z2 = np.where(used[active], (res[:, :n] / sigma_toa) ** 2, 0.0)
        chi2[active] = z2.sum(axis=1)
        rows_used = used[active] if prior is None else np.column_stack([used[active], prior[1][active]])
        A = J * rows_used[:, :, None] / sigma_toa
        info = np.einsum("mki,mkj->mij", A, A)
        finite = np.isfinite(info).all(axis=(1, 2))  # a diverged iteration's (the fix refused below)
        cov = np.full(info.shape, np.nan)
        with np.errstate(all="ignore"):
            cov[finite] = np.linalg.pinv(info[finite])
        if survey_sigma is not None:
            cov = cov + _survey_term(cov, J[:, :n], used[active], sigma_toa, np.asarray(survey_sigma, float), dim)
        covariances[active] = cov
        again = (used[active].sum(axis=1) + known[active] >= dim + 3) & (z2.max(axis=1) > gate)
        if not again.any():
            break
        worst = np.argmax(z2[again], axis=1)
        used[active[again], worst] = False
        active, p, te = active[again], p_a[again], te_a[again]
    bad = ~(np.isfinite(positions).all(axis=1) & np.isfinite(emissions) & np.isfinite(covariances).all(axis=(1, 2))) \
        | ~valid
    positions[bad], emissions[bad], chi2[bad] = np.nan, np.nan, np.nan
    return positions, emissions, covariances, used & ~bad[:, None], chi2


def survey_fix_covariance(receivers: np.ndarray, c: float, sigma_toa: float, positions: np.ndarray,
                          emissions: np.ndarray, covariances: np.ndarray, used: np.ndarray,
                          survey_sigma: np.ndarray) -> np.ndarray:
    """The receivers' survey error's share of fixes' covariances (the term :func:`fix_pings` adds where
    ``survey_sigma`` is given), for fixes made without it.

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        [m].
    c : float
        [m/s].
    sigma_toa : float or ndarray, (n,)
        [s], as the fixes were made with.
    positions, emissions, covariances, used : ndarray
        What :func:`fix_pings` returned: (m, dim) [m], (m,) [s], (m, dim + 1, dim + 1), (m, n).
    survey_sigma : ndarray, (n,) or (n dim, p)
        Each receiver's survey error per axis [m], or the square root of the receivers' errors' covariance [m]
        (:func:`~sblsim.models.tracking.survey_root.survey_root`: correlated errors).

    Returns
    -------
    ndarray, (m, dim + 1, dim + 1)
        NaN where a ping has no fix.
    """
    receivers = np.asarray(receivers, float)
    _, J = _evaluate_pings(receivers, c, np.nan_to_num(positions), np.nan_to_num(emissions))
    return _survey_term(np.asarray(covariances, float), J, np.asarray(used, bool), sigma_toa,
                        np.asarray(survey_sigma, float), receivers.shape[1])


def speed_fix_covariance(receivers: np.ndarray, c: float, sigma_toa: float, positions: np.ndarray,
                         emissions: np.ndarray, covariances: np.ndarray, used: np.ndarray,
                         sigma_c: float) -> np.ndarray:
    """The sound speed's error's share of fixes' covariances, a consider covariance (Tapley, Schutz & Born,
    *Statistical Orbit Determination*, Elsevier 2004, § 6.3): an error δc moves a fix by ``δx = C Σ_i J_iᵀ
    (∂m_i/∂c) δc / σ_toa²`` (C its covariance, J_i the arrival's row, ``∂m_i/∂c = −ρ_i / c²`` its travel time's
    derivative), so the term is ``σ_c² S Sᵀ`` with that S.

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        [m].
    c : float
        The speed the fixes were made at [m/s].
    sigma_toa : float or ndarray, (n,)
        [s], as the fixes were made with.
    positions, emissions, covariances, used : ndarray
        What :func:`fix_pings` returned: (m, dim) [m], (m,) [s], (m, dim + 1, dim + 1), (m, n).
    sigma_c : float
        The speed's standard error [m/s].

    Returns
    -------
    ndarray, (m, dim + 1, dim + 1)
        NaN where a ping has no fix.
    """
    receivers = np.asarray(receivers, float)
    positions = np.asarray(positions, float)
    travel, J = _evaluate_pings(receivers, c, np.nan_to_num(positions), np.zeros(len(positions)))
    dm = -travel / c  # the travel time ρ / c differentiated by c: −ρ / c²
    if per_receiver(sigma_toa):  # each arrival's row over its own σ_i²
        S = np.einsum("kab,knb,kn->ka", np.nan_to_num(np.asarray(covariances, float)),
                      J * np.asarray(used, bool)[:, :, None], dm / np.asarray(sigma_toa, float) ** 2)
    else:
        S = np.einsum("kab,knb,kn->ka", np.nan_to_num(np.asarray(covariances, float)),
                      J * np.asarray(used, bool)[:, :, None], dm) / sigma_toa**2
    out = float(sigma_c) ** 2 * S[:, :, None] * S[:, None, :]
    out[~np.isfinite(positions).all(axis=1)] = np.nan
    return out


def _survey_term(cov: np.ndarray, J: np.ndarray, used: np.ndarray, sigma_toa: float | np.ndarray,
                 survey: np.ndarray, dim: int) -> np.ndarray:
    """The fixes' consider covariance of the receivers' survey error (:func:`fix_pings`): ``Σ_i σ_i² S_i S_iᵀ``,
    ``S_i = C J_iᵀ J_p,i / σ_toa²`` (k, dim + 1, dim + 1) for the fixes' covariances C (k, dim + 1, dim + 1), their
    arrivals' rows J (k, n, dim + 1), the arrivals used (k, n) and the survey errors (n,) [m] (``σ_toa`` one, or
    each receiver's (n,)); given their square root L (n dim, p) [m] instead (correlated errors,
    :mod:`~sblsim.models.tracking.survey_root`), ``T Tᵀ`` with ``T = Σ_(i,a) S_(i,a) L_(i a)``."""
    G = np.einsum("kab,knb->kna", np.nan_to_num(cov), J * used[:, :, None])  # C J_iᵀ: (k, n, d+1)
    G = G / np.asarray(sigma_toa, float)[None, :, None] ** 2 if per_receiver(sigma_toa) else G / sigma_toa**2
    S = G[:, :, :, None] * J[:, :, None, :dim]  # (k, n, dim + 1, dim)
    if survey.ndim == 2:
        T = np.einsum("knab,nbp->kap", S, survey.reshape(S.shape[1], dim, -1))
        return np.einsum("kap,kcp->kac", T, T)
    return np.einsum("n,knab,kncb->kac", survey**2, S, S)


def _gauss_newton_pings(toa, filled, used, receivers, c, p, te, prior=None, relative=None):
    """Gauss-Newton iterations with step halving of many pings' fixes at once: positions (k, dim), emission times
    (k,), Jacobians (k, n[ + 1], dim + 1) and residuals (k, n[ + 1]) (0 where not used) at the end; ``prior``
    (heights (k,) [m], which are known (k,), their weight σ_toa / σ_depth [s/m]) one more row, the height's;
    ``relative`` (n,) each arrival's row weight ``σ_toa / σ_i`` (None: all 1), applied to the residuals and the
    Jacobians returned."""
    dim = receivers.shape[1]
    p, te = p.copy(), te.copy()
    if relative is not None:
        filled = filled * relative
    if prior is not None:
        height, known, weight = prior
        used = np.column_stack([used, known])
        filled = np.column_stack([filled, np.where(known, height * weight, 0.0)])

    def evaluate(idx, p, te):
        model, J = _evaluate_pings(receivers, c, p, te)
        if relative is not None:  # each arrival's row weighed by σ_toa / σ_i
            model, J = model * relative, J * relative[:, None]
        if prior is not None:  # the height's row: weight · z, its Jacobian weight on z
            row = np.zeros((len(p), 1, dim + 1))
            row[:, 0, 2] = weight
            model, J = np.column_stack([model, weight * p[:, 2]]), np.concatenate([J, row], axis=1)
        return np.where(used[idx], filled[idx] - model, 0.0), J

    res, J = evaluate(slice(None), p, te)
    cost = (res**2).sum(axis=1)
    moving = np.arange(len(p))
    for _ in range(FIX_ITERATIONS):
        Jw = J[moving] * used[moving][:, :, None]
        normal = np.einsum("mki,mkj->mij", Jw, Jw) + 1e-12 * np.eye(dim + 1)
        step = np.linalg.solve(normal, np.einsum("mki,mk->mi", Jw, res[moving])[..., None])[..., 0]
        big = np.abs(step[:, :-1]).max(axis=1) >= 1e-6  # converged: a step below a micrometre
        moving, step = moving[big], step[big]
        trying, scale = np.arange(len(moving)), 1.0  # places in moving
        for _halving in range(10):
            if not len(trying):
                break
            rows = moving[trying]
            p_try, te_try = p[rows] + scale * step[:, :-1], te[rows] + scale * step[:, -1]
            res_try, J_try = evaluate(rows, p_try, te_try)
            cost_try = (res_try**2).sum(axis=1)
            better = cost_try <= cost[rows]
            done = rows[better]
            p[done], te[done], res[done], J[done], cost[done] = (p_try[better], te_try[better], res_try[better],
                                                                 J_try[better], cost_try[better])
            trying, step, scale = trying[~better], step[~better], 0.5 * scale
        stuck = np.zeros(len(moving), bool)
        stuck[trying] = True
        moving = moving[~stuck]  # no step lowers the cost: done
        if not len(moving):
            break
    return p, te, J, res


__all__ = ["FIX_ITERATIONS", "GATE_ONE", "START_OFFSET", "Fix", "fix_pings", "single_ping_fix", "speed_fix_covariance",
           "survey_fix_covariance"]

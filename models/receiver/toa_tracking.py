"""Tracking a pinger from its times of arrival at a fixed, synchronised array (an inverted LBL).

A target emits a ping on its own clock about every ``Δ`` seconds; N receivers at known positions ``r_i``
with synchronised clocks record its times of arrival (TOA). The emission time ``t_e`` of each ping is unknown
to the receivers, so the measurement model of receiver i is

    ``toa_i = t_e + ‖p − r_i‖ / c + w_i``,   ``w_i ~ N(0, σ_toa²)``,

with the target's position ``p`` at emission (2-D, or 3-D), the sound speed ``c`` [m/s] and the timing noise
``σ_toa`` [s]. Only differences of arrival times locate the target (TDOA); the emission time is estimated
beside the position. The model and its Jacobian are casadi expressions (:func:`toa_function`).

The estimators:

* :func:`single_ping_fix`: each ping alone, Gauss-Newton least squares over ``(p, t_e)`` (needs dim + 1
  receivers), the receiver with the largest normalised residual dropped while it fails the χ² test and
  redundancy remains.
* :func:`calibrate_sound_speed_robust`: the sound speed fitted jointly with the pings' positions and emission
  times under a soft-L1 loss (late arrivals weigh as in an L1 fit); the replay's calibration.
* :class:`ToaTracker`: an extended Kalman filter (EKF) over the pings, state
  ``[p, v, t_e, Δ]`` (position [m], velocity [m/s], emission time [s], ping interval [s]) with a
  nearly-constant-velocity motion model (white-noise acceleration), the emission time advancing by the
  interval plus a jitter and the interval a random walk (its drift); the times of arrival of each ping
  gated by their NIS (each one, then the ping's set), restarted from a single-ping fix when lost, and the
  fixed-interval Rauch-Tung-Striebel smoother
  (:func:`rts_smooth`) over the filter's record, with its own covariance.

Units: seconds [s], metres [m], metres per second [m/s].

References
----------
Baktoft, Gjelland, Økland, Thygesen, "Positioning of aquatic animals based on time-of-arrival and random walk
models using YAPS (Yet Another Positioning Solver)", Scientific Reports 7:14294, 2017,
doi:10.1038/s41598-017-14278-z (the random-walk model of the track and of the emission times, and the Lake
Hald data). Rauch, Tung, Striebel, "Maximum likelihood estimates of linear dynamic systems", AIAA Journal
3(8), 1965 (the smoother). Bar-Shalom, Li, Kirubarajan, Estimation with Applications to Tracking and
Navigation, Wiley 2001, Sections 5.4 (NIS), 6.2 (white-noise acceleration model) and 10.3 (the EKF).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import lru_cache

import casadi as ca
import numpy as np
from scipy.linalg import solveh_banded

from sblsim.models.declarations import ModelError
from sblsim.models.receiver.sigma_points import MerweScaledSigmaPoints
from sblsim.models.receiver.toa_bound import predict, process_noise
from sblsim.models.tracking.schedule import PingSchedule

#: The sound speeds a tracker accepts and the calibration searches [m/s].
SOUND_SPEED_RANGE = (1300.0, 1700.0)
#: χ²(1) quantile of probability 0.999: the gate of one time of arrival.
GATE_ONE = 10.828
#: Iterations of a single-ping Gauss-Newton fix.
FIX_ITERATIONS = 30


@lru_cache(maxsize=32)
def toa_function(n: int, dim: int) -> ca.Function:
    """The TOA model of n receivers and its Jacobian, a casadi function.

    ``toa(p, t_e, R, c) -> (toa, J)``: ``p`` (dim, 1) the target's position at emission [m], ``t_e`` the
    emission time [s], ``R`` (dim, n) the receivers' positions [m], ``c`` the sound speed [m/s];
    ``toa`` (n, 1) the times of arrival [s], ``J`` (n, dim + 1) their derivatives with respect to
    ``(p, t_e)`` [s/m, 1].
    """
    p = ca.SX.sym("p", dim)
    te = ca.SX.sym("t_e")
    R = ca.SX.sym("R", dim, n)
    c = ca.SX.sym("c")
    toa = ca.vertcat(*[te + ca.norm_2(p - R[:, i]) / c for i in range(n)])
    J = ca.jacobian(toa, ca.vertcat(p, te))
    return ca.Function("toa", [p, te, R, c], [toa, J], ["p", "t_e", "R", "c"], ["toa", "J"])


def toa_model(position: np.ndarray, emission: float, receivers: np.ndarray, c: float) -> tuple[np.ndarray, np.ndarray]:
    """Times of arrival of one ping and their Jacobian (:func:`toa_function` evaluated).

    Parameters
    ----------
    position : ndarray, (dim,)
        Target position at emission [m].
    emission : float
        Emission time [s].
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    c : float
        Sound speed [m/s].

    Returns
    -------
    toa : ndarray, (n,)
        Times of arrival [s].
    J : ndarray, (n, dim + 1)
        Derivatives with respect to the position [s/m] and the emission time [1].
    """
    receivers = np.asarray(receivers, float)
    n, dim = receivers.shape
    toa, J = toa_function(n, dim)(np.asarray(position, float), float(emission), receivers.T, float(c))
    return np.asarray(toa).ravel(), np.asarray(J)


@dataclass
class Fix:
    """A single-ping fix: position [m] (dim,), emission time [s], covariance of ``(p, t_e)`` (dim + 1, dim + 1)
    [m², m·s, s²], the receivers used (n,) and the normalised residuals' sum of squares."""

    position: np.ndarray
    emission: float
    covariance: np.ndarray
    used: np.ndarray
    chi2: float


def single_ping_fix(toa: np.ndarray, receivers: np.ndarray, c: float, sigma_toa: float,
                    guess: np.ndarray | None = None, gate: float = GATE_ONE) -> Fix | None:
    """The least-squares fix of one ping from its times of arrival, the emission time unknown (TOA/TDOA).

    Gauss-Newton on ``Σ_i (toa_i − t_e − ‖p − r_i‖/c)²`` with step halving; while the ping keeps at least
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
    sigma_toa : float
        Standard deviation of a time of arrival [s].
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


@lru_cache(maxsize=32)
def _mapped(n: int, dim: int, m: int) -> ca.Function:
    """:func:`toa_function` over m pings at once (the receivers and the sound speed shared)."""
    return toa_function(n, dim).map("toa_pings", "serial", m, [2, 3], [])


def fix_pings(toa: np.ndarray, receivers: np.ndarray, c: float, sigma_toa: float, guesses: np.ndarray | None = None,
              gate: float = GATE_ONE) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`single_ping_fix` of every ping at once (one casadi call per Gauss-Newton iteration for all pings).

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
        Sum of the squared normalised residuals.
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    m, (n, dim) = len(toa), receivers.shape
    used = np.isfinite(toa)
    valid = used.sum(axis=1) >= dim + 1
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
    te = toa[np.arange(m), first] - np.linalg.norm(p - receivers[first], axis=1) / c
    p, te = p[rows], te[rows]
    active = rows
    for _ in range(n + 1):  # outlier rounds: the worst residual dropped while it fails the gate and redundancy remains
        p_a, te_a, J, res = _gauss_newton_pings(toa[active], filled[active], used[active], receivers, c, p, te)
        positions[active], emissions[active] = p_a, te_a
        z2 = np.where(used[active], (res / sigma_toa) ** 2, 0.0)
        chi2[active] = z2.sum(axis=1)
        A = J * used[active][:, :, None] / sigma_toa
        info = np.einsum("mki,mkj->mij", A, A)
        finite = np.isfinite(info).all(axis=(1, 2))  # a diverged iteration's (the fix refused below)
        cov = np.full(info.shape, np.nan)
        with np.errstate(all="ignore"):
            cov[finite] = np.linalg.pinv(info[finite])
        covariances[active] = cov
        again = (used[active].sum(axis=1) >= dim + 3) & (z2.max(axis=1) > gate)
        if not again.any():
            break
        worst = np.argmax(z2[again], axis=1)
        used[active[again], worst] = False
        active, p, te = active[again], p_a[again], te_a[again]
    bad = ~(np.isfinite(positions).all(axis=1) & np.isfinite(emissions)) | ~valid
    positions[bad], emissions[bad], chi2[bad] = np.nan, np.nan, np.nan
    return positions, emissions, covariances, used & ~bad[:, None], chi2


def _evaluate_pings(receivers: np.ndarray, c: float, p: np.ndarray, te: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`toa_function` at k pings' positions (k, dim) and emission times (k,): times of arrival (k, n) and
    Jacobians (k, n, dim + 1); evaluated by a mapped function of the next power of two of k (few sizes made)."""
    k, (n, dim) = len(p), receivers.shape
    size = 1 << max(k - 1, 0).bit_length()
    pad = size - k
    model, J = _mapped(n, dim, size)(np.pad(p, ((0, pad), (0, 0))).T, np.pad(te, (0, pad))[None, :], receivers.T, c)
    return np.asarray(model).T[:k], np.asarray(J).reshape(n, size, dim + 1).transpose(1, 0, 2)[:k]


def _evaluate_arrivals(receivers: np.ndarray, c: float, p: np.ndarray, te: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`toa_function` of one receiver at each of h arrivals: the receiver (h, dim) [m], the target's position
    (h, dim) [m] and emission time (h,) [s] of each; times of arrival (h,) and Jacobians (h, dim + 1) (a mapped
    function of the next power of two of h)."""
    h, dim = p.shape
    size = 1 << max(h - 1, 0).bit_length()
    pad = ((0, size - h), (0, 0))
    model, J = _mapped_arrivals(dim, size)(np.pad(p, pad).T, np.pad(te, pad[0])[None, :], np.pad(receivers, pad).T, c)
    return np.asarray(model).ravel()[:h], np.asarray(J).reshape(size, dim + 1)[:h]


@lru_cache(maxsize=32)
def _mapped_arrivals(dim: int, h: int) -> ca.Function:
    """:func:`toa_function` of one receiver over h arrivals at once (each its own receiver; the sound speed shared)."""
    return toa_function(1, dim).map("toa_arrivals", "serial", h, [3], [])


def _gauss_newton_pings(toa, filled, used, receivers, c, p, te):
    """Gauss-Newton iterations with step halving of many pings' fixes at once: positions (k, dim), emission times
    (k,), Jacobians (k, n, dim + 1) and residuals (k, n) (0 where not used) at the end."""
    dim = receivers.shape[1]
    p, te = p.copy(), te.copy()

    def evaluate(idx, p, te):
        model, J = _evaluate_pings(receivers, c, p, te)
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
        trying, scale = moving, 1.0
        for _halving in range(10):
            if not len(trying):
                break
            p_try, te_try = p[trying] + scale * step[:, :-1], te[trying] + scale * step[:, -1]
            res_try, J_try = evaluate(trying, p_try, te_try)
            cost_try = (res_try**2).sum(axis=1)
            better = cost_try <= cost[trying]
            done = trying[better]
            p[done], te[done], res[done], J[done], cost[done] = (p_try[better], te_try[better], res_try[better],
                                                                 J_try[better], cost_try[better])
            trying, step, scale = trying[~better], step[~better], 0.5 * scale
        moving = np.setdiff1d(moving, trying)  # no step lowers the cost: done
        if not len(moving):
            break
    return p, te, J, res


#: The robust calibration's soft-L1 scale, in standard deviations of a time of arrival: residuals beyond it weigh
#: as in an L1 fit (late multipath arrivals).
ROBUST_SCALE = 2.0
#: The robust calibration's most joint steps, and the change of the sound speed [m/s] it stops below.
JOINT_ITERATIONS = 200
JOINT_TOLERANCE = 0.01


def _calibration_pings(toa: np.ndarray, dim: int, max_pings: int) -> np.ndarray:
    """The rows of ``toa`` (m, n) a sound-speed calibration uses: at most ``max_pings`` pings, evenly spread, of
    those heard by at least dim + 3 receivers (redundant ones); ModelError (one line) if fewer than 3."""
    rich = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= dim + 3)
    if len(rich) < 3:
        raise ModelError(f"sound speed calibration: {len(rich)} pings heard by at least {dim + 3} receivers; at "
                         "least 3 are needed (give the sound speed)")
    return rich[np.unique(np.linspace(0, len(rich) - 1, min(max_pings, len(rich))).round().astype(int))]


def calibrate_sound_speed_robust(toa: np.ndarray, receivers: np.ndarray, sigma_toa: float, max_pings: int = 300,
                                 scale: float = ROBUST_SCALE,
                                 bounds: tuple[float, float] = SOUND_SPEED_RANGE) -> tuple[float, float, int]:
    """The sound speed, the pings' positions and their emission times fitted jointly with a robust loss (a
    calibration step).

    Over at most ``max_pings`` pings (evenly spread) heard by at least dim + 3 receivers, every arrival kept, the
    sum ``Σ ρ((toa_ij − t_e,i − ‖p_i − r_j‖/c)² / (scale σ_toa)²)`` with the soft-L1 loss
    ``ρ(z) = 2 (√(1 + z) − 1)`` (the objective of scipy's ``least_squares(loss="soft_l1")``) is minimised over c
    and every ``(p_i, t_e,i)``. From the middle of ``bounds``, the pings started from their single-ping fixes
    there: each iteration solves the weighted normal equations (the soft-L1 weights) with the pings' blocks
    eliminated (a Schur complement onto c), and takes the joint step, halved until the cost falls once every
    ping's ``(p_i, t_e,i)`` has been fitted again at the new c (reweighted Gauss-Newton, each ping its own step
    halving), until c moves by less than :data:`JOINT_TOLERANCE`. The search follows one continuous solution
    from the start (a global scalar search over c jumps between the local solutions of pings with late
    arrivals). The standard error is that of the weighted normal equations at the solution, reduced onto c.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    sigma_toa : float
        Standard deviation of a time of arrival [s].
    max_pings : int
        Most pings used.
    scale : float
        The soft-L1 scale [σ_toa].
    bounds : (float, float)
        The speeds allowed [m/s]; a solution outside is refused.
    Returns
    -------
    c : float
        Sound speed [m/s].
    sigma_c : float
        Its standard error [m/s].
    pings : int
        Pings used.
    """
    receivers = np.asarray(receivers, float)
    dim = receivers.shape[1]
    rich = _calibration_pings(toa, dim, max_pings)
    c = 0.5 * (bounds[0] + bounds[1])
    p, te, _, _, _ = fix_pings(toa[rich], receivers, c, sigma_toa)
    ok = np.isfinite(p).all(axis=1) & np.isfinite(te)
    if ok.sum() < 3:
        raise ModelError("sound speed calibration: fewer than 3 pings could be fixed; give the sound speed")
    T, p, te = toa[rich][ok], p[ok], te[ok]
    heard = np.isfinite(T)
    y = np.where(heard, T, 0.0)
    f = scale * sigma_toa

    def residuals(c, p, te):
        diff = p[:, None, :] - receivers[None]
        d = np.linalg.norm(diff, axis=2)
        return np.where(heard, y - te[:, None] - d / c, 0.0), diff, d

    def cost(r):
        return float((2 * (np.sqrt(1 + (r / f) ** 2) - 1))[heard].sum())

    def ping_costs(r):
        return np.where(heard, 2 * (np.sqrt(1 + (r / f) ** 2) - 1), 0.0).sum(axis=1)

    def normal(c, p, te):
        """The weighted normal equations' blocks at (c, p, te): per ping A (k, dim+1, dim+1), b (k, dim+1), the
        gradient gp (k, dim+1); for c the scalars Jc·W·Jc and gc."""
        r, diff, d = residuals(c, p, te)
        w = np.where(heard, 1 / np.sqrt(1 + (r / f) ** 2), 0.0)  # the soft-L1 weights ρ'
        # the derivatives of the model (not of the residual) with respect to p_i, t_e,i and c
        Jp = np.concatenate([diff / (np.maximum(d, 1e-9)[..., None] * c), np.ones(d.shape + (1,))], axis=2)
        Jc = -d / c**2
        A = np.einsum("kn,kni,knj->kij", w, Jp, Jp) + 1e-18 * np.eye(dim + 1)
        return r, A, np.einsum("kn,kni,kn->ki", w, Jp, Jc), np.einsum("kn,kni,kn->ki", w, Jp, r), \
            float((w * Jc**2).sum()), float((w * Jc * r).sum())

    def pings_at(c, p, te):
        """Every ping's (p, t_e) fitted at the sound speed c (reweighted Gauss-Newton, each ping's own step
        halving)."""
        p, te = p.copy(), te.copy()
        for _ in range(FIX_ITERATIONS):
            r, A, _, gp, _, _ = normal(c, p, te)
            dq = np.linalg.solve(A, gp[..., None])[..., 0]
            scale = (np.abs(dq[:, :dim]).max(axis=1) >= 1e-4).astype(float)  # moving by a tenth of a mm or more
            if not scale.any():
                break
            before = ping_costs(r)
            for _halving in range(12):
                r_try = residuals(c, p + scale[:, None] * dq[:, :dim], te + scale * dq[:, dim])[0]
                worse = (ping_costs(r_try) > before) & (scale > 0)
                if not worse.any():
                    break
                scale[worse] *= 0.5
            scale[worse] = 0.0
            p, te = p + scale[:, None] * dq[:, :dim], te + scale * dq[:, dim]
        return p, te

    p, te = pings_at(c, p, te)
    current = cost(residuals(c, p, te)[0])
    for _iteration in range(JOINT_ITERATIONS):
        _, A, b, gp, cc, gc = normal(c, p, te)
        Ainv_b = np.linalg.solve(A, b[..., None])[..., 0]
        Ainv_g = np.linalg.solve(A, gp[..., None])[..., 0]
        dc = (gc - float(np.einsum("ki,ki->", b, Ainv_g))) / (cc - float(np.einsum("ki,ki->", b, Ainv_b)))
        dq = Ainv_g - Ainv_b * dc
        for halving in range(20):  # the joint step halved until the cost, the pings fitted again, falls
            step = 0.5**halving
            c_try = c + step * dc
            p_try, te_try = pings_at(c_try, p + step * dq[:, :dim], te + step * dq[:, dim])
            cost_try = cost(residuals(c_try, p_try, te_try)[0])
            if cost_try <= current:
                break
        else:
            break
        c, p, te, current = c_try, p_try, te_try, cost_try
        if abs(step * dc) < JOINT_TOLERANCE:
            break
    _, A, b, _, cc, _ = normal(c, p, te)
    S = cc - float(np.einsum("ki,ki->", b, np.linalg.solve(A, b[..., None])[..., 0]))
    if not bounds[0] <= c <= bounds[1]:
        raise ModelError(f"sound speed calibration: {c:.1f} m/s is outside [{bounds[0]:g}, {bounds[1]:g}] m/s; give "
                         "the sound speed")
    return float(c), float(sigma_toa / np.sqrt(S)) if S > 0 else float("inf"), int(len(T))


@dataclass
class TrackerSettings:
    """The tracker's model.

    Attributes
    ----------
    sound_speed : float
        [m/s].
    sigma_toa : float
        Standard deviation of a time of arrival [s].
    acceleration_psd : float
        Power spectral density of the white-noise acceleration, per axis [m²/s³].
    interval : float
        The nominal ping interval, the initial Δ [s].
    sigma_interval : float
        Initial standard deviation of Δ [s].
    jitter : float
        Standard deviation of the emission time's step beyond Δ, per ping [s].
    interval_drift : float
        Standard deviation of Δ's random-walk step, per ping [s].
    sigma_speed : float
        Initial standard deviation of each velocity component [m/s].
    gate : float
        χ²(1) threshold of one time of arrival's NIS.
    gate_probability : float
        Probability that the χ² test of a ping's set of times of arrival passes a consistent set.
    reinit_after : int
        Pings heard by dim + 2 or more receivers, every arrival refused, after which the filter starts again from a
        single-ping fix.
    fix_gate : float
        The squared Mahalanobis distance (against the prediction's and the fix's position covariances summed)
        beyond which an overdetermined single-ping fix (dim + 3 receivers or more) disagrees with the prediction
        (χ²(2) at 1 − 2·10⁻⁹ is 40).
    disagree_after : int
        Consecutive disagreeing pings after which the filter starts again from a single-ping fix (it is lost:
        a diverged filter with a grown covariance keeps accepting arrivals, so the refusals alone rarely restart
        it); only when :meth:`ToaTracker.run` is given the fixes.
    agree_after : int or None
        Consecutive single-ping fixes of dim + 2 receivers or more that kept every arrival of their ping, each
        outside the prediction's ``fix_gate`` and each agreeing with the previous one (below), after which the
        filter starts again from a fix; None: off. An array of few receivers rarely gives the dim + 3 of
        ``disagree_after``, and a fix of dim + 2 receivers has one redundant arrival only (a gross fix passes its
        own test more often), so a single one must not restart: the sequence is the confirmation, the M-of-N
        logic of track initiation (Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
        Navigation*, Wiley 2001, § 11.7; Blackman & Popoli, *Design and Analysis of Modern Tracking Systems*,
        1999, § 6.3). A fix that dropped an arrival (multipath) neither counts nor breaks the sequence.
    fix_speed : float
        [m/s]. Two consecutive fixes of the ``agree_after`` sequence agree when their squared Mahalanobis distance,
        against their position covariances summed plus ``(fix_speed · elapsed time)² / fix_gate`` per axis (so
        that a move of ``fix_speed`` over the elapsed time sits on the gate), is at most ``fix_gate``.
    """

    sound_speed: float
    sigma_toa: float = 2e-4
    acceleration_psd: float = 0.01
    interval: float = 2.0
    sigma_interval: float = 0.05
    jitter: float = 1e-3
    interval_drift: float = 1e-4
    sigma_speed: float = 1.0
    gate: float = GATE_ONE
    gate_probability: float = 0.999
    reinit_after: int = 3
    fix_gate: float = 40.0
    disagree_after: int = 5
    agree_after: int | None = None
    fix_speed: float = 2.0


@dataclass
class TrackRecord:
    """What :meth:`ToaTracker.run` records: per ping k (m pings), state size s = 2 dim + 2.

    Attributes
    ----------
    x_filtered, P_filtered : ndarray, (m, s), (m, s, s)
        The EKF's estimate after ping k (NaN before the filter starts).
    x_predicted, P_predicted : ndarray, (m, s), (m, s, s)
        The prediction of ping k from ping k − 1.
    F : ndarray, (m, s, s)
        The transition's Jacobian from ping k − 1 to k.
    used : ndarray of bool, (m, n)
        The times of arrival the update used.
    start : int
        The first ping with an estimate.
    restarts : list of int
        The pings where the filter started again from a single-ping fix.
    """

    x_filtered: np.ndarray
    P_filtered: np.ndarray
    x_predicted: np.ndarray
    P_predicted: np.ndarray
    F: np.ndarray
    used: np.ndarray
    start: int
    restarts: list[int] = field(default_factory=list)


class ToaTracker:
    """EKF and RTS smoother of a pinger's track from times of arrival, the emission times unknown.

    State ``x = [p (dim), v (dim), t_e, Δ]``; from ping k − 1 to ping k (one row of the TOA matrix each, heard or
    not), with ``T = Δ``:

        ``p ← p + T v``, ``v ← v``, ``t_e ← t_e + Δ``, ``Δ ← Δ``,

    process noise ``q [T³/3, T²/2; T²/2, T]`` per axis (white-noise acceleration), ``jitter²`` on ``t_e`` and
    ``interval_drift²`` on ``Δ``. The update of ping k uses :func:`toa_function` with the receivers that heard
    it, gated one by one (NIS against ``settings.gate``) and then as a set (the χ² quantile of
    ``settings.gate_probability``): a set that fails with dim + 3 arrivals or more is first cut to those the
    ping's own single-ping fix keeps, then the largest NIS is dropped until it passes.

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
    """

    def __init__(self, receivers: np.ndarray, settings: TrackerSettings) -> None:
        self.receivers = np.asarray(receivers, float)
        self.n, self.dim = self.receivers.shape
        self.settings = settings
        self.size = 2 * self.dim + 2
        self._f = toa_function(self.n, self.dim)
        from scipy.stats import chi2

        self._set_gate = chi2.ppf(settings.gate_probability, np.arange(1, self.n + 1))

    def transition(self, x: np.ndarray, step: int | None = None, schedule: PingSchedule | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The prediction of the next ping: state (s,), the Jacobian F (s, s), the process noise Q (s, s), over the
        step ``step`` of ``schedule`` (:class:`~sblsim.models.tracking.schedule.PingSchedule`; default one stable
        interval), its duration at the state's interval."""
        s = self.settings
        if schedule is None or step is None:
            count, offset, te, drift = 1.0, 0.0, s.jitter, s.interval_drift
        else:
            count, offset = schedule.count[step], schedule.offset[step]
            te, drift = schedule.te_sigma[step], schedule.drift_sigma[step]
        xp, F = predict(x[None], self.dim, np.array([count]), np.array([offset]))
        Q = process_noise(np.array([count * float(x[-1]) + offset]), s.acceleration_psd, np.array([te]),
                          np.array([drift]), self.dim)[0]
        return xp[0], F[0], Q

    def initial(self, fix: Fix) -> tuple[np.ndarray, np.ndarray]:
        """The state and covariance started from a single-ping fix (velocity 0, the nominal interval)."""
        d, s = self.dim, self.settings
        x = np.concatenate([fix.position, np.zeros(d), [fix.emission, s.interval]])
        P = np.zeros((self.size, self.size))
        idx = list(range(d)) + [2 * d]
        P[np.ix_(idx, idx)] = fix.covariance
        P[d:2 * d, d:2 * d] = s.sigma_speed**2 * np.eye(d)
        P[-1, -1] = s.sigma_interval**2
        return x, P

    def update(self, x: np.ndarray, P: np.ndarray, toa: np.ndarray, kept: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The EKF update with one ping's times of arrival (n,) (NaN: not heard), gated (:meth:`_gated`, ``kept``
        (n,) the arrivals the ping's single-ping fix keeps, if known); returns the state, the covariance (Joseph
        form) and the arrivals used (n,)."""
        d, s = self.dim, self.settings
        model, J = self._f(x[:d], x[-2], self.receivers.T, s.sound_speed)
        model, J = np.asarray(model).ravel(), np.asarray(J)
        H = np.zeros((self.n, self.size))
        H[:, :d] = J[:, :d]
        H[:, -2] = J[:, d]
        R = s.sigma_toa**2
        nu = toa - model

        def S(used):
            return H[used] @ P @ H[used].T + R * np.eye(int(used.sum()))

        used, Su = self._gated(toa, nu, np.einsum("ij,jk,ik->i", H, P, H) + R, S, kept)
        if Su is not None:
            Hu = H[used]
            K = np.linalg.solve(Su, Hu @ P).T
            x = x + K @ nu[used]
            A = np.eye(self.size) - K @ Hu
            P = A @ P @ A.T + R * K @ K.T
            P = 0.5 * (P + P.T)
        return x, P, used

    def _gated(self, toa: np.ndarray, nu: np.ndarray, variance: np.ndarray, S, kept: np.ndarray | None
               ) -> tuple[np.ndarray, np.ndarray | None]:
        """The arrivals (n,) a ping's update uses, and their innovations' covariance (None when none is used):
        each heard one whose NIS (innovation ``nu`` (n,) [s] over its ``variance`` (n,) [s²]) passes
        ``settings.gate``; then as a set (``S(used)`` the predicted covariance [s²] of the innovations of the
        arrivals ``used`` (n,) bool) against the χ² quantile of ``settings.gate_probability``: a set that fails is
        first cut to the arrivals the ping's single-ping fix keeps (:meth:`_fix_kept`), then its largest NIS is
        dropped until it passes."""
        used = np.isfinite(toa)
        used[used] = nu[used] ** 2 / variance[used] <= self.settings.gate
        screened = False
        while used.any():
            Su = S(used)
            if self._set_passes(used, nu, Su):
                return used, Su
            if not screened:
                screened, cut = True, self._fix_kept(toa, used, kept)
                if not np.array_equal(cut, used):
                    used = cut
                    continue
            used[np.flatnonzero(used)[int(np.argmax(nu[used] ** 2 / variance[used]))]] = False
        return used, None

    def _set_passes(self, used: np.ndarray, nu: np.ndarray, Su: np.ndarray) -> bool:
        """Whether the arrivals ``used`` (n,) pass the set's χ² test, ``Su`` their innovations' covariance [s²]."""
        return float(nu[used] @ np.linalg.solve(Su, nu[used])) <= self._set_gate[int(used.sum()) - 1]

    def _fix_kept(self, toa: np.ndarray, used: np.ndarray, kept: np.ndarray | None) -> np.ndarray:
        """The arrivals ``used`` (n,) of a ping cut, with redundancy to spare (dim + 3 or more), to those its own
        single-ping fix keeps (``kept`` (n,), computed here when None). After a poor prediction (the velocity
        unknown at the start, a turn) the prediction's residuals cannot tell a late multipath arrival from the good
        ones, and dropping the largest of them until the set passes can drop the good ones and keep the late; the
        fix's own residuals single it out."""
        if int(used.sum()) < self.dim + 3:
            return used
        if kept is None:
            fix = single_ping_fix(toa, self.receivers, self.settings.sound_speed, self.settings.sigma_toa)
            kept = None if fix is None else fix.used
        return used if kept is None else used & kept

    def run(self, toa: np.ndarray, fixes: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
            kept: np.ndarray | None = None, schedule: PingSchedule | None = None) -> TrackRecord:
        """The EKF over every ping (rows of ``toa``, (m, n) [s], NaN: not heard), started at the first ping with a
        single-ping fix of dim + 2 receivers or more, and started again from a fix after ``reinit_after``
        pings whose arrivals were all refused or, given ``fixes`` (the single-ping fixes of every ping: positions
        (m, dim) [m], NaN where none, covariances (m, ≥dim, ≥dim) [m²] and the receivers each used (m,), as
        :func:`fix_pings` returns them), after ``disagree_after`` consecutive overdetermined fixes outside the
        prediction's ``fix_gate``, or after ``agree_after`` consecutive mutually consistent fixes of dim + 2
        receivers or more outside it (:class:`TrackerSettings`). ``kept`` (m, n): the arrivals each ping's
        single-ping fix keeps (:func:`fix_pings`' ``used``), for the screening of a set that fails its test
        (computed ping by ping where needed when not given). ``schedule``: the steps between the rows
        (:class:`~sblsim.models.tracking.schedule.PingSchedule`, default one stable interval each); the first ping
        after each of its gaps starts a new segment (the filter started again from a fix there)."""
        m, size, s = len(toa), self.size, self.settings
        if schedule is None:
            schedule = PingSchedule.stable(m, s.interval, s.jitter, s.interval_drift)
        times, gaps = schedule.times(), set(schedule.gaps)
        rec = TrackRecord(np.full((m, size), np.nan), np.full((m, size, size), np.nan), np.full((m, size), np.nan),
                          np.full((m, size, size), np.nan), np.tile(np.eye(size), (m, 1, 1)),
                          np.zeros((m, self.n), bool), m)
        x = P = None
        refused = disagree = 0
        chain, agreeing = None, 0
        d = self.dim
        heard = np.isfinite(toa).sum(axis=1)
        for k in range(m):
            if x is not None:
                xp, F, Q = self.transition(x, k - 1, schedule)
                P = F @ P @ F.T + Q
                x = xp
                rec.x_predicted[k], rec.P_predicted[k], rec.F[k] = x, P, F
                segment = k - 1 in gaps  # a new segment: started again from a fix
                if not segment and fixes is not None and np.isfinite(fixes[0][k]).all() and fixes[2][k] >= d + 2:
                    # an overdetermined single-ping fix far outside the prediction's ellipse: the filter may be lost
                    e = fixes[0][k] - x[:d]
                    far = float(e @ np.linalg.solve(P[:d, :d] + fixes[1][k][:d, :d], e)) > s.fix_gate
                    if fixes[2][k] >= d + 3:
                        disagree = disagree + 1 if far else 0
                    if not far:
                        chain, agreeing = None, 0
                    elif s.agree_after is not None and fixes[2][k] == heard[k]:
                        # a fix that kept every arrival of its ping counts if it agrees with the previous such fix
                        # (the same target, moved at most fix_speed since): one gross fix does not restart, a
                        # consistent sequence does
                        if chain is not None:
                            gap = fixes[0][k] - fixes[0][chain]
                            allowed = fixes[1][k][:d, :d] + fixes[1][chain][:d, :d] + \
                                (s.fix_speed * (times[k] - times[chain])) ** 2 / s.fix_gate * np.eye(d)
                            agreeing = agreeing + 1 if float(gap @ np.linalg.solve(allowed, gap)) <= s.fix_gate else 1
                        else:
                            agreeing = 1
                        chain = k
                if segment:
                    refused = s.reinit_after
                else:
                    x, P, used = self.update(x, P, toa[k], None if kept is None else kept[k])
                    rec.used[k] = used
                    refused = refused + 1 if heard[k] >= self.dim + 2 and not used.any() else 0
                if disagree >= s.disagree_after or (s.agree_after is not None and agreeing >= s.agree_after):
                    refused = s.reinit_after
            if x is None or refused >= s.reinit_after:
                disagree, chain, agreeing = 0, None, 0
                fix = single_ping_fix(toa[k], self.receivers, s.sound_speed, s.sigma_toa) \
                    if heard[k] >= self.dim + 2 else None
                if fix is None:
                    if x is not None:  # no fix to start again from: the prediction kept (coasting, not positioned)
                        rec.x_filtered[k], rec.P_filtered[k] = x, P
                    continue
                if x is None:
                    rec.start = k
                    rec.x_predicted[k], rec.P_predicted[k] = self.initial(fix)
                else:
                    rec.restarts.append(k)
                x, P = self.initial(fix)
                if k > rec.start:  # the prediction of this ping stays the filter's; keep the interval
                    x[-1] = rec.x_predicted[k][-1]
                    P[-1, -1] = rec.P_predicted[k][-1, -1]
                rec.used[k] = fix.used
                refused = 0
            rec.x_filtered[k], rec.P_filtered[k] = x, P
        return rec

    def smooth(self, rec: TrackRecord) -> tuple[np.ndarray, np.ndarray]:
        """The RTS smoother over the filter's record from its first ping (:func:`rts_smooth`); NaN before it.
        Returns the smoothed states (m, s) and covariances (m, s, s)."""
        xs = np.full_like(rec.x_filtered, np.nan)
        Ps = np.full_like(rec.P_filtered, np.nan)
        k0 = rec.start
        if k0 < len(xs):
            xs[k0:], Ps[k0:] = rts_smooth(rec.x_filtered[k0:], rec.P_filtered[k0:], rec.x_predicted[k0:],
                                          rec.P_predicted[k0:], rec.F[k0:])
        return xs, Ps


class ToaSeqTracker(ToaTracker):
    """The sequential EKF of the same track (the ``ekf-seq`` receiver's update): :class:`ToaTracker`'s motion model,
    start and restarts, with one scalar update per time of arrival (sequential processing, Bar-Shalom, Li &
    Kirubarajan 2001, section 3.6), each gated alone by its NIS (``settings.gate``) against the state and
    covariance the arrivals before it left, the model linearised once at the prediction; the ping's arrivals are
    first screened as the EKF's are (by the ping's own single-ping fix where the set fails its test).

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
    """

    def update(self, x: np.ndarray, P: np.ndarray, toa: np.ndarray, kept: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The arrivals of one ping (n,) (NaN: not heard) one at a time, in the receivers' order (``kept`` as
        :meth:`ToaTracker.update`'s); returns the state, the covariance (Joseph form) and the arrivals used (n,)."""
        d, s = self.dim, self.settings
        R = s.sigma_toa**2
        model, J = self._f(x[:d], x[-2], self.receivers.T, s.sound_speed)
        model, J = np.asarray(model).ravel(), np.asarray(J)
        H = np.zeros((self.n, self.size))
        H[:, :d], H[:, -2] = J[:, :d], J[:, d]
        heard = np.isfinite(toa)
        if heard.any() and not self._set_passes(heard, toa - model,
                                                H[heard] @ P @ H[heard].T + R * np.eye(int(heard.sum()))):
            heard = self._fix_kept(toa, heard, kept)
        prediction, eye = x, np.eye(self.size)
        used = np.zeros(self.n, bool)
        for i in np.flatnonzero(heard):
            h = H[i]
            nu = toa[i] - (model[i] + h @ (x - prediction))
            S = h @ P @ h + R
            if nu**2 / S > s.gate:
                continue
            k = P @ h / S
            x = x + k * nu
            A = eye - np.outer(k, h)
            P = A @ P @ A.T + R * np.outer(k, k)
            P = 0.5 * (P + P.T)
            used[i] = True
        return x, P, used


#: The scaled sigma points of :class:`ToaUkfTracker`: spread α, prior weight β (2: Gaussian), secondary scaling κ
#: (the ``ukf`` receiver's defaults; λ = α²(n + κ) − n = 0: the points at ±√n standard deviations, the centre
#: weighted in the covariance only).
UKF_ALPHA, UKF_BETA, UKF_KAPPA = 1.0, 2.0, 0.0


@lru_cache(maxsize=None)
def _sigma_function(size: int, alpha: float, beta: float, kappa: float) -> ca.Function:
    """``(x (size,), P (size, size)) -> (points (size, 2 size + 1), wm, wc (2 size + 1,))``: the scaled sigma points
    of :class:`~sblsim.models.receiver.sigma_points.MerweScaledSigmaPoints` (the ``ukf`` receiver's) as a
    function."""
    x, P = ca.SX.sym("x", size), ca.SX.sym("P", size, size)
    points = MerweScaledSigmaPoints(size, alpha, beta, kappa)
    wm, wc = points.weights()
    return ca.Function("sblsim_toa_sigma_points", [x, P], [ca.horzcat(*points.points(x, P)), wm, wc])


class ToaUkfTracker(ToaTracker):
    """The unscented Kalman filter of the same track: :class:`ToaTracker`'s motion model, start, gates and restarts,
    with the unscented measurement update (the motion model is linear, so its prediction is the EKF's).

    The scaled sigma points of the predicted state (α, β, κ: :data:`UKF_ALPHA`, :data:`UKF_BETA`,
    :data:`UKF_KAPPA`; Wan & van der Merwe, "The unscented Kalman filter for nonlinear estimation", Proc. IEEE
    AS-SPCC 2000) go through :func:`toa_function`; their weighted mean, covariance and cross-covariance with the
    state take the place of the EKF's linearisation, in the same gates (each arrival's NIS, then the set's).

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
    alpha, beta, kappa : float
        The sigma points' parameters.
    """

    def __init__(self, receivers: np.ndarray, settings: TrackerSettings, alpha: float = UKF_ALPHA,
                 beta: float = UKF_BETA, kappa: float = UKF_KAPPA) -> None:
        super().__init__(receivers, settings)
        self._sigma = _sigma_function(self.size, float(alpha), float(beta), float(kappa))

    def update(self, x: np.ndarray, P: np.ndarray, toa: np.ndarray, kept: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The unscented update with one ping's times of arrival (n,) (NaN: not heard), gated as the EKF's
        (``kept`` as :meth:`ToaTracker.update`'s); returns the state, the covariance and the arrivals used (n,)."""
        d, s = self.dim, self.settings
        points, wm, wc = (np.asarray(v) for v in self._sigma(x, P))
        wm, wc = wm.ravel(), wc.ravel()
        Z = _evaluate_pings(self.receivers, s.sound_speed, points[:d].T, points[-2])[0]  # (2 size + 1, n)
        predicted = wm @ Z
        dZ, dX = Z - predicted, points.T - x
        Pzz = (wc[:, None] * dZ).T @ dZ
        Pxz = (wc[:, None] * dX).T @ dZ
        R = s.sigma_toa**2
        nu = toa - predicted

        def S(used):
            return Pzz[np.ix_(used, used)] + R * np.eye(int(used.sum()))

        used, Su = self._gated(toa, nu, np.diag(Pzz) + R, S, kept)
        if Su is not None:
            K = np.linalg.solve(Su, Pxz[:, used].T).T
            x = x + K @ nu[used]
            P = P - K @ Su @ K.T
            P = 0.5 * (P + P.T)
        return x, P, used


#: The causal filters of a pinger's track by their receivers' names (one model, start and restarts; their own
#: measurement update).
CAUSAL_TRACKERS = {"ekf": ToaTracker, "ekf-seq": ToaSeqTracker, "ukf": ToaUkfTracker}


def rts_smooth(x_filtered: np.ndarray, P_filtered: np.ndarray, x_predicted: np.ndarray, P_predicted: np.ndarray,
               F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The fixed-interval Rauch-Tung-Striebel smoother over a Kalman filter's (or EKF's) record.

    For k = m − 2 down to 0, with ``C_k = P_k|k F_{k+1}ᵀ P_{k+1|k}⁻¹``:
    ``x_k|m = x_k|k + C_k (x_{k+1}|m − x_{k+1|k})`` and ``P_k|m = P_k|k + C_k (P_{k+1}|m − P_{k+1|k}) C_kᵀ``.

    Parameters
    ----------
    x_filtered, P_filtered : ndarray, (m, s), (m, s, s)
        Filtered states and covariances.
    x_predicted, P_predicted : ndarray, (m, s), (m, s, s)
        Row k: the prediction of step k from step k − 1 (row 0 is not used).
    F : ndarray, (m, s, s)
        Row k: the transition (its Jacobian) from step k − 1 to k (row 0 is not used).

    Returns
    -------
    x_smoothed : ndarray, (m, s)
    P_smoothed : ndarray, (m, s, s)
    """
    xs = np.array(x_filtered, float)
    Ps = np.array(P_filtered, float)
    for k in range(len(xs) - 2, -1, -1):
        C = np.linalg.solve(P_predicted[k + 1], F[k + 1] @ P_filtered[k]).T
        xs[k] = x_filtered[k] + C @ (xs[k + 1] - x_predicted[k + 1])
        Ps[k] = P_filtered[k] + C @ (Ps[k + 1] - P_predicted[k + 1]) @ C.T
        Ps[k] = 0.5 * (Ps[k] + Ps[k].T)
    return xs, Ps


#: Degrees of freedom of the Student-t error of a time of arrival in the robust smoother (:func:`robust_smooth`): a
#: heavy tail (a late multipath arrival 10 σ off weighs 4 / 103 of a good one), the common robust choice (Lange,
#: Little, Taylor 1989).
ROBUST_DOF = 3.0
#: Gauss-Newton iterations of the robust smoother, at most (of the start it keeps, its screening steps among them).
ROBUST_ITERATIONS = 100
#: The weight from which the robust smoother counts an arrival as kept (not weighed down as an outlier): a
#: normalised residual within √(10 (ν + 1) − ν) ≈ 6.1 σ at ν = 3.
ROBUST_KEPT_WEIGHT = 0.1
#: The robust smoother stops when an iteration lowers its cost by less than this share.
ROBUST_TOLERANCE = 1e-9
#: Gauss-Newton iterations of each start before the robust smoother keeps the one of the lowest cost.
ROBUST_SCREEN = 20
#: The timing noise's scale of the robust smoother's graduated start (:func:`graduated_start`), in σ_toa.
ROBUST_COARSE_SCALE = 10.0
#: Gauss-Newton iterations of the graduated start's coarse solve.
ROBUST_COARSE_ITERATIONS = 20


@dataclass
class RobustTrack:
    """What :func:`robust_smooth` returns, over the pings it was given (m pings, state size s = 2 dim + 2).

    Attributes
    ----------
    x : ndarray, (m, s)
        The maximum a-posteriori states ``[p, v, t_e, Δ]`` [m, m/s, s, s].
    P : ndarray, (m, s, s), or None
        Their covariances (None when not asked for): the diagonal blocks of the inverse of the cost's Hessian at
        ``x`` (the Laplace approximation; each arrival's share its :func:`observed_information`, the model's
        second derivatives left out as in Gauss-Newton).
    weights : ndarray, (m, n)
        Each time of arrival's weight at the end, ``(ν + 1) / (ν + z²)`` (1 for an arrival as expected, near 0
        for an outlier; 0 where not heard).
    cost : float
        The cost at ``x`` (:func:`robust_smooth`) [1].
    iterations : int
        The Gauss-Newton iterations of the start kept.
    start : int
        Which of the starts given gave ``x`` (the lowest cost).
    start_names : tuple of str
        What each start was (:func:`robust_track`: ``fixes``, ``graduated``, ``rts``; empty when not named).
    P_lag : ndarray, (m − 1, s, s), or None
        The covariances of successive states, ``cov(x_k+1, x_k)`` (with ``P``; the lag-one blocks of the same
        inverse).
    """

    x: np.ndarray
    P: np.ndarray | None
    weights: np.ndarray
    cost: float
    iterations: int
    start: int
    start_names: tuple[str, ...] = ()
    P_lag: np.ndarray | None = None


def observed_information(z: np.ndarray, dof: float = ROBUST_DOF) -> np.ndarray:
    """Each time of arrival's share of the robust smoother's observed information, its Student-t log-likelihood's
    second derivative: ``(ν + 1) (ν − z²) / (ν + z²)²`` [1], and 0 where that is negative (``|z| > √ν``).

    The Gauss-Newton weight ``(ν + 1) / (ν + z²)`` is the same at ``z = 0`` and larger everywhere else: over
    Student-t errors it is 1 on average against the observed information's ``(ν + 1) / (ν + 3)`` (2/3 at ν = 3, the
    Fisher information of the t's location: Lange, Little, Taylor 1989), so a covariance from those weights is too
    small by a third (a NEES 1.5 times too large). Clipped at 0: an arrival that the track disagrees with by more
    than √ν σ adds no information (it would make the Hessian indefinite).

    Parameters
    ----------
    z : ndarray, (h,)
        The arrivals' normalised residuals [1].
    dof : float
        ν.

    Returns
    -------
    ndarray, (h,)
    """
    return np.maximum((dof + 1.0) * (dof - z**2) / (dof + z**2) ** 2, 0.0)


def _process(settings: TrackerSettings, dim: int, schedule: PingSchedule) -> np.ndarray:
    """The inverses of the Cholesky factors of the tracker's process noise Q_k over each step of ``schedule`` at the
    nominal interval (:func:`~sblsim.models.receiver.toa_bound.process_noise`): (m − 1, s, s)."""
    Q = process_noise(schedule.steps(settings.interval), settings.acceleration_psd, schedule.te_sigma,
                      schedule.drift_sigma, dim)
    return np.linalg.inv(np.linalg.cholesky(Q))


def _interval_prior(settings: TrackerSettings, X: np.ndarray) -> float:
    """The first ping's interval's normalised distance from the nominal one, ``(Δ_0 − Δ) / σ_Δ`` (the filters'
    start, :meth:`ToaTracker.initial`)."""
    return float((X[0, -1] - settings.interval) / settings.sigma_interval)


def _robust_terms(toa, heard, receivers, settings, X, Li, dof, schedule):
    """The robust smoother's residuals at the states X (m, s): the arrivals' normalised ones z (h,), the weights
    (h,), the TOA Jacobians (h, dim + 1) [1/σ units], the whitened process residuals e (m − 1, s) and the
    transitions' Jacobians F (m − 1, s, s); and the cost."""
    dim = receivers.shape[1]
    k, i = heard
    model, J = _evaluate_arrivals(receivers[i], settings.sound_speed, X[k, :dim], X[k, -2])
    z = (toa[k, i] - model) / settings.sigma_toa
    Jz = -J / settings.sigma_toa
    predicted, F = predict(X[:-1], dim, schedule.count, schedule.offset)
    e = np.einsum("kij,kj->ki", Li, X[1:] - predicted)
    cost = float((dof + 1.0) * np.log1p(z**2 / dof).sum() + (e**2).sum() + _interval_prior(settings, X) ** 2)
    return z, (dof + 1.0) / (dof + z**2), Jz, e, F, cost


def _per_ping(m: int, pings: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The sums of ``values`` (h, ...) per ping of the arrivals ``pings`` (h,), sorted (as :func:`numpy.nonzero`
    gives them): (m, ...), 0 for a ping none arrived from."""
    out = np.zeros((m,) + values.shape[1:])
    if len(pings):
        first = np.flatnonzero(np.r_[True, pings[1:] != pings[:-1]])
        out[pings[first]] = np.add.reduceat(values, first, axis=0)
    return out


def _normal_blocks(m, s, dim, heard, w, Jz, Li, prev, settings):
    """The Gauss-Newton Hessian of the robust cost, block tridiagonal: diagonal blocks (m, s, s) and the blocks
    (k, k + 1) (m − 1, s, s); ``Li`` (m − 1, s, s) the steps' whitening, ``prev`` (m − 1, s, s) the whitened process
    residuals' Jacobians with respect to the previous state, ``−L_k⁻¹ F_k``; the first interval's prior."""
    D = np.zeros((m, s, s))
    cols = list(range(dim)) + [s - 2]
    outer = w[:, None, None] * Jz[:, :, None] * Jz[:, None, :]
    D[np.ix_(np.arange(m), cols, cols)] += _per_ping(m, heard[0], outer)
    # e_k's Jacobian with respect to x_k is L_k⁻¹, with respect to x_k−1 is −L_k⁻¹ F_k
    D[1:] += np.einsum("kji,kjl->kil", Li, Li)
    D[:-1] += np.einsum("kji,kjl->kil", prev, prev)
    D[0, -1, -1] += 1.0 / settings.sigma_interval**2
    B = np.einsum("kji,kjl->kil", prev, Li)
    return D, B


def _banded_solve(D, B, g):
    """Solve ``N δ = g`` for the symmetric positive definite block-tridiagonal N (diagonal blocks D (m, s, s), upper
    blocks B (m − 1, s, s)) by LAPACK's banded Cholesky (:func:`scipy.linalg.solveh_banded`); δ (m, s)."""
    m, s = D.shape[:2]
    u = 2 * s - 1
    ab = np.zeros((u + 1, m * s))
    starts = np.arange(m) * s
    for a in range(s):
        for b in range(a, s):
            ab[u + a - b, starts + b] = D[:, a, b]
        for b in range(s):
            ab[u + a - s - b, starts[1:] + b] = B[:, a, b]
    return solveh_banded(ab, g.ravel()).reshape(m, s)


def _damped_solve(D, B, g):
    """:func:`_banded_solve` of the Gauss-Newton step, damped where the system is numerically indefinite (a track far
    from its arrivals, each weighed down to nothing): ``μ diag(N)`` added (Levenberg–Marquardt; Nocedal & Wright,
    *Numerical Optimization*, Springer 2006, § 10.3), μ from 10⁻¹² up by tenfold steps to 1 after an undamped try;
    None if none holds."""
    s = D.shape[1]
    diagonal = np.einsum("kii->ki", D)
    for mu in [None, *10.0 ** np.arange(-12, 1)]:  # first undamped (a 10⁻¹² ridge)
        damped = D + 1e-12 * np.eye(s) if mu is None else D + np.einsum("ki,ij->kij", mu * (diagonal + 1.0), np.eye(s))
        try:
            step = _banded_solve(damped, B, g)
        except np.linalg.LinAlgError:
            continue
        if np.isfinite(step).all():
            return step
    return None


def _inverse(a: np.ndarray) -> np.ndarray:
    """The inverse of a block, its pseudo-inverse where it is singular."""
    try:
        return np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(a)


def _block_covariance(D, B, lag=False):
    """The diagonal blocks (m, s, s) of N⁻¹ for the block-tridiagonal N of :func:`_banded_solve` (the block
    elimination and its backward pass: the Rauch-Tung-Striebel recursion in information form); with ``lag`` also
    its blocks (k + 1, k) (m − 1, s, s), ``−(S_k⁻¹ B_k N⁻¹_k+1,k+1)ᵀ``."""
    m = len(D)
    Sinv = np.empty_like(D)
    Sinv[0] = _inverse(D[0])
    for k in range(1, m):
        Sinv[k] = _inverse(D[k] - B[k - 1].T @ Sinv[k - 1] @ B[k - 1])
    cov = np.empty_like(D)
    cross = np.empty((max(m - 1, 0),) + D.shape[1:])
    cov[-1] = Sinv[-1]
    for k in range(m - 2, -1, -1):
        G = Sinv[k] @ B[k]
        cross[k] = -(G @ cov[k + 1]).T
        cov[k] = Sinv[k] + G @ cov[k + 1] @ G.T
    cov = 0.5 * (cov + cov.transpose(0, 2, 1))
    return (cov, cross) if lag else cov


def robust_smooth(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, starts: list[np.ndarray],
                  dof: float = ROBUST_DOF, iterations: int = ROBUST_ITERATIONS, covariance: bool = True,
                  schedule: PingSchedule | None = None) -> RobustTrack:
    """The robust fixed-interval smoother: the track's maximum a-posteriori states with heavy-tailed times of arrival.

    Over the whole record at once (YAPS's approach, Baktoft et al. 2017: the state-space model fitted to every
    time of arrival, here its MAP rather than its marginal likelihood), the states ``x_k = [p, v, t_e, Δ]`` of
    :class:`ToaTracker` minimise

        ``Σ_k ‖L_k⁻¹ (x_k − f_k(x_k−1))‖² + Σ_(k,i) heard (ν + 1) ln(1 + z_ki² / ν) + ((Δ_0 − Δ) / σ_Δ)²``,
        ``z_ki = (toa_ki − t_e,k − ‖p_k − r_i‖ / c) / σ_toa``,

    the tracker's motion model over each step of the ping schedule (``f_k``, ``Q_k = L_k L_kᵀ`` over the step's
    duration at the nominal interval Δ, :mod:`sblsim.models.tracking.schedule`: the ping type, gaps), the filters'
    prior of the first interval (σ_Δ ``sigma_interval``) and a Student-t error of ν degrees of
    freedom for each time of arrival (σ_toa its scale): a late multipath arrival is weighed down where the rest of
    the track disagrees with it, with no gate and no restart. Gauss-Newton with iteratively reweighted least
    squares (weights ``(ν + 1) / (ν + z²)``, the EM weights of the Student-t; Lange, Little, Taylor, "Robust
    statistical modeling using the t distribution", JASA 84(408), 1989), the step halved until the cost falls,
    each step solved as the banded system it is (the normal matrix is block tridiagonal over the pings: the
    iterated Kalman smoother as a Gauss-Newton method, Bell, SIAM J. Optim. 4(3), 1994), the covariance by the
    block recursion (the Rauch-Tung-Striebel backward pass in information form) from the arrivals' observed
    information (:func:`observed_information`), not their Gauss-Newton weights. The cost is not convex: each
    start given takes :data:`ROBUST_SCREEN` steps, and the one of the lowest cost then goes on to the end.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
        The motion model, ``sound_speed``, ``sigma_toa`` and the nominal ``interval``.
    starts : list of ndarray, each (m, 2 dim + 2)
        Starting tracks (finite), e.g. the RTS smoother's states.
    dof : float
        ν.
    iterations : int
        Gauss-Newton iterations at most (of the start kept, its screening steps among them).
    covariance : bool
        Compute the covariance ``P`` (else None: a start's states alone, :func:`graduated_start`).
    schedule : PingSchedule, optional
        The steps between the rows (:class:`~sblsim.models.tracking.schedule.PingSchedule`, m − 1 steps; default
        one stable interval each).

    Returns
    -------
    RobustTrack

    Raises
    ------
    ModelError
        If no start is given, a start is not finite or of the wrong shape.
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    m, (n, dim) = len(toa), receivers.shape
    s = 2 * dim + 2
    if not starts:
        raise ModelError("robust smoother: no starting track")
    heard = np.nonzero(np.isfinite(toa))
    if schedule is None:
        schedule = PingSchedule.stable(m, settings.interval, settings.jitter, settings.interval_drift)
    Li = _process(settings, dim, schedule)
    runs = []
    for start in starts:
        X = np.array(start, float)
        if X.shape != (m, s) or not np.isfinite(X).all():
            raise ModelError(f"robust smoother: a starting track of shape {X.shape} or not finite; allowed: "
                             f"({m}, {s}), finite")
        runs.append({"X": X, "terms": _robust_terms(toa, heard, receivers, settings, X, Li, dof, schedule),
                     "done": 0,
                     "converged": False})

    def iterate(run, count):
        """Up to ``count`` more Gauss-Newton steps of a start (stopping where it has converged)."""
        X, (z, w, Jz, e, F, cost) = run["X"], run["terms"]
        for _ in range(count):
            if run["converged"]:
                return
            prev = -np.einsum("kij,kjl->kil", Li, F)
            D, B = _normal_blocks(m, s, dim, heard, w, Jz, Li, prev, settings)
            g = np.zeros((m, s))  # the gradient's half: Jᵀ W r
            g[:, list(range(dim)) + [s - 2]] += _per_ping(m, heard[0], (w * z)[:, None] * Jz)
            g[1:] += np.einsum("ki,kij->kj", e, Li)
            g[0, -1] += _interval_prior(settings, X) / settings.sigma_interval
            g[:-1] += np.einsum("kji,kj->ki", prev, e)
            step = _damped_solve(D, B, -g)
            if step is None:  # no damping makes the system positive definite: stopped where it is
                run["converged"] = True
                return
            scale = 1.0
            while scale > 1e-6:
                trial = X + scale * step
                terms = _robust_terms(toa, heard, receivers, settings, trial, Li, dof, schedule)
                if terms[-1] < cost:
                    break
                scale *= 0.5
            else:  # no step lowers the cost: a minimum
                run["converged"] = True
                return
            gain = cost - terms[-1]
            X, (z, w, Jz, e, F, cost) = trial, terms
            run.update(X=X, terms=terms, done=run["done"] + 1, converged=gain <= ROBUST_TOLERANCE * cost)

    # each start a few steps, then the one of the lowest cost to the end (the ranking of the starts' costs is
    # settled within a few steps)
    for run in runs:
        iterate(run, min(ROBUST_SCREEN, iterations))
    index = int(np.argmin([run["terms"][-1] for run in runs]))
    best = runs[index]
    iterate(best, iterations - best["done"])
    X, (z, w, Jz, _, F, cost) = best["X"], best["terms"]
    P = lag = None
    if covariance:
        P, lag = _block_covariance(*_normal_blocks(m, s, dim, heard, observed_information(z, dof), Jz, Li,
                                                   -np.einsum("kij,kjl->kil", Li, F), settings), lag=True)
    weights = np.zeros((m, n))
    weights[heard] = w
    return RobustTrack(X, P, weights, cost, best["done"], index, P_lag=lag)


def graduated_start(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, start: np.ndarray,
                    schedule: PingSchedule | None = None) -> np.ndarray:
    """A start for :func:`robust_smooth` by graduated non-convexity (Blake & Zisserman, *Visual Reconstruction*,
    MIT Press 1987): the robust smoother with the timing noise's scale :data:`ROBUST_COARSE_SCALE` times larger
    (the arrivals' Student-t cost flatter over the residuals seen, the motion model weighing more: fewer local
    minima), :data:`ROBUST_COARSE_ITERATIONS` steps from ``start`` (m, 2 dim + 2); its states (m, 2 dim + 2).

    Raises
    ------
    ModelError
        As :func:`robust_smooth`.
    """
    coarse = replace(settings, sigma_toa=settings.sigma_toa * ROBUST_COARSE_SCALE)
    return robust_smooth(toa, receivers, coarse, [start], iterations=ROBUST_COARSE_ITERATIONS, covariance=False,
                         schedule=schedule).x


def robust_track(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings,
                 fixes: tuple[np.ndarray, np.ndarray, np.ndarray], rts: np.ndarray,
                 schedule: PingSchedule | None = None) -> RobustTrack:
    """The robust smoother of a record from its starts: the single-ping fixes' own track (:func:`anchored_start`),
    that track graduated (:func:`graduated_start`) and the RTS smoother's states ``rts`` (m, 2 dim + 2); the lowest
    cost kept (:func:`robust_smooth`). ``fixes``: positions (m, dim), emission times (m,) and the arrivals used
    (m, n) of :func:`fix_pings` for the same pings as ``toa`` (m, n); ``schedule`` the steps between them
    (:class:`~sblsim.models.tracking.schedule.PingSchedule`, default one stable interval each).

    Raises
    ------
    ModelError
        As :func:`robust_smooth`.
    """
    if schedule is None:
        schedule = PingSchedule.stable(len(toa), settings.interval, settings.jitter, settings.interval_drift)
    starts = {"rts": rts}
    anchored = anchored_start(fixes, np.isfinite(toa).sum(axis=1), settings, receivers.shape[1], schedule.times())
    if anchored is not None:
        starts = {"fixes": anchored, "graduated": graduated_start(toa, receivers, settings, anchored, schedule),
                  **starts}
    return replace(robust_smooth(toa, receivers, settings, list(starts.values()), schedule=schedule),
                   start_names=tuple(starts))


def anchored_start(fixes: tuple[np.ndarray, np.ndarray, np.ndarray], heard: np.ndarray, settings: TrackerSettings,
                   dim: int, times: np.ndarray | None = None) -> np.ndarray | None:
    """A starting track for :func:`robust_smooth` from the single-ping fixes alone: the fixes of dim + 2 receivers or
    more that kept every arrival of their ping (each within ``fix_speed`` × elapsed time + 5 m of the median of its
    six neighbours among them), interpolated linearly in time (the velocity their differences, the emission
    time advanced by the time elapsed since the nearest such fix before); None when fewer than 2 remain.

    Parameters
    ----------
    fixes : tuple
        Positions (m, dim) [m], emission times (m,) [s] and the arrivals used (m, n), as :func:`fix_pings` gives.
    heard : ndarray, (m,)
        The arrivals of each ping.
    settings : TrackerSettings
    dim : int
    times : ndarray, (m,), optional
        Each ping's time from the first [s] (:meth:`~sblsim.models.tracking.schedule.PingSchedule.times`; default
        the nominal interval per ping).
    """
    position, emission, used = fixes
    m = len(position)
    times = np.arange(m) * settings.interval if times is None else np.asarray(times, float)
    good = np.flatnonzero(np.isfinite(emission) & (used.sum(axis=1) >= dim + 2) & (used.sum(axis=1) == heard))
    keep = np.ones(len(good), bool)
    for j in range(len(good)):
        near = [i for i in range(max(0, j - 3), min(len(good), j + 4)) if i != j]
        if not near:
            continue
        elapsed = np.abs(times[good[near]] - times[good[j]]).max()
        keep[j] = np.linalg.norm(position[good[j]] - np.median(position[good[near]], axis=0)) <= \
            settings.fix_speed * elapsed + 5.0
    good = good[keep]
    if len(good) < 2:
        return None
    pings = np.arange(m)
    X = np.empty((m, 2 * dim + 2))
    for a in range(dim):
        X[:, a] = np.interp(times, times[good], position[good, a])
        X[:, dim + a] = np.gradient(X[:, a], times) if m > 1 else 0.0
    before = good[np.clip(np.searchsorted(good, pings, side="right") - 1, 0, len(good) - 1)]
    X[:, -2] = emission[before] + (times - times[before])
    X[:, -1] = settings.interval
    return X


def simulate_pings(receivers: np.ndarray, n_pings: int, settings: TrackerSettings, rng: np.random.Generator,
                   start: np.ndarray | None = None, speed: float = 1.0, detection: float = 0.8,
                   first_emission: float = 0.0, ping_type: str = "sbi",
                   burst_interval: tuple[float, float] | None = None, burst_sequence: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pings of a target moving as the tracker's model says, heard by an array.

    The target starts at ``start`` (default the array's centroid) at ``speed`` [m/s] in a random direction and
    moves by the discrete white-noise-acceleration model of ``settings.acceleration_psd`` over each step's
    duration; the ping types (:mod:`sblsim.models.tracking.schedule`): ``sbi``, ping k emitted at
    ``t_e,k = t_e,k−1 + Δ_k−1 + jitter`` and the interval walking by ``interval_drift``; ``rbi``, each step a draw
    of ``U(min, max)`` (``burst_interval``); ``pbi``, the steps of ``burst_sequence`` in turn (from its start) plus
    the jitter. Each receiver hears each ping with probability ``detection`` with Gaussian timing noise
    ``sigma_toa``.

    Returns
    -------
    toa : ndarray, (n_pings, n)
        Times of arrival [s], NaN where not heard.
    positions : ndarray, (n_pings, dim)
        The target's position at each emission [m].
    emissions : ndarray, (n_pings,)
        Emission times [s].
    """
    receivers = np.asarray(receivers, float)
    n, dim = receivers.shape
    s = settings
    p = receivers.mean(axis=0) if start is None else np.asarray(start, float)
    heading = rng.normal(size=dim)
    v = speed * heading / np.linalg.norm(heading)
    if ping_type == "rbi" and burst_interval is None:
        raise ModelError("simulate_pings: a random burst interval needs burst_interval (min, max) [s]")
    if ping_type == "pbi" and (burst_sequence is None or not len(burst_sequence)):
        raise ModelError("simulate_pings: a pseudo-random burst interval needs burst_sequence [s]")
    te, interval = first_emission, s.interval
    positions, emissions = np.empty((n_pings, dim)), np.empty(n_pings)
    for k in range(n_pings):
        positions[k], emissions[k] = p, te
        if ping_type == "rbi":
            T = rng.uniform(*burst_interval)
        elif ping_type == "pbi":
            T = float(burst_sequence[k % len(burst_sequence)]) + s.jitter * rng.normal()
        else:
            T = interval
        cov = s.acceleration_psd * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
        w = rng.multivariate_normal(np.zeros(2), cov, size=dim)  # (dim, 2): position and velocity noise per axis
        p, v = p + T * v + w[:, 0], v + w[:, 1]
        if ping_type == "sbi":
            te = te + interval + s.jitter * rng.normal()
            interval = interval + s.interval_drift * rng.normal()
        else:
            te = te + T
    ranges = np.linalg.norm(positions[:, None, :] - receivers[None, :, :], axis=2)
    toa = emissions[:, None] + ranges / s.sound_speed + s.sigma_toa * rng.normal(size=(n_pings, n))
    toa[rng.random((n_pings, n)) > detection] = np.nan
    return toa, positions, emissions


__all__ = ["CAUSAL_TRACKERS", "FIX_ITERATIONS", "GATE_ONE", "JOINT_ITERATIONS", "JOINT_TOLERANCE",
           "ROBUST_COARSE_ITERATIONS", "ROBUST_COARSE_SCALE", "ROBUST_DOF", "ROBUST_ITERATIONS", "ROBUST_KEPT_WEIGHT",
           "ROBUST_SCALE", "ROBUST_SCREEN", "ROBUST_TOLERANCE", "SOUND_SPEED_RANGE", "UKF_ALPHA", "UKF_BETA",
           "UKF_KAPPA", "Fix", "RobustTrack", "ToaSeqTracker", "ToaTracker", "ToaUkfTracker", "TrackRecord",
           "TrackerSettings", "anchored_start", "calibrate_sound_speed_robust", "fix_pings", "graduated_start",
           "observed_information", "robust_smooth", "robust_track", "rts_smooth", "simulate_pings", "single_ping_fix",
           "toa_function", "toa_model"]

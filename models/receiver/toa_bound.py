"""The accuracy limit of a fixed, synchronised array tracking a pinger whose emission times are unknown.

**One ping** (the single-ping fix's limit). With the times of arrival ``toa_i = t_e + ‖p − r_i‖ / c + w_i``,
``w_i ~ N(0, σ²)`` independent, of the receivers i that heard the ping, the Fisher information of
``θ = (p, t_e)`` is (Kay, Fundamentals of Statistical Signal Processing: Estimation Theory, Prentice Hall 1993,
Eq. (3.31), Gaussian noise)

    ``I(θ) = Σ_i h_i h_iᵀ / σ²``,   ``h_i = ∂toa_i/∂θ = [u_iᵀ / c, 1]``,   ``u_i = (p − r_i) / ‖p − r_i‖``,

and the information of the position with the emission time unknown is the Schur complement that removes
``t_e`` (Kay 1993, Section 3.7: the bound of a subset of parameters is the corresponding block of
``I⁻¹``; its inverse is the Schur complement)

    ``I_p = Σ_i u_i u_iᵀ / (σ c)² − (Σ_i u_i)(Σ_i u_i)ᵀ / (n σ² c²)``
    ``    = Σ_i (u_i − ū)(u_i − ū)ᵀ / (σ c)²``,  ``ū`` the mean of the heard receivers' ``u_i``,

so only the spread of the directions locates the target (a TDOA geometry). The predicted DRMS of an unbiased
fix is ``sqrt(trace I_p⁻¹)`` [m] (infinite when ``I_p`` is singular: fewer than dim + 1 receivers, or all on a
line through the target).

**The tracker** (:class:`~sblsim.models.tracking.ekf.ToaTracker`'s EKF). With the state
``x = [p, v, t_e, Δ]`` and the transition ``x_k+1 = f(x_k) + w_k``, ``w_k ~ N(0, Q_k)`` (nearly constant
velocity, ``t_e ← t_e + Δ`` with jitter, ``Δ`` a random walk), the posterior Cramér–Rao bound's information
``J_k`` obeys (Tichavský, Muravchik, Nehorai, "Posterior Cramér–Rao bounds for discrete-time nonlinear
filtering", IEEE Trans. Signal Processing 46(5):1386–1396, 1998, Eqs. (21) and (34)–(36), additive Gaussian
noises)

    ``J_k+1 = D22 − D21 (J_k + D11)⁻¹ D12``,
    ``D11 = F_kᵀ Q_k⁻¹ F_k``,  ``D12 = D21ᵀ = −F_kᵀ Q_k⁻¹``,  ``D22 = Q_k⁻¹ + H_k+1ᵀ H_k+1 / σ²``,

with ``F_k = ∂f/∂x`` and ``H_k+1`` (the heard receivers' rows of ``∂toa/∂x``) taken at the true state; the
expectations of the paper are replaced by their value along the one true track (the usual evaluation for a given
path, as :mod:`sblsim.models.bound` does). ``J_0`` is the tracker's own start: the first ping's information of
``(p, t_e)`` above, ``1/σ_v²`` on each velocity, ``1/σ_Δ²`` on the interval. The bound's position DRMS is
``sqrt(trace)`` of the position block of ``J_k⁻¹``.

**The smoother.** For the fixed-interval smoother, the smoothing bound along the same track is the
Rauch–Tung–Striebel backward pass over the bound's own covariances ``B_k = J_k⁻¹`` (Šimandl, Královec,
Tichavský, "Filtering, predictive, and smoothing Cramér–Rao bounds for discrete-time nonlinear dynamic
systems", Automatica 37(11):1703–1716, 2001, Section 5, additive Gaussian noises with the Jacobians at the truth):
``C_k = B_k F_kᵀ B_k+1|k⁻¹``, ``B_k|m = B_k + C_k (B_k+1|m − B_k+1|k) C_kᵀ``, ``B_k+1|k = F_k B_k F_kᵀ + Q_k``.

Not in the bounds: the truth's own error (a GPS), a lever arm between the truth and the tag, multipath (late)
arrivals, a wrong sound speed: they add to an observed error, never to these limits.

Units: seconds [s], metres [m], metres per second [m/s]. numpy only (no casadi: the derivatives are closed forms,
checked against finite differences in the tests).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def directions(positions: np.ndarray, receivers: np.ndarray) -> np.ndarray:
    """The unit vectors from the receivers to the target, ``u_i = (p − r_i) / ‖p − r_i‖``.

    Parameters
    ----------
    positions : ndarray, (m, dim)
        The target's positions at emission [m].
    receivers : ndarray, (n, dim)
        Receiver positions [m].

    Returns
    -------
    ndarray, (m, n, dim)
        Unit vectors [1].
    """
    d = np.asarray(positions, float)[:, None, :] - np.asarray(receivers, float)[None, :, :]
    return d / np.linalg.norm(d, axis=2, keepdims=True)


def ping_information(positions: np.ndarray, heard: np.ndarray, receivers: np.ndarray, c: float,
                     sigma_toa: float) -> np.ndarray:
    """The Fisher information of ``(p, t_e)`` from one ping's times of arrival, per ping.

    ``I = Σ_{i heard} h_i h_iᵀ / σ²`` with ``h_i = [u_iᵀ / c, 1]`` (module docstring; Kay 1993, Eq. (3.31)).

    Parameters
    ----------
    positions : ndarray, (m, dim)
        The target's positions at emission [m].
    heard : ndarray of bool, (m, n)
        Which receivers heard each ping.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    c : float
        Sound speed [m/s].
    sigma_toa : float or ndarray, (n,)
        Standard deviation of a time of arrival [s]: one, or each receiver's.

    Returns
    -------
    ndarray, (m, dim + 1, dim + 1)
        Information of ``(p [m], t_e [s])`` [1/m², 1/(m·s), 1/s²].
    """
    u = directions(positions, receivers)
    h = np.concatenate([u / c, np.ones(u.shape[:2] + (1,))], axis=2) * np.asarray(heard, float)[:, :, None]
    if np.ndim(sigma_toa) > 0:  # each receiver's own σ_i: h_i / σ_i
        h = h / np.asarray(sigma_toa, float)[None, :, None]
        return np.einsum("mki,mkj->mij", h, h)
    return np.einsum("mki,mkj->mij", h, h) / sigma_toa**2


def position_information(positions: np.ndarray, heard: np.ndarray, receivers: np.ndarray, c: float,
                         sigma_toa: float) -> np.ndarray:
    """The information of the position with the emission time unknown: the Schur complement of :func:`ping_information`
    that removes ``t_e``, ``I_pp − I_pt I_tt⁻¹ I_tp`` (zero for a ping nobody heard).

    Parameters
    ----------
    positions, heard, receivers, c, sigma_toa
        As :func:`ping_information`.

    Returns
    -------
    ndarray, (m, dim, dim)
        [1/m²].
    """
    info = ping_information(positions, heard, receivers, c, sigma_toa)
    tt = info[:, -1, -1]
    safe = np.where(tt > 0, tt, 1.0)
    cross = info[:, :-1, -1]
    return info[:, :-1, :-1] - np.einsum("mi,mj->mij", cross, cross) / safe[:, None, None]


def drms(information: np.ndarray) -> np.ndarray:
    """``sqrt(trace I⁻¹)`` of position informations (m, dim, dim) [1/m²]: the DRMS [m] (m,); ``inf`` where an
    information is singular (its condition number above 1e12)."""
    information = np.asarray(information, float)
    out = np.full(len(information), np.inf)
    ok = np.linalg.cond(information) < 1e12
    if ok.any():
        trace = np.trace(np.linalg.inv(information[ok]), axis1=1, axis2=2)
        out[ok] = np.where(trace > 0, np.sqrt(np.abs(trace)), np.inf)
    return out


def fix_drms(positions: np.ndarray, heard: np.ndarray, receivers: np.ndarray, c: float,
             sigma_toa: float) -> np.ndarray:
    """The predicted DRMS of a single-ping fix [m] (m,) at each ping's true position with the receivers that heard
    it, the emission time unknown (:func:`position_information`, :func:`drms`); ``inf`` where fewer than dim + 1
    receivers heard the ping or the geometry is degenerate."""
    heard = np.asarray(heard, bool)
    out = drms(position_information(positions, heard, receivers, c, sigma_toa))
    out[heard.sum(axis=1) < np.asarray(receivers).shape[1] + 1] = np.inf
    return out


@dataclass
class MotionModel:
    """The tracker's motion model (:class:`~sblsim.models.tracking.ekf.TrackerSettings`'s names).

    Attributes
    ----------
    acceleration_psd : float
        White-noise acceleration's power spectral density per axis [m²/s³].
    jitter : float
        Standard deviation of the emission time's step beyond the interval [s].
    interval_drift : float
        Standard deviation of the interval's random-walk step [s].
    sigma_speed : float
        Initial standard deviation of each velocity component [m/s].
    sigma_interval : float
        Initial standard deviation of the interval [s].
    """

    acceleration_psd: float
    jitter: float
    interval_drift: float
    sigma_speed: float
    sigma_interval: float

    @classmethod
    def of(cls, settings) -> MotionModel:
        """The motion model of a tracker's settings (any object with these attributes)."""
        return cls(settings.acceleration_psd, settings.jitter, settings.interval_drift, settings.sigma_speed,
                   settings.sigma_interval)


def predict(x: np.ndarray, dim: int, count: np.ndarray | None = None, offset: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """The tracker's motion model from one ping to the next, for states ``x`` (k, 2 dim + 2) = ``[p, v, t_e, Δ]``
    over steps of ``T = n Δ + o`` [s] (:mod:`sblsim.models.tracking.schedule`: ``n`` the intervals elapsed, ``o``
    a fixed duration): ``p + T v``, ``v``, ``t_e + T``, ``Δ`` (k, s), and its Jacobians F (k, s, s).

    Parameters
    ----------
    x : ndarray, (k, s)
        States [m, m/s, s, s].
    dim : int
        2 or 3.
    count : ndarray, (k,), optional
        ``n`` per step (default 1: one stable interval).
    offset : ndarray, (k,), optional
        ``o`` per step [s] (default 0).
    """
    n = np.ones(len(x)) if count is None else np.asarray(count, float)
    T = n * x[:, -1] + (0.0 if offset is None else np.asarray(offset, float))
    predicted = x.copy()
    predicted[:, :dim] += T[:, None] * x[:, dim:2 * dim]
    predicted[:, -2] += T
    F = np.tile(np.eye(x.shape[1]), (len(x), 1, 1))
    F[:, :dim, dim:2 * dim] = T[:, None, None] * np.eye(dim)
    F[:, :dim, -1] = n[:, None] * x[:, dim:2 * dim]
    F[:, -2, -1] = n
    return predicted, F


def process_noise(steps: np.ndarray, acceleration_psd: float, te_sigma: np.ndarray, drift_sigma: np.ndarray,
                  dim: int) -> np.ndarray:
    """The process noise Q (k, s, s) of steps of ``steps`` (k,) [s]: the white-noise acceleration's
    ``q [T³/3, T²/2; T²/2, T]`` per axis (Bar-Shalom, Li & Kirubarajan 2001, Eq. (6.2.3-8)), ``te_sigma²`` (k,) [s²]
    on the emission time and ``drift_sigma²`` (k,) [s²] on the interval."""
    T = np.asarray(steps, float)
    s = 2 * dim + 2
    Q = np.zeros((len(T), s, s))
    eye = np.eye(dim)
    Q[:, :dim, :dim] = (acceleration_psd * T**3 / 3)[:, None, None] * eye
    Q[:, :dim, dim:2 * dim] = Q[:, dim:2 * dim, :dim] = (acceleration_psd * T**2 / 2)[:, None, None] * eye
    Q[:, dim:2 * dim, dim:2 * dim] = (acceleration_psd * T)[:, None, None] * eye
    Q[:, -2, -2] = np.asarray(te_sigma, float) ** 2
    Q[:, -1, -1] = np.asarray(drift_sigma, float) ** 2
    return Q


def transition(velocity: np.ndarray, interval: float, motion: MotionModel, count: float = 1.0,
               te_sigma: float | None = None, drift_sigma: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The Jacobian F (s, s) and the process noise Q (s, s) of one step of the state ``[p, v, t_e, Δ]``
    (s = 2 dim + 2) at the true velocity (dim,) [m/s] over a step of ``interval`` [s] (the tracker's model,
    :func:`predict`): ``count`` stable intervals (``interval / count`` each; 0: a step of its own, the random and
    pseudo-random burst intervals), the emission time's step error ``te_sigma`` [s] (default the motion's jitter)
    and the interval's ``drift_sigma`` [s] (default its drift)."""
    F, Q = transitions(np.asarray(velocity, float)[None], np.array([interval], float), motion, np.array([count]),
                       None if te_sigma is None else np.array([te_sigma]),
                       None if drift_sigma is None else np.array([drift_sigma]))
    return F[0], Q[0]


def transitions(velocities: np.ndarray, intervals: np.ndarray, motion: MotionModel, count: np.ndarray | None = None,
                te_sigma: np.ndarray | None = None, drift_sigma: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`transition` of k steps at once: F (k, s, s) and Q (k, s, s) at the true velocities (k, dim) [m/s]
    over steps of ``intervals`` (k,) [s], ``count`` (k,) stable intervals each (default 1), ``te_sigma`` and
    ``drift_sigma`` (k,) [s] (default the motion's jitter and drift)."""
    velocities = np.asarray(velocities, float)
    k, d = velocities.shape
    T = np.asarray(intervals, float)
    n = np.ones(k) if count is None else np.asarray(count, float)
    stable = n != 0
    states = np.zeros((k, 2 * d + 2))
    states[:, d:2 * d] = velocities
    states[stable, -1] = T[stable] / n[stable]
    F = predict(states, d, n, np.where(stable, 0.0, T))[1]
    Q = process_noise(T, motion.acceleration_psd, np.full(k, motion.jitter) if te_sigma is None else te_sigma,
                      np.full(k, motion.interval_drift) if drift_sigma is None else drift_sigma, d)
    return F, Q


@dataclass
class TrackBound:
    """What :func:`pcrb` returns, per ping k (m pings), state size s = 2 dim + 2.

    Attributes
    ----------
    filtered : ndarray, (m,)
        The PCRB's position DRMS of a causal filter after ping k [m].
    smoothed : ndarray, (m,)
        The smoothing bound's position DRMS [m].
    B_filtered, B_smoothed : ndarray, (m, s, s)
        The bounds' covariances ``J_k⁻¹`` [m², m²/s, m·s, ...].
    """

    filtered: np.ndarray
    smoothed: np.ndarray
    B_filtered: np.ndarray
    B_smoothed: np.ndarray


def pcrb(positions: np.ndarray, velocities: np.ndarray, emissions: np.ndarray, heard: np.ndarray,
         receivers: np.ndarray, c: float, sigma_toa: float, motion: MotionModel, schedule=None) -> TrackBound:
    """The tracker's PCRB along a true track, and the smoothing bound (module docstring).

    Parameters
    ----------
    positions : ndarray, (m, dim)
        The true positions at each ping's emission [m].
    velocities : ndarray, (m, dim)
        The true velocities there [m/s] (they enter ``F``'s coupling of the interval into the position).
    emissions : ndarray, (m,)
        The true emission times [s]; their differences are the true intervals.
    heard : ndarray of bool, (m, n)
        The receivers that heard each ping (the first ping must be heard by dim + 1 or more: the start).
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    c : float
        Sound speed [m/s].
    sigma_toa : float or ndarray, (n,)
        Standard deviation of a time of arrival [s]: one, or each receiver's.
    motion : MotionModel
        The tracker's motion model.
    schedule : PingSchedule, optional
        The steps' ping type (:class:`~sblsim.models.tracking.schedule.PingSchedule`, m − 1 steps): each step's
        intervals elapsed and its emission-time and interval errors, the prior of the ping type's emission times
        (default: one stable interval per step, the motion's jitter and drift).

    Returns
    -------
    TrackBound
    """
    positions = np.asarray(positions, float)
    m, d = positions.shape
    s = 2 * d + 2
    idx = np.r_[0:d, 2 * d]  # (p, t_e) inside the state
    info = ping_information(positions, heard, receivers, c, sigma_toa)  # (m, d + 1, d + 1)
    Jz = np.zeros((m, s, s))
    Jz[np.ix_(np.arange(m), idx, idx)] = info
    J = Jz[0].copy()
    J[d:2 * d, d:2 * d] += np.eye(d) / motion.sigma_speed**2
    J[-1, -1] += 1.0 / motion.sigma_interval**2
    intervals = np.diff(np.asarray(emissions, float))
    B = np.empty((m, s, s))
    Bp = np.empty((m, s, s))  # row k: the prediction of k from k − 1
    B[0] = np.linalg.inv(J)
    Bp[0] = B[0]
    # every step's terms at once (they follow the true track, not the recursion); the recursion alone a step at a time:
    # F[k], Q[k] the step from ping k to k + 1
    F, Q = transitions(velocities[:m - 1], intervals, motion) if schedule is None else \
        transitions(velocities[:m - 1], intervals, motion, schedule.count[:m - 1], schedule.te_sigma[:m - 1],
                    schedule.drift_sigma[:m - 1])
    Qi = np.linalg.inv(Q)
    FT = np.swapaxes(F, 1, 2)
    D11 = FT @ Qi @ F
    D12 = -FT @ Qi
    D22 = Qi + Jz[1:]
    for k in range(m - 1):
        J = D22[k] - D12[k].T @ np.linalg.solve(J + D11[k], D12[k])
        J = 0.5 * (J + J.T)
        B[k + 1] = J  # the information, made the bound below
    B[1:] = np.linalg.inv(B[1:])
    Bp[1:] = F @ B[:-1] @ FT + Q
    gains = np.swapaxes(np.linalg.solve(Bp[1:], F @ B[:-1]), 1, 2)  # the smoother's C_k
    Bs = B.copy()
    for k in range(m - 2, -1, -1):
        C = gains[k]
        Bs[k] = B[k] + C @ (Bs[k + 1] - Bp[k + 1]) @ C.T
        Bs[k] = 0.5 * (Bs[k] + Bs[k].T)

    def position_drms(b: np.ndarray) -> np.ndarray:
        return np.sqrt(np.trace(b[:, :d, :d], axis1=1, axis2=2))

    return TrackBound(position_drms(B), position_drms(Bs), B, Bs)


def rms(values: np.ndarray) -> float:
    """The root mean square of values (NaN where there are none)."""
    values = np.asarray(values, float)
    return float(np.sqrt(np.mean(values**2))) if len(values) else float("nan")


__all__ = ["MotionModel", "TrackBound", "directions", "drms", "fix_drms", "ping_information", "pcrb",
           "position_information", "predict", "process_noise", "rms", "transition", "transitions"]

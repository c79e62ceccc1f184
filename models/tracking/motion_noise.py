"""How much the tag's velocity wanders: the motion model's acceleration noise estimated from the data by EM.

The tracker's motion model is the white-noise acceleration (nearly constant velocity) model: over a step of ``T``
seconds each axis's position and velocity take a Gaussian error of covariance ``q [T³/3, T²/2; T²/2, T]`` (Bar-Shalom,
Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*, Wiley 2001, § 6.2), ``q`` the
acceleration's power spectral density [m²/s³]. A towed pinger, a cod and a swimming eel differ in ``q`` by orders of
magnitude, and ``q`` decides how far the smoother trusts the motion between pings: at a 2 s stable interval the
arrivals outweigh it whatever it is, at a 20–40 s random interval it is what tells a ping's multipath fix from its
neighbours. YAPS estimates its movement model's variance by maximum likelihood (Baktoft et al. 2017); here ``q`` is
the maximum-likelihood estimate of the state-space model by expectation-maximisation (Shumway & Stoffer, "An
approach to time series smoothing and forecasting using the EM algorithm", J. Time Series Analysis 3(4), 1982;
Ghahramani & Hinton, "Parameter estimation for linear dynamical systems", 1996): each E-step is the robust smoother
at the current ``q`` (its states, covariances and lag-one covariances: the Laplace approximation of the posterior),
each M-step the closed form

    ``q ← (1 / (2 dim (m − 1))) Σ_k Σ_axes tr(A_k⁻¹ E[w_k w_kᵀ])``,
    ``E[w_k w_kᵀ] = ŵ_k ŵ_kᵀ + P_k + F_k P_k−1 F_kᵀ − C_k F_kᵀ − F_k C_kᵀ``,

``w_k = x_k − f(x_k−1)`` the process error of step k on one axis's (position, velocity), ``A_k`` its unit-``q``
covariance, ``P`` the smoothed covariances and ``C_k = cov(x_k, x_k−1)``. EM's steps are short where the data
determine ``q`` well; each is lengthened in ``log q`` by :data:`EM_OVERRELAXATION` (an over-relaxed EM; Salakhutdinov
& Roweis, "Adaptive overrelaxed bound optimization methods", ICML 2003), and a step that overshoots (the M-step turns
back) is taken at EM's own length.

A record of more than :data:`EM_PINGS` pings (a high-residency tag's season: a ping every 2.5 s is 35,000 a day)
takes its E-steps over :data:`EM_WINDOWS` windows of the record, spread evenly over it and :data:`EM_PINGS` pings
together, each smoothed alone, and its M-step the closed form over their steps pooled (``q`` is one number for the
record: the same expectation over any of its steps): EM's cost is then that of :data:`EM_PINGS` pings whatever the
record's length, where each iteration over the whole record cost as much as the smoother's track itself.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sblsim.models.receiver.toa_bound import predict

#: The range of ``q`` searched [m²/s³].
PSD_RANGE = (1e-6, 1.0)
#: EM's iterations at most, and the change of ``log q`` it stops below.
EM_ITERATIONS = 15
EM_TOLERANCE = 0.02
#: The over-relaxation of EM's steps in ``log q``.
EM_OVERRELAXATION = 2.0
#: The robust smoother's Gauss-Newton iterations in each E-step (warm-started at the previous states).
E_STEP_ITERATIONS = 10
#: The most pings EM smooths in each E-step, and the windows a longer record's E-steps take (module docstring).
EM_PINGS = 20_000
EM_WINDOWS = 4


@dataclass(frozen=True)
class NoiseEstimate:
    """What :func:`estimate_acceleration_psd` returns: ``q`` [m²/s³], the EM ``iterations``, whether it
    ``converged``, the ``history`` of ``q``, the last smoother's track (``track``, a
    :class:`~sblsim.models.tracking.smoother.RobustTrack` at ``q``: the last window's where the record was taken in
    windows) and the ``windows`` smoothed (rows first to end − 1: :func:`em_windows`)."""

    q: float
    iterations: int
    converged: bool
    history: tuple[float, ...]
    track: object
    windows: tuple[tuple[int, int], ...] = ()


def m_step(x: np.ndarray, P: np.ndarray, lag: np.ndarray, steps: np.ndarray, count: np.ndarray,
           offset: np.ndarray, dim: int) -> float:
    """EM's closed-form ``q`` from smoothed states (module docstring).

    Parameters
    ----------
    x : ndarray, (m, s)
        The smoothed states ``[p, v, t_e, Δ]``.
    P : ndarray, (m, s, s)
        Their covariances.
    lag : ndarray, (m − 1, s, s)
        ``cov(x_k+1, x_k)``.
    steps : ndarray, (m − 1,)
        The steps' durations [s] (the unit-``q`` covariances' ``T``).
    count, offset : ndarray, (m − 1,)
        The steps' intervals elapsed and fixed durations (:func:`~sblsim.models.receiver.toa_bound.predict`).
    dim : int

    Returns
    -------
    float
        [m²/s³].
    """
    predicted, F = predict(x[:-1], dim, count, offset)
    w = x[1:] - predicted
    T = np.asarray(steps, float)
    A = np.stack([np.stack([T**3 / 3, T**2 / 2], -1), np.stack([T**2 / 2, T], -1)], -2)
    Ai = np.linalg.inv(A)
    total = np.zeros(len(T))
    for a in range(dim):  # E's (position, velocity) block of the axis alone: each entry's products and sums those
        # of the whole (s, s) E's entry, in about half its time; laid out as that block's gather lays it out (Fortran
        # order), which decides the order of the trace's sum: the same numbers to the last bit
        axis = [a, dim + a]
        Fa, wa, lag_a = F[:, axis], w[:, axis], lag[:, axis]
        E = (np.einsum("ki,kj->kij", wa, wa) + P[1:, axis][:, :, axis] + np.einsum("kij,kjl,kml->kim", Fa, P[:-1], Fa)
             - np.einsum("kij,klj->kil", lag_a, Fa) - np.einsum("kij,klj->kil", Fa, lag_a))
        total += np.einsum("kij,kji->k", Ai, np.asfortranarray(E))
    return float(total.mean() / (2 * dim))


def em_windows(m: int) -> list[tuple[int, int]]:
    """The rows each E-step smooths, (first, end) pairs: the whole record where it has at most :data:`EM_PINGS`
    pings, else :data:`EM_WINDOWS` windows of ``EM_PINGS // EM_WINDOWS`` pings each, centred in as many equal parts
    of the record (module docstring)."""
    if m <= EM_PINGS:
        return [(0, m)]
    size = EM_PINGS // EM_WINDOWS
    firsts = ((np.arange(EM_WINDOWS) + 0.5) * m / EM_WINDOWS - size / 2).astype(int)
    return [(int(a), int(a) + size) for a in firsts]


def estimate_acceleration_psd(toa: np.ndarray, receivers: np.ndarray, settings, start: np.ndarray,
                              schedule) -> NoiseEstimate:
    """The motion model's ``q`` by over-relaxed EM (module docstring), from the robust smoother started at
    ``start``; a record of more than :data:`EM_PINGS` pings in the windows of :func:`em_windows`.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        [m].
    settings : TrackerSettings
        The tracker's model; its ``acceleration_psd`` the first ``q``.
    start : ndarray, (m, 2 dim + 2)
        The first E-step's start (e.g. the single-ping fixes' track).
    schedule : PingSchedule
        The steps between the rows.

    Returns
    -------
    NoiseEstimate
    """
    from sblsim.models.tracking.smoother import robust_smooth

    dim = receivers.shape[1]
    windows = em_windows(len(toa))
    parts = [(toa[a:b], schedule.rows(a, b)) for a, b in windows]
    q = float(np.clip(settings.acceleration_psd, *PSD_RANGE))
    starts = [np.asarray(start, float)[a:b] for a, b in windows]
    history = [q]
    previous = None
    track = None
    converged = False
    for iteration in range(1, EM_ITERATIONS + 1):
        totals = []  # each window's M-step and its steps' count
        for k, (rows, part) in enumerate(parts):
            track = robust_smooth(rows, receivers, replace(settings, acceleration_psd=q), [starts[k]], schedule=part,
                                  iterations=E_STEP_ITERATIONS if iteration > 1 else 3 * E_STEP_ITERATIONS)
            starts[k] = track.x
            totals.append((m_step(track.x, track.P, track.P_lag, part.steps(settings.interval), part.count,
                                  part.offset, dim), len(rows) - 1))
        # the whole record's own M-step where it is one window (v n / n need not be v to the bit)
        pooled = totals[0][0] if len(totals) == 1 else sum(v * n for v, n in totals) / sum(n for _, n in totals)
        target = float(np.clip(pooled, *PSD_RANGE))
        change = np.log(target / q)
        if abs(change) < EM_TOLERANCE:
            converged = True
            q = target
            history.append(q)
            break
        # over-relaxed, unless the last step overshot (EM turned back)
        relax = EM_OVERRELAXATION if previous is None or np.sign(previous) == np.sign(change) else 1.0
        q = float(np.clip(q * np.exp(relax * change), *PSD_RANGE))
        previous = change
        history.append(q)
    return NoiseEstimate(q, iteration, converged, tuple(history), track, tuple(windows))


__all__ = ["EM_ITERATIONS", "EM_OVERRELAXATION", "EM_PINGS", "EM_TOLERANCE", "EM_WINDOWS", "E_STEP_ITERATIONS",
           "NoiseEstimate", "PSD_RANGE", "em_windows", "estimate_acceleration_psd", "m_step"]

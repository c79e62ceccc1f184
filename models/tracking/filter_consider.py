"""The consider covariance of the causal filters' and the RTS smoother's tracks: the share of the receivers' survey
error and of the sound speed's error in their estimates, which they do not estimate.

A filter solved with the receivers as surveyed and the speed as given leaves an error that follows those
parameters θ (whitened: each scaled by its standard error, so that their covariance is the identity). Its estimate's
sensitivity to them follows the filter's own recursion (the consider analysis of a Kalman filter: Tapley, Schutz &
Born, *Statistical Orbit Determination*, Elsevier 2004, § 6.3; Bierman, *Factorization Methods for Discrete
Sequential Estimation*, Academic Press 1977, ch. VIII):

    ``S_k = (I − K_k H_k) F_k S_{k−1} − K_k H_θ,k``,

``H_k`` and ``H_θ,k`` the Jacobians of the arrivals the update used by the state and by θ at the prediction, ``K_k``
their gain; at a start or restart from a single-ping fix, the fix's own, ``−C Jᵀ H_θ / σ_toa²`` (C its covariance,
J its arrivals' rows). The RTS smoother's follows its gain ``C_k = P_k|k F_{k+1}ᵀ P_{k+1|k}⁻¹``:
``S^s_k = S_k + C_k (S^s_{k+1} − F_{k+1} S_k)``. The term added to a covariance is ``S Sᵀ``; the estimates and
gains are the filters' own (their gates take the errors' spread where their settings hold it:
:class:`~sblsim.models.tracking.ekf.TrackerSettings` ``survey_sigma``, ``sound_speed_sigma``). Of a time of arrival
``m_i = t_e + ‖p − r_i‖ / c``: ``∂m_i/∂c = −(m_i − t_e) / c`` and ``∂m_i/∂r_i = −∂m_i/∂p``.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from sblsim.models.tracking.ekf import TrackRecord, rts_gains
from sblsim.models.tracking.toa import _evaluate_pings, per_receiver

#: The pings whose arrivals' Jacobians (by θ: (pings, n, n dim + 1)) and consider terms are made at once (the
#: Jacobians of a record's 52,000 pings of 22 receivers in 3-D made whole took 0.6 GiB).
BLOCK = 2048


def _jacobians(receivers: np.ndarray, c: float, states: np.ndarray, survey: np.ndarray, sigma_c: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """The arrivals' Jacobians at states (m, s) (NaN rows: zero): by the position and emission time (m, n, dim + 1),
    and by the whitened parameters (m, n, p + 1: the receivers' errors' p, then the speed), for the receivers'
    survey errors (n,) [m] (p = n dim: each receiver's axes) or their square root (n dim, p) [m]
    (:mod:`~sblsim.models.tracking.survey_root`) and the speed's [m/s]."""
    n, dim = receivers.shape
    finite = np.isfinite(states).all(axis=1)
    model, J = _evaluate_pings(receivers, c, np.where(finite[:, None], states[:, :dim], 0.0),
                               np.where(finite, states[:, -2], 0.0))
    Ht = np.zeros((len(states), n, _columns(survey, n, dim) + 1))
    for i in range(n):
        if survey.ndim == 2:  # correlated: receiver i's axes' rows of the root
            Ht[:, i, :-1] = -J[:, i, :dim] @ survey[i * dim:(i + 1) * dim]
        else:
            Ht[:, i, i * dim:(i + 1) * dim] = -J[:, i, :dim] * survey[i]
    Ht[:, :, -1] = -(model - np.where(finite, states[:, -2], 0.0)[:, None]) / c * sigma_c
    return J, Ht


def filter_sensitivity(record: TrackRecord, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray,
                       survey_sigma: np.ndarray | None = None, sigma_c: float | None = None) -> np.ndarray:
    """The sensitivity of a causal filter's states to the whitened survey and speed errors, along its record.

    Parameters
    ----------
    record : TrackRecord
        A filter's record (:meth:`~sblsim.models.tracking.ekf.ToaTracker.run`; the EKF's, the sequential EKF's or
        the UKF's, whose update is linearised as the EKF's here).
    receivers : ndarray, (n, dim)
        [m].
    c : float
        The speed the filter ran at [m/s].
    sigma_toa : float or ndarray, (n,)
        A time of arrival's standard deviation [s], one or each receiver's (as the filter ran with).
    survey_sigma : ndarray, (n,) or (n dim, p), or None
        Each receiver's survey error per axis [m], or the square root of the receivers' errors' covariance [m]
        (:func:`~sblsim.models.tracking.survey_root.survey_root`: correlated errors).
    sigma_c : float or None
        The speed's standard error [m/s].

    Returns
    -------
    ndarray, (m, s, n dim + 1) or (m, s, p + 1)
        ``S_k`` (module docstring) [m, m/s, s, s per unit of θ]; NaN before the filter's start.
    """
    receivers = np.asarray(receivers, float)
    m, size = record.x_filtered.shape
    out = np.full((m, size, _columns(survey_sigma, *receivers.shape) + 1), np.nan)
    for k, S in _recursion(record, receivers, c, sigma_toa, survey_sigma, sigma_c, 0, m, None):
        out[k] = S
    return out


def _columns(survey: np.ndarray | None, n: int, dim: int) -> int:
    """The receivers' whitened errors' count: n dim for a σ per receiver (or none), p for a root (n dim, p)."""
    return n * dim if survey is None or np.ndim(survey) < 2 else int(np.shape(survey)[1])


def _recursion(record: TrackRecord, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray,
               survey_sigma: np.ndarray | None, sigma_c: float | None, lo: int, hi: int, S: np.ndarray | None
               ) -> Iterator[tuple[int, np.ndarray]]:
    """``(k, S_k)`` for the pings ``k`` from ``lo`` (or the filter's start, the later) to ``hi`` (excluded), from ``S``
    the sensitivity at ``lo − 1`` (None before the start): the recursion of :func:`filter_sensitivity`, begun at any
    ping with the same numbers (each ping's Jacobians made in its own block of :data:`BLOCK`, as from the first)."""
    n, dim = receivers.shape
    survey = np.zeros(n) if survey_sigma is None else np.asarray(survey_sigma, float)
    sc = float(sigma_c or 0.0)
    q = _columns(survey, n, dim) + 1
    m, size = record.x_filtered.shape
    starts = {record.start, *record.restarts}
    R = np.asarray(sigma_toa, float) ** 2 if per_receiver(sigma_toa) else sigma_toa**2
    idx = list(range(dim)) + [2 * dim]
    block = -1
    for k in range(max(lo, record.start), hi):
        if k // BLOCK != block:  # the arrivals' Jacobians a block of pings at a time (each ping's its own)
            block = k // BLOCK
            a, b = block * BLOCK, min((block + 1) * BLOCK, m)
            at = np.array(record.x_predicted[a:b], float)  # an update linearised at the prediction, a start at its fix
            for j in starts:
                if a <= j < b:
                    at[j - a] = record.x_filtered[j]
            J_all, Ht_all = _jacobians(receivers, c, at, survey, sc)
        used = record.used[k]
        J, Ht = J_all[k % BLOCK][used], Ht_all[k % BLOCK][used]
        if k in starts:  # the fix the filter started from: its position, emission time, covariance and arrivals
            if per_receiver(R):
                G = -record.P_filtered[k][np.ix_(idx, idx)] @ J.T @ (Ht / R[used][:, None])  # the fix's (dim + 1, θ)
            else:
                G = -record.P_filtered[k][np.ix_(idx, idx)] @ J.T @ Ht / R
            interval = np.zeros(q) if S is None else (record.F[k] @ S)[-1]
            S = np.zeros((size, q))
            S[:dim], S[-2], S[-1] = G[:dim], G[dim], interval
        elif S is not None:
            S = record.F[k] @ S
            if used.any():
                Pp = record.P_predicted[k]
                H = np.zeros((len(J), size))
                H[:, :dim], H[:, -2] = J[:, :dim], J[:, dim]
                noise = np.diag(R[used]) if per_receiver(R) else R * np.eye(len(J))
                K = np.linalg.solve(H @ Pp @ H.T + noise, H @ Pp).T
                S = S - K @ (H @ S + Ht)
        if S is not None:
            yield k, S


def smoothed_sensitivity(record: TrackRecord, sensitivity: np.ndarray, overwrite: bool = False) -> np.ndarray:
    """The RTS smoother's sensitivity (module docstring) from its filter's record and the filter's
    :func:`filter_sensitivity` (m, s, p); NaN before the start. ``overwrite``: made in ``sensitivity`` itself (a
    float array; the recursion reads a ping's filter value before it writes its smoothed one), not in a copy."""
    out = sensitivity if overwrite else np.array(sensitivity, float)
    k0 = record.start
    gains = rts_gains(record.P_filtered[k0:], record.P_predicted[k0:], record.F[k0:])
    for k in range(len(out) - 2, k0 - 1, -1):
        out[k] = sensitivity[k] + gains[k - k0] @ (out[k + 1] - record.F[k + 1] @ sensitivity[k])
    return out


def consider_terms(sensitivity: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
    """``S Sᵀ`` per ping (m, s, s) of a sensitivity (m, s, p) [the states' units²]; of its pings ``rows`` (r,) int
    alone (r, s, s) where given, :data:`BLOCK` pings at a time (no copy of those rows' sensitivity made whole)."""
    rows = np.arange(len(sensitivity)) if rows is None else np.asarray(rows)
    s = sensitivity.shape[1]
    out = np.empty((len(rows), s, s))
    for lo in range(0, len(rows), BLOCK):
        block = sensitivity[rows[lo:lo + BLOCK]]
        out[lo:lo + BLOCK] = np.einsum("kap,kbp->kab", block, block)
    return out


def consider_terms_along(record: TrackRecord, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray,
                         rows: np.ndarray, survey_sigma: np.ndarray | None = None, sigma_c: float | None = None,
                         smoothed: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """The consider terms ``S Sᵀ`` of a causal filter's pings ``rows`` and, ``smoothed``, of its RTS smoother's,
    made without the record's whole sensitivity.

    The filter's pass keeps ``S`` at each block's edge alone (every :data:`BLOCK` pings); the smoother's pass, back
    from the last block, makes each block's filter sensitivity again from its edge and smooths it in place (the
    module docstring's recursions). Held at once: a block's sensitivity (:data:`BLOCK`, s, p) and the edges, where
    :func:`filter_sensitivity` holds (m, s, p): 0.1 GiB for a season's tag of 46,523 pings heard by 22 receivers in
    2-D. The same numbers to the bit as :func:`consider_terms` of :func:`filter_sensitivity` and of
    :func:`smoothed_sensitivity`, at the cost of the filter's recursion made twice where ``smoothed``.

    Parameters
    ----------
    record, receivers, c, sigma_toa, survey_sigma, sigma_c
        As :func:`filter_sensitivity`'s.
    rows : ndarray, (r,) int
        The pings whose terms are made, in increasing order.
    smoothed : bool
        Also the RTS smoother's terms (its gains :func:`~sblsim.models.tracking.ekf.rts_gains` of the same record).

    Returns
    -------
    filtered : ndarray, (r, s, s)
        The filter's terms [the states' units²]; NaN before its start.
    smoothed : ndarray, (r, s, s), or None
        The smoother's terms, None unless ``smoothed``.
    """
    receivers = np.asarray(receivers, float)
    rows = np.asarray(rows, int)
    m, size = record.x_filtered.shape
    p = _columns(survey_sigma, *receivers.shape) + 1
    args = (record, receivers, c, sigma_toa, survey_sigma, sigma_c)

    def block(a: int, b: int) -> np.ndarray:  # the filter's sensitivity of pings a to b (NaN before the start)
        sens = np.full((b - a, size, p), np.nan)
        for k, S in _recursion(*args, a, b, edges[a]):
            sens[k - a] = S
        return sens

    def terms(out: np.ndarray, sens: np.ndarray, a: int, b: int) -> None:  # the terms of the rows among a to b
        lo, hi = np.searchsorted(rows, [a, b])
        out[lo:hi] = consider_terms(sens, rows[lo:hi] - a)

    filtered = np.empty((len(rows), size, size))
    back = np.empty((len(rows), size, size)) if smoothed else None
    edges: dict[int, np.ndarray | None] = {0: None}  # each block's entering S (None before the start)
    for a in range(0, m, BLOCK):
        b = min(a + BLOCK, m)
        sens = block(a, b)
        edges[b] = sens[-1].copy() if b > record.start else None  # (a copy: not the whole block held)
        terms(filtered, sens, a, b)
    if not smoothed:
        return filtered, None
    k0, after = record.start, None  # after: the smoother's S at the next block's first ping
    for a in range(((m - 1) // BLOCK) * BLOCK, -1, -BLOCK) if m else ():
        b = min(a + BLOCK, m)
        sens = block(a, b)
        first = max(a, k0)
        if first < b:
            ends = min(b + 1, m)  # the gains of the block's pings but the record's last (the next ping's P and F)
            gains = rts_gains(record.P_filtered[first:ends], record.P_predicted[first:ends], record.F[first:ends])
            for k in range(b - 1, first - 1, -1):
                if k == m - 1:
                    continue  # the last ping's smoothed S is its filter's
                nxt = after if k == b - 1 else sens[k + 1 - a]
                sens[k - a] = sens[k - a] + gains[k - first] @ (nxt - record.F[k + 1] @ sens[k - a])
            after = sens[first - a].copy()
        terms(back, sens, a, b)
    return filtered, back


__all__ = ["BLOCK", "consider_terms", "consider_terms_along", "filter_sensitivity", "smoothed_sensitivity"]

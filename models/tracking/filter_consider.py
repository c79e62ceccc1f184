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

import numpy as np

from sblsim.models.tracking.ekf import TrackRecord, rts_gains
from sblsim.models.tracking.toa import _evaluate_pings, per_receiver

#: The pings whose arrivals' Jacobians (by θ: (pings, n, n dim + 1)) and consider terms are made at once (the
#: Jacobians of a record's 52,000 pings of 22 receivers in 3-D made whole took 0.6 GiB).
BLOCK = 2048


def _jacobians(receivers: np.ndarray, c: float, states: np.ndarray, survey: np.ndarray, sigma_c: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """The arrivals' Jacobians at states (m, s) (NaN rows: zero): by the position and emission time (m, n, dim + 1),
    and by the whitened parameters (m, n, n dim + 1: each receiver's axes, then the speed), for the receivers'
    survey errors (n,) [m] and the speed's [m/s]."""
    n, dim = receivers.shape
    finite = np.isfinite(states).all(axis=1)
    model, J = _evaluate_pings(receivers, c, np.where(finite[:, None], states[:, :dim], 0.0),
                               np.where(finite, states[:, -2], 0.0))
    Ht = np.zeros((len(states), n, n * dim + 1))
    for i in range(n):
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
    survey_sigma : ndarray, (n,), or None
        Each receiver's survey error per axis [m].
    sigma_c : float or None
        The speed's standard error [m/s].

    Returns
    -------
    ndarray, (m, s, n dim + 1)
        ``S_k`` (module docstring) [m, m/s, s, s per unit of θ]; NaN before the filter's start.
    """
    receivers = np.asarray(receivers, float)
    n, dim = receivers.shape
    survey = np.zeros(n) if survey_sigma is None else np.asarray(survey_sigma, float)
    sc = float(sigma_c or 0.0)
    m, size = record.x_filtered.shape
    out = np.full((m, size, n * dim + 1), np.nan)
    starts = {record.start, *record.restarts}
    at = np.array(record.x_predicted, float)  # an update linearised at the prediction, a start at its fix
    fixed = sorted(starts & set(range(m)))
    at[fixed] = record.x_filtered[fixed]
    R = np.asarray(sigma_toa, float) ** 2 if per_receiver(sigma_toa) else sigma_toa**2
    idx = list(range(dim)) + [2 * dim]
    S, block = None, -1
    for k in range(record.start, m):
        if k // BLOCK != block:  # the arrivals' Jacobians a block of pings at a time (each ping's its own)
            block = k // BLOCK
            J_all, Ht_all = _jacobians(receivers, c, at[block * BLOCK:(block + 1) * BLOCK], survey, sc)
        used = record.used[k]
        J, Ht = J_all[k % BLOCK][used], Ht_all[k % BLOCK][used]
        if k in starts:  # the fix the filter started from: its position, emission time, covariance and arrivals
            if per_receiver(R):
                G = -record.P_filtered[k][np.ix_(idx, idx)] @ J.T @ (Ht / R[used][:, None])  # the fix's (dim + 1, θ)
            else:
                G = -record.P_filtered[k][np.ix_(idx, idx)] @ J.T @ Ht / R
            interval = np.zeros(n * dim + 1) if S is None else (record.F[k] @ S)[-1]
            S = np.zeros((size, n * dim + 1))
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
        out[k] = np.nan if S is None else S
    return out


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


__all__ = ["BLOCK", "consider_terms", "filter_sensitivity", "smoothed_sensitivity"]

"""The times of arrival of a pinger at a fixed array, and their Jacobian: the measurement model of tracking.

A target emits a ping on its own clock; N receivers at known positions ``r_i`` with synchronised clocks record its
times of arrival (TOA). The emission time ``t_e`` of each ping is unknown to the receivers, so the measurement model
of receiver i is

    ``toa_i = t_e + ‖p − r_i‖ / c + w_i``,   ``w_i ~ N(0, σ_toa²)``,

with the target's position ``p`` at emission (2-D, or 3-D), the sound speed ``c`` [m/s] and the timing noise
``σ_toa`` [s]. Only differences of arrival times locate the target (TDOA); the emission time is estimated beside the
position. The model and its Jacobian are casadi expressions (:func:`toa_function`), evaluated over many pings or
arrivals at once by casadi's ``map``.

Units: seconds [s], metres [m], metres per second [m/s].

References
----------
Baktoft, Gjelland, Økland, Thygesen, "Positioning of aquatic animals based on time-of-arrival and random walk
models using YAPS (Yet Another Positioning Solver)", Scientific Reports 7:14294, 2017,
doi:10.1038/s41598-017-14278-z.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

#: The sound speeds a tracker accepts and the calibration searches [m/s].
SOUND_SPEED_RANGE = (1300.0, 1700.0)


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


@lru_cache(maxsize=32)
def _mapped(n: int, dim: int, m: int) -> ca.Function:
    """:func:`toa_function` over m pings at once (the receivers and the sound speed shared)."""
    return toa_function(n, dim).map("toa_pings", "serial", m, [2, 3], [])


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


__all__ = ["SOUND_SPEED_RANGE", "toa_function", "toa_model"]

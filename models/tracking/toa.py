"""The times of arrival of a pinger at a fixed array, and their Jacobian: the measurement model of tracking.

A target emits a ping on its own clock; N receivers at known positions ``r_i`` with synchronised clocks record its
times of arrival (TOA). The emission time ``t_e`` of each ping is unknown to the receivers, so the measurement model
of receiver i is

    ``toa_i = t_e + ‖p − r_i‖ / c + w_i``,   ``w_i ~ N(0, σ_toa²)``,

with the target's position ``p`` at emission (2-D, or 3-D), the sound speed ``c`` [m/s] and the timing noise
``σ_toa`` [s]: one for every receiver, or each receiver's own ``σ_i`` (a synchronisation's residuals differ from
receiver to receiver: :func:`checked_sigma`), the measurement covariance then ``diag(σ_i²)``. Only differences of
arrival times locate the target (TDOA); the emission time is estimated beside the position. The model and its
Jacobian are casadi expressions (:func:`toa_function`, the EKF's); over many pings or arrivals at once (the fixes,
the smoother) the same closed form is evaluated in numpy.

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

from sblsim.models.errors import ModelError

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


class PingModel:
    """:func:`toa_function` of one array at one sound speed, evaluated one ping at a time through casadi's buffer
    API (``Function.buffer``: the arguments and results numpy arrays bound once, no conversion per call; a filter's
    update calls it every ping). The same function, so the same numbers to the last bit as calling it.

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    c : float
        Sound speed [m/s].
    """

    def __init__(self, receivers: np.ndarray, c: float) -> None:
        n, dim = np.shape(receivers)
        function = toa_function(n, dim)
        # casadi reads and writes the buffers in column-major order: R (dim, n) is receivers (n, dim) in C order,
        # and the Jacobian (n, dim + 1) is written as its transpose (dim + 1, n) in C order
        self._position, self._emission = np.zeros(dim), np.zeros(1)
        self._receivers = np.array(receivers, float, order="C")
        self._c = np.array([float(c)])
        self._toa, self._jacobian = np.zeros(n), np.zeros((dim + 1, n))
        self._buffer, self._evaluate = function.buffer()
        for k, argument in enumerate((self._position, self._emission, self._receivers, self._c)):
            self._buffer.set_arg(k, memoryview(argument))
        self._buffer.set_res(0, memoryview(self._toa))
        self._buffer.set_res(1, memoryview(self._jacobian))

    def __call__(self, position: np.ndarray, emission: float) -> tuple[np.ndarray, np.ndarray]:
        """The times of arrival (n,) [s] and their Jacobian (n, dim + 1) [s/m, 1] of a ping emitted at ``position``
        (dim,) [m] at ``emission`` [s] (:func:`toa_model`'s, new arrays each call)."""
        self._position[:] = position
        self._emission[0] = emission
        self._evaluate()
        return self._toa.copy(), self._jacobian.T.copy()


def _ranges(d: np.ndarray, c: float, single: bool) -> tuple[np.ndarray, np.ndarray]:
    """The travel times ``‖d‖ / c`` [s] (...) of the offsets ``d`` (..., dim) [m] from the receivers to the target,
    and their derivatives ``d / (c ‖d‖)`` [s/m] (..., dim), by the operations of :func:`toa_function`'s own
    algorithm in its order (the same numbers to the last bit; its derivative of one receiver, ``single``, is
    written ``(2 d) ((1 / (2 ‖d‖)) / c)``, of several ``(d / ‖d‖) / c``): NaN where the target is on a receiver."""
    squares = np.square(d[..., 0])
    for a in range(1, d.shape[-1]):
        squares += np.square(d[..., a])
    rho = np.sqrt(squares)
    with np.errstate(invalid="ignore", divide="ignore"):
        grad = (2.0 * d) * ((1.0 / (2.0 * rho)) / c)[..., None] if single else (d / rho[..., None]) / c
    return rho / c, grad


def _evaluate_pings(receivers: np.ndarray, c: float, p: np.ndarray, te: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`toa_function` at k pings' positions (k, dim) and emission times (k,): times of arrival (k, n) and
    Jacobians (k, n, dim + 1); the same closed form in numpy (no casadi call: a record of 10⁶ pings is one pass)."""
    k, (n, dim) = len(p), receivers.shape
    travel, grad = _ranges(np.asarray(p, float)[:, None, :] - receivers[None, :, :], c, n == 1)
    J = np.empty((k, n, dim + 1))
    J[:, :, :dim], J[:, :, dim] = grad, 1.0
    return np.asarray(te, float)[:, None] + travel, J


def checked_sigma(sigma_toa: float | np.ndarray, n: int) -> float | np.ndarray:
    """The timing noise of n receivers' times of arrival checked: one standard deviation for all (returned as given),
    or one per receiver (n,) [s] (returned as a float array; :func:`per_receiver` tells the two apart).

    Raises
    ------
    ModelError
        Not one value or n, or a value not finite and positive (one line).
    """
    if np.ndim(sigma_toa) == 0:
        if not (np.isfinite(sigma_toa) and sigma_toa > 0):
            raise ModelError(f"sigma_toa: {sigma_toa!r} s is not allowed; allowed: a finite number above 0")
        return sigma_toa
    sigma = np.asarray(sigma_toa, float)
    if sigma.shape != (n,) or not (np.isfinite(sigma).all() and (sigma > 0).all()):
        raise ModelError(f"sigma_toa: {sigma.shape[0] if sigma.ndim == 1 else sigma.shape} values, not all finite "
                         f"and above 0, or not one per receiver; allowed: one value, or {n} finite values above 0 "
                         "(one per receiver)")
    return sigma


def per_receiver(sigma_toa: float | np.ndarray) -> bool:
    """Whether a timing noise is one per receiver (an array) rather than one for all (a number)."""
    return np.ndim(sigma_toa) > 0


def reference_sigma(sigma_toa: float | np.ndarray) -> float:
    """One timing noise [s] for what takes a single one (a depth reading's weight against the arrivals, a late
    arrival's delay in units of σ_toa): the value itself, or the median of the receivers' own."""
    return sigma_toa if np.ndim(sigma_toa) == 0 else float(np.median(sigma_toa))


__all__ = ["PingModel", "SOUND_SPEED_RANGE", "checked_sigma", "per_receiver", "reference_sigma", "toa_function",
           "toa_model"]

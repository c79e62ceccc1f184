"""A still tag's place fitted with the sound speed's change over its record.

The water's sound speed follows its temperature over hours, and every range of a still tag follows it at once:
ping k's travel time to receiver i is ``ρ_i (1 + s_k) / c``, ``s_k`` the slowness's relative change from the
calibrated ``c`` at the ping's time. Pooled at one ``c`` (:mod:`sblsim.models.tracking.stationary`), a change of
±5 m/s leaves residuals of ±0.3 % of each range about each ping's emission time (tenths of a millisecond at a few
hundred metres): the Student-t takes one half of the swing as outliers and the place moves by decimetres, far beyond
its covariance. Here the speed is a slow error of its own, fitted with the place: ``s(t)`` linear between knots
every :data:`~sblsim.models.tracking.still.SLOW_TIME_S` (the slow errors' correlation time), each knot of prior
standard deviation ``W = SPEED_WANDER / c`` about the calibrated ``c``
(:data:`~sblsim.models.tracking.still.SPEED_WANDER`: a gap of pings keeps its knots near ``c``). A still tag's
arrivals tell its ranges' scale (its sound speed: :mod:`sblsim.models.tracking.still_speed`), so the knots' mean is
the tag's own and its error is in the fit's covariance, where the calibration's error was a consider term (a
calibration's spread over its stretches counts the water's change as an error of the mean):

    ``min over p, a, t_1..t_m  ½ Σ_(k,i) heard (ν + 1) ln(1 + z_ki² / ν) + Σ_j a_j² / (2 W²)``,
    ``z_ki = (toa_ki − t_k − ‖p − r_i‖ (1 + s_k) / c) / σ_i``, ``s_k = Σ_j B_j(t_k) a_j``,

``B_j`` the knots' hat functions. Solved by iteratively reweighted Gauss-Newton with each ping's emission time
eliminated (the arrivals centred per ping: Triggs et al., "Bundle adjustment — a modern synthesis", 1999, § 6.1).
The place's covariance is the place's block of the inverse of the arrivals' observed information with the knots'
prior (the speed's uncertainty in it). Each ping's times of arrival less the speed's change at the place found
(``toa − ρ_i s_k / c``) are those of water at ``c``: what the still tag's other terms (the consider sensitivity, the
receivers' jackknife, the survey's gains) take. Tested against the truth of simulated water (±5 m/s over a day:
tests/models/test_speed_change.py).

Units: seconds [s], metres [m], metres per second [m/s].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_array, diags_array
from scipy.sparse.linalg import splu

from sblsim.models.tracking import stationary as st
from sblsim.models.tracking.smoother_cost import ROBUST_DOF, observed_information
from sblsim.models.tracking.stationary import ITERATIONS, TOLERANCE, StationaryFix, _centred
from sblsim.models.tracking.still import SLOW_TIME_S, SPEED_WANDER
from sblsim.models.tracking.toa import checked_sigma

#: The fewest pings a record needs for the speed's change to be fitted (fewer: one speed, the pooled fit as it was).
MIN_PINGS = 30


@dataclass(frozen=True)
class SpeedChangeFix:
    """What :func:`speed_change_fix` returns: the pooled ``fix`` (its position, the covariance with the knots'
    uncertainty, the emission times and the arrivals' weights), each ping's relative slowness change ``change`` (m,)
    [1] (0 where not fitted), the times of arrival less it ``corrected`` (m, n) [s], and the ``knots`` fitted."""

    fix: StationaryFix
    change: np.ndarray
    corrected: np.ndarray
    knots: int

    def speed_range(self, c: float) -> list[float]:
        """The fitted sound speed's change from ``c`` [m/s] over the pings heard: its least and largest [m/s]."""
        heard = np.isfinite(self.corrected).any(axis=1)
        if not heard.any():
            return [0.0, 0.0]
        dc = c / (1.0 + self.change[heard]) - c
        return [float(dc.min()), float(dc.max())]


def _basis(times: np.ndarray, spacing: float):
    """The knots' hat functions at ``times`` (m,) [s]: a sparse (m, K) matrix (``scipy.sparse.csr_array``), K knots
    ``spacing`` [s] apart over the times' span, two hats at each finite time (NaN times: a zero row)."""
    finite = np.isfinite(times)
    t0, t1 = float(times[finite].min()), float(times[finite].max())
    K = max(2, int(np.ceil((t1 - t0) / spacing)) + 1)
    rows = np.flatnonzero(finite)
    u = ((times[rows] - t0) / spacing).clip(0.0, K - 1 - 1e-12)
    j = np.floor(u).astype(int)
    frac = u - j
    return csr_array((np.r_[1.0 - frac, frac], (np.r_[rows, rows], np.r_[j, j + 1])), shape=(len(times), K))


def speed_change_fix(toa: np.ndarray, receivers: np.ndarray, c: float, sigma_toa: float | np.ndarray,
                     start: np.ndarray, dof: float = ROBUST_DOF, spacing: float = SLOW_TIME_S,
                     wander: float = SPEED_WANDER) -> SpeedChangeFix:
    """A still tag's place and its sound speed's change over the record (module docstring).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard; rows in time order or not.
    receivers : ndarray, (n, dim)
        [m].
    c : float
        The calibrated sound speed [m/s].
    sigma_toa : float or ndarray, (n,)
        [s]: one, or each receiver's.
    start : ndarray, (dim,)
        The first position [m].
    dof : float
        ν.
    spacing : float
        The knots' spacing [s].
    wander : float
        Each knot's prior standard deviation [m/s].

    Returns
    -------
    SpeedChangeFix
        Where fewer than :data:`MIN_PINGS` pings were heard, or the record spans less than two knots' spacing, the
        change is 0 and the fix is the pooled fit at ``c``.

    Raises
    ------
    ModelError
        Fewer than dim + 1 receivers heard the tag, or the start is not finite (one line).
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    heard = np.isfinite(toa)
    n, dim = receivers.shape
    m = len(toa)
    pinged = heard.any(axis=1)
    times = np.where(pinged, np.nanmin(np.where(heard, toa, np.inf), axis=1), np.nan)
    if pinged.sum() < MIN_PINGS or np.ptp(times[pinged]) < 2.0 * spacing:
        fix = st.stationary_fix(toa, receivers, c, sigma_toa, start, dof)
        return SpeedChangeFix(fix, np.zeros(m), toa, 0)
    p = st.checked_start(heard, receivers, start)
    sigma = np.broadcast_to(np.asarray(checked_sigma(sigma_toa, n), float), (n,))
    y = np.where(heard, toa, 0.0)
    B = _basis(times, spacing)
    K = B.shape[1]
    prior = (c / wander) ** 2  # W⁻², W = wander / c, each knot's
    a = np.zeros(K)
    w = heard.astype(float)

    def terms(p: np.ndarray, a: np.ndarray, w: np.ndarray):
        """At (p, a) with the weights w: the normalised residuals, their weights settled (each ping's emission time
        the Student-t location of its arrivals), and the rows of the place (m, n, dim) and of the change (m, n)."""
        diff = p[None, :] - receivers
        rho = np.linalg.norm(diff, axis=1)
        s = B @ a
        emitted = y - rho[None, :] * (1.0 + s[:, None]) / c
        r, w = st.settled(heard, emitted, w, sigma, dof)
        wp = w / sigma**2
        unit = diff / np.maximum(rho, 1e-9)[:, None] / c
        Jp = -(1.0 + s)[:, None, None] * np.broadcast_to(unit, heard.shape + (dim,))
        Jp = np.where(heard[..., None], _centred(Jp, wp), 0.0) / sigma[:, None]
        g = np.where(heard, _centred(np.broadcast_to(-rho / c, heard.shape), wp), 0.0) / sigma
        return r, w, Jp, g, emitted, rho

    def blocks(weight: np.ndarray, Jp: np.ndarray, g: np.ndarray):
        """The normal matrix of (p, a) at the arrivals' weights, the knots' prior with it, in blocks: the place's
        (dim, dim), the place's with the knots' (dim, K), and the knots' LU (tridiagonal: each ping on two knots)."""
        Npp = np.einsum("mn,mni,mnj->ij", weight, Jp, Jp)
        Npa = (B.T @ np.einsum("mn,mni,mn->mi", weight, Jp, g)).T
        Naa = B.T @ diags_array((weight * g**2).sum(axis=1)) @ B + prior * diags_array(np.ones(K))
        return Npp, Npa, splu(Naa.tocsc())

    iterations = 0
    while iterations < ITERATIONS:
        iterations += 1
        r, w, Jp, g = terms(p, a, w)[:4]
        Npp, Npa, lu = blocks(w, Jp, g)
        gp, ga = np.einsum("mn,mni,mn->i", w, Jp, r), B.T @ (w * g * r).sum(axis=1) + prior * a
        X = lu.solve(np.column_stack([Npa.T, ga]))  # Naa⁻¹ [Nap, ga]: the knots eliminated (Schur complement)
        dp = np.linalg.lstsq(Npp - Npa @ X[:, :dim], Npa @ X[:, dim] - gp, rcond=None)[0]
        da = -X[:, dim] - X[:, :dim] @ dp
        p, a = p + dp, a + da
        if np.abs(dp).max() < TOLERANCE and np.abs(c * da).max() < 1e-3:
            break
    r, w, Jp, g, emitted, rho = terms(p, a, w)
    Npp, Npa, lu = blocks(np.where(heard, observed_information(r, dof), 0.0), Jp, g)
    covariance = np.linalg.pinv(Npp - Npa @ lu.solve(np.ascontiguousarray(Npa.T)))  # the place's block of the inverse
    s = np.where(pinged, B @ a, 0.0)
    fix = StationaryFix(p, 0.5 * (covariance + covariance.T), st.emission_times(emitted, w, sigma), w,
                        int(pinged.sum()), iterations)
    return SpeedChangeFix(fix, s, np.where(heard, toa - rho[None, :] * s[:, None] / c, np.nan), K)


__all__ = ["MIN_PINGS", "SpeedChangeFix", "speed_change_fix"]

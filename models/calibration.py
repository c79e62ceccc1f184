"""Calibration of seafloor transponders from the surface: positions from two-way travel times.

A surface transducer (a vessel's or a wave glider's, positioned by GNSS) interrogates seafloor transponders
and records each reply's two-way travel time (TWTT). The transducer moves between the transmission and the
reply, so one TWTT measures two legs,

.. math:: c\\,T_i = \\ell(\\mathbf p_{\\mathrm{tx},i}, \\mathbf x_j) + \\ell(\\mathbf x_j, \\mathbf p_{\\mathrm{rx},i}),

with :math:`T_i` the TWTT without the transponder's turnaround, :math:`c` the sound speed, :math:`\\mathbf x_j`
the replying transponder and :math:`\\ell` the acoustic path length of a leg at speed :math:`c` (for a straight
ray its length :math:`|\\mathbf p - \\mathbf x|`). :func:`solve` estimates the transponders' positions (each, or
one common rigid shift of a known array) and optionally a sound-speed scale :math:`s` (:math:`c = s\\,c_0`) by
weighted least squares (Gauss-Newton) of the range residuals :math:`v_i = s\\,c_0\\,T_i - \\ell_{\\mathrm{tx}} -
\\ell_{\\mathrm{rx}}` [m], with the weights of Xie et al. (2023): the transducer's GNSS 1-sigma projected on the
two lines of sight,

.. math:: \\sigma_i^2 = \\sum_{k\\in\\{e,n,u\\}} (u_{\\mathrm{tx},k}\\,\\sigma_{\\mathrm{tx},k})^2
          + (u_{\\mathrm{rx},k}\\,\\sigma_{\\mathrm{rx},k})^2 + (c\\,\\sigma_T)^2,

(:math:`\\mathbf u` the unit vectors of the legs; :math:`\\sigma_T` an optional TWTT noise, 0 in their work),
and their outlier rule: while the largest :math:`|v_i|` exceeds ``outlier_factor`` times the weighted RMS
:math:`\\sqrt{\\sum w_i v_i^2 / \\sum w_i}`, the reply (or replies) with it is dropped and the solution redone
(when Gauss-Newton diverges, a gross outlier, the largest residual after one step is dropped, as their script
does).
The covariance is :math:`(J^\\top W J)^{-1}` scaled by the a posteriori variance of unit weight
:math:`\\sum w_i v_i^2 / (n - p)`. Several solutions (time segments) combine as the authors combine them
(:func:`combine`): a weighted mean with weights one over the squared weighted RMS of the half residuals projected
on North, East and Up.

The leg model is a hook: :class:`StraightRay` is the straight ray at one speed (what Xie et al. use) or at one
speed per transponder (GNATSS's harmonic mean down to each transponder), :class:`EigenRay` the direct eigenray
through a sound-speed profile (:mod:`sblsim.models.acoustics.rays`); a leg's path length is its travel time
times the reference speed :math:`c_0`.

Frames: every position is local East, North, Up [m] of the survey's origin, in that column order.

Source: S. Xie, M. Zumberge, G. Sasagawa, D. Voytenko, "Shallow Water Seafloor Geodesy with Wave Glider-Based
GNSS-Acoustic Surveying of a Single Transponder", Earth and Space Science, 2023 (weights, outlier rule, segment
combination); the Gauss-Newton normal equations as in any geodetic adjustment (e.g. Strang & Borre, *Linear
Algebra, Geodesy, and GPS*, 1997, ch. 9).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np
from scipy.linalg import cholesky_banded, solve_banded

from sblsim.models.acoustics.ray_tables import exact_points
from sblsim.models.acoustics.rays import profile_arrays
from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS
from sblsim.models.declarations import ModelError
from sblsim.models.perturbation import (
    BASES_RANGE,
    CRITERIA,
    DEGREE,
    GRADIENT_LENGTH,
    GRADIENTS,
    KNOT_INTERVAL_RANGE,
    PERTURBATIONS,
    TRAVEL_TIME_SCALE,
    akaike,
    basis,
    correlation_band,
    effective_scale,
    interval_bases,
    nadir_cosine,
    roughness,
    slant_direction,
    uniform_knots,
)

#: The sound speeds accepted [m/s].
SOUND_SPEED_RANGE = (1300.0, 1800.0)
#: The outlier factors accepted (times the weighted RMS).
OUTLIER_FACTOR_RANGE = (1.0, 100.0)
#: Gauss-Newton stops when no position moves more than this [m] (and the speed scale less than
#: :data:`SCALE_TOLERANCE`), or after :data:`MAX_ITERATIONS`.
POSITION_TOLERANCE = 1e-7
SCALE_TOLERANCE = 1e-10
MAX_ITERATIONS = 50
#: A solved sound speed (``solve_sound_speed``) must lie in :data:`SOUND_SPEED_RANGE` (sea water's physical range)
#: with a 1-sigma of at most this [m/s]; otherwise the replies do not determine it (e.g. a circle at one
#: radius: every reply at one elevation angle, so that depth and speed trade one for the other) and the solution
#: is refused. Surveys that determine it give 0.05-1 m/s (NCL1, Xie et al.'s days, a box or figure-eight).
MAX_SOUND_SPEED_SIGMA = 10.0
#: The radii of a spherically layered ocean accepted [m] (0: flat layers) and the transducer depths of a profile
#: hung from the transducer [m] (0: the sea surface fixed): :class:`EigenRay`.
EARTH_RADIUS_RANGE = (6.3e6, 6.4e6)
TRANSDUCER_DEPTH_RANGE = (1e-3, 1000.0)


class LegModel(Protocol):
    """What :func:`solve` asks of the propagation: the acoustic path lengths of legs to a transponder.

    A path length is the leg's travel time times the solver's reference speed :math:`c_0` (for a straight ray
    at :math:`c_0`, the leg's length), so that the range residual :math:`c_0 T - \\ell_{tx} - \\ell_{rx}` over
    :math:`c_0` is the TWTT residual [s].
    """

    def legs(self, points: np.ndarray, x: np.ndarray, transponder: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Path lengths [m] from ``points`` (n, 3) to ``x`` (n, 3), the position of transponder ``transponder``
        (n,) (an index), and their gradients w.r.t. ``x`` (n, 3)."""


class StraightRay:
    """A straight ray: a leg's path length is its length, at the solver's speed or at one speed per transponder.

    Parameters
    ----------
    scale : array_like of float, shape (k,), or None
        Per transponder, the solver's reference speed over the transponder's own speed, :math:`c_0 / c_j` [1]
        (each transponder's harmonic mean of the water column above it, as GNATSS takes it); None: 1 for all
        (the solver's speed, as Xie et al. take it).

    Source: the straight-ray model of Xie et al. (2023), Section 2 (harmonic-mean sound speed); Chadwell and
    Sweeney (2010), Marine Geodesy 33(2-3), 164-186 (the harmonic mean down to each transponder).
    """

    def __init__(self, scale: Sequence[float] | np.ndarray | None = None):
        self.scale = None if scale is None else np.asarray(scale, dtype=float)
        if self.scale is not None and (self.scale.ndim != 1 or not np.all(np.isfinite(self.scale))
                                       or np.any(self.scale <= 0.0)):
            raise ModelError("scale: the speed ratios must be finite and > 0, one per transponder")

    def legs(self, points: np.ndarray, x: np.ndarray, transponder: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Lengths and unit vectors of the legs (times the transponder's speed ratio).

        Parameters
        ----------
        points, x : numpy.ndarray, shape (n, 3)
            The legs' ends, local ENU [m].
        transponder : numpy.ndarray of int, shape (n,)
            The transponder at ``x`` (its index).

        Returns
        -------
        length : numpy.ndarray, shape (n,)
            :math:`(c_0 / c_j) |\\mathbf x - \\mathbf p|` [m].
        gradient : numpy.ndarray, shape (n, 3)
            Its gradient with respect to ``x``, the unit vector from ``points`` to ``x`` times the ratio [1].

        Raises
        ------
        ModelError
            A transponder index without a speed ratio.
        """
        d = x - points
        length = np.sqrt(np.sum(d * d, axis=1))
        if self.scale is None:
            return length, d / length[:, None]
        if len(transponder) and int(np.max(transponder)) >= len(self.scale):
            raise ModelError(f"scale: {len(self.scale)} speed ratios for transponder index {int(np.max(transponder))}")
        r = self.scale[transponder]
        return r * length, (r / length)[:, None] * d


class EigenRay:
    """The direct eigenray through a sound-speed profile: a leg's path length is its travel time times
    :math:`c_0`.

    Each leg is the direct eigenray (:func:`sblsim.models.acoustics.ray_tables.exact_points`, the exact bracketed-Newton
    solve, no boundaries) between the depths of its ends over their horizontal distance; the depth of a point is
    ``surface_u`` minus its Up. The gradient with respect to the transponder's position ``x`` is the ray's:
    along the horizontal, :math:`\\partial\\tau/\\partial X = \\xi = \\cos\\theta / c` (Snell's invariant, the ray
    parameter; :math:`\\theta` the grazing angle) on the horizontal unit vector from the other end to ``x``;
    along the depth, :math:`\\partial\\tau/\\partial z = \\sin\\theta_x / c(z_x)
    = \\xi\\tan\\theta_x` with :math:`\\theta_x` the grazing angle at ``x`` in the direction of travel toward ``x``,
    positive downward (Jensen, Kuperman, Porter, Schmidt, *Computational Ocean Acoustics*, 2nd ed., 2011, ch. 3.2).

    Two options follow SeaGap (Tomita and Kido, 2022, Earth, Planets and Space, doi:10.1186/s40623-022-01740-0;
    its ``traveltime.jl``): ``earth_radius`` > 0 layers the ocean in spherical shells (the frame's Up is height
    above a sphere of that radius, a horizontal distance :math:`X` is the arc :math:`\\Delta = X/R` at Up 0), traced
    exactly by the Earth-flattening transformation: a point at radius :math:`r` is at flat depth
    :math:`z_f = R_s \\ln(R_s/r)` with the speed :math:`c_f = c\\,R_s/r` and the arc is the flat distance
    :math:`X_f = R_s \\Delta`, :math:`R_s` the radius of depth 0 (K. Aki, P. G. Richards, *Quantitative
    Seismology*, 2nd ed., 2002, ch. 9; G. Müller, Geophys. J. R. astr. Soc. 23, 435-449, 1971); the profile is flattened
    once about :math:`R + ` ``surface_u`` (a radius off by tens of metres changes a flattened speed by
    :math:`10^{-9}` of itself). ``transducer_depth`` > 0 hangs the profile from each surface point: that point is
    at this depth of the profile and the other end that much deeper plus their height difference (SeaGap's
    ``XDUCER_DEPTH``: the water column rides with the sea surface, tide and waves), instead of the surface at
    ``surface_u``.

    Parameters
    ----------
    table : array_like, shape (rows, 2)
        The profile: depth [m, positive down, increasing], sound speed [m/s] (linear between rows, the end
        speeds beyond).
    reference_speed : float
        The solver's :math:`c_0` [m/s] (give :func:`solve` the same).
    surface_u : float
        Up of the sea surface in the survey's frame [m] (depth 0 of the profile).
    exact : casadi.Function or None
        :func:`~sblsim.models.acoustics.ray_tables.exact_points` as it is evaluated (e.g. compiled in the local engine's
        library, some 100 times faster); default that function itself.
    earth_radius : float
        The radius of the spherical layering [m], in :data:`EARTH_RADIUS_RANGE`; 0: flat layers.
    transducer_depth : float
        The surface point's depth in the profile [m], in :data:`TRANSDUCER_DEPTH_RANGE`; 0: the sea surface at
        ``surface_u``.

    Raises
    ------
    ModelError
        A table that is empty, not (rows, 2), too long, with depths not increasing or speeds outside
        :data:`SOUND_SPEED_RANGE`; a reference speed, an Earth radius or a transducer depth outside its range.
    """

    def __init__(self, table: np.ndarray, reference_speed: float, surface_u: float = 0.0, exact=None,
                 earth_radius: float = 0.0, transducer_depth: float = 0.0):
        table = np.asarray(table, dtype=float)
        lo, hi = SOUND_SPEED_RANGE
        if table.ndim != 2 or table.shape[1] != 2 or not 1 <= table.shape[0] <= MAX_PROFILE_ROWS \
                or not np.all(np.isfinite(table)):
            raise ModelError(f"sound_speed_profile: expected 1 to {MAX_PROFILE_ROWS} finite rows of depth [m] and "
                             "speed [m/s]")
        if np.any(np.diff(table[:, 0]) <= 0.0) or np.any(table[:, 1] < lo) or np.any(table[:, 1] > hi):
            raise ModelError(f"sound_speed_profile: depths must increase and speeds lie in [{lo:g}, {hi:g}] m/s")
        if not (np.isfinite(reference_speed) and lo <= reference_speed <= hi):
            raise ModelError(f"sound_speed_mps: {reference_speed!r} is outside the allowed range [{lo:g}, {hi:g}] m/s")
        if not (np.isfinite(surface_u) and abs(surface_u) <= 1e4):
            raise ModelError(f"surface_u_m: {surface_u!r} is outside the allowed range [-10000, 10000] m")
        for name, value, (low, high) in (("earth_radius_m", earth_radius, EARTH_RADIUS_RANGE),
                                          ("transducer_depth_m", transducer_depth, TRANSDUCER_DEPTH_RANGE)):
            if not (np.isfinite(value) and (value == 0.0 or low <= value <= high)):
                raise ModelError(f"{name}: {value!r} is outside the allowed range 0 or [{low:g}, {high:g}] m")
        self.table = table
        self.reference_speed = float(reference_speed)
        self.surface_u = float(surface_u)
        self.earth_radius = float(earth_radius)
        self.transducer_depth = float(transducer_depth)
        if self.earth_radius > 0.0:
            top = self.earth_radius + self.surface_u
            radius = top - table[:, 0]
            table = np.column_stack((top * np.log(top / radius), table[:, 1] * top / radius))
        self.nodes, self.speeds = profile_arrays(table)
        self._exact = exact_points() if exact is None else exact

    def times(self, zs: np.ndarray, zr: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, ...]:
        """The direct eigenrays between two depths over a horizontal distance.

        Parameters
        ----------
        zs, zr : numpy.ndarray, shape (n,)
            Depths of the source and of the receiver [m, positive down].
        x : numpy.ndarray, shape (n,)
            Horizontal distances [m].

        Returns
        -------
        tau : numpy.ndarray, shape (n,)
            Travel time [s].
        launch, arrival : numpy.ndarray, shape (n,)
            Grazing angles at the source and at the receiver [rad], positive downward in the direction of travel.
        found : numpy.ndarray of bool, shape (n,)
            Whether the direct eigenray exists (False: a shadow zone; the other values are meaningless).
        """
        n = len(x)
        if n == 0:
            return np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool)
        out = self._exact.map(n)(zs[None, :], zr[None, :], x[None, :], np.zeros((1, n)), self.nodes, self.speeds)
        tau, launch, arrival, kind = (np.asarray(o).ravel() for o in out)
        return tau, launch, arrival, kind == 1

    def legs(self, points: np.ndarray, x: np.ndarray, transponder: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:math:`c_0\\tau` of each leg's direct eigenray and its gradient with respect to ``x``.

        Parameters
        ----------
        points, x : numpy.ndarray, shape (n, 3)
            The legs' ends (the transducer, the transponder), local ENU [m].
        transponder : numpy.ndarray of int, shape (n,)
            Not used (the profile is the same for every transponder).

        Returns
        -------
        length : numpy.ndarray, shape (n,)
            :math:`c_0 \\tau` [m].
        gradient : numpy.ndarray, shape (n, 3)
            :math:`c_0\\,\\partial\\tau/\\partial\\mathbf x` [1].

        Raises
        ------
        ModelError
            A leg without a direct eigenray (a shadow zone of the profile).
        """
        if self.transducer_depth > 0.0:  # the profile hangs from the surface point
            zs = np.full(len(points), self.transducer_depth)
            zr = self.transducer_depth + points[:, 2] - x[:, 2]
        else:
            zs = self.surface_u - points[:, 2]
            zr = self.surface_u - x[:, 2]
        dh = x[:, :2] - points[:, :2]
        horizontal = np.sqrt(np.sum(dh * dh, axis=1))
        stretch, steep = np.ones(len(x)), np.ones(len(x))  # dX_f/dX and dz_f/dz at x (1 in flat layers)
        if self.earth_radius > 0.0:  # Earth-flattening: the depths, the arc and their derivatives
            top = self.earth_radius + (points[:, 2] + zs if self.transducer_depth > 0.0 else self.surface_u)
            stretch, steep = top / self.earth_radius, top / (top - zr)
            zs, zr, horizontal = top * np.log(top / (top - zs)), top * np.log(steep), horizontal * stretch
        tau, launch, arrival, found = self.times(zs, zr, horizontal)
        if not np.all(found):
            k = int(np.flatnonzero(~found)[0])
            raise ModelError(f"sound_speed_profile: no direct eigenray from depth {zs[k]:.1f} m to {zr[k]:.1f} m over "
                             f"{horizontal[k]:.1f} m (a shadow zone)")
        c_s = np.interp(zs, self.nodes, self.speeds)
        xi = np.cos(launch) / c_s  # Snell's invariant [s/m]
        # toward x: the arrival angle is at x, positive downward = toward greater depth = -Up
        d_depth = xi * np.tan(arrival) * steep
        unit = np.divide(dh, horizontal[:, None], out=np.zeros_like(dh), where=horizontal[:, None] > 0.0)
        gradient = np.column_stack(((xi * stretch)[:, None] * unit, -d_depth))
        c0 = self.reference_speed
        return c0 * tau, c0 * gradient


@dataclass(frozen=True)
class Replies:
    """The replies of a survey as arrays (one row per reply), local ENU [m].

    Attributes
    ----------
    tx, rx : numpy.ndarray, shape (n, 3)
        The transducer at transmit and at the reply's receive time [m].
    tx_sigma, rx_sigma : numpy.ndarray, shape (n, 3)
        Their 1-sigma per axis [m], > 0.
    twtt : numpy.ndarray, shape (n,)
        Two-way travel time without the turnaround [s], > 0.
    transponder : numpy.ndarray of int, shape (n,)
        The replying transponder's index into the a-priori positions (replies are paired by identity).
    t_tx, t_rx : numpy.ndarray, shape (n,), or None
        Transmit and receive times [s] (a sound-speed perturbation, :class:`Perturbation`, needs them).
    """

    tx: np.ndarray
    tx_sigma: np.ndarray
    rx: np.ndarray
    rx_sigma: np.ndarray
    twtt: np.ndarray
    transponder: np.ndarray
    t_tx: np.ndarray | None = None
    t_rx: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.twtt)

    def subset(self, rows: np.ndarray) -> Replies:
        """The replies at ``rows`` (indices or a boolean mask)."""
        times = (None, None) if self.t_tx is None else (self.t_tx[rows], self.t_rx[rows])
        return Replies(self.tx[rows], self.tx_sigma[rows], self.rx[rows], self.rx_sigma[rows], self.twtt[rows],
                       self.transponder[rows], *times)


@dataclass
class Solution:
    """A calibration solution (:func:`solve`).

    Attributes
    ----------
    position : numpy.ndarray, shape (k, 3)
        The transponders' positions, local ENU [m].
    offset : numpy.ndarray, shape (k, 3)
        ``position`` minus the a-priori positions [m].
    sigma : numpy.ndarray, shape (k, 3)
        1-sigma of ``position`` per axis from the scaled covariance [m].
    covariance : numpy.ndarray, shape (p, p)
        Covariance of the unknowns (3 per transponder, or 3 for a rigid shift; then the speed scale) [m², 1].
    sound_speed : float
        The sound speed used (estimated when asked) [m/s].
    sound_speed_sigma : float
        Its 1-sigma [m/s] (0 when it was fixed).
    used : numpy.ndarray of bool, shape (n,)
        The replies kept by the outlier rule.
    residual_m : numpy.ndarray, shape (n,)
        :math:`s c_0 T - \\ell_{tx} - \\ell_{rx}` of every reply at the solution [m] (also the rejected ones).
    residual_s : numpy.ndarray, shape (n,)
        The same as a TWTT residual, ``residual_m / sound_speed`` [s].
    weight : numpy.ndarray, shape (n,)
        :math:`1/\\sigma_i^2` [1/m²].
    elevation : numpy.ndarray, shape (n,)
        Elevation of the receive point above the transponder's horizontal [rad].
    azimuth : numpy.ndarray, shape (n,)
        Azimuth of the receive point from the transponder, clockwise from North [rad].
    wrms_m : float
        Weighted RMS of the used residuals [m].
    variance_factor : float
        A posteriori variance of unit weight (1 when the weights are right).
    scatter : numpy.ndarray, shape (k, 3)
        Weighted RMS of the used half residuals projected on East, North, Up per transponder [m] (Xie et al.'s
        weights of the segment combination, :func:`combine`).
    iterations : int
        Gauss-Newton iterations of the last solution.
    converged : bool
        Whether the last solution met the tolerances within :data:`MAX_ITERATIONS`.
    perturbation : PerturbationFit or None
        The sound-speed perturbation solved with the positions (None without one). With it, ``covariance`` is the
        positions' block, ``residual_s`` the TWTT residual of the whole model (legs and perturbation) and
        ``variance_factor`` the a posteriori variance of the perturbation's residuals (SeaGap: of the
        nadir-normalised time [s²]; GARPOS: of unit weight).
    """

    position: np.ndarray
    offset: np.ndarray
    sigma: np.ndarray
    covariance: np.ndarray
    sound_speed: float
    sound_speed_sigma: float
    used: np.ndarray
    residual_m: np.ndarray
    residual_s: np.ndarray
    weight: np.ndarray
    elevation: np.ndarray
    azimuth: np.ndarray
    wrms_m: float
    variance_factor: float
    scatter: np.ndarray
    iterations: int
    converged: bool
    perturbation: PerturbationFit | None = None


def _check(replies: Replies, apriori: np.ndarray, sound_speed: float, outlier_factor: float | None,
           twtt_sigma: float) -> None:
    lo, hi = SOUND_SPEED_RANGE
    if not (np.isfinite(sound_speed) and lo <= sound_speed <= hi):
        raise ModelError(f"sound_speed_mps: {sound_speed!r} is outside the allowed range [{lo:g}, {hi:g}] m/s")
    if outlier_factor is not None:
        lo, hi = OUTLIER_FACTOR_RANGE
        if not (np.isfinite(outlier_factor) and lo <= outlier_factor <= hi):
            raise ModelError(f"outlier_factor: {outlier_factor!r} is outside the allowed range [{lo:g}, {hi:g}]")
    if not (np.isfinite(twtt_sigma) and 0.0 <= twtt_sigma <= 1.0):
        raise ModelError(f"twtt_sigma_s: {twtt_sigma!r} is outside the allowed range [0, 1] s")
    if apriori.ndim != 2 or apriori.shape[1] != 3 or not np.all(np.isfinite(apriori)):
        raise ModelError("apriori: the a-priori positions must be finite, shape (k, 3) [m]")
    if len(replies) and (replies.transponder.min() < 0 or replies.transponder.max() >= len(apriori)):
        raise ModelError(f"transponder: an index is outside [0, {len(apriori) - 1}]")


def _check_solved_speed(speed: float, sigma: float, what: str) -> None:
    """Refuse a solved sound speed outside the physical range or not determined by the replies
    (:data:`MAX_SOUND_SPEED_SIGMA`)."""
    lo, hi = SOUND_SPEED_RANGE
    if np.isfinite(speed) and np.isfinite(sigma) and lo <= speed <= hi and sigma <= MAX_SOUND_SPEED_SIGMA:
        return
    raise ModelError(f"solve_sound_speed: the replies of {what} do not determine the sound speed: its estimate "
                     f"{speed:.6g} m/s (1-sigma {sigma:.3g} m/s) must lie in the physical range [{lo:g}, {hi:g}] m/s "
                     f"with a 1-sigma of at most {MAX_SOUND_SPEED_SIGMA:g} m/s (replies at one elevation angle, e.g. a "
                     "circle at one radius, cannot separate depth from speed): give the sound speed and solve it "
                     "false, or survey at several distances")


def _line_of_sight_variance(replies: Replies, x: np.ndarray, u_tx: np.ndarray, u_rx: np.ndarray, c: float,
                            twtt_sigma: float) -> np.ndarray:
    """:math:`\\sigma_i^2` [m²]: the transducer's sigmas projected on the legs' unit vectors."""
    return (np.sum((u_tx * replies.tx_sigma) ** 2, axis=1) + np.sum((u_rx * replies.rx_sigma) ** 2, axis=1)
            + (c * twtt_sigma) ** 2)


def _directions(replies: Replies, x: np.ndarray, residual: np.ndarray, w: np.ndarray, used: np.ndarray,
                k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each reply's elevation and azimuth of the receive point seen from the transponder [rad], and per transponder
    the weighted RMS of the used half residuals projected on East, North, Up [m] (:attr:`Solution.scatter`)."""
    horizontal = np.hypot(replies.rx[:, 0] - x[:, 0], replies.rx[:, 1] - x[:, 1])
    elevation = np.arctan2(replies.rx[:, 2] - x[:, 2], horizontal)
    azimuth = np.arctan2(replies.rx[:, 0] - x[:, 0], replies.rx[:, 1] - x[:, 1])
    half = 0.5 * residual
    projected = np.column_stack((half * np.sin(azimuth), half * np.cos(azimuth), half * np.sin(elevation)))
    scatter = np.full((k, 3), np.nan)
    for j in range(k):
        mine = used & (replies.transponder == j)
        if mine.any():
            scatter[j] = np.sqrt(np.sum(w[mine, None] * projected[mine] ** 2, axis=0) / np.sum(w[mine]))
    return elevation, azimuth, scatter


def _unknowns(k: int, rigid: bool, solve_speed: bool) -> int:
    return (3 if rigid else 3 * k) + int(solve_speed)


def _model(replies: Replies, apriori: np.ndarray, theta: np.ndarray, c0: float, rigid: bool, solve_speed: bool,
           legs: LegModel, twtt_sigma: float):
    """Residuals [m], Jacobian of the predicted path, variances [m²] and geometry at the unknowns ``theta``."""
    k = len(apriori)
    shift = theta[:3 * (1 if rigid else k)].reshape(-1, 3)
    position = apriori + shift if not rigid else apriori + shift[0]
    scale = theta[-1] if solve_speed else 1.0
    x = position[replies.transponder]
    l_tx, u_tx = legs.legs(replies.tx, x, replies.transponder)
    l_rx, u_rx = legs.legs(replies.rx, x, replies.transponder)
    c = scale * c0
    residual = c * replies.twtt - l_tx - l_rx
    g = u_tx + u_rx  # d(l_tx + l_rx)/dx
    n, p = len(replies), len(theta)
    jacobian = np.zeros((n, p))
    if rigid:
        jacobian[:, :3] = g
    else:
        for axis in range(3):
            jacobian[np.arange(n), 3 * replies.transponder + axis] = g[:, axis]
    if solve_speed:
        jacobian[:, -1] = -c0 * replies.twtt
    variance = _line_of_sight_variance(replies, x, u_tx, u_rx, c, twtt_sigma)
    return residual, jacobian, variance, position, c, x


def _gauss_newton(replies: Replies, apriori: np.ndarray, theta: np.ndarray, c0: float, rigid: bool,
                  solve_speed: bool, legs: LegModel, twtt_sigma: float, what: str) -> tuple[np.ndarray, int, bool]:
    for iteration in range(1, MAX_ITERATIONS + 1):
        residual, jacobian, variance, *_ = _model(replies, apriori, theta, c0, rigid, solve_speed, legs, twtt_sigma)
        w = 1.0 / variance
        normal = jacobian.T @ (w[:, None] * jacobian)
        try:
            step = np.linalg.solve(normal, jacobian.T @ (w * residual))
        except np.linalg.LinAlgError:
            raise ModelError(f"{what}: the replies do not determine the unknowns (the normal matrix is singular): "
                             "more replies, from more directions, are needed") from None
        theta = theta + step
        moved = np.abs(step[:-1] if solve_speed else step)
        if np.max(moved) <= POSITION_TOLERANCE and (not solve_speed or abs(step[-1]) <= SCALE_TOLERANCE):
            return theta, iteration, True
    return theta, MAX_ITERATIONS, False


def solve(replies: Replies, apriori: Sequence[Sequence[float]] | np.ndarray, sound_speed: float, *,
          rigid: bool = False, solve_sound_speed: bool = False, outlier_factor: float | None = 3.0,
          twtt_sigma: float = 0.0, legs: LegModel | None = None, what: str = "calibration",
          perturbation: Perturbation | None = None) -> Solution:
    """Transponder positions from two-way travel times by weighted least squares with the outlier rule.

    Parameters
    ----------
    replies : Replies
        The replies (n rows), paired with transponders by ``replies.transponder``.
    apriori : array_like, shape (k, 3)
        The transponders' a-priori positions, local ENU [m] (the start of Gauss-Newton; offsets are from them).
    sound_speed : float
        The sound speed :math:`c_0` [m/s], in :data:`SOUND_SPEED_RANGE`.
    rigid : bool
        Solve one common shift of all transponders (a known array) instead of each position.
    solve_sound_speed : bool
        Also estimate a sound-speed scale (the result's ``sound_speed`` is then estimated).
    outlier_factor : float or None
        Drop the reply with the largest absolute residual while it exceeds this many weighted RMS
        (:data:`OUTLIER_FACTOR_RANGE`); None keeps every reply.
    twtt_sigma : float
        A TWTT noise added to the weights [s], in [0, 1] (0: the GNSS sigmas only, as Xie et al.).
    legs : LegModel or None
        The propagation (default :class:`StraightRay`).
    what : str
        What errors name (e.g. the segment).
    perturbation : Perturbation or None
        Solve a sound-speed perturbation in time with the positions (:class:`Perturbation`; the replies need their
        times): the residuals, weights and statistics are then the perturbation's (SeaGap's nadir-normalised
        time with equal weights, or GARPOS's log time with its covariance and prior), the outlier rule judges the
        TWTT residuals [s] against their RMS, ``twtt_sigma`` is not used. None: the model above.

    Returns
    -------
    Solution

    Raises
    ------
    ModelError
        A value outside its range, fewer replies than unknowns + 1, or replies that do not determine the unknowns
        (with ``solve_sound_speed``: a sound speed outside :data:`SOUND_SPEED_RANGE` or with a 1-sigma above
        :data:`MAX_SOUND_SPEED_SIGMA`).
    """
    apriori = np.asarray(apriori, dtype=float)
    _check(replies, apriori, float(sound_speed), outlier_factor, float(twtt_sigma))
    legs = legs or StraightRay()
    if perturbation is not None:
        _check_perturbation(perturbation, replies, solve_sound_speed)
        return _solve_perturbed(replies, apriori, float(sound_speed), rigid, legs, perturbation, outlier_factor, what)
    k = len(apriori)
    p = _unknowns(k, rigid, solve_sound_speed)
    n = len(replies)
    if n <= p:
        raise ModelError(f"{what}: {n} replies for {p} unknowns; at least {p + 1} are needed")
    theta = np.zeros(p)
    if solve_sound_speed:
        theta[-1] = 1.0
    used = np.ones(n, dtype=bool)
    while True:
        subset = replies.subset(used)
        if used.sum() <= p:
            raise ModelError(f"{what}: the outlier rule left {int(used.sum())} replies for {p} unknowns")
        start = theta
        try:
            theta, iterations, converged = _gauss_newton(subset, apriori, start, sound_speed, rigid,
                                                         solve_sound_speed, legs, twtt_sigma, what)
        except ModelError:
            if outlier_factor is None:
                raise
            converged = False
        if not converged and outlier_factor is not None and used.sum() > p + 1:
            # Gauss-Newton diverged (a gross outlier): as Xie et al.'s script, judge the replies after one step
            # from the start, drop the worst and solve again from the start
            residual, jacobian, variance, *_ = _model(subset, apriori, start, sound_speed, rigid, solve_sound_speed,
                                                      legs, twtt_sigma)
            w = 1.0 / variance
            try:
                one = start + np.linalg.solve(jacobian.T @ (w[:, None] * jacobian), jacobian.T @ (w * residual))
            except np.linalg.LinAlgError:
                raise ModelError(f"{what}: the replies do not determine the unknowns (the normal matrix is "
                                 "singular): more replies, from more directions, are needed") from None
            residual = _model(subset, apriori, one, sound_speed, rigid, solve_sound_speed, legs, twtt_sigma)[0]
            rows = np.flatnonzero(used)
            used[rows[np.abs(residual) == np.max(np.abs(residual))]] = False
            theta = start
            continue
        residual, _, variance, _, _, _ = _model(subset, apriori, theta, sound_speed, rigid, solve_sound_speed, legs,
                                                twtt_sigma)
        w = 1.0 / variance
        wrms = float(np.sqrt(np.sum(w * residual**2) / np.sum(w)))
        worst = float(np.max(np.abs(residual)))
        if outlier_factor is None or used.sum() < 3 or worst <= outlier_factor * wrms:
            break
        rows = np.flatnonzero(used)
        used[rows[np.abs(residual) == worst]] = False
    residual, jacobian, variance, position, c, x = _model(replies, apriori, theta, sound_speed, rigid,
                                                          solve_sound_speed, legs, twtt_sigma)
    w = 1.0 / variance
    ju, ru, wu = jacobian[used], residual[used], w[used]
    q = np.linalg.inv(ju.T @ (wu[:, None] * ju))
    dof = int(used.sum()) - p
    factor = float(np.sum(wu * ru**2) / dof)
    covariance = q * factor
    sd = np.sqrt(np.diag(covariance))
    if solve_sound_speed:
        _check_solved_speed(float(c), float(sound_speed * sd[-1]), what)
    sigma = np.tile(sd[:3], (k, 1)) if rigid else sd[:3 * k].reshape(k, 3)
    elevation, azimuth, scatter = _directions(replies, x, residual, w, used, k)
    return Solution(position=position, offset=position - apriori, sigma=sigma, covariance=covariance,
                    sound_speed=float(c), sound_speed_sigma=float(sound_speed * sd[-1]) if solve_sound_speed else 0.0,
                    used=used, residual_m=residual, residual_s=residual / c, weight=w, elevation=elevation,
                    azimuth=azimuth, wrms_m=wrms, variance_factor=factor, scatter=scatter, iterations=iterations,
                    converged=converged)


@dataclass(frozen=True)
class Perturbation:
    """The settings of a sound-speed perturbation solved with the positions (:mod:`sblsim.models.perturbation`).

    Attributes
    ----------
    kind : str
        ``"ntd"`` (SeaGap's nadir total delay) or ``"garpos"`` (GARPOS's correction of the log travel time).
    n_bases : int
        Cubic B-spline bases over the survey, in :data:`~sblsim.models.perturbation.BASES_RANGE`; 0: one knot every
        ``knot_interval``.
    knot_interval : float
        The knots' spacing when ``n_bases`` is 0 [s].
    gradient : str
        ``"none"``, ``"deep"`` or ``"shallow+deep"`` (:data:`~sblsim.models.perturbation.GRADIENTS`).
    log_lambda0, log_grad_lambda : float
        GARPOS's smoothness: :math:`\\log_{10}\\lambda_0^2` of the background, :math:`\\log_{10}` of the gradients'
        :math:`\\lambda_g^2/\\lambda_0^2` (``garpos`` only).
    mu_t : float
        GARPOS's data correlation length [s] (0: independent replies; ``garpos`` only).
    mu_mt : float
        GARPOS's correlation between different transponders' replies, in [0, 1].
    reject_sigma : float
        Drop the replies whose residual is more than this many standard deviations from the mean, re-judged after
        each solution (GARPOS's ``RejectCriteria``; 0: none). A correlated data covariance is not used with it (as
        GARPOS).
    earth_radius : float
        The radius of the nadir angle's geometry [m] (the legs' :class:`EigenRay` ``earth_radius``; 0: flat).
    t0 : float
        GARPOS's characteristic travel time :math:`T_0` [s] (twice the mean depth over the mean speed: the unit of
        its coefficients and residuals is :data:`~sblsim.models.perturbation.TRAVEL_TIME_SCALE` over it); 0: twice
        the a-priori positions' mean depth below Up 0 over the solver's speed.
    """

    kind: str = "ntd"
    n_bases: int = 0
    knot_interval: float = 300.0
    gradient: str = "none"
    log_lambda0: float = -2.0
    log_grad_lambda: float = -1.0
    mu_t: float = 0.0
    mu_mt: float = 0.5
    reject_sigma: float = 0.0
    earth_radius: float = 0.0
    t0: float = 0.0


@dataclass
class PerturbationFit:
    """A solved perturbation (:attr:`Solution.perturbation`).

    Attributes
    ----------
    settings : Perturbation
    n_bases : int
        The splines' bases.
    knots : numpy.ndarray, shape (n_bases + 4,)
        [s].
    used_bases : numpy.ndarray of bool, shape (n_bases,)
        The bases solved (``ntd`` drops those no used reply touches, as SeaGap; ``garpos`` keeps all, the prior
        holds them).
    coefficients, coefficient_sigma : numpy.ndarray, shape (n_bases,)
        The background's coefficients and their 1-sigma: ``ntd`` the NTD [s], ``garpos`` :math:`\\alpha_0` [1]
        (0 for an unused basis).
    gradient, gradient_sigma : dict of numpy.ndarray
        ``deep`` and ``shallow`` when solved, each (2, ...) East and North: ``ntd`` two constants ([s], and [s/km]
        for the shallow), ``garpos`` the coefficients of :math:`\\boldsymbol\\alpha_2` and
        :math:`\\boldsymbol\\alpha_1` (2, n_bases) [1/km].
    delay : numpy.ndarray, shape (n,)
        The model's perturbation of each reply as a two-way nadir delay [s]: ``ntd`` the NTD at its mid-time,
        ``garpos`` :math:`(\\hat T - \\tau)\\cos\\xi`.
    observed : numpy.ndarray, shape (n,)
        :math:`(T - \\tau)\\cos\\xi` less the gradients' part [s]: what the delay fits.
    mapping : numpy.ndarray, shape (n,)
        :math:`\\cos\\xi` of each reply [1].
    mid_time : numpy.ndarray, shape (n,)
        Each reply's mid-time [s].
    parameters : int
        The unknowns solved (positions, bases, gradients).
    aic, bic : float or None
        SeaGap's criteria (:func:`~sblsim.models.perturbation.akaike`; ``ntd``).
    abic : float or None
        GARPOS's ABIC (``garpos``).
    effective_scale : float
        The realistic sigma's factor over the formal one for the residuals' correlation in time
        (:func:`~sblsim.models.perturbation.effective_scale`).
    """

    settings: Perturbation
    n_bases: int
    knots: np.ndarray
    used_bases: np.ndarray
    coefficients: np.ndarray
    coefficient_sigma: np.ndarray
    gradient: dict
    gradient_sigma: dict
    delay: np.ndarray
    observed: np.ndarray
    mapping: np.ndarray
    mid_time: np.ndarray
    parameters: int
    aic: float | None
    bic: float | None
    abic: float | None
    effective_scale: float


def _check_perturbation(pert: Perturbation, replies: Replies, solve_speed: bool) -> None:
    if pert.kind not in PERTURBATIONS[1:]:
        raise ModelError(f"perturbation: {str(pert.kind)[:40]!r} is not one of {', '.join(PERTURBATIONS[1:])}")
    if pert.gradient not in GRADIENTS:
        raise ModelError(f"gradient: {str(pert.gradient)[:40]!r} is not one of {', '.join(GRADIENTS)}")
    if solve_speed:
        raise ModelError("solve_sound_speed: a speed scale and a perturbation are one unknown twice (the perturbation "
                         "holds the speed's change); solve one of them")
    if replies.t_tx is None:
        raise ModelError("perturbation: the replies carry no transmit and receive times")
    lo, hi = BASES_RANGE
    if pert.n_bases and not lo <= pert.n_bases <= hi:
        raise ModelError(f"n_bases: {pert.n_bases!r} is outside the allowed range 0 or [{lo}, {hi}]")
    lo, hi = KNOT_INTERVAL_RANGE
    if not pert.n_bases and not lo <= pert.knot_interval <= hi:
        raise ModelError(f"knot_interval: {pert.knot_interval!r} is outside the allowed range [{lo:g}, {hi:g}] s")
    if pert.kind == "ntd" and pert.mu_t > 0.0:
        raise ModelError("mu_t: the data correlation is GARPOS's (perturbation = garpos); SeaGap's NTD takes "
                         "independent replies")


class _Design:
    """A perturbed survey's fixed parts for all its replies: times, splines, the gradients' fixed factors, GARPOS's
    units and prior; the columns of a fit are those of its replies (:meth:`active`)."""

    def __init__(self, pert: Perturbation, replies: Replies, apriori: np.ndarray, knots: np.ndarray, c0: float):
        self.pert = pert
        self.replies = replies
        #: None, or (positions' unknowns, residuals [m], Jacobian) of the legs at a reference solution
        self.linear: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.mid = 0.5 * (replies.t_tx + replies.t_rx)
        self.deep = pert.gradient != "none"
        self.shallow = pert.gradient == "shallow+deep"
        self.n_bases = len(knots) - DEGREE - 1
        # the transducer's horizontal offsets from their means [km], at transmit and at receive
        d_tx = (replies.tx[:, :2] - replies.tx[:, :2].mean(axis=0)) / GRADIENT_LENGTH
        d_rx = (replies.rx[:, :2] - replies.rx[:, :2].mean(axis=0)) / GRADIENT_LENGTH
        if pert.kind == "ntd":
            self.spline = basis(self.mid, knots)
            self.fixed = [self.spline] + ([0.5 * (d_tx + d_rx)] if self.shallow else [])
            self.unit, self.t0, self.prior_blocks = 1.0, 0.0, []
            return
        b_tx, b_rx = basis(replies.t_tx, knots), basis(replies.t_rx, knots)
        mean = 0.5 * (b_tx + b_rx)
        centre = (apriori[replies.transponder] - apriori.mean(axis=0))[:, :2] / GRADIENT_LENGTH
        blocks = [mean]
        if self.shallow:
            blocks += [0.5 * (b_tx * d_tx[:, j:j + 1] + b_rx * d_rx[:, j:j + 1]) for j in (0, 1)]
        if self.deep:
            blocks += [mean * centre[:, j:j + 1] for j in (0, 1)]
        self.fixed = blocks
        self.t0 = pert.t0 or 2.0 * abs(float(np.mean(apriori[:, 2]))) / c0
        self.unit = TRAVEL_TIME_SCALE / self.t0  # GARPOS's unit of the log residuals and the coefficients
        lam0 = 10.0 ** pert.log_lambda0
        omega = roughness(knots)
        self.prior_blocks = [omega / lam0] + [omega / (lam0 * 10.0 ** pert.log_grad_lambda)] * (len(blocks) - 1)

    def width(self) -> int:
        """The perturbation's coefficients, all bases."""
        if self.pert.kind == "garpos":
            return sum(b.shape[1] for b in self.fixed)
        return self.n_bases + 2 * self.deep + 2 * self.shallow

    def active(self, used: np.ndarray) -> np.ndarray:
        """The coefficients a fit of the ``used`` replies solves: ``ntd`` the bases they touch (SeaGap's
        ``retrieveb``) and the gradients, ``garpos`` all (the prior holds a basis without data)."""
        if self.pert.kind == "garpos":
            return np.ones(self.width(), dtype=bool)
        touched = np.any(self.spline[used] != 0.0, axis=0)
        return np.concatenate((touched, np.ones(2 * self.deep + 2 * self.shallow, dtype=bool)))

    def columns(self, rows: np.ndarray, tx: np.ndarray, rx: np.ndarray, x: np.ndarray) -> np.ndarray:
        """All the perturbation's columns at ``rows`` (``ntd``: of the nadir-normalised time [s]; ``garpos``: of
        the log time in units of :attr:`unit`), shape (len(rows), width)."""
        if self.pert.kind == "garpos":
            return np.hstack([b[rows] for b in self.fixed])
        blocks = [self.spline[rows]]
        if self.deep:
            blocks.append(0.5 * (slant_direction(tx, x) + slant_direction(rx, x)))
        if self.shallow:
            blocks.append(self.fixed[1][rows])
        return np.hstack(blocks)

    def prior(self, q: int, active: np.ndarray) -> np.ndarray | None:
        """GARPOS's prior information over the solved unknowns (none on the positions); None for ``ntd``."""
        if self.pert.kind == "ntd":
            return None
        out = np.zeros((q + len(active), q + len(active)))
        at = q
        for block in self.prior_blocks:
            out[at:at + len(block), at:at + len(block)] = block
            at += len(block)
        keep = np.concatenate((np.ones(q, dtype=bool), active))
        return out[np.ix_(keep, keep)]

    def covariance(self, used: np.ndarray) -> _DataCovariance:
        """The data covariance of the ``used`` replies (``ntd``: the identity)."""
        return _DataCovariance(self, used)


class _DataCovariance:
    """:math:`E = L L^\\top` of a fit's replies: ``whiten`` applies :math:`L^{-1}`; ``log_det_inverse`` is
    :math:`\\ln|E^{-1}|` (GARPOS's units)."""

    def __init__(self, design: _Design, used: np.ndarray):
        self.kind = design.pert.kind
        self.factor = None
        self.log_det_inverse = 0.0
        if self.kind == "ntd":
            return
        r = design.replies
        scale = r.twtt[used] / design.t0
        self.inverse_sd = scale  # GARPOS: the log residual's sigma in units of ``unit`` is T0 / T
        pert = design.pert
        if pert.mu_t > 0.0 and pert.reject_sigma == 0.0:
            t, transponder = r.t_tx[used], r.transponder[used]
            self.order = np.argsort(t, kind="stable")
            band = correlation_band(t[self.order], transponder[self.order], scale[self.order], pert.mu_t, pert.mu_mt)
            try:
                self.factor = cholesky_banded(band, lower=True)
            except np.linalg.LinAlgError:
                raise ModelError(f"mu_t: the data covariance of correlation length {pert.mu_t:g} s is not positive "
                                 "definite (its reach is cut at 4 lengths); take a shorter one") from None
            self.log_det_inverse = -2.0 * float(np.sum(np.log(self.factor[0])))
        else:
            self.log_det_inverse = float(np.sum(np.log(scale**2)))

    def whiten(self, a: np.ndarray) -> np.ndarray:
        if self.kind == "ntd":
            return a
        if self.factor is None:
            return a * (self.inverse_sd[:, None] if a.ndim == 2 else self.inverse_sd)
        out = np.empty_like(a)
        out[self.order] = solve_banded((self.factor.shape[0] - 1, 0), self.factor, a[self.order])
        return out


def _perturbed_model(design: _Design, apriori: np.ndarray, theta: np.ndarray, c0: float, rigid: bool,
                     legs: LegModel, rows: np.ndarray):
    """At the unknowns ``theta`` (positions, then all the perturbation's coefficients), for the replies ``rows``:
    the residual and the Jacobian of the prediction in the perturbation's units, the legs' time, the TWTT residual
    [s], the mapping, the positions, the transponders and the perturbation's columns."""
    q = 3 if rigid else 3 * len(apriori)
    replies = design.replies.subset(rows)
    if design.linear is None:
        residual_m, jacobian, _, position, _, x = _model(replies, apriori, theta[:q], c0, rigid, False, legs, 0.0)
    else:  # the legs linearised about a reference solution (a search's candidates)
        reference, residual_0, jacobian_0 = design.linear
        jacobian = jacobian_0[rows]
        residual_m = residual_0[rows] - jacobian @ (theta[:q] - reference)
        shift = theta[:q].reshape(-1, 3)
        position = apriori + shift if not rigid else apriori + shift[0]
        x = position[replies.transponder]
    tau = replies.twtt - residual_m / c0
    p = design.columns(rows, replies.tx, replies.rx, x)
    radius = design.pert.earth_radius
    mapping = 0.5 * (nadir_cosine(replies.tx, x, radius) + nadir_cosine(replies.rx, x, radius))
    model = p @ theta[q:]
    if design.pert.kind == "ntd":
        residual = mapping * (replies.twtt - tau) - model
        a = np.hstack((mapping[:, None] * jacobian / c0, p))
        seconds = residual / mapping
    else:
        residual = (np.log(replies.twtt) - np.log(tau)) / design.unit + model
        a = np.hstack((jacobian / (c0 * tau * design.unit)[:, None], -p))
        seconds = replies.twtt - tau * np.exp(-design.unit * model)
    return residual, a, tau, seconds, mapping, position, x, p


def _perturbed_fit(design: _Design, apriori: np.ndarray, c0: float, rigid: bool, legs: LegModel, used: np.ndarray,
                   theta: np.ndarray, what: str):
    """Gauss-Newton on the positions and the active coefficients of the ``used`` replies (GARPOS: with its prior),
    from ``theta``; returns theta (inactive coefficients 0), the iterations, convergence, the active mask, the
    prior, the data covariance and the last normal matrix."""
    q = 3 if rigid else 3 * len(apriori)
    rows = np.flatnonzero(used)
    active = design.active(used)
    keep = np.concatenate((np.ones(q, dtype=bool), active))
    theta = np.where(keep, theta, 0.0)
    prior = design.prior(q, active)
    data = design.covariance(used)
    converged, iterations, normal = False, 0, None
    for iterations in range(1, MAX_ITERATIONS + 1):  # noqa: B007 (the count is returned)
        residual, a, *_ = _perturbed_model(design, apriori, theta, c0, rigid, legs, rows)
        wa, wr = data.whiten(a[:, keep]), data.whiten(residual)
        normal, rhs = wa.T @ wa, wa.T @ wr
        if prior is not None:
            normal = normal + prior
            rhs = rhs - prior @ theta[keep]
        try:
            step = np.linalg.solve(normal, rhs)
        except np.linalg.LinAlgError:
            raise ModelError(f"{what}: the replies do not determine the positions and the perturbation (the normal "
                             "matrix is singular): fewer bases, or replies from more directions") from None
        theta[keep] += step
        if np.max(np.abs(step[:q])) <= POSITION_TOLERANCE:
            converged = True
            break
    return theta, iterations, converged, keep, prior, data, normal


def _solve_perturbed(replies: Replies, apriori: np.ndarray, c0: float, rigid: bool, legs: LegModel,
                     pert: Perturbation, outlier_factor: float | None, what: str,
                     linear: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                     start_positions: np.ndarray | None = None) -> Solution:
    """:func:`solve` with a sound-speed perturbation (:class:`Perturbation`): the outlier rule on the TWTT
    residuals [s], and GARPOS's rejection of the residuals beyond ``reject_sigma`` standard deviations of their
    mean (judged on every reply after each solution). ``linear``: the legs linearised about a reference
    (:func:`select`); ``start_positions``: the positions' unknowns to start from."""
    k = len(apriori)
    q = 3 if rigid else 3 * k
    n = len(replies)
    start, end = float(np.min(replies.t_tx)), float(np.max(replies.t_rx))
    if not end > start:
        raise ModelError(f"{what}: the replies span no time; a perturbation in time needs a survey of some duration")
    n_bases = pert.n_bases or interval_bases(start, end, pert.knot_interval)
    knots = uniform_knots(start, end, n_bases)
    design = _Design(pert, replies, apriori, knots, c0)
    design.linear = linear
    theta = np.zeros(q + design.width())
    if start_positions is not None:
        theta[:q] = start_positions
    used = np.ones(n, dtype=bool)
    every = np.arange(n)
    for _ in range(n):
        size = q + int(design.active(used).sum())
        if used.sum() <= size:
            raise ModelError(f"{what}: {int(used.sum())} replies for {size} unknowns (the positions and the "
                             f"perturbation's {n_bases} bases); at least {size + 1} are needed: fewer bases")
        theta, iterations, converged, keep, prior, data, normal = _perturbed_fit(design, apriori, c0, rigid, legs,
                                                                                  used, theta, what)
        model = _perturbed_model(design, apriori, theta, c0, rigid, legs, every)
        residual, seconds = model[0], model[3]
        if outlier_factor is not None and used.sum() > size + 1:
            worst = float(np.max(np.abs(seconds[used])))
            if worst > outlier_factor * float(np.sqrt(np.mean(seconds[used] ** 2))):
                used &= np.abs(seconds) != worst
                continue
        if pert.reject_sigma > 0.0:
            mean, sd = float(np.mean(residual[used])), float(np.std(residual[used], ddof=1))
            judged = np.abs(residual - mean) <= pert.reject_sigma * sd
            if not np.array_equal(judged, used):
                used = judged
                continue
        break
    return _perturbed_solution(design, apriori, c0, rigid, knots, theta, used, keep, prior, data, normal, iterations,
                               converged, model)


def _perturbed_solution(design: _Design, apriori: np.ndarray, c0: float, rigid: bool, knots: np.ndarray,
                        theta: np.ndarray, used: np.ndarray, keep: np.ndarray, prior: np.ndarray | None,
                        data: _DataCovariance, normal: np.ndarray, iterations: int, converged: bool,
                        model: tuple) -> Solution:
    """The solution's statistics: SeaGap's (a posteriori variance, AIC, BIC) or GARPOS's (ABIC); ``model`` is
    :func:`_perturbed_model` of every reply at ``theta``."""
    pert = design.pert
    replies = design.replies
    k = len(apriori)
    q = 3 if rigid else 3 * k
    n = len(replies)
    residual, _, tau, seconds, mapping, position, x, p = model
    m = int(used.sum())
    parameters = int(keep.sum())
    inverse = np.linalg.inv(normal)
    aic = bic = abic = None
    if pert.kind == "ntd":
        variance = float(np.sum(residual[used] ** 2) / (m - parameters))
        aic, bic = akaike(residual[used], parameters)
        sigma_t = np.sqrt(variance) / mapping  # each TWTT residual's sigma [s]
    else:
        misfit = float(np.sum(data.whiten(residual[used]) ** 2))
        penalty = float(theta[keep] @ prior @ theta[keep])
        eigen = np.linalg.eigvalsh(prior[q:, q:])
        positive = eigen[eigen > 1e-8 / 10.0**pert.log_lambda0]
        dof = m + len(positive) - parameters
        variance = (misfit + penalty) / dof
        abic = (dof * math.log(misfit + penalty) - data.log_det_inverse - float(np.sum(np.log(positive)))
                + float(np.linalg.slogdet(normal)[1]))
        sigma_t = np.full(n, np.sqrt(variance) * TRAVEL_TIME_SCALE)
    covariance_all = variance * inverse
    sd = np.sqrt(np.diag(covariance_all))
    full_sd = np.zeros(len(theta))
    full_sd[keep] = sd
    sigma = np.tile(sd[:3], (k, 1)) if rigid else sd[:q].reshape(k, 3)
    w = 1.0 / (c0 * sigma_t) ** 2
    residual_m = c0 * seconds
    wrms = float(np.sqrt(np.sum(w[used] * residual_m[used] ** 2) / np.sum(w[used])))
    elevation, azimuth, scatter = _directions(replies, x, residual_m, w, used, k)
    order = np.argsort(design.mid[used], kind="stable")
    coefficients = theta[q:]
    units = design.unit
    background, bg_sd = coefficients[:design.n_bases] * units, full_sd[q:q + design.n_bases] * units
    gradient, gradient_sd = {}, {}
    rest, rest_sd = coefficients[design.n_bases:] * units, full_sd[q + design.n_bases:] * units
    if pert.kind == "ntd":  # the columns' order: the bases, the deep gradient, the shallow one
        names = (["deep"] if design.deep else []) + (["shallow"] if design.shallow else [])
        for j, name in enumerate(names):
            gradient[name], gradient_sd[name] = rest[2 * j:2 * j + 2], rest_sd[2 * j:2 * j + 2]
        delay = design.spline @ coefficients[:design.n_bases]
        observed = mapping * (replies.twtt - tau) - (p[:, design.n_bases:] @ coefficients[design.n_bases:])
    else:  # GARPOS's order: the background, the shallow gradient, the deep one
        b = design.n_bases
        names = (["shallow"] if design.shallow else []) + (["deep"] if design.deep else [])
        for j, name in enumerate(names):
            gradient[name] = rest[2 * j * b:(2 * j + 2) * b].reshape(2, b)
            gradient_sd[name] = rest_sd[2 * j * b:(2 * j + 2) * b].reshape(2, b)
        delay = (tau * np.exp(-units * (p @ coefficients)) - tau) * mapping
        observed = (replies.twtt - tau) * mapping
    fit = PerturbationFit(settings=pert, n_bases=design.n_bases, knots=knots, used_bases=keep[q:q + design.n_bases],
                          coefficients=background, coefficient_sigma=bg_sd, gradient=gradient,
                          gradient_sigma=gradient_sd, delay=delay, observed=observed, mapping=mapping,
                          mid_time=design.mid, parameters=parameters, aic=aic, bic=bic, abic=abic,
                          effective_scale=effective_scale(residual[used][order]))
    return Solution(position=position, offset=position - apriori, sigma=sigma, covariance=covariance_all[:q, :q],
                    sound_speed=float(c0), sound_speed_sigma=0.0, used=used, residual_m=residual_m,
                    residual_s=seconds, weight=w, elevation=elevation, azimuth=azimuth, wrms_m=wrms,
                    variance_factor=variance, scatter=scatter, iterations=iterations, converged=converged,
                    perturbation=fit)


def _search_criterion(kind: str, criterion: str) -> str:
    return "abic" if kind == "garpos" else criterion


def select(replies: Replies, apriori: Sequence[Sequence[float]] | np.ndarray, sound_speed: float,
           candidates: Sequence[Perturbation], *, rigid: bool = False, outlier_factor: float | None = None,
           legs: LegModel | None = None, what: str = "calibration", criterion: str = "bic",
           reference: Solution | None = None) -> tuple[Solution, list[dict]]:
    """The perturbation chosen among ``candidates`` by an information criterion, and every candidate's.

    SeaGap's search over the number of bases takes the smallest AIC or BIC (:func:`~sblsim.models.perturbation.
    akaike`; Tomita and Kido, 2022), GARPOS's over its hyperparameters the smallest ABIC (Akaike's Bayesian
    information criterion of the smoothness prior, H. Akaike, in *Bayesian Statistics*, 1980; Watanabe et al.,
    2020, eq. 22). The first candidate is solved in full; every candidate is then solved with the legs linearised
    about that solution's positions (the candidates move them by millimetres, which changes the travel times'
    linearisation by :math:`10^{-10}` s), and the chosen one is solved in full from there.

    Parameters
    ----------
    replies, apriori, sound_speed, rigid, outlier_factor, legs, what
        As :func:`solve`.
    candidates : sequence of Perturbation
        One kind for all (``ntd`` or ``garpos``).
    criterion : str
        ``"aic"`` or ``"bic"`` (:data:`~sblsim.models.perturbation.CRITERIA`) for ``ntd``; ``garpos`` takes ABIC.
    reference : Solution or None
        A solution of these replies to linearise about instead of the first candidate's.

    Returns
    -------
    solution : Solution
        The chosen candidate's.
    table : list of dict
        Per candidate: ``n_bases``, ``log_lambda0``, ``log_grad_lambda``, ``mu_t``, ``mu_mt``, ``aic``, ``bic``,
        ``abic``, ``twtt_residual_rms_s``, ``e_m``, ``n_m``, ``u_m`` (the first transponder's offset), ``chosen``.

    Raises
    ------
    ModelError
        No candidate, kinds mixed, an unknown criterion, or what :func:`solve` raises.
    """
    if not candidates:
        raise ModelError(f"{what}: no candidate perturbation to choose from")
    if len({c.kind for c in candidates}) != 1:
        kinds = ", ".join(sorted({c.kind for c in candidates}))
        raise ModelError(f"{what}: the candidates mix perturbations ({kinds})")
    if criterion not in CRITERIA:
        raise ModelError(f"criterion: {str(criterion)[:40]!r} is not one of {', '.join(CRITERIA)}")
    apriori = np.asarray(apriori, dtype=float)
    legs = legs or StraightRay()
    first = reference or solve(replies, apriori, sound_speed, rigid=rigid, outlier_factor=outlier_factor, legs=legs,
                               what=what, perturbation=candidates[0])
    if len(candidates) == 1 and reference is None:
        return first, [_candidate_row(candidates[0], first, True)]
    reference = first.offset[0] if rigid else first.offset.ravel()
    residual, jacobian = _model(replies, apriori, reference, float(sound_speed), rigid, False, legs, 0.0)[:2]
    name = _search_criterion(candidates[0].kind, criterion)
    solutions = []
    for candidate in candidates:
        _check_perturbation(candidate, replies, False)
        solutions.append(_solve_perturbed(replies, apriori, float(sound_speed), rigid, legs, candidate, outlier_factor,
                                          what, (reference, residual, jacobian), reference))
    values = [getattr(s.perturbation, name) for s in solutions]
    best = int(np.argmin(values))
    start = solutions[best].offset[0] if rigid else solutions[best].offset.ravel()
    chosen = first if best == 0 and first.perturbation.settings == candidates[0] else \
        _solve_perturbed(replies, apriori, float(sound_speed), rigid, legs, candidates[best], outlier_factor, what,
                         None, start)
    return chosen, [_candidate_row(c, s, k == best) for k, (c, s) in enumerate(zip(candidates, solutions))]


def _candidate_row(candidate: Perturbation, solution: Solution, chosen: bool) -> dict:
    fit = solution.perturbation
    used = solution.used
    return {"n_bases": fit.n_bases, "log_lambda0": candidate.log_lambda0, "log_grad_lambda": candidate.log_grad_lambda,
            "mu_t": candidate.mu_t, "mu_mt": candidate.mu_mt, "aic": fit.aic, "bic": fit.bic, "abic": fit.abic,
            "twtt_residual_rms_s": float(np.sqrt(np.mean(solution.residual_s[used] ** 2))),
            "e_m": float(solution.offset[0, 0]), "n_m": float(solution.offset[0, 1]),
            "u_m": float(solution.offset[0, 2]), "chosen": chosen}


def crb(replies: Replies, positions: Sequence[Sequence[float]] | np.ndarray, sound_speed: float, *,
        rigid: bool = False, solve_sound_speed: bool = False, twtt_sigma: float = 0.0,
        legs: LegModel | None = None, perturbation: Perturbation | None = None) -> np.ndarray:
    """The Cramér-Rao bound of a survey's unknowns: :math:`(J^\\top W J)^{-1}` at the truth.

    The Fisher information of the replies' range residuals (Gaussian, independent, variances
    :math:`\\sigma_i^2` of the line-of-sight projection of :func:`solve`) is :math:`J^\\top W J`, with
    :math:`J` the Jacobian of the two legs at the true positions and :math:`W = \\mathrm{diag}(1/\\sigma_i^2)`.
    Its inverse bounds the covariance of any unbiased estimator of the (static) transponders: for a static
    state the posterior CRB (PCRB) without a prior is this CRB.

    Parameters
    ----------
    replies : Replies
        The replies at the truth: the transducer's true transmit and receive positions [m], their 1-sigma [m]
        (the noise the positions carry), the true TWTTs [s] (used only with ``solve_sound_speed``).
    positions : array_like, shape (k, 3)
        The transponders' true positions, local ENU [m].
    sound_speed : float
        The true sound speed [m/s].
    rigid, solve_sound_speed, twtt_sigma, legs
        As :func:`solve` (``twtt_sigma``: the TWTT noise [s]).
    perturbation : Perturbation or None
        The perturbation solved with the positions (the replies need their times): its coefficients are unknowns
        too (its Jacobian at the truth, the same noise mapped to its residuals, GARPOS's prior as prior
        information); the bound returned is then the positions' block.

    Returns
    -------
    numpy.ndarray, shape (p, p)
        The bound on the unknowns' covariance (3 per transponder, or 3 for a rigid shift; then the speed scale)
        [m², 1]. The horizontal bound of transponder j is ``sqrt(P[3j, 3j] + P[3j+1, 3j+1])`` [m].

    Raises
    ------
    ModelError
        A value outside its range, or replies that do not determine the unknowns (a singular information).

    Source: the CRB of a nonlinear least-squares problem with Gaussian noise, e.g. S. M. Kay, *Fundamentals of
    Statistical Signal Processing: Estimation Theory*, 1993, ch. 3; P. Tichavsky, C. H. Muravchik, A. Nehorai,
    "Posterior Cramér-Rao bounds for discrete-time nonlinear filtering", IEEE Trans. Signal Process. 46(5), 1998.
    """
    positions = np.asarray(positions, dtype=float)
    _check(replies, positions, float(sound_speed), None, float(twtt_sigma))
    theta = np.zeros(_unknowns(len(positions), rigid, solve_sound_speed))
    if solve_sound_speed:
        theta[-1] = 1.0
    _, jacobian, variance, *_ = _model(replies, positions, theta, float(sound_speed), rigid, solve_sound_speed,
                                       legs or StraightRay(), float(twtt_sigma))
    if perturbation is not None:
        return _perturbed_crb(replies, positions, float(sound_speed), rigid, legs or StraightRay(), perturbation,
                              variance)
    information = jacobian.T @ (jacobian / variance[:, None])
    try:
        return np.linalg.inv(information)
    except np.linalg.LinAlgError:
        raise ModelError("calibration: the replies do not determine the unknowns (the information is "
                         "singular)") from None


def _perturbed_crb(replies: Replies, positions: np.ndarray, c0: float, rigid: bool, legs: LegModel,
                   pert: Perturbation, variance: np.ndarray) -> np.ndarray:
    """:func:`crb` with a perturbation: the positions' block of :math:`(A^\\top W A + D/\\sigma_0^2)^{-1}`,
    :math:`A` the Jacobian of the perturbation's prediction at the truth (no perturbation), :math:`W` the inverse
    variances of its residuals (each reply's line-of-sight variance [m²] over :math:`c_0^2`, mapped), :math:`D`
    GARPOS's prior, whose covariance scales with the data's (:math:`\\sigma_0` the replies' RMS sigma over
    GARPOS's travel-time scale)."""
    _check_perturbation(pert, replies, False)
    q = 3 if rigid else 3 * len(positions)
    start, end = float(np.min(replies.t_tx)), float(np.max(replies.t_rx))
    knots = uniform_knots(start, end, pert.n_bases or interval_bases(start, end, pert.knot_interval))
    design = _Design(pert, replies, positions, knots, c0)
    theta = np.zeros(q + design.width())
    used = np.ones(len(replies), dtype=bool)
    _, a, tau, _, mapping, *_ = _perturbed_model(design, positions, theta, c0, rigid, legs, np.arange(len(replies)))
    seconds = np.sqrt(variance) / c0
    sd = mapping * seconds if pert.kind == "ntd" else seconds / (replies.twtt * design.unit)
    keep = np.concatenate((np.ones(q, dtype=bool), design.active(used)))
    information = a[:, keep].T @ (a[:, keep] / sd[:, None] ** 2)
    prior = design.prior(q, design.active(used))
    if prior is not None:
        information = information + prior / float(np.mean((seconds / TRAVEL_TIME_SCALE) ** 2))
    try:
        return np.linalg.inv(information)[:q, :q]
    except np.linalg.LinAlgError:
        raise ModelError("calibration: the replies do not determine the positions and the perturbation (the "
                         "information is singular)") from None


#: The running solution's prior 1-sigma of the a-priori positions accepted [m] and its default (wide against
#: the metre an a-priori position is usually off, not so wide that the first, far from linear, replies mislead).
PRIOR_SIGMA_RANGE = (1e-3, 1e4)
PRIOR_SIGMA_M = 10.0
#: The running solution's prior 1-sigma of the sound-speed scale [1] (0.1: 150 m/s at 1500 m/s).
PRIOR_SCALE_SIGMA = 0.1
#: The passes of the running solution accepted (1: the extended Kalman filter; more: re-linearised).
PASSES_RANGE = (1, 20)
#: The running solution's last positions agree with the least-squares solution of the same replies when no axis
#: differs by more than this many combined 1-sigma :math:`\sqrt{\sigma_{run}^2 + \sigma_{WLS}^2}` (the built-in
#: surveys stay within 2.2); farther, it did not converge from the prior (an a-priori position far outside
#: ``prior_sigma``) and its states are no solution (:func:`running_disagreement`).
RUNNING_AGREEMENT_SIGMA = 10.0


@dataclass
class Running:
    """The running solution (:func:`running`): the state after each reply.

    Attributes
    ----------
    state : numpy.ndarray, shape (n, p)
        The unknowns after each reply (3 per transponder, or 3 for a rigid shift, as offsets from the a-priori
        positions [m]; then the speed scale [1]).
    sigma : numpy.ndarray, shape (n, p)
        Their 1-sigma after each reply (the square roots of the covariance's diagonal) [m, 1].
    covariance : numpy.ndarray, shape (p, p)
        The covariance after the last reply [m², 1].
    position, position_sigma : numpy.ndarray, shape (n, k, 3)
        The transponders' positions (local ENU [m]) and their 1-sigma per axis [m] after each reply.
    innovation : numpy.ndarray, shape (n,)
        Each reply's innovation, the range residual :math:`s c_0 T - \\ell_{tx} - \\ell_{rx}` predicted by the
        state before it [m].
    innovation_variance : numpy.ndarray, shape (n,)
        Its variance :math:`S_i = H_i P_{i-1} H_i^\\top + \\sigma_i^2` [m²].
    nis : numpy.ndarray, shape (n,)
        The normalised innovation squared :math:`\\nu_i^2 / S_i` [1] (chi-square with 1 degree of freedom when the
        model and its noise are right).
    sound_speed : numpy.ndarray, shape (n,)
        The sound speed after each reply [m/s] (:math:`c_0` when it is not solved).
    passes : int
        The passes made (1: the extended Kalman filter).
    """

    state: np.ndarray
    sigma: np.ndarray
    covariance: np.ndarray
    position: np.ndarray
    position_sigma: np.ndarray
    innovation: np.ndarray
    innovation_variance: np.ndarray
    nis: np.ndarray
    sound_speed: np.ndarray
    passes: int


def running(replies: Replies, apriori: Sequence[Sequence[float]] | np.ndarray, sound_speed: float, *,
            rigid: bool = False, solve_sound_speed: bool = False, twtt_sigma: float = 0.0,
            legs: LegModel | None = None, prior_sigma: float = PRIOR_SIGMA_M, iterated: bool = True,
            passes: int = 1, what: str = "calibration") -> Running:
    """The running solution of :func:`solve`'s measurement model: a static-state Kalman filter, one scalar update
    per reply, in the replies' order.

    The state :math:`\\theta` is :func:`solve`'s unknowns (the offsets of each transponder, or one rigid shift,
    from the a-priori positions [m]; then the speed scale :math:`s`), static: no process noise. The prior is
    :math:`\\hat\\theta_0 = 0` (:math:`s = 1`) with covariance :math:`P_0 = \\mathrm{diag}(\\sigma_p^2, \\ldots,
    \\sigma_s^2)`, :math:`\\sigma_p` = ``prior_sigma`` and :math:`\\sigma_s` = :data:`PRIOR_SCALE_SIGMA`. Reply
    :math:`i` is one scalar update, linearised at the current estimate by the same leg model, Jacobian and
    line-of-sight variance as :func:`solve` (``_model``):

    .. math:: \\nu_i = s\\,c_0 T_i - \\ell_{tx} - \\ell_{rx}, \\quad S_i = H_i P_{i-1} H_i^\\top + \\sigma_i^2,
              \\quad K_i = P_{i-1} H_i^\\top / S_i,

    .. math:: \\hat\\theta_i = \\hat\\theta_{i-1} + K_i \\nu_i, \\quad
              P_i = (I - K_i H_i) P_{i-1} (I - K_i H_i)^\\top + K_i \\sigma_i^2 K_i^\\top

    (the Joseph form), with :math:`H_i` the Jacobian of the predicted path :math:`\\ell_{tx} + \\ell_{rx} - s c_0
    T_i`. ``iterated`` (the default) makes each update the iterated extended Kalman filter's: the update is
    re-linearised at its own result, :math:`\\theta^{(j+1)} = \\hat\\theta_{i-1} + K^{(j)} [\\nu(\\theta^{(j)}) -
    H^{(j)} (\\hat\\theta_{i-1} - \\theta^{(j)})]` with :math:`K^{(j)}, H^{(j)}, \\sigma_i^{(j)}` at
    :math:`\\theta^{(j)}`, until it moves less than :data:`POSITION_TOLERANCE` (Gauss-Newton on the prior and
    the one reply): with a prior metres wide the first replies are far from linear, and the plain extended filter
    (``iterated=False``) can lock onto a wrong point; the innovation and its variance are those at
    :math:`\\hat\\theta_{i-1}`. With a linear model this is recursive least squares: the last state is the
    weighted least-squares solution with the prior as one more observation. With ``passes`` > 1 the filter is run
    again from the same prior, each reply linearised at the previous pass's last state :math:`\\bar\\theta` (the
    innovation :math:`\\nu_i(\\bar\\theta) - H_i(\\hat\\theta_{i-1} - \\bar\\theta)`, the variance at
    :math:`\\bar\\theta`): each pass is one Gauss-Newton step of the batch problem with the prior, so the last
    state converges to :func:`solve`'s (to the prior's pull, :math:`\\sim\\sigma^2_{\\mathrm{WLS}}/\\sigma_p^2` of
    the offset); its running states are then no longer causal. No outlier rule: give it the replies :func:`solve` kept.

    Parameters
    ----------
    replies : Replies
        The replies (n rows), in the order they are taken (time).
    apriori : array_like, shape (k, 3)
        The a-priori positions, local ENU [m] (the prior's mean).
    sound_speed : float
        :math:`c_0` [m/s], in :data:`SOUND_SPEED_RANGE`.
    rigid, solve_sound_speed, twtt_sigma, legs, what
        As :func:`solve`.
    prior_sigma : float
        The prior 1-sigma of the a-priori positions per axis [m], in :data:`PRIOR_SIGMA_RANGE`.
    iterated : bool
        Iterate each update (the iterated extended Kalman filter); False: the extended Kalman filter.
    passes : int
        1: one causal pass; more: passes re-linearised at the previous pass's last state, in :data:`PASSES_RANGE`.

    Returns
    -------
    Running

    Raises
    ------
    ModelError
        A value outside its range, no reply, or a leg the leg model cannot trace.

    Source: Y. Bar-Shalom, X. R. Li, T. Kirubarajan, *Estimation with Applications to Tracking and Navigation*,
    Wiley, 2001: ch. 5 (the Kalman filter, the Joseph form, the NIS test), ch. 3.4 (recursive least squares as
    the static Kalman filter), ch. 10.3 (the extended and the iterated filters).
    """
    apriori = np.asarray(apriori, dtype=float)
    _check(replies, apriori, float(sound_speed), None, float(twtt_sigma))
    lo, hi = PRIOR_SIGMA_RANGE
    if isinstance(prior_sigma, bool) or not (np.isfinite(prior_sigma) and lo <= prior_sigma <= hi):
        raise ModelError(f"prior_sigma_m: {prior_sigma!r} is outside the allowed range [{lo:g}, {hi:g}] m")
    lo, hi = PASSES_RANGE
    if isinstance(passes, bool) or not isinstance(passes, (int, np.integer)) or not lo <= passes <= hi:
        raise ModelError(f"passes: {passes!r} is outside the allowed range [{lo}, {hi}]")
    if len(replies) == 0:
        raise ModelError(f"{what}: no reply for the running solution")
    legs = legs or StraightRay()
    k = len(apriori)
    p = _unknowns(k, rigid, solve_sound_speed)
    n = len(replies)
    prior = np.zeros(p)
    p0 = np.full(p, float(prior_sigma) ** 2)
    if solve_sound_speed:
        prior[-1] = 1.0
        p0[-1] = PRIOR_SCALE_SIGMA**2
    reference = None
    for _ in range(passes):
        theta, cov = prior.copy(), np.diag(p0)
        states, sigmas = np.zeros((n, p)), np.zeros((n, p))
        innovation, variance_s = np.zeros(n), np.zeros(n)
        eye = np.eye(p)
        for i in range(n):
            one = replies.subset(np.array([i]))
            at = theta if reference is None else reference
            for iteration in range(MAX_ITERATIONS if iterated and reference is None else 1):
                residual, jacobian, variance, *_ = _model(one, apriori, at, float(sound_speed), rigid,
                                                          solve_sound_speed, legs, float(twtt_sigma))
                h = jacobian[0]
                nu = residual[0] - h @ (theta - at)  # the innovation linearised at ``at``
                ph = cov @ h
                s = float(h @ ph + variance[0])
                gain = ph / s
                if iteration == 0:
                    innovation[i], variance_s[i] = nu, s
                updated = theta + gain * nu
                step = np.abs(updated - at)
                at = updated
                if np.max(step[:-1] if solve_sound_speed else step) <= POSITION_TOLERANCE:
                    break
            theta = at
            a = eye - np.outer(gain, h)
            cov = a @ cov @ a.T + variance[0] * np.outer(gain, gain)
            # noise-free replies (sigma 0) leave round-off below zero on the diagonal: a sigma of 0
            states[i], sigmas[i] = theta, np.sqrt(np.clip(np.diag(cov), 0.0, None))
        reference = theta
    if rigid:
        offset = np.repeat(states[:, None, :3], k, axis=1)
        offset_sigma = np.repeat(sigmas[:, None, :3], k, axis=1)
    else:
        offset = states[:, :3 * k].reshape(n, k, 3)
        offset_sigma = sigmas[:, :3 * k].reshape(n, k, 3)
    speed = float(sound_speed) * (states[:, -1] if solve_sound_speed else np.ones(n))
    return Running(state=states, sigma=sigmas, covariance=cov, position=apriori[None] + offset,
                   position_sigma=offset_sigma, innovation=innovation, innovation_variance=variance_s,
                   nis=innovation**2 / variance_s, sound_speed=speed, passes=int(passes))


def running_disagreement(run: Running, solution: Solution) -> tuple[np.ndarray, np.ndarray]:
    """How far the running solution ends from the least-squares solution of the same replies, per transponder.

    Parameters
    ----------
    run : Running
        :func:`running` of the replies :func:`solve` kept.
    solution : Solution
        :func:`solve`'s solution.

    Returns
    -------
    distance : numpy.ndarray, shape (k,)
        From the running solution's last position to the least-squares position [m].
    sigmas : numpy.ndarray, shape (k,)
        The largest per-axis difference in combined 1-sigma :math:`\\sqrt{\\sigma_{run}^2 + \\sigma_{WLS}^2}` [1]
        (above :data:`RUNNING_AGREEMENT_SIGMA`: the running solution did not converge).
    """
    difference = run.position[-1] - solution.position
    combined = np.sqrt(run.position_sigma[-1] ** 2 + solution.sigma ** 2)
    scaled = np.divide(np.abs(difference), combined, out=np.full_like(difference, np.inf), where=combined > 0.0)
    scaled[difference == 0.0] = 0.0
    return np.linalg.norm(difference, axis=1), np.max(scaled, axis=1)


@dataclass(frozen=True)
class Combined:
    """Segment solutions combined (:func:`combine`), per transponder, local ENU [m].

    Attributes
    ----------
    position, sigma : numpy.ndarray, shape (k, 3)
        The weighted mean and its 1-sigma propagated from the segments' covariances (taken as independent) [m].
    scatter : numpy.ndarray, shape (k, 3)
        The weighted standard deviation of the segment solutions about the mean [m] (Xie et al.'s "std"); NaN
        with one segment.
    """

    position: np.ndarray
    sigma: np.ndarray
    scatter: np.ndarray


def combine(solutions: Sequence[Solution]) -> Combined:
    """Combine segment solutions as Xie et al. (2023) do: a weighted mean per axis, weights
    :math:`1/s_k^2` with :math:`s_k` the segment's projected residual RMS (:attr:`Solution.scatter`).

    Parameters
    ----------
    solutions : sequence of Solution
        The segments' solutions of the same transponders (at least one).

    Returns
    -------
    Combined

    Raises
    ------
    ModelError
        No solution.
    """
    if not solutions:
        raise ModelError("segments: no segment to combine")
    x = np.stack([s.position for s in solutions])  # (m, k, 3)
    sd = np.stack([s.sigma for s in solutions])
    w = 1.0 / np.stack([s.scatter for s in solutions]) ** 2
    total = np.sum(w, axis=0)
    mean = np.sum(w * x, axis=0) / total
    sigma = np.sqrt(np.sum(w**2 * sd**2, axis=0)) / total
    m = len(solutions)
    if m > 1:
        scatter = np.sqrt(np.sum(w * (x - mean) ** 2, axis=0) / ((m - 1) * total / m))
    else:
        scatter = np.full_like(mean, np.nan)
    return Combined(mean, sigma, scatter)


__all__ = ["combine", "Combined", "crb", "EARTH_RADIUS_RANGE", "EigenRay", "LegModel", "MAX_ITERATIONS",
           "MAX_SOUND_SPEED_SIGMA", "OUTLIER_FACTOR_RANGE", "PASSES_RANGE", "Perturbation", "PerturbationFit",
           "POSITION_TOLERANCE", "PRIOR_SCALE_SIGMA", "PRIOR_SIGMA_M", "PRIOR_SIGMA_RANGE", "Replies", "Running",
           "running", "RUNNING_AGREEMENT_SIGMA", "running_disagreement", "SCALE_TOLERANCE", "select", "Solution",
           "solve", "SOUND_SPEED_RANGE", "StraightRay", "TRANSDUCER_DEPTH_RANGE"]

"""The leg models of a calibration: the acoustic path length of a leg between the surface transducer and a
seafloor transponder, and its gradient.

The solver (:func:`~sblsim.models.calibration.solve`) asks a leg model (:class:`LegModel`) for the path length of
each leg, its travel time times the solver's reference speed :math:`c_0`: :class:`StraightRay` is the straight ray
at one speed (what Xie et al. use) or at one speed per transponder (GNATSS's harmonic mean down to each
transponder), :class:`EigenRay` the direct eigenray through a sound-speed profile
(:mod:`sblsim.models.acoustics.rays`), in flat or spherical layers, the profile fixed to the sea surface or hung
from the transducer (SeaGap's options). The sound speeds every solver of the package accepts are
:data:`SOUND_SPEED_RANGE`.
"""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np

from sblsim.models.acoustics.ray_tables import exact_points
from sblsim.models.acoustics.rays import profile_arrays
from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS
from sblsim.models.declarations import ModelError

#: The sound speeds accepted [m/s].
SOUND_SPEED_RANGE = (1300.0, 1800.0)
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


__all__ = ["EARTH_RADIUS_RANGE", "EigenRay", "LegModel", "SOUND_SPEED_RANGE", "StraightRay", "TRANSDUCER_DEPTH_RANGE"]

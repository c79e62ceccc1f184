"""Sound-speed profiles and the effective sound speed of a straight acoustic path.

Along a straight ray between depths z1 and z2 (ray bending is negligible over
the tens of metres of an SBL system) the travel time is
``τ = (ρ / |z2 - z1|) ∫ dz / c(z)``: the range ρ over the harmonic mean of
c(z) between the two depths. :class:`SoundSpeedProfile` precomputes the
cumulative slowness ``S(z) = ∫_0^z dz / c`` on the cast's depths (trapezoid
rule, constant extrapolation outside the cast) and evaluates the harmonic mean
in O(1) per path.

References
----------
Jensen, Kuperman, Porter, Schmidt, Computational Ocean Acoustics, 2nd ed.,
Springer 2011, ch. 3 (ray travel time). IOC, SCOR, IAPSO, The international
thermodynamic equation of seawater - 2010 (TEOS-10), via the ``gsw`` package.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np

from models.core import ModelError

#: Real CTD casts shipped with sblsim (see models/acoustics/data/README.md).
BUILTIN_CASTS = ("11E101663_20120821_122817", "11E101663_20120821_145912")


class SoundSpeedProfile:
    """A sound-speed profile c(z) and harmonic means over depth intervals.

    Parameters
    ----------
    depth : ndarray, shape (n,)
        Strictly increasing depths [m].
    speed : ndarray, shape (n,)
        Sound speed at those depths [m/s].

    Raises
    ------
    ModelError
        If the arrays are empty, not finite, depths not increasing or speeds
        not positive.
    """

    def __init__(self, depth: np.ndarray, speed: np.ndarray) -> None:
        depth = np.asarray(depth, dtype=float).reshape(-1)
        speed = np.asarray(speed, dtype=float).reshape(-1)
        if depth.size < 1 or depth.size != speed.size or not (np.all(np.isfinite(depth)) and np.all(np.isfinite(speed))):
            raise ModelError("acoustics.sound_speed_profile: needs matching finite depth and speed columns")
        if np.any(np.diff(depth) <= 0.0):
            raise ModelError("acoustics.sound_speed_profile: depths must be strictly increasing")
        if np.any(speed <= 0.0):
            raise ModelError("acoustics.sound_speed_profile: sound speeds must be positive [m/s]")
        # Extend to the surface and far below with the end values (constant extrapolation).
        self.depth = np.concatenate([[min(depth[0], 0.0) - 1e4], depth, [depth[-1] + 1e4]])
        self.speed = np.concatenate([[speed[0]], speed, [speed[-1]]])
        slowness = 1.0 / self.speed
        steps = 0.5 * (slowness[1:] + slowness[:-1]) * np.diff(self.depth)
        self._cumulative = np.concatenate([[0.0], np.cumsum(steps)])

    @classmethod
    def constant(cls, speed: float) -> "SoundSpeedProfile":
        """A depth-independent sound speed [m/s]."""
        return cls(np.array([0.0]), np.array([speed]))

    def speed_at(self, z: np.ndarray) -> np.ndarray:
        """Sound speed at depth ``z`` [m], linear interpolation [m/s]."""
        return np.interp(z, self.depth, self.speed)

    def slowness_integral(self, z: np.ndarray) -> np.ndarray:
        """``S(z) = ∫ dz / c`` from the profile's top to ``z`` [s]."""
        z = np.asarray(z, dtype=float)
        k = np.clip(np.searchsorted(self.depth, z) - 1, 0, self.depth.size - 2)
        z0, c0 = self.depth[k], self.speed[k]
        gradient = (self.speed[k + 1] - c0) / (self.depth[k + 1] - z0)
        c = c0 + gradient * (z - z0)
        # trapezoid within the segment, consistent with the cumulative table
        return self._cumulative[k] + 0.5 * (1.0 / c0 + 1.0 / c) * (z - z0)

    def harmonic_mean(self, z1: np.ndarray, z2: np.ndarray) -> np.ndarray:
        """Harmonic-mean sound speed between depths ``z1`` and ``z2`` [m/s].

        Parameters
        ----------
        z1, z2 : ndarray, broadcastable
            End depths of the path [m].

        Returns
        -------
        ndarray
            ``|z2 - z1| / |S(z2) - S(z1)|``, or ``c(z1)`` where the path is level.
        """
        z1, z2 = np.broadcast_arrays(np.asarray(z1, float), np.asarray(z2, float))
        dz = z2 - z1
        level = np.abs(dz) < 1e-9
        ds = self.slowness_integral(z2) - self.slowness_integral(z1)
        safe = np.where(level, 1.0, ds)
        return np.where(level, self.speed_at(0.5 * (z1 + z2)), dz / safe)


def read_castaway_csv(path: str | Path) -> SoundSpeedProfile:
    """Read a Castaway CTD processed cast (``%`` header lines, then CSV).

    Uses the columns ``Depth (Meter)`` and ``Sound velocity (Meters per Second)``;
    a plain two-column CSV ``depth, sound_speed`` (with a header line) is read too.
    Repeated depths are averaged.

    Raises
    ------
    ModelError
        If the file is missing or has no usable depth and sound-speed columns.
    """
    import pandas as pd

    try:
        table = pd.read_csv(path, comment="%")
    except (OSError, ValueError) as exc:
        raise ModelError(f"acoustics.sound_speed_profile: cannot read {str(path)!r} ({exc.__class__.__name__})") from None
    depth_col = next((c for c in table.columns if c.lower().startswith("depth")), None)
    speed_col = next((c for c in table.columns if "sound" in c.lower() or "velocity" in c.lower()), None)
    if depth_col is None or speed_col is None:
        raise ModelError(f"acoustics.sound_speed_profile: {str(path)!r} needs a depth and a sound-speed column")
    grouped = table[[depth_col, speed_col]].apply(pd.to_numeric, errors="coerce").dropna().groupby(depth_col).mean()
    return SoundSpeedProfile(grouped.index.to_numpy(), grouped[speed_col].to_numpy())


def teos10_profile(temperature: float, salinity: float, max_depth: float = 100.0,
                   latitude: float = 43.0) -> SoundSpeedProfile:
    """Sound-speed profile of a uniform water column from TEOS-10 (``gsw``).

    Parameters
    ----------
    temperature : float
        In-situ temperature [degC].
    salinity : float
        Practical salinity [g/kg] (PSS-78, taken as absolute salinity).
    max_depth : float
        Deepest depth of the profile [m].
    latitude : float
        Latitude for the depth-to-pressure conversion [deg].
    """
    import gsw

    depth = np.linspace(0.0, max_depth, 101)
    pressure = gsw.p_from_z(-depth, latitude)
    conservative = gsw.CT_from_t(salinity, temperature, pressure)
    return SoundSpeedProfile(depth, gsw.sound_speed(salinity, conservative, pressure))


def load_profile(spec: str, constant_speed: float, temperature: float, salinity: float) -> SoundSpeedProfile:
    """Profile from the ``acoustics.sound_speed_profile`` setting.

    Parameters
    ----------
    spec : str
        ``""`` or ``"constant"``: ``constant_speed``; ``"teos10"``: uniform
        water of the given temperature and salinity; ``"ctd:NAME"``: a cast
        shipped with sblsim (:data:`BUILTIN_CASTS`); anything else: a path to
        a CSV cast.

    Raises
    ------
    ModelError
        On an unknown built-in cast or an unreadable file.
    """
    if spec in ("", "constant"):
        return SoundSpeedProfile.constant(constant_speed)
    if spec == "teos10":
        return teos10_profile(temperature, salinity)
    if spec.startswith("ctd:"):
        name = spec[4:]
        if name not in BUILTIN_CASTS:
            raise ModelError(f"acoustics.sound_speed_profile: unknown cast {name!r}; one of "
                             + ", ".join(f"ctd:{c}" for c in BUILTIN_CASTS))
        return read_castaway_csv(resources.files("models.acoustics") / "data" / f"{name}.csv")
    if not Path(spec).is_file():
        raise ModelError(f"acoustics.sound_speed_profile: no such file {spec!r}; use constant, teos10, "
                         "ctd:NAME or a CSV path")
    return read_castaway_csv(spec)

"""Beacon geometry of the SBL platform and attitude rotations (casadi expressions).

References
----------
Cario, Casavola, Gagliardi, Lupia, Severino, "Accurate Localization in
Acoustic Underwater Localization Systems", Sensors 21(3):762, 2021,
doi:10.3390/s21030762 (Section 3, the SBL cross).
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import casadi as ca
import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.platform.waves import wave_motion
from sblsim.models.systems import SYSTEMS, system


def cross_directions(n_beacons: int = 4) -> list[tuple[float, float]]:
    """Unit arm directions ``(cos θ_i, sin θ_i)`` of a cross, θ_i = 2π i / n, with exact zeros on the axes."""
    out = []
    for i in range(n_beacons):
        theta = 2.0 * math.pi * i / n_beacons
        c, s = math.cos(theta), math.sin(theta)
        out.append((0.0 if abs(c) < 1e-15 else c, 0.0 if abs(s) < 1e-15 else s))
    return out


def cross_offsets(baseline, transducer_depth, n_beacons: int = 4) -> list[ca.SX]:
    """Body-frame offsets of beacons on a cross (equally spaced arms).

    ``a_i = L (cos θ_i, sin θ_i, 0) + (0, 0, h)`` with θ_i = 2π i / n
    (0°, 90°, 180°, 270° for the paper's four beacons).

    Parameters
    ----------
    baseline : casadi.SX or float
        Support-arm length L [m].
    transducer_depth : casadi.SX or float
        Depth h of the transducers below the platform reference [m].
    n_beacons : int
        Number of arms.

    Returns
    -------
    list of casadi.SX, each (3, 1)
        Offsets in the body frame (x forward/North, y East, z down) [m].
    """
    return [ca.vertcat(baseline * c, baseline * s, transducer_depth) for c, s in cross_directions(n_beacons)]


def parse_offsets(text: str, field: str = "platform.beacon_offsets") -> np.ndarray:
    """Parse a custom layout ``"x y z; x y z; ..."`` (commas or blanks) [m].

    Returns
    -------
    ndarray, shape (n, 3)

    Raises
    ------
    ModelError
        If the text is not a list of finite 3-vectors.
    """
    rows = [r for r in text.replace(",", " ").split(";") if r.strip()]
    try:
        offsets = np.array([[float(x) for x in r.split()] for r in rows], dtype=float)
    except ValueError:
        raise ModelError(f"{field}: expected 'x y z; x y z; ...' in metres, got {text!r}") from None
    if offsets.ndim != 2 or offsets.shape[1] != 3 or offsets.shape[0] < 1 or not np.all(np.isfinite(offsets)):
        raise ModelError(f"{field}: expected 'x y z; x y z; ...' in metres, got {text!r}")
    return offsets


def layout_offsets(layout: str, baseline: float, transducer_depth: float, beacon_offsets: str = "",
                   n_beacons: int = 4) -> np.ndarray:
    """Body-frame beacon offsets of a platform configuration, (n, 3) [m].

    Parameters
    ----------
    layout : {'cross', 'circle', 'custom'}
        ``cross`` and ``circle`` put ``n_beacons`` beacons equally spaced on a circle of radius
        ``baseline`` at depth ``transducer_depth`` (beacon i at 2π(i-1)/n from North, towards East:
        :func:`cross_offsets` with numbers); ``custom`` parses ``beacon_offsets``.
    baseline : float
        Support-arm length L, the radius of the circle [m].
    transducer_depth : float
        Depth h of the transducers below the platform reference [m].
    beacon_offsets : str
        A custom layout's offsets ``"x y z; ..."`` [m].
    n_beacons : int
        Beacons of the cross or circle (ignored for ``custom``).

    Raises
    ------
    ModelError
        If a custom layout's offsets are malformed.
    """
    if layout == "custom":
        return parse_offsets(beacon_offsets)
    return np.array([[baseline * c, baseline * s, transducer_depth] for c, s in cross_directions(n_beacons)],
                    dtype=float)  # cross_offsets with numbers


def _system(platform: Mapping[str, Any]):
    """The system of a ``[platform]`` section (without a ``system`` key: the first registered, SBL, the platform's
    default)."""
    return system(platform["system"]) if "system" in platform else next(iter(SYSTEMS.values()))


def platform_offsets(platform: Mapping[str, Any]) -> np.ndarray:
    """Offsets of the transducers of a ``[platform]`` configuration section, (n, 3) [m]: its system's
    (:meth:`sblsim.models.systems.System.offsets`: SBL body-frame offsets, LBL seafloor positions, the USBL
    transceiver's lever arm)."""
    return _system(platform).offsets(platform)


def lever_arms(platform: Mapping[str, Any]) -> np.ndarray:
    """Lever arms of the transducers of a ``[platform]`` section in NED at the mean heading (level platform),
    (n, 3) [m]: their positions when the platform reference is at the NED origin
    (:meth:`sblsim.models.systems.System.lever_arms`)."""
    return _system(platform).lever_arms(platform)


def largest_arm(platform: Mapping[str, Any]) -> float:
    """The largest distance of a beacon of a ``[platform]`` section from the platform reference [m]."""
    return float(max(np.linalg.norm(platform_offsets(platform), axis=1)))


def transducer_span(platform: Mapping[str, Any], margin: float) -> tuple[float, float, float]:
    """Where the transducers of a ``[platform]`` section go: their depths, least and greatest [m] (widened by
    ``margin`` [m] and, for transducers on the platform, by the wave heave and the lever arms' tilt at
    ``platform.beaufort``, :func:`sblsim.models.platform.waves.wave_motion`; transducers that stand elsewhere,
    seafloor transponders, do not heave; never above the surface), and their greatest horizontal distance from the
    platform's centre [m]."""
    arms = lever_arms(platform)
    rise = margin
    if not _system(platform).places_transducers:
        reach = float(np.linalg.norm(arms, axis=1).max(initial=0.0))
        tilt, _yaw, heave, _frequency = (float(v) for v in wave_motion(int(platform.get("beaufort", 0)),
                                                                         float(platform.get("hull_length", 1.0))))
        rise += heave + reach * np.sin(tilt)  # the transducers' largest vertical excursion, widened
    return (max(float(arms[:, 2].min()) - rise, 0.0), float(arms[:, 2].max()) + rise,
            float(np.linalg.norm(arms[:, :2], axis=1).max(initial=0.0)))


#: Smallest distance between two beacons [m]: closer ones are refused (:func:`check_geometry`).
MIN_SEPARATION = 1e-3


def check_geometry(platform: Mapping[str, Any], field: str = "") -> np.ndarray:
    """The body-frame beacon offsets of a ``[platform]`` section, (n, 3) [m], refused when two beacons are
    closer than :data:`MIN_SEPARATION` to each other.

    Two beacons that close (four at one point, or a cross of a 1e-300 m baseline) are one point for the
    fix: their ranges differ by less than the acoustic noise of any real system, so the position is
    ill-conditioned in every direction whatever the diver's distance, and the receivers still return
    finite numbers that look like an answer. That is a configuration mistake, so it is refused, not
    warned about. A spread that is merely small against the diver's distance is real geometry (the fix
    degrades with distance, the numbers are the system's true accuracy) and is warned about after the
    run instead (:data:`sblsim.orchestrator.cosim.metrics.REACH_RATIO`).

    Parameters
    ----------
    platform : mapping
        A resolved ``[platform]`` section.
    field : str
        The key named in the message (default ``platform.beacon_offsets`` for a custom layout,
        ``platform.baseline`` for the cross).

    Raises
    ------
    ModelError
        Naming the field, the two beacons, their distance and the allowed minimum.
    """
    offsets = platform_offsets(platform)
    field = field or ("platform.beacon_offsets" if platform["layout"] == "custom" else "platform.baseline")
    for i in range(len(offsets)):
        gaps = np.linalg.norm(offsets[i + 1:] - offsets[i], axis=1)
        if gaps.size and gaps.min() < MIN_SEPARATION:
            j = i + 1 + int(np.argmin(gaps))
            raise ModelError(f"{field}: beacons {i} and {j} are {gaps.min():.3g} m apart; at least "
                             f"{MIN_SEPARATION * 1e3:g} mm between any two beacons (closer ones are one point and "
                             "the fix is ill-conditioned)")
    return offsets


def horizontal_spread(platform: Mapping[str, Any]) -> float:
    """The largest horizontal distance between two transducers of a ``[platform]`` section [m] (the aperture that
    resolves the diver's horizontal position; :meth:`sblsim.models.systems.System.horizontal_spread`)."""
    return _system(platform).horizontal_spread(platform)


def rotation_ned(roll, pitch, yaw) -> ca.SX:
    """Body-to-NED rotation ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (ZYX Tait-Bryan).

    Parameters
    ----------
    roll, pitch, yaw : casadi.SX or float
        Attitude angles [rad].

    Returns
    -------
    casadi.SX, shape (3, 3)
        Rotation mapping body vectors to NED.
    """
    cr, sr = ca.cos(roll), ca.sin(roll)
    cp, sp = ca.cos(pitch), ca.sin(pitch)
    cy, sy = ca.cos(yaw), ca.sin(yaw)
    return ca.vertcat(
        ca.horzcat(cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr),
        ca.horzcat(sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr),
        ca.horzcat(-sp, cp * sr, cp * cr),
    )


def unit_vector(azimuth, elevation) -> ca.SX:
    """The NED unit vector ``(cos ε cos α, cos ε sin α, sin ε)`` (3, 1) of an azimuth α (clockwise from North) and an
    elevation ε (below the horizontal) [rad]."""
    return ca.vertcat(ca.cos(elevation) * ca.cos(azimuth), ca.cos(elevation) * ca.sin(azimuth), ca.sin(elevation))


def beacon_positions(position: ca.SX, rotation: ca.SX, offsets: list[ca.SX]) -> list[ca.SX]:
    """Beacon positions ``b_i = p + R a_i`` in NED [m], one (3, 1) vector per beacon."""
    return [position + ca.mtimes(rotation, a) for a in offsets]


__all__ = ["MIN_SEPARATION", "beacon_positions", "check_geometry", "cross_directions", "cross_offsets",
           "transducer_span",
           "horizontal_spread", "layout_offsets", "parse_offsets", "rotation_ned", "unit_vector"]

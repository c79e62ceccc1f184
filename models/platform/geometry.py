"""Beacon geometry of the SBL platform and attitude rotations.

References
----------
Cario, Casavola, Gagliardi, Lupia, Severino, "Accurate Localization in
Acoustic Underwater Localization Systems", Sensors 21(3):762, 2021,
doi:10.3390/s21030762 (Section 3, the SBL cross).
"""

from __future__ import annotations

import numpy as np

from models.core import ModelError


def cross_offsets(baseline, transducer_depth, n_beacons: int = 4) -> np.ndarray:
    """Body-frame offsets of beacons on a cross (equally spaced arms).

    ``a_i = L (cos θ_i, sin θ_i, 0) + (0, 0, h)`` with θ_i = 2π i / n
    (0°, 90°, 180°, 270° for the paper's four beacons).

    Parameters
    ----------
    baseline : float or ndarray, shape (B,)
        Support-arm length L [m], one per replicate if an array.
    transducer_depth : float or ndarray, shape (B,)
        Depth h of the transducers below the platform reference [m].
    n_beacons : int
        Number of arms.

    Returns
    -------
    ndarray, shape (n_beacons, 3) or (B, n_beacons, 3)
        Offsets in the body frame (x forward/North, y East, z down) [m].
    """
    theta = 2.0 * np.pi * np.arange(n_beacons) / n_beacons
    cos, sin = np.cos(theta), np.sin(theta)
    cos[np.abs(cos) < 1e-15] = 0.0  # exact zeros on the axes
    sin[np.abs(sin) < 1e-15] = 0.0
    arm, depth = np.broadcast_arrays(np.asarray(baseline, dtype=float)[..., None],
                                     np.asarray(transducer_depth, dtype=float)[..., None])
    return np.stack([arm * cos, arm * sin, np.broadcast_to(depth, arm.shape[:-1] + (n_beacons,))], axis=-1)


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


def rotation_ned(roll: np.ndarray, pitch: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Body-to-NED rotation ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (ZYX Tait-Bryan).

    Parameters
    ----------
    roll, pitch, yaw : ndarray, shape (B,)
        Attitude angles [rad].

    Returns
    -------
    ndarray, shape (B, 3, 3)
        Rotation matrices mapping body vectors to NED.
    """
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=-1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=-1),
        np.stack([-sp, cp * sr, cp * cr], axis=-1),
    ], axis=-2)


def beacon_positions(position: np.ndarray, rotation: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Beacon positions ``b_i = p + R a_i`` in NED.

    Parameters
    ----------
    position : ndarray, shape (B, 3)
        Platform reference position [m].
    rotation : ndarray, shape (B, 3, 3)
        Body-to-NED rotation.
    offsets : ndarray, shape (n, 3) or (B, n, 3)
        Body-frame beacon offsets [m], shared or one set per replicate.

    Returns
    -------
    ndarray, shape (B, n, 3)
        Beacon positions [m].
    """
    offsets = np.broadcast_to(offsets, (position.shape[0],) + offsets.shape[-2:])
    return position[:, None, :] + np.einsum("bij,bnj->bni", rotation, offsets)

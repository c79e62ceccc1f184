"""Geodesy of a survey's local frame: ECEF and geodetic positions to local east/north/up at an origin, and the
rotation of ECEF axes to ENU (pymap3d, on WGS84).

References
----------
IOGP, Geomatics Guidance Note 7-2, method 9836 (geocentric/topocentric conversions: the ENU rotation).
"""

from __future__ import annotations

import numpy as np
import pymap3d


def ecef_to_enu(xyz: np.ndarray, lat_deg: float, lon_deg: float, height_m: float) -> np.ndarray:
    """ECEF positions to local east/north/up at an origin (WGS84, pymap3d.ecef2enu).

    Parameters
    ----------
    xyz : ndarray, shape (n, 3)
        ECEF x, y, z [m].
    lat_deg, lon_deg, height_m : float
        The origin [deg, deg, m ellipsoidal].

    Returns
    -------
    ndarray, shape (n, 3)
        East, north, up [m].
    """
    xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)
    e, n, u = pymap3d.ecef2enu(xyz[:, 0], xyz[:, 1], xyz[:, 2], lat_deg, lon_deg, height_m)
    return np.column_stack([e, n, u])


def geodetic_to_enu(lat_deg, lon_deg, height_m, lat0_deg: float, lon0_deg: float, height0_m: float) -> np.ndarray:
    """Geodetic positions to local east/north/up at an origin (WGS84, pymap3d.geodetic2enu).

    Returns
    -------
    ndarray, shape (n, 3)
        East, north, up [m].
    """
    e, n, u = pymap3d.geodetic2enu(np.atleast_1d(lat_deg), np.atleast_1d(lon_deg), np.atleast_1d(height_m),
                                   lat0_deg, lon0_deg, height0_m)
    return np.column_stack([e, n, u])


def enu_rotation(lat_deg: float, lon_deg: float) -> np.ndarray:
    """The rotation R from ECEF to local ENU axes at a latitude and longitude: ``v_enu = R v_ecef``.

    Its columns are pymap3d's ECEF -> ENU vector rotation (``ecef2enuv``) of the three ECEF unit vectors.

    Returns
    -------
    ndarray, shape (3, 3)
    """
    eye = np.eye(3)
    return np.array(pymap3d.ecef2enuv(eye[0], eye[1], eye[2], lat_deg, lon_deg), dtype=float)


__all__ = ["ecef_to_enu", "enu_rotation", "geodetic_to_enu"]

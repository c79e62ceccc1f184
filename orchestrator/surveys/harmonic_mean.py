"""The harmonic-mean sound speed of a profile between two depths, by sblsim's acoustics model
(:func:`sblsim.models.acoustics.sound_speed.harmonic_mean`): a survey's straight-ray speed per transponder.

References
----------
Chadwell, C. D., and Sweeney, A. D. (2010), Acoustic ray-trace equations for seafloor geodesy, Marine
Geodesy 33(2-3), 164-186 (the straight ray at the harmonic-mean speed).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS, harmonic_mean, profile_nodes, profile_table
from sblsim.models.errors import ModelError


@lru_cache(maxsize=1)
def _harmonic_function():
    """The model's harmonic mean (sblsim.models.acoustics.sound_speed) as a function of a padded table."""
    count, z1, z2 = ca.MX.sym("count"), ca.MX.sym("z1"), ca.MX.sym("z2")
    depth, speed = ca.MX.sym("depth", MAX_PROFILE_ROWS), ca.MX.sym("speed", MAX_PROFILE_ROWS)
    nodes, slowness = profile_nodes(count, depth, speed)
    return ca.Function("gnatss_harmonic_mean", [count, depth, speed, z1, z2],
                       [harmonic_mean(z1, z2, 0.0, count, nodes, slowness)]), MAX_PROFILE_ROWS


def harmonic_mean_speed(z1: float, z2: float, profile: str | np.ndarray = "ctd:NCL1") -> float:
    """Harmonic-mean sound speed of a profile between two depths [m/s], by sblsim's acoustics model.

    Parameters
    ----------
    z1, z2 : float
        Depths [m, positive down].
    profile : str or numpy.ndarray
        An ``acoustics.sound_speed_profile`` value (``ctd:NCL1``: the NCL1 cast, resampled to the model's
        table of at most 256 rows), or a table (rows, 2) of depth [m] and speed [m/s].

    Returns
    -------
    float
        ``(z2 − z1) / ∫ dz / c(z)`` [m/s] (sblsim.models.acoustics.sound_speed.harmonic_mean).

    Raises
    ------
    ModelError
        An unknown or unreadable profile, or a constant one (no table).
    """
    table = profile if isinstance(profile, np.ndarray) else profile_table(profile, "", 15.0, 35.0)
    if table.shape[0] == 0:
        raise ModelError(f"profile: {profile!r} has no table; give a cast such as ctd:NCL1")
    function, rows = _harmonic_function()
    depth, speed = np.zeros(rows), np.zeros(rows)
    depth[:table.shape[0]], speed[:table.shape[0]] = table[:, 0], table[:, 1]
    return float(function(table.shape[0], depth, speed, z1, z2))


__all__ = ["harmonic_mean_speed"]

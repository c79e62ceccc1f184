"""The site's eigenrays between pairs of points and what the channel makes of them, in numbers (accuracy maps,
design, tests): each eigenray family's travel time, launch angle, SNR and detection probability at the channel's
FMU parameters (:func:`site_levels`), and the site's numbers of those parameters (:func:`site_vector`).
"""

from __future__ import annotations

from typing import Any, Mapping

import casadi as ca
import numpy as np

from sblsim.models.acoustics.channel.component import Acoustics
from sblsim.models.acoustics.channel.site import site_from
from sblsim.models.acoustics.detection import family_levels
from sblsim.models.acoustics.rays import profile_arrays
from sblsim.models.acoustics.sound_speed import NODES, PROFILE
from sblsim.models.expressions import map_in_chunks


def _site(parameters: Mapping[str, Any]) -> tuple[dict[str, Any], np.ndarray]:
    """The channel's parameters (missing ones: their declared start) and the site's numbers they give
    (:func:`~sblsim.models.acoustics.channel.site.site_from` of the channel's FMU parameters)."""
    return site_from(Acoustics.fmu_parameters_declared(), parameters)


def site_vector(parameters: Mapping[str, Any]) -> np.ndarray:
    """The site's numbers (:data:`~sblsim.models.acoustics.detection.SITE`) of the channel's FMU parameters
    ``parameters`` (missing ones take their declared start, String choices as text), as :func:`site_numbers`.

    Returns
    -------
    ndarray, shape (len(SITE),)
    """
    return _site(parameters)[1]


def site_levels(parameters: Mapping[str, Any], sources: Any, receivers: Any,
                levels: ca.Function | None = None) -> dict[str, np.ndarray]:
    """The eigenrays between pairs of points and what the channel's site makes of them (numbers, for maps).

    Parameters
    ----------
    parameters : mapping
        The channel's FMU parameters (a plan's ``component_parameters("acoustics")``; missing ones take their
        declared start, String choices as text).
    sources, receivers : array_like, shape (K, 3)
        NED positions [m] of each pair's ends.
    levels : casadi.Function, optional
        :func:`~sblsim.models.acoustics.detection.family_levels` as compiled code (default: casadi's own
        evaluation of it, the same numbers, far slower).

    Returns
    -------
    dict
        ``tau`` [s], ``launch`` (the grazing angle at the source [rad], positive downward), ``valid``,
        ``snr`` [dB], ``pd``, each (K, 4) (direct, surface, bottom, the direct family's other eigenray;
        :func:`~sblsim.models.acoustics.detection.family_levels`).
    """
    p, site = _site(parameters)
    rows = PROFILE.rows(p, "sound_speed_rows")
    nodes, speeds = profile_arrays(rows) if rows.shape[0] else (np.zeros(NODES), np.zeros(NODES))
    sources, receivers = np.atleast_2d(np.asarray(sources, float)), np.atleast_2d(np.asarray(receivers, float))
    horizontal = np.hypot(*(receivers[:, :2] - sources[:, :2]).T)
    # a range-independent site: pairs of the same depths and distance (a map's symmetric grid) are solved once
    geometry, pair = np.unique(np.column_stack([sources[:, 2], receivers[:, 2], horizontal]), axis=0,
                               return_inverse=True)
    # in calls of a fraction of a second (a large map is minutes of compiled code: Ctrl-C between two calls)
    out = map_in_chunks(family_levels() if levels is None else levels, geometry.T,
                        (float(p["water_depth"]), float(rows.shape[0] > 0), float(p["sound_speed_true"]), nodes,
                         speeds, site))
    return {name: out[k].T[pair.ravel()] for k, name in ((0, "tau"), (1, "launch"), (3, "valid"), (4, "snr"),
                                                          (5, "pd"))}


__all__ = ["site_levels", "site_vector"]

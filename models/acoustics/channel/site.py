"""The site's numbers of the sonar equation: source level, detection threshold, directivity, fluctuation,
frequency, absorption, the ambient noise (Wenz: wind of the Beaufort number and shipping), the probable wave
height and the sea floor's reflection row (:data:`~sblsim.models.acoustics.detection.SITE`), from the channel's
parameters, symbolic (the channel's ``prepare``) or numbers (:func:`site_from`; the eigenrays and levels between
pairs of points are :mod:`~sblsim.models.acoustics.channel.site_levels`').
"""

from __future__ import annotations

from typing import Any, Mapping, Sequence

import casadi as ca
import numpy as np

from sblsim.models.acoustics.ambient_noise import noise_level, wind_speed
from sblsim.models.acoustics.boundary_loss import BOTTOMS, wave_height
from sblsim.models.declarations import Variable
from sblsim.models.expressions import lookup


def site_numbers(p: Mapping[str, Any]) -> Any:
    """The site's numbers (:data:`~sblsim.models.acoustics.detection.SITE`) from the channel's parameters ``p``
    (by name; casadi symbols or numbers): the ambient noise over the signal's band from the Beaufort number's
    wind and the shipping (Wenz), the probable wave height of the Beaufort number, the sea floor's row of
    :data:`~sblsim.models.acoustics.boundary_loss.BOTTOMS` (``p["bottom"]`` its index).

    Returns
    -------
    casadi.SX or casadi.DM, shape (len(SITE), 1)
    """
    floor = [lookup(p["bottom"], [BOTTOMS[name][j] for name in BOTTOMS]) for j in range(3)]
    noise = noise_level(p["frequency"], p["bandwidth"], wind_speed(p["beaufort"]), p["shipping"])
    return ca.vertcat(p["source_level"], p["detection_threshold"], p["directivity_index"], p["fluctuation"],
                      p["frequency"], p["absorption"], noise, wave_height(p["beaufort"]), *floor)


def site_from(declared: Sequence[Variable], parameters: Mapping[str, Any]) -> tuple[dict[str, Any], np.ndarray]:
    """The channel's parameters ``parameters`` (by name; String choices as text), each of its FMU parameters
    ``declared`` that they miss (but a table's) at its declared start, and the site's numbers they give
    (:func:`site_numbers`).

    Returns
    -------
    dict
        The parameters, completed.
    ndarray, shape (len(SITE),)
        The site's numbers (:data:`~sblsim.models.acoustics.detection.SITE`).
    """
    declared = {v.name: v for v in declared}
    p = {name: v.start for name, v in declared.items() if not v.in_table} | dict(parameters)
    numeric = {**p, "bottom": float(declared["bottom"].choices.index(p["bottom"]))}
    return p, np.asarray(ca.evalf(site_numbers(numeric))).ravel()


__all__ = ["site_from", "site_numbers"]

"""Two tags under one transmitter id: a times-of-arrival matrix whose trusted single-ping fixes jump between two
places as no animal moves is refused (:func:`~sblsim.models.tracking.twins.two_places`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.twins import MAX_SPEED, two_places


def _one_tag(toa_path: Path, fixes: np.ndarray, emissions: np.ndarray, covariances: np.ndarray,
             trusted: np.ndarray) -> None:
    """Refuse a times-of-arrival matrix whose trusted single-ping fixes jump between two places as no animal moves:
    two tags under one transmitter id (:func:`~sblsim.models.tracking.twins.two_places`), named by the file's stem.

    Raises
    ------
    ModelError
        One line naming the transmitter, the two places, the jumps and what is allowed.
    """
    found = two_places(fixes[trusted], emissions[trusted], covariances[trusted])
    if found is None:
        return
    (x0, y0), (x1, y1) = found.centres
    raise ModelError(f"transmitter {Path(toa_path).stem}: looks like two tags, at ({x0:.0f}, {y0:.0f}) m and "
                     f"({x1:.0f}, {y1:.0f}) m, {found.separation:.0f} m apart ({found.shares[0]:.0%} and "
                     f"{found.shares[1]:.0%} of {found.fixes} trusted fixes): {found.jumps} of {found.steps} steps "
                     f"between consecutive fixes are faster than {MAX_SPEED:g} m/s; allowed: one tag's pings (two "
                     "tags sharing an id: split its detections by place or by receiver)")

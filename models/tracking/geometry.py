"""An array's geometry checked before tracking: the receivers must be able to position a tag at all.

Refused in one line (:class:`~sblsim.models.declarations.ModelError`), whether or not the sound speed is given:

* receivers all at one point (the array's largest distance below :data:`MIN_SPAN`): no time difference of arrival
  exists;
* positions in the wrong unit: two arrivals of one ping can differ by no more than the travel time between their
  receivers, ``‖r_i − r_j‖ / c`` (the triangle inequality); when the typical ping's arrivals spread over more than
  :data:`SPREAD_FACTOR` times the array's crossing time at the slowest sound speed accepted, the positions cannot be
  in metres (kilometres, or another array's);
* receivers on one line (the array's width across its longest axis below :data:`MIN_WIDTH_SHARE` of its length,
  or below :data:`MIN_SPAN`): every fix has a mirror image across the line, equally likely, which no estimator can
  tell apart (in 3-D the same holds about the line's axis).

Receivers on one plane in 3-D (all at one depth) are allowed: the tag's depth then has a mirror image above and below
the plane, while its horizontal position is still determined.
"""

from __future__ import annotations

import numpy as np

from sblsim.models.declarations import ModelError

#: The smallest extent of an array [m] (the largest distance between two receivers; the width across its axis).
MIN_SPAN = 1.0
#: The smallest width of an array across its longest axis, as a share of its length.
MIN_WIDTH_SHARE = 1e-3
#: How far the typical ping's arrivals may spread beyond the array's crossing time at the slowest sound speed
#: (late multipath arrivals of a few pings do not move the median).
SPREAD_FACTOR = 1.5


def check_array(receivers: np.ndarray, names: list[str], toa: np.ndarray, slowest: float) -> None:
    """Refuse an array that cannot position a tag (module docstring).

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        The receivers' positions [m].
    names : list of str
        Their names (for the message).
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    slowest : float
        The slowest sound speed accepted [m/s].

    Raises
    ------
    ModelError
        One line naming what is wrong and what is allowed.
    """
    r = np.asarray(receivers, float)
    centred = r - r.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False) if len(r) > 1 else np.zeros(r.shape[1])
    span = float(np.max(np.linalg.norm(r[:, None] - r[None], axis=2))) if len(r) > 1 else 0.0
    if span < MIN_SPAN:
        raise ModelError(f"receivers: the {len(r)} receivers lie within {span:.3g} m of each other; allowed: an array "
                         f"at least {MIN_SPAN:g} m across (positions in metres)")
    heard = np.isfinite(toa)
    rows = heard.sum(axis=1) >= 2
    if rows.any():
        spreads = np.nanmax(toa[rows], axis=1) - np.nanmin(toa[rows], axis=1)
        crossing = span / slowest
        typical = float(np.median(spreads))
        if typical > SPREAD_FACTOR * crossing:
            raise ModelError(f"receivers: a typical ping's arrivals spread over {typical:.4g} s, more than the "
                             f"{crossing:.4g} s a sound wave takes across the array ({span:.4g} m at {slowest:g} "
                             "m/s); allowed: the receivers' positions in metres, in the frame of the times of arrival")
    length, width = spread[0], spread[1]
    if width < MIN_WIDTH_SHARE * length or width * 2.0 / np.sqrt(len(r)) < MIN_SPAN:
        shown = ", ".join(names[:3]) + (", ..." if len(names) > 3 else "")
        raise ModelError(f"receivers: {shown} lie on one line (within {width * 2.0 / np.sqrt(len(r)):.3g} m of it): "
                         "every fix has a mirror image across it; allowed: receivers off the line (at least 3 not in "
                         "a row)")


__all__ = ["MIN_SPAN", "MIN_WIDTH_SHARE", "SPREAD_FACTOR", "check_array"]

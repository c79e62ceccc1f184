"""The tag's depth the tracker takes: a pressure sensor's readings (a ``depth_m`` column), one given depth, a prior
where the receivers are in 3-D but their arrivals do not determine the depth
(:mod:`sblsim.models.tracking.depth`), or none (receivers in 2-D); and what was done, for ``summary.json``'s
``depth`` and the console."""

from __future__ import annotations

from typing import Any

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.depth import DepthPrior, at_least, depth_prior

#: ``summary.json``'s ``depth`` ``source`` where the depth is taken with a prior.
PRIOR_SOURCE = "prior (the arrivals do not determine it)"


def tag_depth(readings: np.ndarray | None, m: int, dim: int, fixed: float | None,
              sigma: float) -> tuple[np.ndarray | None, dict[str, Any]]:
    """The tag's depth per ping [m] (m,) the fix and the robust smoother take as a measurement (σ ``sigma`` [m]):
    the TOA file's ``depth_m`` column (a pressure sensor's reading per ping), else one ``fixed`` depth for every ping
    (a tag at a known depth), else None (the depth estimated with the position where the receivers are in 3-D,
    unless the arrivals do not determine it: :func:`undetermined_depth`);
    and what was done (``summary.json``'s ``depth``).

    Raises
    ------
    ModelError
        Both given, or a depth with receivers in 2-D (one line).
    """
    if readings is not None and fixed is not None:
        raise ModelError("tag_depth: not with a depth_m column in the times of arrival (one depth per ping given)")
    depth = readings if readings is not None else None if fixed is None else np.full(m, float(fixed))
    if depth is not None and dim != 3:
        raise ModelError("depth_m: the tag's depth needs the receivers' depths (a z_m column in the receivers file); "
                         "allowed: receivers in 3-D")
    if depth is None:
        return None, {"source": "estimated with the position" if dim == 3 else "none (2-D)"}
    return depth, {"source": "sensor (depth_m)" if readings is not None else "given (one depth)",
                   "readings": int(np.isfinite(depth).sum()), "sigma_m": sigma}


def undetermined_depth(depth: np.ndarray | None, fixes: np.ndarray, fix_covariances: np.ndarray,
                       fix_used: np.ndarray, positions: np.ndarray) -> DepthPrior | None:
    """The prior on the tag's depth where none is given, the receivers are in 3-D and the single-ping fixes (made
    without a depth) do not tell where among the receivers' heights the tag is
    (:func:`~sblsim.models.tracking.depth.depth_prior`); else None.

    Parameters
    ----------
    depth : ndarray or None
        The depth taken so far (:func:`tag_depth`): a prior is sought only where it is None.
    fixes : ndarray, (m, dim)
        The fixes' positions [m].
    fix_covariances : ndarray, (m, dim + 1, dim + 1)
        The fixes' covariances [m², m·s, s²].
    fix_used : ndarray, (m,)
        The receivers each fix used.
    positions : ndarray, (n, dim)
        The receivers' positions [m].
    """
    if depth is not None or positions.shape[1] != 3:
        return None
    return depth_prior(fixes, fix_covariances, fix_used, positions)


def prior_info(prior: DepthPrior) -> dict[str, Any]:
    """``summary.json``'s ``depth`` where the depth is the prior's (``source`` :data:`PRIOR_SOURCE`)."""
    return {"source": PRIOR_SOURCE, "depth_m": prior.depth, "sigma_m": prior.sigma, "fixes_ratio": prior.ratio,
            "fixes": prior.fixes}


def depth_term(prior: DepthPrior | None, covariances: np.ndarray) -> np.ndarray | None:
    """What an estimate that took ``prior`` adds to its reported covariances (m, 3, 3) [m²]: its depth's variance
    raised to the prior's (:func:`~sblsim.models.tracking.depth.at_least`); None where no prior was taken."""
    return None if prior is None else at_least(covariances, prior.sigma)


__all__ = ["PRIOR_SOURCE", "depth_term", "prior_info", "tag_depth", "undetermined_depth"]

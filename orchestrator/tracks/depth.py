"""The tag's depth the tracker takes: a pressure sensor's readings (a ``depth_m`` column), one given depth, a prior
where the receivers are in 3-D but their arrivals do not determine the depth (receivers in one plane, or the fixes'
depth σ: :mod:`sblsim.models.tracking.depth`), bounded by the water's depth where it is given, or none (receivers in
2-D); and what was done, for ``summary.json``'s ``depth`` and the console."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.depth import (
    DepthPrior,
    at_least,
    bounded_prior,
    depth_prior,
    fixes_depth,
    plane_prior,
    plane_span,
)

if TYPE_CHECKING:  # (pandas not loaded with the tracker's modules: the command line's start stays light)
    import pandas as pd

#: ``summary.json``'s ``depth`` ``source`` where the depth is taken with a prior.
PRIOR_SOURCE = "prior (the arrivals do not determine it)"
#: ... where the arrivals determine it and the water's depth bounds it.
WATER_SOURCE = "estimated with the position, within the water column (a prior)"
#: The deepest water [m] ``water_depth`` takes.
MAX_WATER_DEPTH = 11000.0


def check_water_depth(water_depth: float | None, positions: np.ndarray, names: list[str],
                      fixed: float | None = None) -> None:
    """A water depth [m] (positive down) against the receivers and a tag's depth given: it needs the receivers'
    depths (3-D), and no receiver and no given depth lies below it.

    Raises
    ------
    ModelError
        One line naming ``water_depth``, the value and what it must be.
    """
    if water_depth is None:
        return
    if positions.shape[1] != 3:
        raise ModelError(f"water_depth: {water_depth:g} m needs the receivers' depths (a z_m column in the receivers "
                         "file); allowed: receivers in 3-D")
    deepest = int(np.argmin(positions[:, 2]))
    if -positions[deepest, 2] > water_depth:
        raise ModelError(f"water_depth: {water_depth:g} m is above receiver {names[deepest]!r} at "
                         f"{-positions[deepest, 2]:.6g} m; allowed: [{-positions[deepest, 2]:.6g}, "
                         f"{MAX_WATER_DEPTH:g}] m (at least the deepest receiver's depth)")
    if fixed is not None and not 0.0 <= fixed <= water_depth:
        raise ModelError(f"tag_depth: {fixed:g} m is outside the water column [0, {water_depth:g}] m (water_depth); "
                         "allowed: a depth between the surface and the bottom")


def study_water_depth(table: pd.DataFrame, water_depth: float | None, notes: list[str]
                      ) -> tuple[pd.Series | None, dict[str, Any]]:
    """The water depth a study's tags take (``table`` the deployments': ``receiver``, ``x``, ``y``, ``z`` [m],
    ``bottom_depth`` [m]): ``water_depth`` [m] given (checked against the deployments' depths), else the
    deployments' ``bottom_depth`` by receiver (each tag's taken from those that heard it) where the geometry is 3-D
    (said in a note where it is not); returns that series (None where not used) and ``summary["water_depth"]``.

    Raises
    ------
    ModelError
        ``water_depth`` without the deployments' depths, or above a deployment's (one line).
    """
    three_d = bool(np.isfinite(table["z"].to_numpy(float)).all())
    axes = ["x", "y", "z"] if three_d else ["x", "y"]
    if water_depth is not None:
        check_water_depth(water_depth, table[axes].to_numpy(float), table["receiver"].tolist())
        return None, {"source": "given", "water_depth_m": water_depth}
    bottom = table.set_index("receiver")["bottom_depth"]
    if not np.isfinite(bottom.to_numpy(float)).any():
        return None, {}
    if not three_d:
        notes.append("bottom_depth not used: the deployments' own depths are not all given (a 2-D geometry; give "
                     "instrument_depth or z_m for every deployment)")
        return None, {}
    return bottom, {"source": "bottom_depth", "rule": "the deepest bottom_depth of the deployments that heard the tag",
                    "per_tag_m": {}}


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


def plane_depth(depth: np.ndarray | None, positions: np.ndarray, water_depth: float | None = None,
                sigma: float = 0.0) -> DepthPrior | None:
    """The depth held for a tag where none is given and the receivers lie in one plane
    (:func:`~sblsim.models.tracking.depth.plane_prior`: mid-water with ``water_depth`` [m], else the receivers' mean
    depth, at least ``sigma`` [m] uncertain), decided from the array alone before anything is fitted (the fixes' and
    the calibration's depth would trade against the sound speed); else None."""
    if depth is not None or positions.shape[1] != 3:
        return None
    return plane_prior(positions, water_depth, sigma)


def undetermined_depth(depth: np.ndarray | None, fixes: np.ndarray, fix_covariances: np.ndarray,
                       fix_used: np.ndarray, positions: np.ndarray, water_depth: float | None = None
                       ) -> DepthPrior | None:
    """The prior on the tag's depth where none is given, the receivers are in 3-D and the single-ping fixes (made
    without a depth) do not tell where among the receivers' heights the tag is
    (:func:`~sblsim.models.tracking.depth.depth_prior`), bounded by the water column where ``water_depth`` [m] is
    given (:func:`~sblsim.models.tracking.depth.bounded_prior`: the column's own prior where the arrivals determine
    the depth); else None. (Receivers in one plane hold it before: :func:`plane_depth`.)

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
    water_depth : float, optional
        The water's depth [m], positive down.

    Returns
    -------
    DepthPrior or None
    """
    if depth is not None or positions.shape[1] != 3:
        return None
    prior = depth_prior(fixes, fix_covariances, fix_used, positions)
    return bounded_prior(prior, water_depth, fixes_depth(fixes, fix_covariances, fix_used)[2])


def prior_info(prior: DepthPrior, positions: np.ndarray | None = None,
               water_depth: float | None = None) -> dict[str, Any]:
    """``summary.json``'s ``depth`` where the depth is the prior's: ``source`` :data:`PRIOR_SOURCE` (or
    :data:`WATER_SOURCE` where the prior only bounds a depth the arrivals determine), ``basis`` (``fixes``,
    ``plane``, ``water column``), ``depth_m``, ``sigma_m`` [m]; the fixes' ``fixes_ratio`` and count, the receivers'
    ``span_m`` and ``aperture_m`` [m] (``positions`` (n, 3) given) and the ``water_depth_m`` where given."""
    info = {"source": PRIOR_SOURCE if prior.floor else WATER_SOURCE, "basis": prior.basis, "depth_m": prior.depth,
            "sigma_m": prior.sigma, "fixes_ratio": None if not np.isfinite(prior.ratio) else prior.ratio,
            "fixes": prior.fixes}
    if positions is not None:
        span, aperture = plane_span(positions)
        info |= {"span_m": span, "aperture_m": aperture}
    return info | {"water_depth_m": water_depth}


def prior_line(info: dict[str, Any]) -> str | None:
    """The console's warning on a prior that holds the tag's depth (``summary.json``'s ``depth``,
    :func:`prior_info`), after ``sblsim: warning:``; None where no prior holds it."""
    if info.get("source") != PRIOR_SOURCE:
        return None
    water = info.get("water_depth_m")
    if info.get("fixes_ratio") is None:  # the plane's rule (the fixes did not decide)
        why = f"their heights span {info['span_m']:.2g} m over {info['aperture_m']:.3g} m: one plane"
    else:
        why = f"the fixes' depth σ is {info['fixes_ratio']:.2f} of their heights' scale"
    where = f"mid-water of the {water:g} m given" if water is not None and info.get("basis") != "fixes" else \
        "the receivers' mean depth"
    ask = "give --tag-depth or a depth_m column" + ("" if water is not None else ", or --water-depth")
    return (f"the receivers do not determine the tag's depth ({why}): taken at {where} {info['depth_m']:.2f} ± "
            f"{info['sigma_m']:.2g} m ({ask})")


def bottom_water_depth(bottom: np.ndarray, heard: np.ndarray) -> float | None:
    """The water depth [m] a tag's depth is bounded by, from its receivers' ``bottom`` (n,) [m, positive down; NaN
    where not given]: the deepest bottom of those that ``heard`` (n,) the tag (a bound the tag stays above wherever
    it was heard, and at least every such receiver's depth); None where none of them has one."""
    known = np.asarray(heard, bool) & np.isfinite(bottom)
    return float(np.max(np.asarray(bottom, float)[known])) if known.any() else None


def water_line(info: dict[str, Any], option: str = "--water-depth") -> str:
    """The console's line on the water depth a study's tags take (``study.json``'s ``water_depth``): given
    (``option``), or each tag's from its receivers' ``bottom_depth`` (:func:`bottom_water_depth`)."""
    if info["source"] == "given":
        return (f"water depth {info['water_depth_m']:g} m (given, {option}): each tag's depth kept between the "
                "surface and it")
    values = [v for v in info["per_tag_m"].values() if v is not None]
    span = "none of the tags' receivers has one" if not values else (
        f"{min(values):g} m" if min(values) == max(values) else f"{min(values):g} to {max(values):g} m")
    return (f"water depth per tag: the deepest bottom_depth of the deployments that heard it ({span}, "
            f"{len(values)} of {len(info['per_tag_m'])} tags): each tag's depth kept between the surface and it "
            f"(give {option} for one depth)")


def depth_term(prior: DepthPrior | None, covariances: np.ndarray) -> np.ndarray | None:
    """What an estimate that took ``prior`` adds to its reported covariances (m, 3, 3) [m²]: its depth's variance
    raised to the prior's (:func:`~sblsim.models.tracking.depth.at_least`); None where no prior was taken or the
    prior only bounds a depth the arrivals determine."""
    return None if prior is None or not prior.floor else at_least(covariances, prior.sigma)


__all__ = ["MAX_WATER_DEPTH", "PRIOR_SOURCE", "WATER_SOURCE", "bottom_water_depth", "check_water_depth", "depth_term",
           "plane_depth", "prior_info", "prior_line", "study_water_depth", "tag_depth", "undetermined_depth",
           "water_line"]

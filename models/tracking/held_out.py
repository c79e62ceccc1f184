"""Whether a refinement of the receivers' positions helps (:func:`held_out`): the data's to say, not the fit's own
residuals (a refined array always fits the pings it was fitted to better). Each block of the record's pings is left
out of the refinement (:func:`~sblsim.models.tracking.receiver_positions.refine_receivers`) in turn, then its pings
are fixed alone with the surveyed and with that refined array
(:func:`~sblsim.models.tracking.receiver_positions.best_fixes`): the refinement helps where the pings it never saw
agree better with it (cross-validation: Stone, "Cross-validatory choice and assessment of statistical predictions",
J. R. Stat. Soc. B 36(2), 1974).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.tracking.receiver_positions import MIN_ARRIVALS, best_fixes, checked_inputs, refine_receivers
from sblsim.models.tracking.smoother_cost import ROBUST_DOF

#: The blocks of the record :func:`held_out` leaves out in turn.
FOLDS = 4
#: The least share by which the held-out pings' median χ² per degree of freedom must fall for a refinement to
#: help: a right array's refinement moves it by its noise, and the pings it never saw fit it within a few per cent
#: (the chance of that noise, or of the echoes' weights), never by a twentieth.
HELD_OUT_GAIN = 0.05


@dataclass(frozen=True)
class HeldOut:
    """The pings of each block of the record fixed with the surveyed array and with the array refined without them
    (:func:`held_out`).

    Attributes
    ----------
    surveyed, refined : float
        [1] the median over the held-out pings of a fix's squared normalised residuals per degree of freedom
        (χ² / (arrivals − unknowns)), with the surveyed and with the refined positions.
    pings : int
        The held-out pings with a degree of freedom (fixed with either array).
    folds : numpy.ndarray
        (k, 2) [1] each block's two medians.
    """

    surveyed: float
    refined: float
    pings: int
    folds: np.ndarray

    @property
    def helps(self) -> bool:
        """The refined array fits the pings it never saw better, by :data:`HELD_OUT_GAIN` in the whole record and
        in most of its blocks."""
        better = self.folds[:, 1] < self.folds[:, 0]
        return bool(self.refined <= (1.0 - HELD_OUT_GAIN) * self.surveyed and better.sum() * 2 > len(better))


def held_out(toa: np.ndarray, receivers: np.ndarray, places: np.ndarray, c: float | np.ndarray,
             sigma_toa: float | np.ndarray, survey_sigma: float, folds: int = FOLDS, dof: float = ROBUST_DOF,
             biases: bool = False, anchored: tuple[np.ndarray, ...] | None = None,
             speed_sigma: float | None = None, times: np.ndarray | None = None,
             edges: np.ndarray | None = None, rescale: bool = False,
             bias_sigma: float | np.ndarray | None = None, clocks: bool = False) -> HeldOut:
    """Each of ``folds`` consecutive blocks of the pings left out of the refinement in turn, then fixed alone with
    the surveyed and with the refined array (the module docstring). Arguments as :func:`refine_receivers` (the
    anchored pings in every refinement, the refined array's times less its biases at the pings' ``times``); the
    blocks' pings fixed with every arrival (no gate: a receiver's error is what is measured), each from its place or
    the fix's own start (the better), their depth kept at the places' in 3-D. With ``clocks`` (the clocks' offsets
    fitted, the positions held: :mod:`sblsim.orchestrator.telemetry.study_offsets`), block k holds every
    ``folds``-th ping from the k-th instead (biases with knots in time that only a left-out stretch of the record
    would tie are tied by the pings around each left-out one) and both arrays' pings are fixed at the fitted sound
    speed (what is checked is the clocks, not a speed the pings' fixes would take up anyway).

    Returns
    -------
    HeldOut

    Raises
    ------
    ModelError
        As :func:`refine_receivers`, for a block left out.
    """
    toa, receivers, places, c, sigma = checked_inputs(toa, receivers, places, c, sigma_toa, survey_sigma)
    times = None if times is None else np.asarray(times, float)
    usable = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= MIN_ARRIVALS)
    per_fold, pooled = [], [[], []]
    for block in ([usable[k::folds] for k in range(folds)] if clocks else np.array_split(usable, folds)):
        keep = np.ones(len(toa), bool)
        keep[block] = False
        refined = refine_receivers(toa[keep], receivers, places[keep], c[keep], sigma, survey_sigma, dof, biases,
                                   anchored, speed_sigma, None if times is None else times[keep], edges, rescale,
                                   bias_sigma)
        moved = receivers.copy()
        moved[:, :2] += refined.shift
        # the refined array's times less its receivers' range biases (where determined, as its shifts), at its speed
        speed = c[block] * refined.speed_scale
        bias = refined.bias_at(None if times is None else times[block], len(block))
        # (with their own prior, each heard receiver's: clocks fitted, the positions the survey's)
        fitted = refined.determined if bias_sigma is None else refined.arrivals > 0
        corrected = toa[block] - np.where(fitted[None], bias, 0.0) / speed[:, None]
        medians = []
        before = speed if clocks else c[block]
        for k, (array, arrivals, at) in enumerate(((receivers, toa[block], before), (moved, corrected, speed))):
            ratio = best_fixes(arrivals, array, places[block], at, sigma)[2]
            pooled[k].append(ratio)
            medians.append(np.nanmedian(ratio) if np.isfinite(ratio).any() else np.nan)
        per_fold.append(medians)
    surveyed, refined = (np.concatenate(p) for p in pooled)
    both = np.isfinite(surveyed) & np.isfinite(refined)
    return HeldOut(float(np.median(surveyed[both])) if both.any() else np.nan,
                   float(np.median(refined[both])) if both.any() else np.nan, int(both.sum()), np.array(per_fold))


__all__ = ["FOLDS", "HELD_OUT_GAIN", "HeldOut", "held_out"]

"""The Cramér-Rao bound of a survey's unknowns at the truth (:func:`crb`), with or without a perturbation
solved with the positions.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from sblsim.models.calibration.legs import LegModel, StraightRay
from sblsim.models.calibration.measurement import _check, _model, _unknowns
from sblsim.models.calibration.ocean import _check_perturbation, _Design, _perturbed_model
from sblsim.models.calibration.perturbation import TRAVEL_TIME_SCALE, interval_bases, uniform_knots
from sblsim.models.calibration.replies import Perturbation, Replies
from sblsim.models.declarations import ModelError


def crb(replies: Replies, positions: Sequence[Sequence[float]] | np.ndarray, sound_speed: float, *,
        rigid: bool = False, solve_sound_speed: bool = False, twtt_sigma: float = 0.0,
        legs: LegModel | None = None, perturbation: Perturbation | None = None) -> np.ndarray:
    """The Cramér-Rao bound of a survey's unknowns: :math:`(J^\\top W J)^{-1}` at the truth.

    The Fisher information of the replies' range residuals (Gaussian, independent, variances
    :math:`\\sigma_i^2` of the line-of-sight projection of :func:`solve`) is :math:`J^\\top W J`, with
    :math:`J` the Jacobian of the two legs at the true positions and :math:`W = \\mathrm{diag}(1/\\sigma_i^2)`.
    Its inverse bounds the covariance of any unbiased estimator of the (static) transponders: for a static
    state the posterior CRB (PCRB) without a prior is this CRB.

    Parameters
    ----------
    replies : Replies
        The replies at the truth: the transducer's true transmit and receive positions [m], their 1-sigma [m]
        (the noise the positions carry), the true TWTTs [s] (used only with ``solve_sound_speed``).
    positions : array_like, shape (k, 3)
        The transponders' true positions, local ENU [m].
    sound_speed : float
        The true sound speed [m/s].
    rigid, solve_sound_speed, twtt_sigma, legs
        As :func:`solve` (``twtt_sigma``: the TWTT noise [s]).
    perturbation : Perturbation or None
        The perturbation solved with the positions (the replies need their times): its coefficients are unknowns
        too (its Jacobian at the truth, the same noise mapped to its residuals, GARPOS's prior as prior
        information); the bound returned is then the positions' block.

    Returns
    -------
    numpy.ndarray, shape (p, p)
        The bound on the unknowns' covariance (3 per transponder, or 3 for a rigid shift; then the speed scale)
        [m², 1]. The horizontal bound of transponder j is ``sqrt(P[3j, 3j] + P[3j+1, 3j+1])`` [m].

    Raises
    ------
    ModelError
        A value outside its range, or replies that do not determine the unknowns (a singular information).

    Source: the CRB of a nonlinear least-squares problem with Gaussian noise, e.g. S. M. Kay, *Fundamentals of
    Statistical Signal Processing: Estimation Theory*, 1993, ch. 3; P. Tichavsky, C. H. Muravchik, A. Nehorai,
    "Posterior Cramér-Rao bounds for discrete-time nonlinear filtering", IEEE Trans. Signal Process. 46(5), 1998.
    """
    positions = np.asarray(positions, dtype=float)
    _check(replies, positions, float(sound_speed), None, float(twtt_sigma))
    theta = np.zeros(_unknowns(len(positions), rigid, solve_sound_speed))
    if solve_sound_speed:
        theta[-1] = 1.0
    _, jacobian, variance, *_ = _model(replies, positions, theta, float(sound_speed), rigid, solve_sound_speed,
                                       legs or StraightRay(), float(twtt_sigma))
    if perturbation is not None:
        return _perturbed_crb(replies, positions, float(sound_speed), rigid, legs or StraightRay(), perturbation,
                              variance)
    information = jacobian.T @ (jacobian / variance[:, None])
    try:
        return np.linalg.inv(information)
    except np.linalg.LinAlgError:
        raise ModelError("calibration: the replies do not determine the unknowns (the information is "
                         "singular)") from None


def _perturbed_crb(replies: Replies, positions: np.ndarray, c0: float, rigid: bool, legs: LegModel,
                   pert: Perturbation, variance: np.ndarray) -> np.ndarray:
    """:func:`crb` with a perturbation: the positions' block of :math:`(A^\\top W A + D/\\sigma_0^2)^{-1}`,
    :math:`A` the Jacobian of the perturbation's prediction at the truth (no perturbation), :math:`W` the inverse
    variances of its residuals (each reply's line-of-sight variance [m²] over :math:`c_0^2`, mapped), :math:`D`
    GARPOS's prior, whose covariance scales with the data's (:math:`\\sigma_0` the replies' RMS sigma over
    GARPOS's travel-time scale)."""
    _check_perturbation(pert, replies, False)
    q = 3 if rigid else 3 * len(positions)
    start, end = float(np.min(replies.t_tx)), float(np.max(replies.t_rx))
    knots = uniform_knots(start, end, pert.n_bases or interval_bases(start, end, pert.knot_interval))
    design = _Design(pert, replies, positions, knots, c0)
    theta = np.zeros(q + design.width())
    used = np.ones(len(replies), dtype=bool)
    _, a, tau, _, mapping, *_ = _perturbed_model(design, positions, theta, c0, rigid, legs, np.arange(len(replies)))
    seconds = np.sqrt(variance) / c0
    sd = mapping * seconds if pert.kind == "ntd" else seconds / (replies.twtt * design.unit)
    keep = np.concatenate((np.ones(q, dtype=bool), design.active(used)))
    information = a[:, keep].T @ (a[:, keep] / sd[:, None] ** 2)
    prior = design.prior(q, design.active(used))
    if prior is not None:
        information = information + prior / float(np.mean((seconds / TRAVEL_TIME_SCALE) ** 2))
    try:
        return np.linalg.inv(information)[:q, :q]
    except np.linalg.LinAlgError:
        raise ModelError("calibration: the replies do not determine the positions and the perturbation (the "
                         "information is singular)") from None


__all__ = ["crb"]

"""The search among candidate perturbations by an information criterion (:func:`select`): SeaGap's AIC or BIC
over the number of bases, GARPOS's ABIC over its hyperparameters.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from sblsim.models.calibration.leastsquares import _solve, judge
from sblsim.models.calibration.legs import LegModel, StraightRay
from sblsim.models.calibration.measurement import _model
from sblsim.models.calibration.ocean import Step, _check_perturbation, _solve_perturbed, bases_of
from sblsim.models.calibration.perturbation import CRITERIA
from sblsim.models.calibration.replies import Perturbation, Replies, Solution
from sblsim.models.declarations import ModelError


def _search_criterion(kind: str, criterion: str) -> str:
    return "abic" if kind == "garpos" else criterion


def select(replies: Replies, apriori: Sequence[Sequence[float]] | np.ndarray, sound_speed: float,
           candidates: Sequence[Perturbation], *, rigid: bool = False, outlier_factor: float | None = None,
           legs: LegModel | None = None, what: str = "calibration", criterion: str = "bic",
           reference: Solution | None = None, progress: Step | None = None) -> tuple[Solution, list[dict]]:
    """The perturbation chosen among ``candidates`` by an information criterion, and every candidate's.

    SeaGap's search over the number of bases takes the smallest AIC or BIC
    (:func:`~sblsim.models.calibration.perturbation.akaike`; Tomita and Kido, 2022), GARPOS's over its
    hyperparameters the smallest ABIC (Akaike's Bayesian information criterion of the smoothness prior, H. Akaike,
    in *Bayesian Statistics*, 1980; Watanabe et al., 2020, eq. 22). The first candidate is solved in full; every
    candidate is then solved with the legs linearised about that solution's positions (the candidates move them by
    millimetres, which changes the travel times' linearisation by :math:`10^{-10}` s), and the chosen one is solved
    in full from there.

    Parameters
    ----------
    replies, apriori, sound_speed, rigid, outlier_factor, legs, what
        As :func:`solve`.
    candidates : sequence of Perturbation
        One kind for all (``ntd`` or ``garpos``).
    criterion : str
        ``"aic"`` or ``"bic"`` (:data:`~sblsim.models.calibration.perturbation.CRITERIA`) for ``ntd``; ``garpos``
        takes ABIC.
    reference : Solution or None
        A solution of these replies to linearise about instead of the first candidate's.
    progress : callable or None
        ``progress(1)`` after each Gauss-Newton iteration of every candidate's solve.

    Returns
    -------
    solution : Solution
        The chosen candidate's.
    table : list of dict
        Per candidate: ``n_bases``, ``log_lambda0``, ``log_grad_lambda``, ``mu_t``, ``mu_mt``, ``aic``, ``bic``,
        ``abic``, ``twtt_residual_rms_s``, ``e_m``, ``n_m``, ``u_m`` (the first transponder's offset), ``chosen``.

    Raises
    ------
    ModelError
        No candidate, kinds mixed, an unknown criterion, or what :func:`solve` raises (every candidate's number
        of bases is checked before any is solved).
    """
    if not candidates:
        raise ModelError(f"{what}: no candidate perturbation to choose from")
    if len({c.kind for c in candidates}) != 1:
        kinds = ", ".join(sorted({c.kind for c in candidates}))
        raise ModelError(f"{what}: the candidates mix perturbations ({kinds})")
    if criterion not in CRITERIA:
        raise ModelError(f"criterion: {str(criterion)[:40]!r} is not one of {', '.join(CRITERIA)}")
    apriori = np.asarray(apriori, dtype=float)
    legs = legs or StraightRay()
    for candidate in candidates:  # every candidate checked before any is solved
        _check_perturbation(candidate, replies, False)
        if len(replies):
            bases_of(candidate, replies.t_tx, replies.t_rx, what)
    first = reference or _solve(replies, apriori, sound_speed, rigid=rigid, outlier_factor=outlier_factor, legs=legs,
                               what=what, perturbation=candidates[0], progress=progress)
    if len(candidates) == 1 and reference is None:
        judge(first, what)
        return first, [_candidate_row(candidates[0], first, True)]
    reference = first.offset[0] if rigid else first.offset.ravel()
    residual, jacobian = _model(replies, apriori, reference, float(sound_speed), rigid, False, legs, 0.0)[:2]
    name = _search_criterion(candidates[0].kind, criterion)
    solutions = []
    for candidate in candidates:
        _check_perturbation(candidate, replies, False)
        solutions.append(_solve_perturbed(replies, apriori, float(sound_speed), rigid, legs, candidate, outlier_factor,
                                          what, (reference, residual, jacobian), reference, progress))
    values = [getattr(s.perturbation, name) for s in solutions]
    best = int(np.argmin(values))
    start = solutions[best].offset[0] if rigid else solutions[best].offset.ravel()
    chosen = first if best == 0 and first.perturbation.settings == candidates[0] else \
        _solve_perturbed(replies, apriori, float(sound_speed), rigid, legs, candidates[best], outlier_factor, what,
                         None, start, progress)
    judge(chosen, what)  # the chosen solution only: a candidate the survey cannot separate loses the search
    return chosen, [_candidate_row(c, s, k == best) for k, (c, s) in enumerate(zip(candidates, solutions))]


def _candidate_row(candidate: Perturbation, solution: Solution, chosen: bool) -> dict:
    fit = solution.perturbation
    used = solution.used
    return {"n_bases": fit.n_bases, "log_lambda0": candidate.log_lambda0, "log_grad_lambda": candidate.log_grad_lambda,
            "mu_t": candidate.mu_t, "mu_mt": candidate.mu_mt, "aic": fit.aic, "bic": fit.bic, "abic": fit.abic,
            "twtt_residual_rms_s": float(np.sqrt(np.mean(solution.residual_s[used] ** 2))),
            "e_m": float(solution.offset[0, 0]), "n_m": float(solution.offset[0, 1]),
            "u_m": float(solution.offset[0, 2]), "chosen": chosen}


__all__ = ["select"]

"""Calibration of seafloor transponders from the surface: positions from two-way travel times.

A surface transducer (a vessel's or a wave glider's, positioned by GNSS) interrogates seafloor transponders
and records each reply's two-way travel time (TWTT). The transducer moves between the transmission and the
reply, so one TWTT measures two legs,

.. math:: c\\,T_i = \\ell(\\mathbf p_{\\mathrm{tx},i}, \\mathbf x_j) + \\ell(\\mathbf x_j, \\mathbf p_{\\mathrm{rx},i}),

with :math:`T_i` the TWTT without the transponder's turnaround, :math:`c` the sound speed, :math:`\\mathbf x_j`
the replying transponder and :math:`\\ell` the acoustic path length of a leg at speed :math:`c` (for a straight
ray its length :math:`|\\mathbf p - \\mathbf x|`). :func:`solve` estimates the transponders' positions (each, or
one common rigid shift of a known array) and optionally a sound-speed scale :math:`s` (:math:`c = s\\,c_0`) by
weighted least squares (Gauss-Newton) of the range residuals :math:`v_i = s\\,c_0\\,T_i - \\ell_{\\mathrm{tx}} -
\\ell_{\\mathrm{rx}}` [m], with the weights of Xie et al. (2023): the transducer's GNSS 1-sigma projected on the
two lines of sight,

.. math:: \\sigma_i^2 = \\sum_{k\\in\\{e,n,u\\}} (u_{\\mathrm{tx},k}\\,\\sigma_{\\mathrm{tx},k})^2
          + (u_{\\mathrm{rx},k}\\,\\sigma_{\\mathrm{rx},k})^2 + (c\\,\\sigma_T)^2,

(:math:`\\mathbf u` the unit vectors of the legs; :math:`\\sigma_T` an optional TWTT noise, 0 in their work),
and their outlier rule: while the largest :math:`|v_i|` exceeds ``outlier_factor`` times the weighted RMS
:math:`\\sqrt{\\sum w_i v_i^2 / \\sum w_i}`, the reply (or replies) with it is dropped and the solution redone
(when Gauss-Newton diverges, a gross outlier, the largest residual after one step is dropped, as their script
does).
The covariance is :math:`(J^\\top W J)^{-1}` scaled by the a posteriori variance of unit weight
:math:`\\sum w_i v_i^2 / (n - p)`. Several solutions (time segments) combine as the authors combine them
(:func:`combine`): a weighted mean with weights one over the squared weighted RMS of the half residuals projected
on North, East and Up.

The leg model is a hook: :class:`StraightRay` is the straight ray at one speed (what Xie et al. use) or at one
speed per transponder (GNATSS's harmonic mean down to each transponder), :class:`EigenRay` the direct eigenray
through a sound-speed profile (:mod:`sblsim.models.acoustics.rays`); a leg's path length is its travel time
times the reference speed :math:`c_0`.

Frames: every position is local East, North, Up [m] of the survey's origin, in that column order.

Source: S. Xie, M. Zumberge, G. Sasagawa, D. Voytenko, "Shallow Water Seafloor Geodesy with Wave Glider-Based
GNSS-Acoustic Surveying of a Single Transponder", Earth and Space Science, 2023 (weights, outlier rule, segment
combination); the Gauss-Newton normal equations as in any geodetic adjustment (e.g. Strang & Borre, *Linear
Algebra, Geodesy, and GPS*, 1997, ch. 9).

Where each part is (one job per module; each imports only the modules listed before it):

* :mod:`~sblsim.models.calibration.determination`: how well a solution is determined (the normal matrix's
  condition, the positions' correlations with the other unknowns) and the refusal of what the survey cannot
  separate or what did not converge;
* :mod:`~sblsim.models.calibration.perturbation`: the sound-speed perturbation's pieces: cubic B-splines and
  their knots, the nadir cosine and the gradients' directions, GARPOS's roughness prior and data correlation, AIC
  and BIC, the realistic sigma's factor;
* :mod:`~sblsim.models.calibration.legs`: the leg models, :class:`LegModel`, :class:`StraightRay` and
  :class:`EigenRay`;
* :mod:`~sblsim.models.calibration.replies`: the survey's replies (:class:`Replies`) and the records a solution
  takes and gives (:class:`Perturbation`, :class:`Solution`, :class:`PerturbationFit`);
* :mod:`~sblsim.models.calibration.measurement`: the measurement model of a reply (range residual, Jacobian,
  line-of-sight variance), the inputs' checks and Gauss-Newton's tolerances;
* :mod:`~sblsim.models.calibration.ocean`: the moving ocean, where SeaGap's NTD and GARPOS's log-TT correction
  are fitted with the positions (the design, the data covariance, the fit, AIC, BIC and ABIC);
* :mod:`~sblsim.models.calibration.leastsquares`: :func:`solve`, the Gauss-Newton array solution with the
  outlier rule;
* :mod:`~sblsim.models.calibration.selection`: :func:`select`, the AIC, BIC or ABIC search among candidate
  perturbations;
* :mod:`~sblsim.models.calibration.bound`: :func:`crb`, the Cramér-Rao bound;
* :mod:`~sblsim.models.calibration.kalman`: :func:`running`, the running solution (a static Kalman filter);
* :mod:`~sblsim.models.calibration.combination`: :func:`combine`, the segments' solutions combined;
* :mod:`~sblsim.models.calibration.boxin`: a simulated box-in survey (its replies and its truth).

The modules' public names are imported from here (``from sblsim.models.calibration import solve``). The package
imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

from sblsim.models.calibration.bound import crb
from sblsim.models.calibration.combination import Combined, combine
from sblsim.models.calibration.determination import MAX_CONDITION, MAX_CORRELATION, Determination
from sblsim.models.calibration.kalman import (
    PASSES_RANGE,
    PRIOR_SCALE_SIGMA,
    PRIOR_SIGMA_M,
    PRIOR_SIGMA_RANGE,
    RUNNING_AGREEMENT_SIGMA,
    Running,
    running,
    running_disagreement,
)
from sblsim.models.calibration.leastsquares import MAX_SOUND_SPEED_SIGMA, solve
from sblsim.models.calibration.legs import (
    EARTH_RADIUS_RANGE,
    SOUND_SPEED_RANGE,
    TRANSDUCER_DEPTH_RANGE,
    EigenRay,
    LegModel,
    StraightRay,
)
from sblsim.models.calibration.measurement import (
    MAX_ITERATIONS,
    OUTLIER_FACTOR_RANGE,
    POSITION_TOLERANCE,
    SCALE_TOLERANCE,
)
from sblsim.models.calibration.replies import Perturbation, PerturbationFit, Replies, Solution
from sblsim.models.calibration.selection import select

__all__ = ["combine", "Combined", "crb", "Determination", "MAX_CONDITION", "MAX_CORRELATION",
           "EARTH_RADIUS_RANGE", "EigenRay", "LegModel", "MAX_ITERATIONS",
           "MAX_SOUND_SPEED_SIGMA", "OUTLIER_FACTOR_RANGE", "PASSES_RANGE", "Perturbation", "PerturbationFit",
           "POSITION_TOLERANCE", "PRIOR_SCALE_SIGMA", "PRIOR_SIGMA_M", "PRIOR_SIGMA_RANGE", "Replies", "Running",
           "running", "RUNNING_AGREEMENT_SIGMA", "running_disagreement", "SCALE_TOLERANCE", "select", "Solution",
           "solve", "SOUND_SPEED_RANGE", "StraightRay", "TRANSDUCER_DEPTH_RANGE"]

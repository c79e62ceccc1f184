"""What a calibration takes and gives: the survey's replies and the records of a solution.

:class:`Replies` holds a survey's replies as arrays (one row per reply: the transducer at transmit and at receive,
their sigmas, the TWTT, the replying transponder, the times); :class:`Perturbation` the settings of a sound-speed
perturbation solved with the positions (:mod:`sblsim.models.calibration.ocean`); :class:`Solution` a solution of
:func:`~sblsim.models.calibration.solve`, and :class:`PerturbationFit` its solved perturbation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.calibration.determination import Determination


@dataclass(frozen=True)
class Replies:
    """The replies of a survey as arrays (one row per reply), local ENU [m].

    Attributes
    ----------
    tx, rx : numpy.ndarray, shape (n, 3)
        The transducer at transmit and at the reply's receive time [m].
    tx_sigma, rx_sigma : numpy.ndarray, shape (n, 3)
        Their 1-sigma per axis [m], > 0.
    twtt : numpy.ndarray, shape (n,)
        Two-way travel time without the turnaround [s], > 0.
    transponder : numpy.ndarray of int, shape (n,)
        The replying transponder's index into the a-priori positions (replies are paired by identity).
    t_tx, t_rx : numpy.ndarray, shape (n,), or None
        Transmit and receive times [s] (a sound-speed perturbation, :class:`Perturbation`, needs them).
    """

    tx: np.ndarray
    tx_sigma: np.ndarray
    rx: np.ndarray
    rx_sigma: np.ndarray
    twtt: np.ndarray
    transponder: np.ndarray
    t_tx: np.ndarray | None = None
    t_rx: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.twtt)

    def subset(self, rows: np.ndarray) -> Replies:
        """The replies at ``rows`` (indices or a boolean mask)."""
        times = (None, None) if self.t_tx is None else (self.t_tx[rows], self.t_rx[rows])
        return Replies(self.tx[rows], self.tx_sigma[rows], self.rx[rows], self.rx_sigma[rows], self.twtt[rows],
                       self.transponder[rows], *times)


@dataclass
class Solution:
    """A calibration solution (:func:`solve`).

    Attributes
    ----------
    position : numpy.ndarray, shape (k, 3)
        The transponders' positions, local ENU [m].
    offset : numpy.ndarray, shape (k, 3)
        ``position`` minus the a-priori positions [m].
    sigma : numpy.ndarray, shape (k, 3)
        1-sigma of ``position`` per axis from the scaled covariance [m].
    covariance : numpy.ndarray, shape (p, p)
        Covariance of the unknowns (3 per transponder, or 3 for a rigid shift; then the speed scale) [m², 1].
    sound_speed : float
        The sound speed used (estimated when asked) [m/s].
    sound_speed_sigma : float
        Its 1-sigma [m/s] (0 when it was fixed).
    used : numpy.ndarray of bool, shape (n,)
        The replies kept by the outlier rule.
    residual_m : numpy.ndarray, shape (n,)
        :math:`s c_0 T - \\ell_{tx} - \\ell_{rx}` of every reply at the solution [m] (also the rejected ones).
    residual_s : numpy.ndarray, shape (n,)
        The same as a TWTT residual, ``residual_m / sound_speed`` [s].
    weight : numpy.ndarray, shape (n,)
        :math:`1/\\sigma_i^2` [1/m²].
    elevation : numpy.ndarray, shape (n,)
        Elevation of the receive point above the transponder's horizontal [rad].
    azimuth : numpy.ndarray, shape (n,)
        Azimuth of the receive point from the transponder, clockwise from North [rad].
    wrms_m : float
        Weighted RMS of the used residuals [m].
    variance_factor : float
        A posteriori variance of unit weight (1 when the weights are right).
    scatter : numpy.ndarray, shape (k, 3)
        Weighted RMS of the used half residuals projected on East, North, Up per transponder [m] (Xie et al.'s
        weights of the segment combination, :func:`combine`).
    iterations : int
        Gauss-Newton iterations of the last solution.
    converged : bool
        Whether the last solution met the tolerances within :data:`MAX_ITERATIONS`.
    perturbation : PerturbationFit or None
        The sound-speed perturbation solved with the positions (None without one). With it, ``covariance`` is the
        positions' block, ``residual_s`` the TWTT residual of the whole model (legs and perturbation) and
        ``variance_factor`` the a posteriori variance of the perturbation's residuals (SeaGap: of the
        nadir-normalised time [s²]; GARPOS: of unit weight).
    determination : Determination or None
        The condition of the normal matrix and the positions' largest correlation with the other unknowns
        (:mod:`sblsim.models.calibration.determination`).
    """

    position: np.ndarray
    offset: np.ndarray
    sigma: np.ndarray
    covariance: np.ndarray
    sound_speed: float
    sound_speed_sigma: float
    used: np.ndarray
    residual_m: np.ndarray
    residual_s: np.ndarray
    weight: np.ndarray
    elevation: np.ndarray
    azimuth: np.ndarray
    wrms_m: float
    variance_factor: float
    scatter: np.ndarray
    iterations: int
    converged: bool
    perturbation: PerturbationFit | None = None
    determination: Determination | None = None


@dataclass(frozen=True)
class Perturbation:
    """The settings of a sound-speed perturbation solved with the positions
    (:mod:`sblsim.models.calibration.perturbation`).

    Attributes
    ----------
    kind : str
        ``"ntd"`` (SeaGap's nadir total delay) or ``"garpos"`` (GARPOS's correction of the log travel time).
    n_bases : int
        Cubic B-spline bases over the survey, in :data:`~sblsim.models.calibration.perturbation.BASES_RANGE`; 0: one
        knot every ``knot_interval``.
    knot_interval : float
        The knots' spacing when ``n_bases`` is 0 [s].
    gradient : str
        ``"none"``, ``"deep"`` or ``"shallow+deep"`` (:data:`~sblsim.models.calibration.perturbation.GRADIENTS`).
    log_lambda0, log_grad_lambda : float
        GARPOS's smoothness: :math:`\\log_{10}\\lambda_0^2` of the background, :math:`\\log_{10}` of the gradients'
        :math:`\\lambda_g^2/\\lambda_0^2` (``garpos`` only).
    mu_t : float
        GARPOS's data correlation length [s] (0: independent replies; ``garpos`` only).
    mu_mt : float
        GARPOS's correlation between different transponders' replies, in [0, 1].
    reject_sigma : float
        Drop the replies whose residual is more than this many standard deviations from the mean, re-judged after
        each solution (GARPOS's ``RejectCriteria``; 0: none). A correlated data covariance is not used with it (as
        GARPOS).
    earth_radius : float
        The radius of the nadir angle's geometry [m] (the legs' :class:`EigenRay` ``earth_radius``; 0: flat).
    t0 : float
        GARPOS's characteristic travel time :math:`T_0` [s] (twice the mean depth over the mean speed: the unit of
        its coefficients and residuals is :data:`~sblsim.models.calibration.perturbation.TRAVEL_TIME_SCALE` over
        it); 0: twice the a-priori positions' mean depth below Up 0 over the solver's speed.
    """

    kind: str = "ntd"
    n_bases: int = 0
    knot_interval: float = 300.0
    gradient: str = "none"
    log_lambda0: float = -2.0
    log_grad_lambda: float = -1.0
    mu_t: float = 0.0
    mu_mt: float = 0.5
    reject_sigma: float = 0.0
    earth_radius: float = 0.0
    t0: float = 0.0


@dataclass
class PerturbationFit:
    """A solved perturbation (:attr:`Solution.perturbation`).

    Attributes
    ----------
    settings : Perturbation
    n_bases : int
        The splines' bases.
    knots : numpy.ndarray, shape (n_bases + 4,)
        [s].
    used_bases : numpy.ndarray of bool, shape (n_bases,)
        The bases solved (``ntd`` drops those no used reply touches, as SeaGap; ``garpos`` keeps all, the prior
        holds them).
    coefficients, coefficient_sigma : numpy.ndarray, shape (n_bases,)
        The background's coefficients and their 1-sigma: ``ntd`` the NTD [s], ``garpos`` :math:`\\alpha_0` [1]
        (0 for an unused basis).
    gradient, gradient_sigma : dict of numpy.ndarray
        ``deep`` and ``shallow`` when solved, each (2, ...) East and North: ``ntd`` two constants ([s], and [s/km]
        for the shallow), ``garpos`` the coefficients of :math:`\\boldsymbol\\alpha_2` and
        :math:`\\boldsymbol\\alpha_1` (2, n_bases) [1/km].
    delay : numpy.ndarray, shape (n,)
        The model's perturbation of each reply as a two-way nadir delay [s]: ``ntd`` the NTD at its mid-time,
        ``garpos`` :math:`(\\hat T - \\tau)\\cos\\xi`.
    observed : numpy.ndarray, shape (n,)
        :math:`(T - \\tau)\\cos\\xi` less the gradients' part [s]: what the delay fits.
    mapping : numpy.ndarray, shape (n,)
        :math:`\\cos\\xi` of each reply [1].
    mid_time : numpy.ndarray, shape (n,)
        Each reply's mid-time [s].
    parameters : int
        The unknowns solved (positions, bases, gradients).
    aic, bic : float or None
        SeaGap's criteria (:func:`~sblsim.models.calibration.perturbation.akaike`; ``ntd``).
    abic : float or None
        GARPOS's ABIC (``garpos``).
    effective_scale : float
        The realistic sigma's factor over the formal one for the residuals' correlation in time
        (:func:`~sblsim.models.calibration.perturbation.effective_scale`).
    """

    settings: Perturbation
    n_bases: int
    knots: np.ndarray
    used_bases: np.ndarray
    coefficients: np.ndarray
    coefficient_sigma: np.ndarray
    gradient: dict
    gradient_sigma: dict
    delay: np.ndarray
    observed: np.ndarray
    mapping: np.ndarray
    mid_time: np.ndarray
    parameters: int
    aic: float | None
    bic: float | None
    abic: float | None
    effective_scale: float


__all__ = ["Perturbation", "PerturbationFit", "Replies", "Solution"]

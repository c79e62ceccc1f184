"""The sound-speed perturbation of a GNSS-Acoustic survey: smooth functions of time in cubic B-splines.

One profile (or one speed) for a whole survey cannot follow the ocean: its sound speed changes over hours by
parts in 10^4, which moves every travel time by tens of microseconds, far more than the centimetre a survey is
after. The field's tools model that change as a smooth function of time on top of the reference travel time
:math:`\\tau` of each reply's two legs (:mod:`sblsim.models.calibration.legs`):

* **NTD** (SeaGap; F. Tomita, M. Kido, Earth, Planets and Space, 2022, doi:10.1186/s40623-022-01740-0; its
  ``static_array.jl``): the nadir total delay :math:`\\delta(t)` [s], a two-way delay along the vertical mapped to
  the slant reply by :math:`M = 1/\\cos\\xi` (:math:`\\xi` the nadir angle of the straight line from the
  transponder to the transducer, the mean of the two legs'), and optionally the deep gradient
  :math:`\\mathbf g_d` [s] on :math:`\\mathbf h = \\tan\\xi\\,(\\sin\\phi, \\cos\\phi)` (the horizontal
  direction from the transducer to the transponder, East and North, times the ratio of horizontal to vertical
  distance) and the
  shallow gradient :math:`\\mathbf g_s` [s/km] on the transducer's horizontal offset from its mean [km]:

  .. math:: \\cos\\xi_i\\,T_i = \\cos\\xi_i\\,\\tau_i + \\sum_j c_j B_j(t_i) + \\mathbf g_d\\cdot\\mathbf h_i
            + \\mathbf g_s\\cdot\\mathbf u_i,

  :math:`t_i` the mid-time of the reply (transmit and receive), :math:`B_j` cubic B-splines;
* **GARPOS** (S. Watanabe, T. Ishikawa, Y. Yokota, Y. Nakamura, Front. Earth Sci. 8:597532, 2020,
  doi:10.3389/feart.2020.597532; its ``forward.py``, ``setup_model.py``): the log of the travel time corrected
  by :math:`\\gamma`, the mean of its values at transmit and at receive,

  .. math:: \\ln T_i = \\ln\\tau_i - \\tfrac12\\,[\\gamma(t_{tx,i}) + \\gamma(t_{rx,i})], \\quad
            \\gamma(t) = \\alpha_0(t) + \\boldsymbol\\alpha_1(t)\\cdot\\mathbf d(t) + \\boldsymbol\\alpha_2(t)
            \\cdot\\mathbf m,

  :math:`\\alpha_0` the background (a relative speed change: :math:`\\delta V = \\gamma V_0`), :math:`\\boldsymbol
  \\alpha_1` the shallow gradient on the transducer's horizontal offset from its mean :math:`\\mathbf d` [km],
  :math:`\\boldsymbol\\alpha_2` the deep gradient on the transponder's a-priori offset from the array's centre
  :math:`\\mathbf m` [km], each a cubic B-spline in time.

The splines' knots are evenly spaced over the survey (:func:`uniform_knots`): ``n_bases`` bases (SeaGap) or one
knot every ``knot_interval`` seconds (GARPOS, :func:`interval_bases`). GARPOS's smoothness prior is the quadratic
form of :func:`roughness`; its data covariance (correlation in time and between transponders) is
:func:`correlation_band`.

This module imports nothing from the FMI or orchestrator layers.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import BSpline

#: ``solver.perturbation``: none, SeaGap's NTD, GARPOS's log-TT correction.
PERTURBATIONS = ("none", "ntd", "garpos")
#: ``solver.gradient``: none, the deep gradient, the shallow and the deep gradients.
GRADIENTS = ("none", "deep", "shallow+deep")
#: The criteria of the search over the number of bases (``solver.criterion``).
CRITERIA = ("aic", "bic")
#: The spline's degree (cubic).
DEGREE = 3
#: The bases accepted (4: one cubic piece) and a knot interval's range [s].
BASES_RANGE = (4, 5000)
KNOT_INTERVAL_RANGE = (1.0, 86400.0)
#: The pings (transmissions) a knot interval must hold on average for its basis to be determined
#: (:func:`determinable_bases`).
PINGS_PER_INTERVAL = 4
#: The most cells (replies times the perturbation's columns) of a moving-ocean solve's design, which is dense
#: (:func:`computable_bases`): 80 MB a copy, a Gauss-Newton iteration within a second or two on two cores.
MAX_DESIGN_CELLS = 10_000_000
#: GARPOS's typical travel-time error, the unit of its residuals and coefficients (``traveltimescale``) [s].
TRAVEL_TIME_SCALE = 1e-4
#: GARPOS's gradients are per km of horizontal offset (its ``ls``) [m].
GRADIENT_LENGTH = 1000.0
#: GARPOS's knots' spacing in its roughness is in hours [s].
ROUGHNESS_TIME = 3600.0
#: Data correlations are kept within this many correlation lengths (GARPOS: 4).
CORRELATION_REACH = 4.0


def uniform_knots(start: float, end: float, n_bases: int) -> np.ndarray:
    """The knots of ``n_bases`` cubic B-splines evenly spaced over ``[start, end]``.

    The interval :math:`\\Delta = (t_1 - t_0)/(n - 3)`; the knots :math:`t_0 + k\\Delta`, :math:`k = -3 \\ldots n`,
    so that the bases sum to one over the survey (SeaGap's ``mktbasis``; GARPOS's ``make_knots`` with
    :math:`n - 3` intervals).

    Parameters
    ----------
    start, end : float
        The survey's first transmission and last reception [s].
    n_bases : int
        In :data:`BASES_RANGE`.

    Returns
    -------
    numpy.ndarray, shape (n_bases + 4,)
        [s].
    """
    step = (end - start) / (n_bases - DEGREE)
    return start + step * np.arange(-DEGREE, n_bases + 1, dtype=float)


def interval_bases(start: float, end: float, interval: float) -> int:
    """The bases of a knot every ``interval`` seconds (GARPOS: ``int(duration / interval)`` intervals, at least
    one), :math:`n = \\lfloor (t_1 - t_0)/\\Delta \\rfloor + 3`."""
    return max(1, int((end - start) / interval)) + DEGREE


def determinable_bases(pings: int) -> int:
    """The most cubic B-spline bases a survey of ``pings`` transmissions determines: :math:`3 + \\lfloor P / 4
    \\rfloor`, so that each knot interval holds :data:`PINGS_PER_INTERVAL` pings on average.

    Each knot interval of a cubic spline adds one coefficient (its polynomial's four less the three continuity
    conditions), and the delay at one instant is one number however many transponders reply to that ping (their
    nadir angles separate it from the positions, not from the delay of another instant): one ping per interval is
    the least that can determine a coefficient, with nothing left to tell its noise. Four leave margin and hold
    the field's practice: SeaGap's tutorial solves its example (857 pings over 14 h) with 100 bases, 8.6 pings per
    interval, and searches up to 150, 5.8 (Tomita and Kido, 2022, its ``pos_array_all`` and
    ``pos_array_all_AICBIC``). The duration enters through the knot interval: a survey of duration :math:`D`
    allows a knot interval down to :math:`D / \\lfloor P/4 \\rfloor`.

    Parameters
    ----------
    pings : int
        The survey's (or segment's) transmissions with a reply [1].

    Returns
    -------
    int
        [1].
    """
    return DEGREE + int(pings) // PINGS_PER_INTERVAL


def computable_bases(replies: int, kind: str, gradient: str) -> int:
    """The most bases whose dense design of ``replies`` rows stays within :data:`MAX_DESIGN_CELLS`.

    A moving-ocean solve holds its design (one row per reply, a column per coefficient) and a few copies of it as
    dense matrices, and each Gauss-Newton iteration forms its normal matrix, :math:`n p^2` operations: 21,601
    replies and 5,000 bases are 0.9 GB a copy, some 5 GB in all and tens of seconds an iteration. SeaGap's NTD has
    one column per basis and four of the gradients; GARPOS's gradients are splines too, one column per basis each
    (``shallow+deep``: five per basis).

    Parameters
    ----------
    replies : int
        The replies solved [1].
    kind : str
        ``"ntd"`` or ``"garpos"``.
    gradient : str
        One of :data:`GRADIENTS`.

    Returns
    -------
    int
        [1].
    """
    deep, shallow = gradient != "none", gradient == "shallow+deep"
    per_basis = 1 + (2 * deep + 2 * shallow if kind == "garpos" else 0)
    fixed = 0 if kind == "garpos" else 2 * deep + 2 * shallow
    return max(0, (MAX_DESIGN_CELLS // max(int(replies), 1) - fixed) // per_basis)


def basis(t: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """The cubic B-splines of ``knots`` at times ``t`` (scipy's ``BSpline.design_matrix``).

    Parameters
    ----------
    t : numpy.ndarray, shape (n,)
        Times inside the knots' span of full support [s] (a time beyond it by round-off is taken at its end).
    knots : numpy.ndarray, shape (m + 4,)

    Returns
    -------
    numpy.ndarray, shape (n, m)
        :math:`B_j(t_i)` [1].
    """
    t = np.clip(np.asarray(t, dtype=float), knots[DEGREE], knots[-DEGREE - 1])
    return BSpline.design_matrix(t, knots, DEGREE).toarray()


def roughness(knots: np.ndarray) -> np.ndarray:
    """GARPOS's roughness of a cubic B-spline's coefficients :math:`\\mathbf c`, :math:`\\mathbf c^\\top
    \\Delta^\\top W \\Delta\\,\\mathbf c`.

    :math:`\\Delta` takes second differences of the coefficients divided by the knots' spacing, row :math:`j`
    :math:`(1/h_0, -1/h_0 - 1/h_1, 1/h_1)` at :math:`j, j+1, j+2`; :math:`W` is tridiagonal,
    :math:`W_{jj} = (h_0 + h_1)/3`, :math:`W_{j,j\\pm1} = h/6`; :math:`h_0, h_1` the spacings of the knots
    :math:`j+3, j+4, j+5` in hours (Watanabe et al., 2020, the smoothness constraint; GARPOS's
    ``derivative2``).

    Parameters
    ----------
    knots : numpy.ndarray, shape (m + 4,)
        [s].

    Returns
    -------
    numpy.ndarray, shape (m, m)
        Symmetric, positive semi-definite (its null space: straight lines in time), [h].
    """
    m = len(knots) - DEGREE - 1
    rows = m - 2
    if rows < 1:
        return np.zeros((m, m))
    h = np.diff(knots) / ROUGHNESS_TIME
    h0, h1 = h[DEGREE:DEGREE + rows], h[DEGREE + 1:DEGREE + 1 + rows]
    delta = np.zeros((rows, m))
    j = np.arange(rows)
    delta[j, j], delta[j, j + 1], delta[j, j + 2] = 1.0 / h0, -1.0 / h0 - 1.0 / h1, 1.0 / h1
    w = np.diag((h0 + h1) / 3.0) + np.diag(h0[1:] / 6.0, 1) + np.diag(h0[1:] / 6.0, -1)
    return delta.T @ w @ delta


def nadir_cosine(points: np.ndarray, x: np.ndarray, earth_radius: float = 0.0) -> np.ndarray:
    """:math:`\\cos\\xi`: the Up difference over the straight line's length from ``x`` to ``points``.

    With an Earth radius :math:`R` the line is the chord between the radii :math:`R + U` over the arc
    :math:`X/R` (SeaGap's ``vert``).

    Parameters
    ----------
    points, x : numpy.ndarray, shape (n, 3)
        The transducer and the transponder, ENU [m].
    earth_radius : float
        0 (flat) or the radius of the spherical layering [m].

    Returns
    -------
    numpy.ndarray, shape (n,)
    """
    rise = points[:, 2] - x[:, 2]
    horizontal = np.hypot(points[:, 0] - x[:, 0], points[:, 1] - x[:, 1])
    if earth_radius > 0.0:
        b, c = earth_radius + points[:, 2], earth_radius + x[:, 2]
        chord = np.sqrt((b - c) ** 2 + 2.0 * b * c * (1.0 - np.cos(horizontal / earth_radius)))
    else:
        chord = np.hypot(horizontal, rise)
    return rise / chord


def slant_direction(points: np.ndarray, x: np.ndarray) -> np.ndarray:
    """:math:`\\tan\\xi\\,(\\sin\\phi, \\cos\\phi)`: the horizontal vector from ``points`` to ``x`` over their Up
    difference (East, North) [1], shape (n, 2) (SeaGap's deep-gradient term)."""
    return (x[:, :2] - points[:, :2]) / (points[:, 2] - x[:, 2])[:, None]


def correlation_band(t: np.ndarray, transponder: np.ndarray, scale: np.ndarray, mu_t: float,
                     mu_mt: float) -> np.ndarray:
    """GARPOS's data covariance of replies sorted by transmit time, as the lower band of a symmetric matrix.

    :math:`E_{ij} = e^{-|t_i - t_j|/\\mu_t}\\,[\\mu_{MT} + (1 - \\mu_{MT})\\,\\delta_{k_i k_j}] / (s_i s_j)`, kept where
    :math:`|t_i - t_j| < 4\\mu_t` (Watanabe et al., 2020, eq. 17; GARPOS's ``data_correlation``), :math:`k` the
    transponders, :math:`s` ``scale``.

    Parameters
    ----------
    t : numpy.ndarray, shape (n,)
        Transmit times, non-decreasing [s].
    transponder : numpy.ndarray of int, shape (n,)
    scale : numpy.ndarray, shape (n,)
        Each reply's scale (GARPOS: its travel time over the characteristic one) [1].
    mu_t : float
        Correlation length [s], > 0.
    mu_mt : float
        Correlation between different transponders' replies, in [0, 1].

    Returns
    -------
    numpy.ndarray, shape (b + 1, n)
        ``band[d, i]`` = :math:`E_{i+d,i}` (scipy's lower banded form, zero beyond the end).
    """
    n = len(t)
    reach = CORRELATION_REACH * mu_t
    width = int(np.max(np.searchsorted(t, t + reach, side="left") - np.arange(n) - 1, initial=0))
    band = np.zeros((width + 1, n))
    for d in range(width + 1):
        i = np.arange(n - d)
        gap = np.abs(t[i + d] - t[i])
        same = transponder[i + d] == transponder[i]
        value = np.exp(-gap / mu_t) * (mu_mt + (1.0 - mu_mt) * same) / (scale[i] * scale[i + d])
        band[d, :n - d] = np.where(gap < reach, value, 0.0)
    return band


def akaike(residual: np.ndarray, parameters: int) -> tuple[float, float]:
    """AIC and BIC of a least-squares fit with an unknown noise variance, as SeaGap computes them.

    :math:`\\mathrm{AIC} = n \\ln s^2 + 2p`, :math:`\\mathrm{BIC} = n \\ln s^2 + p \\ln n`, with
    :math:`s^2 = \\sum (r_i - \\bar r)^2/(n - 1)` the residuals' sample variance (H. Akaike, IEEE Trans. Automatic
    Control 19(6), 1974; G. Schwarz, Ann. Statist. 6(2), 1978; SeaGap's ``static_array.jl``): the Gaussian
    likelihood's criteria up to a constant, the same for every candidate of one survey.

    Parameters
    ----------
    residual : numpy.ndarray, shape (n,)
    parameters : int

    Returns
    -------
    aic, bic : float
    """
    n = len(residual)
    variance = float(np.var(residual, ddof=1))
    return n * math.log(variance) + 2.0 * parameters, n * math.log(variance) + parameters * math.log(n)


def effective_scale(residual: np.ndarray) -> float:
    """The factor a formal sigma takes for residuals correlated in time: :math:`\\sqrt{(1 + \\rho)/(1 - \\rho)}`,
    :math:`\\rho` the lag-one autocorrelation of the residuals in time order (at least 0), the ratio of the
    replies' count to their effective count for a first-order autoregressive noise (C. S. Bretherton et al.,
    J. Climate 12(7), 1999, eq. 31).

    Parameters
    ----------
    residual : numpy.ndarray, shape (n,)
        In time order.

    Returns
    -------
    float
        [1], at least 1.
    """
    r = residual - np.mean(residual)
    denominator = float(np.sum(r * r))
    if len(r) < 3 or denominator == 0.0:
        return 1.0
    rho = min(max(float(np.sum(r[1:] * r[:-1]) / denominator), 0.0), 0.99)
    return math.sqrt((1.0 + rho) / (1.0 - rho))


__all__ = ["BASES_RANGE", "CORRELATION_REACH", "CRITERIA", "DEGREE", "GRADIENTS", "GRADIENT_LENGTH",
           "KNOT_INTERVAL_RANGE", "MAX_DESIGN_CELLS", "PERTURBATIONS", "PINGS_PER_INTERVAL", "ROUGHNESS_TIME",
           "TRAVEL_TIME_SCALE", "akaike", "basis", "computable_bases", "correlation_band", "determinable_bases",
           "effective_scale", "interval_bases", "nadir_cosine", "roughness", "slant_direction", "uniform_knots"]

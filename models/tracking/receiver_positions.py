"""The receivers' horizontal positions from a moving tag's own pings: the tag's places and emission times and the
receivers' shifts from their surveyed positions solved together, the survey a prior (an array's self-calibration).

Each time of arrival is ``toa_ij = t_j + ‖p_j − (r_i + d_i)‖ / c_j`` for ping j (place ``p_j``, emission time
``t_j``, sound speed ``c_j``) at receiver i (surveyed position ``r_i``, horizontal shift ``d_i`` unknown, its depth
as surveyed). The pings' horizontal places and emission times and the shifts are fitted together by Gauss-Newton
with a prior ``d_i ~ N(0, σ₀² I)`` (the survey's σ per axis), the tag's depth kept at its start (a sensor's, or the
fix's in 3-D); each arrival weighed by its Student-t weight ``(ν + 1) / (ν + z²)`` (a late multipath arrival counts
little; iteratively reweighted). The pings are eliminated ping by ping (three unknowns each, Schur's complement),
leaving the receivers' normal matrix (:mod:`sblsim.models.tracking.refinement_terms`): a record's cost is linear in
its pings.

Where asked, three more kinds of unknowns join them: each receiver's **range bias** ``β_i`` [m] (``toa_ij = t_j +
(‖p_j − (r_i + d_i)‖ + β_i) / c_j``, the same prior: the offset a synchronisation made on wrong positions leaves its
clock, a constant or, given the synchronisation's bins' edges, linear in time between knots at them as its clocks
are: with few sync tags the error changes from bin to bin with the sync tags a receiver hears); **anchored pings**,
emitted where a receiver is (a sync tag at its receiver: its place moves with that receiver, its emission time its
only unknown of its own), which tell a receiver's clock from its place (both directions of each pair of receivers
are heard); and the **sound speed's scale** ``m`` (``c_j / m``, a prior on ``m``), where the sound speed was
calibrated from the same pings on the surveyed positions and took up their error. Where asked (``rescale``), each
receiver's timing noise is then taken from its own studentised residuals and the fit made again: a noise taken from a
synchronisation made on wrong positions took up their error.

A ping heard by three receivers (two coordinates and a time) adds nothing: only pings with at least four arrivals
are fitted. What the pings determine is the array's **shape**: a translation or a rotation of the whole array with
its track changes no time of arrival (nor, with the sound speed fitted, a dilation: a larger array at a faster sound
speed), so those stay the survey's (the prior's mean) with its σ₀/√R; a receiver is
**determined** where its posterior σ in the shape is below :data:`~sblsim.models.sync.identifiability.
MAX_SIGMA_RATIO` of the survey's (:func:`~sblsim.models.sync.identifiability.shape_sigma_ratio`), and keeps its
surveyed position elsewhere.

Whether a refinement helps is the data's to say, not the fit's own residuals (a refined array always fits the pings
it was fitted to better): :mod:`sblsim.models.tracking.held_out` leaves each block of the pings out in turn.

References
----------
Triggs, McLauchlan, Hartley, Fitzgibbon, "Bundle adjustment — a modern synthesis", Vision Algorithms 1999, LNCS 1883
(§ 6.1: the points eliminated by Schur's complement, the cameras' reduced system); Tapley, Schutz & Born, *Statistical
Orbit Determination*, Elsevier 2004, § 4.6 (a priori information); Lange, Little, Taylor, JASA 84(408), 1989 (the
Student-t weights); Koch, *Parameter Estimation and Hypothesis Testing in Linear Models*, Springer 1999, § 3.4 (the
free network's datum defect).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.sync.identifiability import MAX_SIGMA_RATIO, shape_sigma_ratio
from sblsim.models.tracking.fix import fix_pings
from sblsim.models.tracking.refinement_terms import Anchored, Normal, Unknowns, ping_terms, solve
from sblsim.models.tracking.smoother_cost import ROBUST_DOF
from sblsim.models.tracking.toa import checked_sigma

#: Arrivals a ping needs to be fitted (two coordinates and an emission time, and one more to say anything).
MIN_ARRIVALS = 4
#: The fit's iterations at most, and the largest shift's step [m] at which it has converged (a millimetre: the
#: arrivals' weights still move a little from one step to the next where an arrival's residual is near √ν σ).
ITERATIONS, STEP_TOLERANCE = 50, 1e-3
#: A ping whose fix at the surveyed positions fits this many times worse than the median ping's (χ² per degree of
#: freedom) is left out of the refinement: a fix in a mirror place or of echoes, no start for Gauss-Newton.
START_GATE = 25.0
#: The arrivals a receiver needs for its timing noise to be its own residuals' (``rescale``), and the least timing
#: noise [s] so found (a microsecond: below any receiver's resolution).
MIN_RESCALE, MIN_SIGMA = 20, 1e-6
#: The σ [m] a place's depth is kept at in a 3-D fix (the depth is the tag's, not refitted).
DEPTH_SIGMA = 0.01
#: The most one Gauss-Newton step moves a receiver's shift or bias [its prior σ]: a step the arrivals' weights are
#: not yet right for (the first, the pings' places still the survey's) cannot throw the fit far.
MAX_STEP = 1.0


@dataclass(frozen=True)
class Refinement:
    """The receivers' shifts fitted from a tag's pings (:func:`refine_receivers`).

    Attributes
    ----------
    shift : numpy.ndarray
        (R, 2) [m] each receiver's horizontal shift from its surveyed position (0 where not ``determined``).
    fitted : numpy.ndarray
        (R, 2) [m] the fit's shifts, every receiver's (a receiver not determined stays near 0: its prior).
    covariance : numpy.ndarray
        (2R, 2R) [m²] the fitted shifts' posterior covariance, x then y per receiver.
    sigma_ratio : numpy.ndarray
        (R,) [1] each receiver's posterior σ in the array's shape over the survey's, worst direction.
    determined : numpy.ndarray
        (R,) bool, ``sigma_ratio`` below :data:`~sblsim.models.sync.identifiability.MAX_SIGMA_RATIO`.
    arrivals : numpy.ndarray
        (R,) int, each receiver's arrivals in the fit.
    pings : int
        The pings fitted (at least :data:`MIN_ARRIVALS` arrivals).
    iterations : int
    converged : bool
    bias, bias_sigma : numpy.ndarray
        (R, K + 1) [m] each receiver's range bias at each knot of ``edges`` and its σ ((R, 1): a constant; 0 where
        not fitted).
    anchored : int
        The anchored pings fitted.
    speed_scale, speed_scale_sigma : float
        [1] the sound speed fitted over the one given, and its σ (1 and 0 where not fitted).
    edges : numpy.ndarray or None
        (K + 1,) [s] the biases' knots (linear in time between them); None: each bias a constant.
    sigma : numpy.ndarray or None
        (R,) [s] the timing noise each receiver's arrivals were weighed by (with ``rescale``, its own residuals').
    """

    shift: np.ndarray
    fitted: np.ndarray
    covariance: np.ndarray
    sigma_ratio: np.ndarray
    determined: np.ndarray
    arrivals: np.ndarray
    pings: int
    iterations: int
    converged: bool
    bias: np.ndarray
    bias_sigma: np.ndarray
    anchored: int = 0
    speed_scale: float = 1.0
    speed_scale_sigma: float = 0.0
    edges: np.ndarray | None = None
    sigma: np.ndarray | None = None

    def bias_at(self, times: np.ndarray | None, rows: int) -> np.ndarray:
        """(rows, R) [m] each receiver's range bias at ``times`` (rows,) [s] on the edges' base (interpolated
        between the knots, the end knots' beyond them; ``times`` unused where the biases are constants)."""
        if self.edges is None:
            return np.broadcast_to(self.bias[:, 0], (rows, len(self.bias)))
        times = np.asarray(times, float)
        return np.stack([np.interp(times, self.edges, knots) for knots in self.bias], axis=1)


def checked_inputs(toa, receivers, places, c, sigma_toa, survey_sigma):
    """:func:`refine_receivers`' arguments checked and as arrays: ``toa`` (P, R), ``receivers`` (R, dim),
    ``places`` (P, dim), ``c`` (P,), ``sigma`` (R,).

    Raises
    ------
    ModelError
        Shapes that do not agree; a sound speed, timing noise or survey σ not positive (one line).
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    if toa.ndim != 2 or receivers.ndim != 2 or toa.shape[1] != len(receivers) or receivers.shape[1] not in (2, 3):
        raise ModelError(f"receiver positions: times of arrival {toa.shape} and receivers {receivers.shape}; allowed: "
                         "(P, R) and (R, 2 or 3)")
    places = np.asarray(places, float)
    if places.shape != (len(toa), receivers.shape[1]):
        raise ModelError(f"receiver positions: places {places.shape}; allowed: ({len(toa)}, {receivers.shape[1]})")
    c = np.broadcast_to(np.asarray(c, float), (len(toa),)).copy()
    if not (np.isfinite(c).all() and (c > 0).all()):
        raise ModelError("receiver positions: the sound speed must be finite and positive [m/s]")
    if not (np.isfinite(survey_sigma) and survey_sigma > 0):
        raise ModelError(f"receiver positions: survey sigma {survey_sigma!r}; allowed: a positive number [m]")
    sigma = np.broadcast_to(np.asarray(checked_sigma(sigma_toa, len(receivers)), float), (len(receivers),))
    return toa, receivers, places, c, sigma.copy()


def refine_receivers(toa: np.ndarray, receivers: np.ndarray, places: np.ndarray, c: float | np.ndarray,
                     sigma_toa: float | np.ndarray, survey_sigma: float, dof: float = ROBUST_DOF,
                     biases: bool = False, anchored: tuple[np.ndarray, ...] | None = None,
                     speed_sigma: float | None = None, times: np.ndarray | None = None,
                     edges: np.ndarray | None = None, rescale: bool = False,
                     bias_sigma: float | np.ndarray | None = None) -> Refinement:
    """The receivers' horizontal shifts and the tag's places fitted together (the module docstring).

    Each ping starts from its fix at the surveyed positions (:func:`~sblsim.models.tracking.fix.fix_pings`, from
    its place in ``places`` or the fix's own start, whichever fits better); a ping whose fix fits
    :data:`START_GATE` times worse than the record's median (a fix in a mirror place, a ping of echoes) is left out;
    each step of the shifts and biases is at most :data:`MAX_STEP` of its prior σ (the survey's where narrower).

    Parameters
    ----------
    toa : numpy.ndarray
        (P, R) [s] times of arrival on one clock, NaN where not heard.
    receivers : numpy.ndarray
        (R, dim) [m] the surveyed positions, dim 2 or 3 (z up).
    places : numpy.ndarray
        (P, dim) [m] each ping's place to start from (a track's), NaN where none. In 3-D its z is kept (a depth
        sensor's, or the track's) and a ping without one is left out.
    c : float or numpy.ndarray
        [m/s] the sound speed, one or (P,) per ping.
    sigma_toa : float or numpy.ndarray
        [s] a time of arrival's σ, one or (R,) per receiver.
    survey_sigma : float
        [m] the survey's σ per horizontal axis (the prior).
    dof : float
        ν of the arrivals' Student-t weights.
    biases : bool
        Fit each receiver's range bias [m] too (``toa_ij = t_j + (‖p_j − (r_i + d_i)‖ + β_i) / c_j``, its prior
        ``N(0, survey_sigma²)`` at each knot): the offset a synchronisation made on wrong positions leaves its clock
        (the sync tags' ranges were as wrong), a constant, or with ``edges`` linear in time between knots at them.
    anchored : tuple of numpy.ndarray, optional
        Pings emitted at a receiver (sync tags at their receivers): their times of arrival (Q, R) [s] on the same
        clock, each one's receiver (Q,) (its row of ``receivers``) and, with ``edges``, each one's time (Q,) [s];
        their places move with that receiver (each emission time an unknown of its own; an arrival at its own
        receiver left out), at the median sound speed. With ``biases`` they tell a receiver's clock from its place:
        both directions of a pair of receivers are heard.
    speed_sigma : float, optional
        [1] fit the sound speed too, as a scale of the one given (``c / m``, a prior σ of ``speed_sigma`` on
        ``m``): a sound speed calibrated from the pings on the surveyed positions took up their error in part. The
        array's scale then trades with it (no time of arrival tells them apart): it is a gauge like the array's
        translation and rotation, the survey's. None: as given.
    times : numpy.ndarray, optional
        (P,) [s] each ping's time on the ``edges``' base (needed with ``edges``).
    edges : numpy.ndarray, optional
        (K + 1,) [s] increasing: with ``biases``, the knots of each receiver's range bias (a synchronisation's bins'
        edges: its clocks are linear between them, and so is the error wrong positions leave in them). None: one
        constant bias per receiver.
    rescale : bool
        Once converged, take each receiver's timing noise from its own studentised residuals (their median absolute
        value over a normal's, a receiver with :data:`MIN_RESCALE` arrivals or more) and fit again:
        a timing noise taken from a synchronisation made on wrong positions took up their error (each receiver's
        as its clock's), and would weigh the receivers the refinement is to move as if they were noisy.
    bias_sigma : float or numpy.ndarray, optional
        [m] with ``biases``, the range biases' prior σ, one, (R,) per receiver (each of its knots') or (R, K + 1)
        per receiver and knot: clocks taken as logged, their offsets fitted from the pings
        (:mod:`~sblsim.orchestrator.telemetry.study_offsets`: a broad prior, one receiver's tiny at each knot, its
        clock the time base there). None: ``survey_sigma``, as the shifts'.

    Returns
    -------
    Refinement

    Raises
    ------
    ModelError
        Shapes that do not agree; a sound speed or survey σ not positive; edges not increasing, or without the
        pings' or the anchored pings' times; no ping heard by :data:`MIN_ARRIVALS` receivers.
    """
    toa, receivers, places, c, sigma = checked_inputs(toa, receivers, places, c, sigma_toa, survey_sigma)
    dim = receivers.shape[1]
    n = len(receivers)
    layout = Unknowns.of(n, biases, edges, speed_sigma is not None)
    times = None if times is None else np.asarray(times, float)
    if layout.knots > 1 and (times is None or times.shape != (len(toa),)):
        layout.bins(times, len(toa))  # refused in one line
    anchor = None if anchored is None else Anchored.of(anchored, receivers, float(np.median(c)), layout)
    heard = np.isfinite(toa)
    rows = np.flatnonzero((heard.sum(axis=1) >= MIN_ARRIVALS) & (np.isfinite(places[:, 2]) if dim == 3 else True))
    fixed, emitted, ratio = best_fixes(toa[rows], receivers, places[rows], c[rows], sigma)
    fits = np.isfinite(ratio)
    if fits.any():
        fits &= ratio <= START_GATE * max(float(np.median(ratio[fits])), 1.0)
    rows, fixed, emitted = rows[fits], fixed[fits], emitted[fits]
    if not len(rows):
        raise ModelError(f"receiver positions: no ping heard by {MIN_ARRIVALS} receivers or more with a fix; "
                         "allowed: a moving tag heard by four receivers at once")
    pings = {"receivers": receivers, "toa": toa[rows], "heard": heard[rows], "xy": fixed[:, :2].copy(),
             "t": emitted.copy(), "z": places[rows, 2] if dim == 3 else None, "c": c[rows]}
    pings["k"], pings["f"] = layout.bins(None if times is None else times[rows], len(rows))
    theta = np.zeros(layout.size)  # the biases' knots [m], the shifts [m], the slowness's scale less 1 [1]
    spread = _prior_sigmas(layout, survey_sigma, bias_sigma)  # the biases' and the shifts' prior σ [m]
    prior = np.r_[spread**-2.0, [speed_sigma**-2.0] if layout.free else []]
    moving = slice(0, layout.size - int(layout.free))  # the biases and the shifts: a step's size
    converged, iterations, limit = False, 0, ITERATIONS
    for stage in range(2 if rescale else 1):
        if stage:  # each receiver's timing noise from its own residuals, then the fit again from where it stands
            sigma = _rescaled(sigma, ping_terms(Normal(layout.size), layout, theta, pings, sigma, dof,
                                                MIN_ARRIVALS, studentised=True)[1])
            converged, limit = False, iterations + ITERATIONS
        while iterations < limit:
            iterations += 1
            normal = Normal(layout.size)
            ping_steps = ping_terms(normal, layout, theta, pings, sigma, dof, MIN_ARRIVALS)[0]
            if anchor is not None:
                anchor.terms(normal, layout, receivers, theta, sigma, dof)
            step = solve(normal.matrix(prior), normal.rhs - prior * theta, layout)[0]
            # (a prior narrower than the survey's, a time base's, holds its unknown still without slowing the rest)
            step *= min(1.0, MAX_STEP / max(float(np.abs(step[moving] / np.maximum(spread, survey_sigma)).max()),
                                            1e-300))
            # the pings' steps given the receivers' (back-substitution: Δθ_j = A_j⁻¹ (b_j − B_j Δφ))
            px, pt = ping_steps(step)
            pings["xy"] += px
            pings["t"] += pt
            if anchor is not None:
                anchor.advance(step)
            theta += step
            if np.abs(step[moving]).max() < STEP_TOLERANCE:
                converged = True
                break
    normal = Normal(layout.size)
    ping_terms(normal, layout, theta, pings, sigma, dof, MIN_ARRIVALS, covariance=True)
    if anchor is not None:
        anchor.terms(normal, layout, receivers, theta, sigma, dof, covariance=True)
    _, border, variance = solve(normal.matrix(prior), normal.rhs, layout, covariance=True)
    covariance = border[:2 * n, :2 * n]
    arrivals = pings["heard"].sum(axis=0)
    ratio = shape_sigma_ratio(receivers[:, :2], covariance, survey_sigma, arrivals > 0, scale=layout.free)
    determined = ratio < MAX_SIGMA_RATIO
    shift = layout.shifts(theta).copy()
    if layout.knots:
        bias = theta[:layout.band].reshape(layout.knots, n).T.copy()
        bias_sigma = np.sqrt(np.maximum(variance, 0.0)).reshape(layout.knots, n).T.copy()
    else:
        bias = bias_sigma = np.zeros((n, 1))
    m = layout.scale(theta)
    return Refinement(np.where(determined[:, None], shift, 0.0), shift, covariance, ratio, determined,
                      arrivals, len(rows), iterations, converged, bias, bias_sigma,
                      0 if anchor is None else int(len(anchor.t)), 1.0 / m,
                      float(np.sqrt(max(border[-1, -1], 0.0))) / m**2 if layout.free else 0.0,
                      layout.edges if layout.knots > 1 else None, sigma)


def _prior_sigmas(layout: Unknowns, survey_sigma: float, bias_sigma) -> np.ndarray:
    """(band + 2R,) [m] the prior σ of the range biases' knots (``bias_sigma``: one, (R,) per receiver or (R, K + 1)
    per receiver and knot; None: ``survey_sigma``) and of the shifts (``survey_sigma``).

    Raises
    ------
    ModelError
        ``bias_sigma`` not positive and finite, or of another length (one line).
    """
    shifts = np.full(2 * layout.receivers, survey_sigma)
    if bias_sigma is None:
        return np.r_[np.full(layout.band, survey_sigma), shifts]
    shape = np.shape(bias_sigma)
    each = np.broadcast_to(np.asarray(bias_sigma, float), (layout.knots, layout.receivers)) if shape in (
        (), (layout.receivers,)) else np.asarray(bias_sigma, float).T if shape == (
        layout.receivers, layout.knots) else None
    if each is None or not (np.isfinite(each).all() and (each > 0).all()):
        raise ModelError(f"receiver positions: the range biases' prior sigma {shape}; allowed: positive numbers "
                         f"[m], one, {layout.receivers} or ({layout.receivers}, {layout.knots})")
    return np.r_[each.ravel(), shifts]


def _rescaled(sigma: np.ndarray, residuals: np.ndarray) -> np.ndarray:
    """Each receiver's timing noise [s]: its arrivals' studentised ``residuals`` (P, R) [s] (NaN where not heard)
    median absolute value over a normal's (×1.4826: robust to the late arrivals of echoes; Rousseeuw & Croux, JASA
    88(424), 1993); a receiver with fewer than :data:`MIN_RESCALE` arrivals keeps its own."""
    heard = np.isfinite(residuals)
    n = heard.sum(axis=0)
    spread = np.array([1.4826 * np.median(np.abs(residuals[heard[:, r], r])) if n[r] >= MIN_RESCALE else np.nan
                       for r in range(len(n))])
    return np.where(n >= MIN_RESCALE, np.maximum(np.nan_to_num(spread), MIN_SIGMA), sigma)


def best_fixes(toa, receivers, places, c, sigma):
    """Each ping fixed alone with every arrival (:func:`~sblsim.models.tracking.fix.fix_pings`, no gate), from its
    place and from the fix's own start, the better kept (its depth the place's in 3-D).

    Parameters
    ----------
    toa : numpy.ndarray
        (k, R) [s] times of arrival, NaN where not heard.
    receivers : numpy.ndarray
        (R, dim) [m].
    places : numpy.ndarray
        (k, dim) [m] each ping's place to start from, NaN where none.
    c : numpy.ndarray
        (k,) [m/s] each ping's sound speed (pings of one speed fixed together).
    sigma : numpy.ndarray
        (R,) [s] each receiver's timing noise.

    Returns
    -------
    places, emissions, ratio : numpy.ndarray
        (k, dim) [m], (k,) [s] and χ² per degree of freedom (k,) [1]; NaN where a ping has none.
    """
    dim = receivers.shape[1]
    out = np.full((len(toa), dim), np.nan), np.full(len(toa), np.nan), np.full(len(toa), np.nan)
    for speed in np.unique(c):
        rows = np.flatnonzero(c == speed)
        depth = None if dim == 2 else -places[rows, 2]
        unknowns = dim + 1 - (0 if depth is None else 1)
        start = np.where(np.isfinite(places[rows]).all(axis=1, keepdims=True), places[rows], receivers.mean(axis=0))
        for guess in (start, None):
            at, emitted, _, used, chi2 = fix_pings(toa[rows], receivers, float(speed), sigma, guess, gate=np.inf,
                                                   depth=depth, depth_sigma=DEPTH_SIGMA)
            free = used.sum(axis=1) - unknowns
            ratio = np.where(free > 0, chi2 / np.maximum(free, 1), np.nan)
            better = np.isfinite(ratio) & ~(ratio >= out[2][rows])
            out[0][rows[better]], out[1][rows[better]], out[2][rows[better]] = (at[better], emitted[better],
                                                                               ratio[better])
    return out


__all__ = ["DEPTH_SIGMA", "ITERATIONS", "MAX_STEP", "MIN_ARRIVALS", "Refinement", "START_GATE",
           "STEP_TOLERANCE", "best_fixes", "checked_inputs", "refine_receivers"]

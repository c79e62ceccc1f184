"""The moving ocean: the transponders' positions solved with a sound-speed perturbation in time, SeaGap's nadir
total delay (NTD) or GARPOS's correction of the log travel time.

:func:`~sblsim.models.calibration.solve` given a :class:`~sblsim.models.calibration.replies.Perturbation` solves
here (``_solve_perturbed``: the outlier rule on the TWTT residuals and GARPOS's rejection around the fit).
``_Design`` holds a perturbed survey's fixed parts (the times, the B-spline bases of
:mod:`sblsim.models.calibration.perturbation`, the gradients' fixed factors, GARPOS's units and smoothness prior),
``_DataCovariance`` the data covariance (GARPOS's correlation in time and between transponders);
``_perturbed_model`` is the prediction and its Jacobian in the perturbation's units (SeaGap's nadir-normalised
time, GARPOS's log time), ``_perturbed_fit`` Gauss-Newton on the positions and the coefficients, and
``_perturbed_solution`` the statistics (SeaGap's a posteriori variance, AIC and BIC; GARPOS's ABIC). The model
and its sources: :mod:`sblsim.models.calibration.perturbation`.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np
from scipy.linalg import cholesky_banded, solve_banded

from sblsim.models.calibration.determination import check_determination, determination
from sblsim.models.calibration.legs import LegModel
from sblsim.models.calibration.measurement import MAX_ITERATIONS, POSITION_TOLERANCE, _directions, _model
from sblsim.models.calibration.perturbation import (
    BASES_RANGE,
    DEGREE,
    GRADIENT_LENGTH,
    GRADIENTS,
    KNOT_INTERVAL_RANGE,
    MAX_DESIGN_CELLS,
    PERTURBATIONS,
    PINGS_PER_INTERVAL,
    TRAVEL_TIME_SCALE,
    akaike,
    basis,
    computable_bases,
    correlation_band,
    determinable_bases,
    effective_scale,
    interval_bases,
    nadir_cosine,
    roughness,
    slant_direction,
    uniform_knots,
)
from sblsim.models.calibration.replies import Perturbation, PerturbationFit, Replies, Solution
from sblsim.models.declarations import ModelError


def _check_perturbation(pert: Perturbation, replies: Replies, solve_speed: bool) -> None:
    if pert.kind not in PERTURBATIONS[1:]:
        raise ModelError(f"perturbation: {str(pert.kind)[:40]!r} is not one of {', '.join(PERTURBATIONS[1:])}")
    if pert.gradient not in GRADIENTS:
        raise ModelError(f"gradient: {str(pert.gradient)[:40]!r} is not one of {', '.join(GRADIENTS)}")
    if solve_speed:
        raise ModelError("solve_sound_speed: a speed scale and a perturbation are one unknown twice (the perturbation "
                         "holds the speed's change); solve one of them")
    if replies.t_tx is None:
        raise ModelError("perturbation: the replies carry no transmit and receive times")
    lo, hi = BASES_RANGE
    if pert.n_bases and not lo <= pert.n_bases <= hi:
        raise ModelError(f"n_bases: {pert.n_bases!r} is outside the allowed range 0 or [{lo}, {hi}]")
    lo, hi = KNOT_INTERVAL_RANGE
    if not pert.n_bases and not lo <= pert.knot_interval <= hi:
        raise ModelError(f"knot_interval: {pert.knot_interval!r} is outside the allowed range [{lo:g}, {hi:g}] s")
    if pert.kind == "ntd" and pert.mu_t > 0.0:
        raise ModelError("mu_t: the data correlation is GARPOS's (perturbation = garpos); SeaGap's NTD takes "
                         "independent replies")


#: What survey separates the positions from a moving ocean (the refusals' advice): a circle at one radius sees each
#: transponder at few elevations, so that its depth and the nadir delay trade one for the other (SeaGap, Tomita &
#: Kido 2022; GARPOS, Watanabe et al. 2020, survey several radii or crosses for this reason).
SEPARATE = ("survey a second circle radius or a cross track over the array (replies at more elevation angles), "
            "or fix the gradient (solver.gradient=none) and take fewer bases")


#: A progress report: called with 1 after each Gauss-Newton iteration of a moving-ocean solve (the caller may show
#: it, and a Ctrl-C is handled there at the latest).
Step = Callable[[int], object]


def bases_of(pert: Perturbation, t_tx: np.ndarray, t_rx: np.ndarray, what: str = "calibration",
             prefix: str = "") -> tuple[int, float, float]:
    """The perturbation's number of bases over replies transmitted at ``t_tx`` and received at ``t_rx`` [s], and
    their span, refused above what the replies determine (:func:`~sblsim.models.calibration.perturbation.
    determinable_bases` of their pings, the distinct transmit times) or what their dense design holds
    (:func:`~sblsim.models.calibration.perturbation.computable_bases`).

    Parameters
    ----------
    pert : Perturbation
    t_tx, t_rx : numpy.ndarray, shape (n,)
        [s].
    what : str
        What errors name (the segment).
    prefix : str
        Put before the key an error names (``"solver."``).

    Returns
    -------
    n_bases : int
    start, end : float
        The first transmission and the last reception [s].

    Raises
    ------
    ModelError
        Replies that span no time, or more bases than they determine or their design holds (naming ``n_bases``,
        or ``knot_interval`` when the bases come from it, the allowed maximum, why, and the knot interval it
        means).
    """
    start, end = float(np.min(t_tx)), float(np.max(t_rx))
    if not end > start:
        raise ModelError(f"{what}: the replies span no time; a perturbation in time needs a survey of some duration")
    n_bases = pert.n_bases or interval_bases(start, end, pert.knot_interval)
    pings = len(np.unique(t_tx))
    determined = determinable_bases(pings)
    computable = computable_bases(len(t_tx), pert.kind, pert.gradient)
    most = min(determined, computable)
    if n_bases <= most:
        return n_bases, start, end
    duration = end - start
    given = (f"{prefix}n_bases: {n_bases} bases" if pert.n_bases else
             f"{prefix}knot_interval: {pert.knot_interval:g} s gives {n_bases} bases, which")
    shortest = (f", a knot interval of {duration / (most - DEGREE):.4g} s or more" if most > DEGREE else
                f"; {BASES_RANGE[0]} bases need {PINGS_PER_INTERVAL * (BASES_RANGE[0] - DEGREE)} pings")
    if determined <= computable:
        raise ModelError(f"{given} are more than {what} determines: at most {most} for its {pings} pings over "
                         f"{duration / 3600.0:.3g} h ({DEGREE} + one per {PINGS_PER_INTERVAL} pings, so that each "
                         f"knot interval holds {PINGS_PER_INTERVAL} pings on average{shortest})")
    raise ModelError(f"{given} are more than a solve of {what} holds: at most {most} for its {len(t_tx)} replies "
                     f"(its dense design, replies times columns, within {MAX_DESIGN_CELLS:,} cells{shortest}); "
                     "solve shorter segments (solver.segments)")


class _Design:
    """A perturbed survey's fixed parts for all its replies: times, splines, the gradients' fixed factors, GARPOS's
    units and prior; the columns of a fit are those of its replies (:meth:`active`)."""

    def __init__(self, pert: Perturbation, replies: Replies, apriori: np.ndarray, knots: np.ndarray, c0: float):
        self.pert = pert
        self.replies = replies
        #: None, or (positions' unknowns, residuals [m], Jacobian) of the legs at a reference solution
        self.linear: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.mid = 0.5 * (replies.t_tx + replies.t_rx)
        self.deep = pert.gradient != "none"
        self.shallow = pert.gradient == "shallow+deep"
        self.n_bases = len(knots) - DEGREE - 1
        # the transducer's horizontal offsets from their means [km], at transmit and at receive
        d_tx = (replies.tx[:, :2] - replies.tx[:, :2].mean(axis=0)) / GRADIENT_LENGTH
        d_rx = (replies.rx[:, :2] - replies.rx[:, :2].mean(axis=0)) / GRADIENT_LENGTH
        if pert.kind == "ntd":
            self.spline = basis(self.mid, knots)
            self.fixed = [self.spline] + ([0.5 * (d_tx + d_rx)] if self.shallow else [])
            self.unit, self.t0, self.prior_blocks = 1.0, 0.0, []
            return
        b_tx, b_rx = basis(replies.t_tx, knots), basis(replies.t_rx, knots)
        mean = 0.5 * (b_tx + b_rx)
        centre = (apriori[replies.transponder] - apriori.mean(axis=0))[:, :2] / GRADIENT_LENGTH
        blocks = [mean]
        if self.shallow:
            blocks += [0.5 * (b_tx * d_tx[:, j:j + 1] + b_rx * d_rx[:, j:j + 1]) for j in (0, 1)]
        if self.deep:
            blocks += [mean * centre[:, j:j + 1] for j in (0, 1)]
        self.fixed = blocks
        self.t0 = pert.t0 or 2.0 * abs(float(np.mean(apriori[:, 2]))) / c0
        self.unit = TRAVEL_TIME_SCALE / self.t0  # GARPOS's unit of the log residuals and the coefficients
        lam0 = 10.0 ** pert.log_lambda0
        omega = roughness(knots)
        self.prior_blocks = [omega / lam0] + [omega / (lam0 * 10.0 ** pert.log_grad_lambda)] * (len(blocks) - 1)

    def width(self) -> int:
        """The perturbation's coefficients, all bases."""
        if self.pert.kind == "garpos":
            return sum(b.shape[1] for b in self.fixed)
        return self.n_bases + 2 * self.deep + 2 * self.shallow

    def active(self, used: np.ndarray) -> np.ndarray:
        """The coefficients a fit of the ``used`` replies solves: ``ntd`` the bases they touch (SeaGap's
        ``retrieveb``) and the gradients, ``garpos`` all (the prior holds a basis without data)."""
        if self.pert.kind == "garpos":
            return np.ones(self.width(), dtype=bool)
        touched = np.any(self.spline[used] != 0.0, axis=0)
        return np.concatenate((touched, np.ones(2 * self.deep + 2 * self.shallow, dtype=bool)))

    def columns(self, rows: np.ndarray, tx: np.ndarray, rx: np.ndarray, x: np.ndarray) -> np.ndarray:
        """All the perturbation's columns at ``rows`` (``ntd``: of the nadir-normalised time [s]; ``garpos``: of
        the log time in units of :attr:`unit`), shape (len(rows), width)."""
        if self.pert.kind == "garpos":
            return np.hstack([b[rows] for b in self.fixed])
        blocks = [self.spline[rows]]
        if self.deep:
            blocks.append(0.5 * (slant_direction(tx, x) + slant_direction(rx, x)))
        if self.shallow:
            blocks.append(self.fixed[1][rows])
        return np.hstack(blocks)

    def names(self) -> list[str]:
        """The names of all the perturbation's coefficients, in :meth:`columns`' order (the diagnostics'
        :func:`~sblsim.models.calibration.determination.determination`)."""
        east_north = ("East", "North")
        if self.pert.kind == "ntd":
            out = [f"NTD basis {j + 1}" for j in range(self.n_bases)]
            out += [f"deep gradient {a}" for a in east_north if self.deep]
            return out + [f"shallow gradient {a}" for a in east_north if self.shallow]
        b = self.n_bases
        out = [f"GARPOS background basis {j + 1}" for j in range(b)]
        for name, on in (("shallow", self.shallow), ("deep", self.deep)):
            if on:
                out += [f"{name} gradient {a} basis {j + 1}" for a in east_north for j in range(b)]
        return out

    def prior(self, q: int, active: np.ndarray) -> np.ndarray | None:
        """GARPOS's prior information over the solved unknowns (none on the positions); None for ``ntd``."""
        if self.pert.kind == "ntd":
            return None
        out = np.zeros((q + len(active), q + len(active)))
        at = q
        for block in self.prior_blocks:
            out[at:at + len(block), at:at + len(block)] = block
            at += len(block)
        keep = np.concatenate((np.ones(q, dtype=bool), active))
        return out[np.ix_(keep, keep)]

    def covariance(self, used: np.ndarray) -> _DataCovariance:
        """The data covariance of the ``used`` replies (``ntd``: the identity)."""
        return _DataCovariance(self, used)


class _DataCovariance:
    """:math:`E = L L^\\top` of a fit's replies: ``whiten`` applies :math:`L^{-1}`; ``log_det_inverse`` is
    :math:`\\ln|E^{-1}|` (GARPOS's units)."""

    def __init__(self, design: _Design, used: np.ndarray):
        self.kind = design.pert.kind
        self.factor = None
        self.log_det_inverse = 0.0
        if self.kind == "ntd":
            return
        r = design.replies
        scale = r.twtt[used] / design.t0
        self.inverse_sd = scale  # GARPOS: the log residual's sigma in units of ``unit`` is T0 / T
        pert = design.pert
        if pert.mu_t > 0.0 and pert.reject_sigma == 0.0:
            t, transponder = r.t_tx[used], r.transponder[used]
            self.order = np.argsort(t, kind="stable")
            band = correlation_band(t[self.order], transponder[self.order], scale[self.order], pert.mu_t, pert.mu_mt)
            try:
                self.factor = cholesky_banded(band, lower=True)
            except np.linalg.LinAlgError:
                raise ModelError(f"mu_t: the data covariance of correlation length {pert.mu_t:g} s is not positive "
                                 "definite (its reach is cut at 4 lengths); take a shorter one") from None
            self.log_det_inverse = -2.0 * float(np.sum(np.log(self.factor[0])))
        else:
            self.log_det_inverse = float(np.sum(np.log(scale**2)))

    def whiten(self, a: np.ndarray) -> np.ndarray:
        if self.kind == "ntd":
            return a
        if self.factor is None:
            return a * (self.inverse_sd[:, None] if a.ndim == 2 else self.inverse_sd)
        out = np.empty_like(a)
        out[self.order] = solve_banded((self.factor.shape[0] - 1, 0), self.factor, a[self.order])
        return out


def _perturbed_model(design: _Design, apriori: np.ndarray, theta: np.ndarray, c0: float, rigid: bool,
                     legs: LegModel, rows: np.ndarray):
    """At the unknowns ``theta`` (positions, then all the perturbation's coefficients), for the replies ``rows``:
    the residual and the Jacobian of the prediction in the perturbation's units, the legs' time, the TWTT residual
    [s], the mapping, the positions, the transponders and the perturbation's columns."""
    q = 3 if rigid else 3 * len(apriori)
    replies = design.replies.subset(rows)
    if design.linear is None:
        residual_m, jacobian, _, position, _, x = _model(replies, apriori, theta[:q], c0, rigid, False, legs, 0.0)
    else:  # the legs linearised about a reference solution (a search's candidates)
        reference, residual_0, jacobian_0 = design.linear
        jacobian = jacobian_0[rows]
        residual_m = residual_0[rows] - jacobian @ (theta[:q] - reference)
        shift = theta[:q].reshape(-1, 3)
        position = apriori + shift if not rigid else apriori + shift[0]
        x = position[replies.transponder]
    tau = replies.twtt - residual_m / c0
    p = design.columns(rows, replies.tx, replies.rx, x)
    radius = design.pert.earth_radius
    mapping = 0.5 * (nadir_cosine(replies.tx, x, radius) + nadir_cosine(replies.rx, x, radius))
    model = p @ theta[q:]
    if design.pert.kind == "ntd":
        residual = mapping * (replies.twtt - tau) - model
        a = np.hstack((mapping[:, None] * jacobian / c0, p))
        seconds = residual / mapping
    else:
        residual = (np.log(replies.twtt) - np.log(tau)) / design.unit + model
        a = np.hstack((jacobian / (c0 * tau * design.unit)[:, None], -p))
        seconds = replies.twtt - tau * np.exp(-design.unit * model)
    return residual, a, tau, seconds, mapping, position, x, p


def _perturbed_fit(design: _Design, apriori: np.ndarray, c0: float, rigid: bool, legs: LegModel, used: np.ndarray,
                   theta: np.ndarray, what: str, progress: Step | None = None):
    """Gauss-Newton on the positions and the active coefficients of the ``used`` replies (GARPOS: with its prior),
    from ``theta`` (``progress(1)`` after each iteration); returns theta (inactive coefficients 0), the iterations,
    convergence, the active mask, the prior, the data covariance and the last normal matrix."""
    q = 3 if rigid else 3 * len(apriori)
    rows = np.flatnonzero(used)
    active = design.active(used)
    keep = np.concatenate((np.ones(q, dtype=bool), active))
    theta = np.where(keep, theta, 0.0)
    prior = design.prior(q, active)
    data = design.covariance(used)
    converged, iterations, normal, first = False, 0, None, None
    names = [name for name, on in zip(design.names(), active) if on]
    for iterations in range(1, MAX_ITERATIONS + 1):  # noqa: B007 (the count is returned)
        with np.errstate(all="ignore"):  # a diverging step overflows: refused below, its cause named
            residual, a, *_ = _perturbed_model(design, apriori, theta, c0, rigid, legs, rows)
            wa, wr = data.whiten(a[:, keep]), data.whiten(residual)
            last, (normal, rhs) = normal, (wa.T @ wa, wa.T @ wr)
            first = normal if last is None else first
        if prior is not None:
            normal = normal + prior
            rhs = rhs - prior @ theta[keep]
        try:
            if not (np.all(np.isfinite(normal)) and np.all(np.isfinite(rhs))):
                raise np.linalg.LinAlgError
            step = np.linalg.solve(normal, rhs)
            if not np.all(np.isfinite(step)):
                raise np.linalg.LinAlgError
        except np.linalg.LinAlgError:  # singular, or diverged: what the survey cannot separate, named
            for finite in (first, normal, last):  # named at the a-priori geometry, else where it diverged
                if finite is not None and np.all(np.isfinite(finite)):
                    det = determination(finite, q, names, rigid, False, iterations)
                    if det.position is not None:
                        check_determination(det, what, SEPARATE)
            raise ModelError(f"{what}: the replies do not determine the positions and the perturbation (the normal "
                             f"matrix is singular, or the solve diverged); {SEPARATE}") from None
        theta[keep] += step
        if progress is not None:
            progress(1)
        if np.max(np.abs(step[:q])) <= POSITION_TOLERANCE:
            converged = True
            break
    return theta, iterations, converged, keep, prior, data, normal


def _solve_perturbed(replies: Replies, apriori: np.ndarray, c0: float, rigid: bool, legs: LegModel,
                     pert: Perturbation, outlier_factor: float | None, what: str,
                     linear: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                     start_positions: np.ndarray | None = None, progress: Step | None = None) -> Solution:
    """:func:`solve` with a sound-speed perturbation (:class:`Perturbation`): the outlier rule on the TWTT
    residuals [s], and GARPOS's rejection of the residuals beyond ``reject_sigma`` standard deviations of their
    mean (judged on every reply after each solution). ``linear``: the legs linearised about a reference
    (:func:`select`); ``start_positions``: the positions' unknowns to start from; ``progress(1)`` after each
    Gauss-Newton iteration."""
    k = len(apriori)
    q = 3 if rigid else 3 * k
    n = len(replies)
    n_bases, start, end = bases_of(pert, replies.t_tx, replies.t_rx, what)
    knots = uniform_knots(start, end, n_bases)
    design = _Design(pert, replies, apriori, knots, c0)
    design.linear = linear
    theta = np.zeros(q + design.width())
    if start_positions is not None:
        theta[:q] = start_positions
    used = np.ones(n, dtype=bool)
    every = np.arange(n)
    for _ in range(n):
        size = q + int(design.active(used).sum())
        if used.sum() <= size:
            raise ModelError(f"{what}: {int(used.sum())} replies for {size} unknowns (the positions and the "
                             f"perturbation's {n_bases} bases); at least {size + 1} are needed: fewer bases")
        theta, iterations, converged, keep, prior, data, normal = _perturbed_fit(design, apriori, c0, rigid, legs,
                                                                                  used, theta, what, progress)
        model = _perturbed_model(design, apriori, theta, c0, rigid, legs, every)
        residual, seconds = model[0], model[3]
        if outlier_factor is not None and used.sum() > size + 1:
            worst = float(np.max(np.abs(seconds[used])))
            if worst > outlier_factor * float(np.sqrt(np.mean(seconds[used] ** 2))):
                used &= np.abs(seconds) != worst
                continue
        if pert.reject_sigma > 0.0:
            mean, sd = float(np.mean(residual[used])), float(np.std(residual[used], ddof=1))
            judged = np.abs(residual - mean) <= pert.reject_sigma * sd
            if not np.array_equal(judged, used):
                used = judged
                continue
        break
    return _perturbed_solution(design, apriori, c0, rigid, knots, theta, used, keep, prior, data, normal, iterations,
                               converged, model, what)


def _perturbed_solution(design: _Design, apriori: np.ndarray, c0: float, rigid: bool, knots: np.ndarray,
                        theta: np.ndarray, used: np.ndarray, keep: np.ndarray, prior: np.ndarray | None,
                        data: _DataCovariance, normal: np.ndarray, iterations: int, converged: bool,
                        model: tuple, what: str = "calibration") -> Solution:
    """The solution's statistics: SeaGap's (a posteriori variance, AIC, BIC) or GARPOS's (ABIC) and its
    :class:`~sblsim.models.calibration.determination.Determination`; ``model`` is :func:`_perturbed_model` of every
    reply at ``theta``. A non-positive variance (a numerically singular normal matrix) is refused here, where it is
    born, rather than square-rooted to NaN."""
    pert = design.pert
    replies = design.replies
    k = len(apriori)
    q = 3 if rigid else 3 * k
    n = len(replies)
    residual, _, tau, seconds, mapping, position, x, p = model
    m = int(used.sum())
    parameters = int(keep.sum())
    inverse = np.linalg.inv(normal)
    aic = bic = abic = None
    if pert.kind == "ntd":
        variance = float(np.sum(residual[used] ** 2) / (m - parameters))
        aic, bic = akaike(residual[used], parameters)
        sigma_t = np.sqrt(variance) / mapping  # each TWTT residual's sigma [s]
    else:
        misfit = float(np.sum(data.whiten(residual[used]) ** 2))
        penalty = float(theta[keep] @ prior @ theta[keep])
        eigen = np.linalg.eigvalsh(prior[q:, q:])
        positive = eigen[eigen > 1e-8 / 10.0**pert.log_lambda0]
        dof = m + len(positive) - parameters
        variance = (misfit + penalty) / dof
        abic = (dof * math.log(misfit + penalty) - data.log_det_inverse - float(np.sum(np.log(positive)))
                + float(np.linalg.slogdet(normal)[1]))
        sigma_t = np.full(n, np.sqrt(variance) * TRAVEL_TIME_SCALE)
    names = [name for name, on in zip(design.names(), keep[q:]) if on]
    det = determination(normal, q, names, rigid, converged, iterations)
    covariance_all = variance * inverse
    diagonal = np.diag(covariance_all)
    if not np.all(diagonal > 0.0):  # born of a numerically singular normal matrix: refused, never a NaN sigma
        check_determination(det, what, SEPARATE)
        raise ModelError(f"{what}: the survey cannot separate the positions from the perturbation (a non-positive "
                         f"variance of the unknowns; the normal matrix's equilibrated condition is "
                         f"{det.condition:.3g}): {SEPARATE}")
    sd = np.sqrt(diagonal)
    full_sd = np.zeros(len(theta))
    full_sd[keep] = sd
    sigma = np.tile(sd[:3], (k, 1)) if rigid else sd[:q].reshape(k, 3)
    w = 1.0 / (c0 * sigma_t) ** 2
    residual_m = c0 * seconds
    wrms = float(np.sqrt(np.sum(w[used] * residual_m[used] ** 2) / np.sum(w[used])))
    elevation, azimuth, scatter = _directions(replies, x, residual_m, w, used, k)
    order = np.argsort(design.mid[used], kind="stable")
    coefficients = theta[q:]
    units = design.unit
    background, bg_sd = coefficients[:design.n_bases] * units, full_sd[q:q + design.n_bases] * units
    gradient, gradient_sd = {}, {}
    rest, rest_sd = coefficients[design.n_bases:] * units, full_sd[q + design.n_bases:] * units
    if pert.kind == "ntd":  # the columns' order: the bases, the deep gradient, the shallow one
        names = (["deep"] if design.deep else []) + (["shallow"] if design.shallow else [])
        for j, name in enumerate(names):
            gradient[name], gradient_sd[name] = rest[2 * j:2 * j + 2], rest_sd[2 * j:2 * j + 2]
        delay = design.spline @ coefficients[:design.n_bases]
        observed = mapping * (replies.twtt - tau) - (p[:, design.n_bases:] @ coefficients[design.n_bases:])
    else:  # GARPOS's order: the background, the shallow gradient, the deep one
        b = design.n_bases
        names = (["shallow"] if design.shallow else []) + (["deep"] if design.deep else [])
        for j, name in enumerate(names):
            gradient[name] = rest[2 * j * b:(2 * j + 2) * b].reshape(2, b)
            gradient_sd[name] = rest_sd[2 * j * b:(2 * j + 2) * b].reshape(2, b)
        delay = (tau * np.exp(-units * (p @ coefficients)) - tau) * mapping
        observed = (replies.twtt - tau) * mapping
    fit = PerturbationFit(settings=pert, n_bases=design.n_bases, knots=knots, used_bases=keep[q:q + design.n_bases],
                          coefficients=background, coefficient_sigma=bg_sd, gradient=gradient,
                          gradient_sigma=gradient_sd, delay=delay, observed=observed, mapping=mapping,
                          mid_time=design.mid, parameters=parameters, aic=aic, bic=bic, abic=abic,
                          effective_scale=effective_scale(residual[used][order]))
    return Solution(position=position, offset=position - apriori, sigma=sigma, covariance=covariance_all[:q, :q],
                    sound_speed=float(c0), sound_speed_sigma=0.0, used=used, residual_m=residual_m,
                    residual_s=seconds, weight=w, elevation=elevation, azimuth=azimuth, wrms_m=wrms,
                    variance_factor=variance, scatter=scatter, iterations=iterations, converged=converged,
                    perturbation=fit, determination=det)


__all__ = ["Step", "bases_of"]

"""The receivers' horizontal positions from a moving tag's own pings: the tag's places and emission times and the
receivers' shifts from their surveyed positions solved together, the survey a prior (an array's self-calibration).

Each time of arrival is ``toa_ij = t_j + ‖p_j − (r_i + d_i)‖ / c_j`` for ping j (place ``p_j``, emission time
``t_j``, sound speed ``c_j``) at receiver i (surveyed position ``r_i``, horizontal shift ``d_i`` unknown, its depth
as surveyed). The pings' horizontal places and emission times and the shifts are fitted together by Gauss-Newton
with a prior ``d_i ~ N(0, σ₀² I)`` (the survey's σ per axis), the tag's depth kept at its start (a sensor's, or the
fix's in 3-D); each arrival weighed by its Student-t weight ``(ν + 1) / (ν + z²)`` (a late multipath arrival counts
little; iteratively reweighted). The pings are eliminated ping by ping (three unknowns each, Schur's complement),
leaving the shifts' normal matrix, ``2R × 2R``: a record's cost is linear in its pings.

Where asked, three more kinds of unknowns join them: each receiver's **range bias** ``β_i`` [m] (``toa_ij = t_j +
(‖p_j − (r_i + d_i)‖ + β_i) / c_j``, the same prior: a constant offset of its clock, as a synchronisation made on
wrong positions leaves it); **anchored pings**, emitted where a receiver is (a sync tag at its receiver: its place
moves with that receiver, its emission time its only unknown of its own), which tell a receiver's clock from its place
(both directions of each pair of receivers are heard); and the **sound speed's scale** ``m`` (``c_j / m``, a prior on
``m``), where the sound speed was calibrated from the same pings on the surveyed positions and took up their error.

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
from sblsim.models.tracking.smoother_cost import ROBUST_DOF, observed_information
from sblsim.models.tracking.toa import checked_sigma

#: Arrivals a ping needs to be fitted (two coordinates and an emission time, and one more to say anything).
MIN_ARRIVALS = 4
#: The fit's iterations at most, and the largest shift's step [m] at which it has converged (a millimetre: the
#: arrivals' weights still move a little from one step to the next where an arrival's residual is near √ν σ).
ITERATIONS, STEP_TOLERANCE = 50, 1e-3
#: Pings per chunk of the elimination (a chunk's (pings, R, R) products stay small).
CHUNK = 4096
#: A ping whose fix at the surveyed positions fits this many times worse than the median ping's (χ² per degree of
#: freedom) is left out of the refinement: a fix in a mirror place or of echoes, no start for Gauss-Newton.
START_GATE = 25.0
#: The σ [m] a place's depth is kept at in a 3-D fix (the depth is the tag's, not refitted).
DEPTH_SIGMA = 0.01
#: The most one Gauss-Newton step moves a receiver [survey σ]: a step the arrivals' weights are not yet right for
#: (the first, the pings' places still the survey's) cannot throw the fit far.
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
        (R,) [m] each receiver's range bias and its σ (0 where not fitted).
    anchored : int
        The anchored pings fitted.
    speed_scale, speed_scale_sigma : float
        [1] the sound speed fitted over the one given, and its σ (1 and 0 where not fitted).
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
                     biases: bool = False, anchored: tuple[np.ndarray, np.ndarray] | None = None,
                     speed_sigma: float | None = None) -> Refinement:
    """The receivers' horizontal shifts and the tag's places fitted together (the module docstring).

    Each ping starts from its fix at the surveyed positions (:func:`~sblsim.models.tracking.fix.fix_pings`, from
    its place in ``places`` or the fix's own start, whichever fits better); a ping whose fix fits
    :data:`START_GATE` times worse than the record's median (a fix in a mirror place, a ping of echoes) is left out;
    each step of the shifts is at most :data:`MAX_STEP` survey σ.

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
        ``N(0, survey_sigma²)``): a constant offset of its clock, as a synchronisation made on wrong positions
        leaves it (the sync tags' ranges were as wrong).
    anchored : (numpy.ndarray, numpy.ndarray), optional
        Pings emitted at a receiver (sync tags at their receivers): their times of arrival (Q, R) [s] on the same
        clock and each one's receiver (Q,) (its row of ``receivers``); their places move with that receiver (each
        emission time an unknown of its own; an arrival at its own receiver left out), at the median sound speed.
        With ``biases`` they tell a receiver's clock from its place: both directions of a pair of receivers are
        heard.
    speed_sigma : float, optional
        [1] fit the sound speed too, as a scale of the one given (``c / m``, a prior σ of ``speed_sigma`` on
        ``m``): a sound speed calibrated from the pings on the surveyed positions took up their error in part. The
        array's scale then trades with it (no time of arrival tells them apart): it is a gauge like the array's
        translation and rotation, the survey's. None: as given.

    Returns
    -------
    Refinement

    Raises
    ------
    ModelError
        Shapes that do not agree; a sound speed or survey σ not positive; no ping heard by
        :data:`MIN_ARRIVALS` receivers.
    """
    toa, receivers, places, c, sigma = checked_inputs(toa, receivers, places, c, sigma_toa, survey_sigma)
    dim = receivers.shape[1]
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
    toa, heard, c = toa[rows], heard[rows], c[rows]
    xy, t = fixed[:, :2].copy(), emitted.copy()
    z = places[rows, 2] if dim == 3 else None
    n = len(receivers)
    anchor = None if anchored is None else _Anchored.of(anchored, receivers, float(np.median(c)))
    d = np.zeros((n, 3 if biases else 2))  # each receiver's shift [m] (and range bias [m])
    free = speed_sigma is not None
    m = 1.0  # the slowness's scale: the sound speed c / m
    prior = np.r_[np.full(d.size, survey_sigma**-2.0), [speed_sigma**-2.0] if free else []]
    converged, iterations = False, 0
    while iterations < ITERATIONS:
        iterations += 1
        normal, rhs, ping_steps = _step(toa, heard, receivers, d, m, free, xy, t, z, c, sigma, dof)
        if anchor is not None:
            more, extra = anchor.terms(receivers, d, m, free, sigma, dof)
            normal, rhs = normal + more, rhs + extra
        normal[np.diag_indices_from(normal)] += prior
        rhs -= prior * np.r_[d.ravel(), [m - 1.0] if free else []]
        step = np.linalg.solve(normal, rhs)
        step *= min(1.0, MAX_STEP * survey_sigma / max(float(np.abs(step[:d.size]).max()), 1e-300))
        # the pings' steps given the receivers' (back-substitution: Δθ_j = A_j⁻¹ (b_j − B_j Δφ))
        px, pt = ping_steps(step)
        xy += px
        t += pt
        if anchor is not None:
            anchor.advance(step)
        d += step[:d.size].reshape(d.shape)
        m += float(step[-1]) if free else 0.0
        if np.abs(step[:d.size]).max() < STEP_TOLERANCE:
            converged = True
            break
    normal, _, _ = _step(toa, heard, receivers, d, m, free, xy, t, z, c, sigma, dof, covariance=True)
    if anchor is not None:
        normal = normal + anchor.terms(receivers, d, m, free, sigma, dof, covariance=True)[0]
    normal[np.diag_indices_from(normal)] += prior
    whole = np.linalg.inv(normal)
    k = d.shape[1]
    shifts = np.ravel(np.c_[k * np.arange(n), k * np.arange(n) + 1])  # the shifts' rows, x then y per receiver
    covariance = whole[np.ix_(shifts, shifts)]
    arrivals = heard.sum(axis=0)
    ratio = shape_sigma_ratio(receivers[:, :2], covariance, survey_sigma, arrivals > 0, scale=free)
    determined = ratio < MAX_SIGMA_RATIO
    bias = d[:, 2].copy() if biases else np.zeros(n)
    bias_sigma = np.sqrt(np.maximum(np.diag(whole)[2:k * n:3], 0.0)) if biases else np.zeros(n)
    return Refinement(np.where(determined[:, None], d[:, :2], 0.0), d[:, :2].copy(), covariance, ratio, determined,
                      arrivals, len(rows), iterations, converged, bias, bias_sigma,
                      0 if anchor is None else int(len(anchor.t)), 1.0 / m,
                      float(np.sqrt(max(whole[-1, -1], 0.0))) / m**2 if free else 0.0)


def _weights(e: np.ndarray, sigma: np.ndarray, dof: float, covariance: bool) -> np.ndarray:
    """Each arrival's Student-t weight over σ² [1/s²] (``(ν + 1) / (ν + z²)``), or its observed information's with
    ``covariance`` (0 past √ν σ: the robust smoother's covariance)."""
    zed = e / sigma
    if covariance:
        return observed_information(zed, dof) / sigma**2
    return (dof + 1.0) / (dof + zed**2) / sigma**2


class _Anchored:
    """Pings emitted where a receiver is (a sync tag at its receiver): each one's place is that receiver's, shifted
    with it; its emission time its only unknown of its own. Each arrival at another receiver i of ping j from the
    receiver k: ``toa = t_j + (‖(r_k + d_k) − (r_i + d_i)‖ + β_i) / c``."""

    def __init__(self, toa: np.ndarray, source: np.ndarray, c: float, t: np.ndarray):
        self.toa, self.source, self.c, self.t = toa, source, c, t
        self.emission, self.receiver = np.nonzero(np.isfinite(toa))  # each arrival's emission and receiver
        self._steps = None

    @classmethod
    def of(cls, anchored, receivers: np.ndarray, c: float) -> "_Anchored":
        toa, source = np.asarray(anchored[0], float), np.asarray(anchored[1], int)
        if toa.ndim != 2 or toa.shape[1] != len(receivers) or source.shape != (len(toa),) \
                or not ((source >= 0) & (source < len(receivers))).all():
            raise ModelError(f"receiver positions: anchored pings {toa.shape} from {source.shape} receivers; allowed: "
                             f"(Q, {len(receivers)}) and (Q,) receiver indices")
        toa = toa.copy()
        toa[np.arange(len(toa)), source] = np.nan  # a receiver's own tag: no distance to learn from
        keep = np.isfinite(toa).sum(axis=1) >= 2
        toa, source = toa[keep], source[keep]
        rho = np.linalg.norm(receivers[source][:, None, :] - receivers[None], axis=2)
        t = np.nanmedian(toa - rho / c, axis=1)
        return cls(toa, source, c, t)

    def terms(self, receivers: np.ndarray, d: np.ndarray, m: float, free: bool, sigma: np.ndarray, dof: float,
              covariance: bool = False):
        """Their reduced normal matrix and right-hand side in the receivers' unknowns (and the slowness's scale,
        last, where ``free``), each emission time eliminated; the emission times' steps kept for :meth:`advance`."""
        n, k = d.shape
        q, i = self.emission, self.receiver
        src = self.source[q]
        where = np.array(receivers, float)
        where[:, :2] += d[:, :2]
        diff = where[src] - where[i]
        rho = np.linalg.norm(diff, axis=1)
        u = m * diff[:, :2] / np.maximum(rho, 1e-9)[:, None] / self.c  # ∂τ/∂(place), (a, 2)
        if k == 3:
            rho = rho + d[i, 2]
        travel = rho / self.c
        e = self.toa[q, i] - self.t[q] - m * travel
        w = _weights(e, sigma[i], dof, covariance)
        J = np.zeros((len(q), n * k + int(free)))  # ∂τ/∂(receivers' unknowns[, m])
        rows = np.arange(len(q))
        J[rows, k * i], J[rows, k * i + 1] = -u[:, 0], -u[:, 1]
        J[rows, k * src] += u[:, 0]
        J[rows, k * src + 1] += u[:, 1]
        if k == 3:
            J[rows, k * i + 2] = m / self.c
        if free:
            J[:, -1] = travel
        a = np.bincount(q, w, minlength=len(self.toa))  # each emission time's information
        b = np.bincount(q, w * e, minlength=len(self.toa))
        Bt = np.zeros((len(self.toa), J.shape[1]))
        np.add.at(Bt, q, w[:, None] * J)
        inv = np.where(a > 0, 1.0 / np.maximum(a, 1e-300), 0.0)
        normal = (J * w[:, None]).T @ J - (Bt * inv[:, None]).T @ Bt
        rhs = J.T @ (w * e) - Bt.T @ (inv * b)
        self._steps = (inv, b, Bt)
        return normal, rhs

    def advance(self, step: np.ndarray) -> None:
        """The emission times moved with the receivers' step: ``Δt_j = (b_j − B_j Δφ) / a_j``."""
        inv, b, Bt = self._steps
        self.t = self.t + inv * (b - Bt @ step)


def _step(toa, heard, receivers, d, m, free, xy, t, z, c, sigma, dof, covariance: bool = False):
    """One Gauss-Newton step's reduced system in the receivers' unknowns ``d`` (R, k: the shift, and the range bias
    where k is 3) and, where ``free``, the slowness's scale ``m`` last: ``(kR [+ 1], kR [+ 1])`` and its right-hand
    side, and the pings' steps as a function of that step (each ping's unknowns eliminated, chunk by chunk).
    ``covariance``: the weights of the observed information."""
    n, k = d.shape
    normal = np.zeros((n, k, n, k))
    rhs = np.zeros((n, k))
    cross = np.zeros((n, k))  # the receivers' unknowns against the slowness's scale
    scale_normal = scale_rhs = 0.0
    pieces = []
    for lo in range(0, len(toa), CHUNK):
        rows = slice(lo, lo + CHUNK)
        here = heard[rows]
        at = receivers[None, :, :2] + d[None, :, :2]  # (1, R, 2)
        delta = xy[rows, None, :] - at  # (p, R, 2)
        vertical = 0.0 if z is None else (z[rows, None] - receivers[None, :, 2]) ** 2
        rho = np.sqrt((delta**2).sum(axis=2) + vertical)
        cc = c[rows, None]
        u = m * delta / np.maximum(rho, 1e-9)[..., None] / cc[..., None]  # ∂τ/∂p, (p, R, 2) [s/m]
        if k == 3:  # the receiver's range bias: a constant offset of its clock, in metres
            rho = rho + d[None, :, 2]
        travel = rho / cc  # ∂τ/∂m, (p, R) [s]
        e = np.where(here, toa[rows] - t[rows, None] - m * travel, 0.0)
        w = np.where(here, _weights(e, sigma[None], dof, covariance), 0.0)  # (p, R) [1/s²]
        w[(w > 0).sum(axis=1) < MIN_ARRIVALS] = 0.0  # a ping the observed information leaves too few: nothing
        g = np.concatenate([u, np.ones(u.shape[:2] + (1,))], axis=2)  # ∂τ/∂(x, y, t), (p, R, 3)
        h = -u if k == 2 else np.concatenate([-u, np.broadcast_to(m / cc, u.shape[:2])[..., None]], axis=2)
        A = np.einsum("pr,pra,prb->pab", w, g, g)
        diagonal_a = A[:, np.arange(3), np.arange(3)]
        # a relative ridge (Levenberg's) keeps a ping of bad geometry invertible; an empty ping's block the identity
        A[:, np.arange(3), np.arange(3)] = np.where(diagonal_a > 0, diagonal_a * (1.0 + 1e-10), 1.0)
        Ainv = np.linalg.inv(A)
        b = np.einsum("pr,pra,pr->pa", w, g, e)
        wg = w[..., None] * g
        # C: Σ_j w h hᵀ on the diagonal blocks; minus Σ_j B_jᵀ A_j⁻¹ B_j over every pair of receivers
        diagonal = np.einsum("pr,pra,prb->rab", w, h, h)
        q = np.einsum("pia,pab,pkb->pik", wg, Ainv, wg)
        normal -= np.einsum("pik,pia,pkb->iakb", q, h, h)
        normal[np.arange(n), :, np.arange(n), :] += diagonal
        Ab = np.einsum("pab,pb->pa", Ainv, b)
        rhs += np.einsum("pr,pra,pr->ra", w, h, e) - np.einsum("pra,pa,prb->rb", wg, Ab, h)
        Bm = None
        if free:  # the slowness's scale: one more unknown, every arrival's
            Bm = np.einsum("pra,pr->pa", wg, travel)  # B_j's column of m, (p, 3)
            AB = np.einsum("pab,pb->pa", Ainv, Bm)
            cross += np.einsum("pr,pra,pr->ra", w, h, travel) - np.einsum("pra,pa,prb->rb", wg, AB, h)
            scale_normal += float(np.sum(w * travel**2) - np.einsum("pa,pa->", Bm, AB))
            scale_rhs += float(np.sum(w * travel * e) - np.einsum("pa,pa->", AB, b))
        pieces.append((Ainv, Ab, wg, h, Bm))

    def ping_steps(step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out = []
        for Ainv, Ab, wg, h, Bm in pieces:
            Bd = np.einsum("pra,prb,rb->pa", wg, h, step[:n * k].reshape(n, k))
            if Bm is not None:
                Bd = Bd + Bm * step[-1]
            out.append(Ab - np.einsum("pab,pb->pa", Ainv, Bd))
        whole = np.concatenate(out) if out else np.zeros((0, 3))
        return whole[:, :2], whole[:, 2]

    size = k * n + int(free)
    full = np.zeros((size, size))
    full[:k * n, :k * n] = normal.reshape(k * n, k * n)
    vector = np.zeros(size)
    vector[:k * n] = rhs.ravel()
    if free:
        full[:k * n, -1] = full[-1, :k * n] = cross.ravel()
        full[-1, -1], vector[-1] = scale_normal, scale_rhs
    return full, vector, ping_steps


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


__all__ = ["CHUNK", "DEPTH_SIGMA", "ITERATIONS", "MAX_STEP", "MIN_ARRIVALS", "Refinement", "START_GATE",
           "STEP_TOLERANCE", "best_fixes", "checked_inputs", "refine_receivers"]

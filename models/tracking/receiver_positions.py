"""The receivers' horizontal positions from a moving tag's own pings: the tag's places and emission times and the
receivers' shifts from their surveyed positions solved together, the survey a prior (an array's self-calibration).

Each time of arrival is ``toa_ij = t_j + ‖p_j − (r_i + d_i)‖ / c_j`` for ping j (place ``p_j``, emission time
``t_j``, sound speed ``c_j``) at receiver i (surveyed position ``r_i``, horizontal shift ``d_i`` unknown, its depth
as surveyed). The pings' horizontal places and emission times and the shifts are fitted together by Gauss-Newton
with a prior ``d_i ~ N(0, σ₀² I)`` (the survey's σ per axis), the tag's depth kept at its start (a sensor's, or the
fix's in 3-D); each arrival weighed by its Student-t weight ``(ν + 1) / (ν + z²)`` (a late multipath arrival counts
little; iteratively reweighted). The pings are eliminated ping by ping (three unknowns each, Schur's complement),
leaving the shifts' normal matrix, ``2R × 2R``: a record's cost is linear in its pings.

A ping heard by three receivers (two coordinates and a time) adds nothing: only pings with at least four arrivals
are fitted. What the pings determine is the array's **shape**: a translation or a rotation of the whole array with
its track changes no time of arrival, so those stay the survey's (the prior's mean) with its σ₀/√R; a receiver is
**determined** where its posterior σ in the shape is below :data:`~sblsim.models.sync.identifiability.
MAX_SIGMA_RATIO` of the survey's (:func:`~sblsim.models.sync.identifiability.shape_sigma_ratio`), and keeps its
surveyed position elsewhere.

Whether a refinement helps is the data's to say, not the fit's own residuals (a refined array always fits the pings
it was fitted to better): :func:`held_out` fits it on all but one block of the record's pings in turn and fixes the
pings of the block left out with the surveyed and with that refined array, each ping alone
(:func:`~sblsim.models.tracking.fix.fix_pings`): the refinement helps where the pings it never saw agree better with
it.

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
from sblsim.models.tracking.smoother_cost import ROBUST_DOF
from sblsim.models.tracking.toa import checked_sigma

#: Arrivals a ping needs to be fitted (two coordinates and an emission time, and one more to say anything).
MIN_ARRIVALS = 4
#: The fit's iterations at most, and the largest shift's step [m] at which it has converged (a millimetre: the
#: arrivals' weights still move a little from one step to the next where an arrival's residual is near √ν σ).
ITERATIONS, STEP_TOLERANCE = 50, 1e-3
#: Pings per chunk of the elimination (a chunk's (pings, R, R) products stay small).
CHUNK = 4096
#: The blocks of the record :func:`held_out` leaves out in turn.
FOLDS = 4
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


def _checked(toa, receivers, places, c, sigma_toa, survey_sigma):
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
                     sigma_toa: float | np.ndarray, survey_sigma: float, dof: float = ROBUST_DOF) -> Refinement:
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

    Returns
    -------
    Refinement

    Raises
    ------
    ModelError
        Shapes that do not agree; a sound speed or survey σ not positive; no ping heard by
        :data:`MIN_ARRIVALS` receivers.
    """
    toa, receivers, places, c, sigma = _checked(toa, receivers, places, c, sigma_toa, survey_sigma)
    dim = receivers.shape[1]
    heard = np.isfinite(toa)
    rows = np.flatnonzero((heard.sum(axis=1) >= MIN_ARRIVALS) & (np.isfinite(places[:, 2]) if dim == 3 else True))
    fixed, emitted, ratio = _best_fixes(toa[rows], receivers, places[rows], c[rows], sigma)
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
    prior = 1.0 / survey_sigma**2
    d = np.zeros((n, 2))
    converged, iteration = False, 0
    for iteration in range(1, ITERATIONS + 1):
        normal, rhs, ping_steps = _step(toa, heard, receivers, d, xy, t, z, c, sigma, dof)
        normal[np.diag_indices_from(normal)] += prior
        rhs -= prior * d.ravel()
        step = np.linalg.solve(normal, rhs).reshape(n, 2)
        step *= min(1.0, MAX_STEP * survey_sigma / max(float(np.abs(step).max()), 1e-300))
        d += step
        # the pings' steps given the shifts' (back-substitution: Δp_j = A_j⁻¹ (b_j − B_j Δd))
        px, pt = ping_steps(step)
        xy += px
        t += pt
        if np.abs(step).max() < STEP_TOLERANCE:
            converged = True
            break
    normal, _, _ = _step(toa, heard, receivers, d, xy, t, z, c, sigma, dof, covariance=True)
    normal[np.diag_indices_from(normal)] += prior
    covariance = np.linalg.inv(normal)
    arrivals = heard.sum(axis=0)
    ratio = shape_sigma_ratio(receivers[:, :2], covariance, survey_sigma, arrivals > 0)
    determined = ratio < MAX_SIGMA_RATIO
    return Refinement(np.where(determined[:, None], d, 0.0), d, covariance, ratio, determined, arrivals,
                      len(rows), iteration, converged)


def _step(toa, heard, receivers, d, xy, t, z, c, sigma, dof, covariance: bool = False):
    """One Gauss-Newton step's reduced system in the shifts, ``(2R, 2R)`` and ``(2R,)``, and the pings' steps as a
    function of the shifts' step (the unknowns of the ping eliminated chunk by chunk). ``covariance``: the weights
    of the observed information (0 past √ν σ) for the posterior, as the robust smoother's covariance."""
    n = len(receivers)
    normal = np.zeros((n, 2, n, 2))
    rhs = np.zeros((n, 2))
    pieces = []
    for lo in range(0, len(toa), CHUNK):
        rows = slice(lo, lo + CHUNK)
        here = heard[rows]
        at = receivers[None, :, :2] + d[None]  # (1, R, 2)
        delta = xy[rows, None, :] - at  # (p, R, 2)
        vertical = 0.0 if z is None else (z[rows, None] - receivers[None, :, 2]) ** 2
        rho = np.sqrt((delta**2).sum(axis=2) + vertical)
        cc = c[rows, None]
        e = np.where(here, toa[rows] - t[rows, None] - rho / cc, 0.0)
        u = delta / np.maximum(rho, 1e-9)[..., None] / cc[..., None]  # ∂ρ/c ∂p, (p, R, 2) [s/m]
        zed = e / sigma[None]
        if covariance:
            weight = np.maximum((dof + 1.0) * (dof - zed**2) / (dof + zed**2) ** 2, 0.0)
        else:
            weight = (dof + 1.0) / (dof + zed**2)
        w = np.where(here, weight / sigma[None] ** 2, 0.0)  # (p, R) [1/s²]
        w[(w > 0).sum(axis=1) < MIN_ARRIVALS] = 0.0  # a ping the observed information leaves too few: nothing
        g = np.concatenate([u, np.ones(u.shape[:2] + (1,))], axis=2)  # ∂τ/∂(x, y, t), (p, R, 3)
        h = -u  # ∂τ/∂d, (p, R, 2)
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
        coupled = np.einsum("pik,pia,pkb->iakb", q, h, h)
        normal -= coupled
        normal[np.arange(n), :, np.arange(n), :] += diagonal
        Ab = np.einsum("pab,pb->pa", Ainv, b)
        rhs += np.einsum("pr,pra,pr->ra", w, h, e) - np.einsum("pra,pa,prb->rb", wg, Ab, h)
        pieces.append((Ainv, Ab, wg, h))

    def ping_steps(step: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        out = []
        for Ainv, Ab, wg, h in pieces:
            Bd = np.einsum("pra,prb,rb->pa", wg, h, step)
            out.append(Ab - np.einsum("pab,pb->pa", Ainv, Bd))
        whole = np.concatenate(out) if out else np.zeros((0, 3))
        return whole[:, :2], whole[:, 2]

    return normal.reshape(2 * n, 2 * n), rhs.ravel(), ping_steps


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
        """The refined array fits the pings it never saw better, in the whole record and in most of its blocks."""
        better = self.folds[:, 1] < self.folds[:, 0]
        return bool(self.refined < self.surveyed and better.sum() * 2 > len(better))


def held_out(toa: np.ndarray, receivers: np.ndarray, places: np.ndarray, c: float | np.ndarray,
             sigma_toa: float | np.ndarray, survey_sigma: float, folds: int = FOLDS,
             dof: float = ROBUST_DOF) -> HeldOut:
    """Each of ``folds`` consecutive blocks of the pings left out of the refinement in turn, then fixed alone with
    the surveyed and with the refined array (the module docstring). Arguments as :func:`refine_receivers`; the
    blocks' pings fixed with every arrival (no gate: a receiver's error is what is measured), each from its place or
    the fix's own start (the better), their depth kept at the places' in 3-D.

    Returns
    -------
    HeldOut

    Raises
    ------
    ModelError
        As :func:`refine_receivers`, for a block left out.
    """
    toa, receivers, places, c, sigma = _checked(toa, receivers, places, c, sigma_toa, survey_sigma)
    usable = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= MIN_ARRIVALS)
    per_fold, pooled = [], [[], []]
    for block in np.array_split(usable, folds):
        keep = np.ones(len(toa), bool)
        keep[block] = False
        refined = refine_receivers(toa[keep], receivers, places[keep], c[keep], sigma, survey_sigma, dof)
        moved = receivers.copy()
        moved[:, :2] += refined.shift
        medians = []
        for k, array in enumerate((receivers, moved)):
            ratio = _best_fixes(toa[block], array, places[block], c[block], sigma)[2]
            pooled[k].append(ratio)
            medians.append(np.nanmedian(ratio) if np.isfinite(ratio).any() else np.nan)
        per_fold.append(medians)
    surveyed, refined = (np.concatenate(p) for p in pooled)
    both = np.isfinite(surveyed) & np.isfinite(refined)
    return HeldOut(float(np.median(surveyed[both])) if both.any() else np.nan,
                   float(np.median(refined[both])) if both.any() else np.nan, int(both.sum()), np.array(per_fold))


def _best_fixes(toa, receivers, places, c, sigma):
    """Each ping fixed alone with every arrival, from its place and from the fix's own start, the better kept (its
    depth the place's in 3-D): places (k, dim) [m], emission times (k,) [s] and χ² per degree of freedom (k,) [1],
    NaN where none. Pings of one sound speed are fixed together."""
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


__all__ = ["CHUNK", "DEPTH_SIGMA", "FOLDS", "HeldOut", "ITERATIONS", "MAX_STEP", "MIN_ARRIVALS", "Refinement",
           "START_GATE", "STEP_TOLERANCE", "held_out", "refine_receivers"]

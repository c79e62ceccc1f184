"""The sound speed calibrated from the pings themselves: a joint robust fit of the speed and every ping's position
and emission time (:func:`calibrate_sound_speed_robust`), made over stretches of the record and their median kept
(:func:`calibrate_sound_speed`: the replay's calibration when no speed is given).

References
----------
The soft-L1 loss of scipy's ``least_squares``; Triggs, McLauchlan, Hartley, Fitzgibbon, "Bundle adjustment — a modern
synthesis", Vision Algorithms 1999, § 6.1 (the Schur complement onto the shared parameter).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.depth import checked_depth
from sblsim.models.tracking.fix import FIX_ITERATIONS, fix_pings
from sblsim.models.tracking.toa import SOUND_SPEED_RANGE, checked_sigma, per_receiver, reference_sigma

#: The robust calibration's soft-L1 scale, in standard deviations of a time of arrival: residuals beyond it weigh
#: as in an L1 fit (late multipath arrivals).
ROBUST_SCALE = 2.0


#: The robust calibration's most joint steps, and the change of the sound speed [m/s] it stops below.
JOINT_ITERATIONS = 200


JOINT_TOLERANCE = 0.01


def _calibration_pings(toa: np.ndarray, dim: int, max_pings: int) -> np.ndarray:
    """The rows of ``toa`` (m, n) a sound-speed calibration uses: at most ``max_pings`` pings, evenly spread, of
    those heard by at least dim + 3 receivers (redundant ones); ModelError (one line) if fewer than 3."""
    rich = np.flatnonzero(np.isfinite(toa).sum(axis=1) >= dim + 3)
    if len(rich) < 3:
        raise ModelError(f"sound speed calibration: {len(rich)} pings heard by at least {dim + 3} receivers; at "
                         "least 3 are needed (give the sound speed)")
    return rich[np.unique(np.linspace(0, len(rich) - 1, min(max_pings, len(rich))).round().astype(int))]


def calibrate_sound_speed_robust(toa: np.ndarray, receivers: np.ndarray, sigma_toa: float | np.ndarray,
                                 max_pings: int = 300,
                                 scale: float = ROBUST_SCALE,
                                 bounds: tuple[float, float] = SOUND_SPEED_RANGE, depth: np.ndarray | None = None,
                                 depth_sigma: float = 0.3) -> tuple[float, float, int]:
    """The sound speed, the pings' positions and their emission times fitted jointly with a robust loss (a
    calibration step).

    Over at most ``max_pings`` pings (evenly spread) heard by at least dim + 3 receivers, every arrival kept, the
    sum ``Σ ρ((toa_ij − t_e,i − ‖p_i − r_j‖/c)² / (scale σ_toa)²)`` with the soft-L1 loss
    ``ρ(z) = 2 (√(1 + z) − 1)`` (the objective of scipy's ``least_squares(loss="soft_l1")``; with a timing noise
    per receiver, each arrival's own ``scale σ_i``) is minimised over c
    and every ``(p_i, t_e,i)``. From the middle of ``bounds``, the pings started from their single-ping fixes
    there: each iteration solves the weighted normal equations (the soft-L1 weights) with the pings' blocks
    eliminated (a Schur complement onto c), and takes the joint step, halved until the cost falls once every
    ping's ``(p_i, t_e,i)`` has been fitted again at the new c (reweighted Gauss-Newton, each ping its own step
    halving), until c moves by less than :data:`JOINT_TOLERANCE`. The search follows one continuous solution
    from the start (a global scalar search over c jumps between the local solutions of pings with late
    arrivals). The standard error is that of the weighted normal equations at the solution, reduced onto c.
    Where the tag's depth is known (``depth``: a sensor's reading, a depth given, or a prior where the receivers do
    not determine it), each ping's depth is one more measurement, ``z_i = −depth_i`` with standard deviation
    ``depth_sigma``, its term ``((z_i + depth_i) / σ_depth)²`` beside the arrivals' (as :func:`fix_pings` takes it):
    receivers a few metres apart in height otherwise leave each ping's depth free to take a mirror image about
    them, which the speed follows.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    sigma_toa : float or ndarray, (n,)
        Standard deviation of a time of arrival [s]: one, or each receiver's.
    max_pings : int
        Most pings used.
    scale : float
        The soft-L1 scale [σ_toa].
    bounds : (float, float)
        The speeds allowed [m/s]; a solution outside is refused.
    depth : ndarray, (m,), optional
        The tag's depth per ping [m], positive down, NaN where none; needs receivers in 3-D.
    depth_sigma : float
        Its standard deviation [m].

    Returns
    -------
    c : float
        Sound speed [m/s].
    sigma_c : float
        Its standard error [m/s].
    pings : int
        Pings used.
    """
    receivers = np.asarray(receivers, float)
    dim = receivers.shape[1]
    sigma_toa = checked_sigma(sigma_toa, len(receivers))
    rich = _calibration_pings(toa, dim, max_pings)
    c = 0.5 * (bounds[0] + bounds[1])
    depth = checked_depth(depth, len(toa), dim)
    reading = None if depth is None else depth[rich]
    p, te, _, _, _ = fix_pings(toa[rich], receivers, c, sigma_toa, depth=reading, depth_sigma=depth_sigma)
    ok = np.isfinite(p).all(axis=1) & np.isfinite(te)
    if ok.sum() < 3:
        raise ModelError("sound speed calibration: fewer than 3 pings could be fixed; give the sound speed")
    T, p, te = toa[rich][ok], p[ok], te[ok]
    heard = np.isfinite(T)
    y = np.where(heard, T, 0.0)
    f = scale * sigma_toa  # one, or each receiver's (n,)
    # the normal equations' unit f0 (a timing noise per receiver: each arrival's weight times (f0 / f_i)²)
    f0 = scale * reference_sigma(sigma_toa)
    relative = (f0 / f) ** 2 if per_receiver(sigma_toa) else None
    # the depth's term: (z + depth)² / σ_depth², in the normal equations' units (those of the arrivals' f² r² / f²)
    read = np.zeros(len(T), bool) if reading is None else np.isfinite(reading[ok])
    target = np.zeros(len(T)) if reading is None else -np.where(read, reading[ok], 0.0)
    weight = np.where(read, (f0 / depth_sigma) ** 2, 0.0)

    def depth_costs(p):
        return np.where(read, ((p[:, -1] - target) / depth_sigma) ** 2, 0.0)

    def residuals(c, p, te):
        diff = p[:, None, :] - receivers[None]
        d = np.linalg.norm(diff, axis=2)
        return np.where(heard, y - te[:, None] - d / c, 0.0), diff, d

    def cost(r, p):
        return float((2 * (np.sqrt(1 + (r / f) ** 2) - 1))[heard].sum() + depth_costs(p).sum())

    def ping_costs(r, p):
        return np.where(heard, 2 * (np.sqrt(1 + (r / f) ** 2) - 1), 0.0).sum(axis=1) + depth_costs(p)

    def normal(c, p, te):
        """The weighted normal equations' blocks at (c, p, te): per ping A (k, dim+1, dim+1), b (k, dim+1), the
        gradient gp (k, dim+1); for c the scalars Jc·W·Jc and gc."""
        r, diff, d = residuals(c, p, te)
        w = np.where(heard, 1 / np.sqrt(1 + (r / f) ** 2), 0.0)  # the soft-L1 weights ρ'
        if relative is not None:
            w = w * relative
        # the derivatives of the model (not of the residual) with respect to p_i, t_e,i and c
        Jp = np.concatenate([diff / (np.maximum(d, 1e-9)[..., None] * c), np.ones(d.shape + (1,))], axis=2)
        Jc = -d / c**2
        A = np.einsum("kn,kni,knj->kij", w, Jp, Jp) + 1e-18 * np.eye(dim + 1)
        gp = np.einsum("kn,kni,kn->ki", w, Jp, r)
        if read.any():  # the depth's measurement of z (its row e_z)
            A[:, dim - 1, dim - 1] += weight
            gp[:, dim - 1] += weight * (target - p[:, -1])
        return r, A, np.einsum("kn,kni,kn->ki", w, Jp, Jc), gp, float((w * Jc**2).sum()), float((w * Jc * r).sum())

    def pings_at(c, p, te):
        """Every ping's (p, t_e) fitted at the sound speed c (reweighted Gauss-Newton, each ping's own step
        halving)."""
        p, te = p.copy(), te.copy()
        for _ in range(FIX_ITERATIONS):
            r, A, _, gp, _, _ = normal(c, p, te)
            dq = np.linalg.solve(A, gp[..., None])[..., 0]
            scale = (np.abs(dq[:, :dim]).max(axis=1) >= 1e-4).astype(float)  # moving by a tenth of a mm or more
            if not scale.any():
                break
            before = ping_costs(r, p)
            for _halving in range(12):
                p_try = p + scale[:, None] * dq[:, :dim]
                r_try = residuals(c, p_try, te + scale * dq[:, dim])[0]
                worse = (ping_costs(r_try, p_try) > before) & (scale > 0)
                if not worse.any():
                    break
                scale[worse] *= 0.5
            scale[worse] = 0.0
            p, te = p + scale[:, None] * dq[:, :dim], te + scale * dq[:, dim]
        return p, te

    p, te = pings_at(c, p, te)
    current = cost(residuals(c, p, te)[0], p)
    for _iteration in range(JOINT_ITERATIONS):
        _, A, b, gp, cc, gc = normal(c, p, te)
        Ainv_b = np.linalg.solve(A, b[..., None])[..., 0]
        Ainv_g = np.linalg.solve(A, gp[..., None])[..., 0]
        dc = (gc - float(np.einsum("ki,ki->", b, Ainv_g))) / (cc - float(np.einsum("ki,ki->", b, Ainv_b)))
        dq = Ainv_g - Ainv_b * dc
        for halving in range(20):  # the joint step halved until the cost, the pings fitted again, falls
            step = 0.5**halving
            c_try = c + step * dc
            p_try, te_try = pings_at(c_try, p + step * dq[:, :dim], te + step * dq[:, dim])
            cost_try = cost(residuals(c_try, p_try, te_try)[0], p_try)
            if cost_try <= current:
                break
        else:
            break
        c, p, te, current = c_try, p_try, te_try, cost_try
        if abs(step * dc) < JOINT_TOLERANCE:
            break
    _, A, b, _, cc, _ = normal(c, p, te)
    S = cc - float(np.einsum("ki,ki->", b, np.linalg.solve(A, b[..., None])[..., 0]))
    if not bounds[0] <= c <= bounds[1]:
        raise ModelError(f"sound speed calibration: {c:.1f} m/s is outside [{bounds[0]:g}, {bounds[1]:g}] m/s; give "
                         "the sound speed")
    return float(c), float(reference_sigma(sigma_toa) / np.sqrt(S)) if S > 0 else float("inf"), int(len(T))


#: The calibration's batches (consecutive stretches of the record) and the most pings each fits.
BATCHES = 8
BATCH_PINGS = 60
#: The largest standard error [m/s] of a calibrated sound speed: beyond it the array does not determine the speed.
MAX_SIGMA = 5.0


@dataclass(frozen=True)
class Calibration:
    """What :func:`calibrate_sound_speed` returns: the sound speed ``c`` [m/s], its standard error ``sigma`` [m/s],
    the pings used, and each batch's own speed (``batches`` [m/s], NaN where a batch could not be fitted; empty where
    the record was too short for stretches and one joint fit gave ``c``)."""

    c: float
    sigma: float
    pings: int
    batches: tuple[float, ...]


def calibrate_sound_speed(toa: np.ndarray, receivers: np.ndarray, sigma_toa: float | np.ndarray,
                          batches: int = BATCHES,
                          max_pings: int = BATCH_PINGS,
                          bounds: tuple[float, float] = SOUND_SPEED_RANGE, strict: bool = True,
                          depth: np.ndarray | None = None, depth_sigma: float = 0.3) -> Calibration:
    """The sound speed calibrated from the pings: the median of the joint robust fits
    (:func:`calibrate_sound_speed_robust`) of ``batches`` consecutive stretches of the record, each of at most
    ``max_pings`` pings.

    One fit over the whole record is one estimate whose error its normal equations do not show: a stretch of pings
    whose late arrivals agree on a wrong speed (a thin array's, where most pings are heard by few receivers) moves
    it by more than its standard error, and its local minimum is then far from the truth (Lake Hald's 8 hydrophones:
    1,429.8 m/s, standard error 0.28 m/s, where the 28 give 1,416.9). The stretches' fits are independent estimates
    of the same speed: their median is robust to a few wrong ones (Huber & Ronchetti, *Robust Statistics*, Wiley
    2009, § 3.2), and their spread is the speed's real uncertainty: the standard error of the median of K estimates,
    ``1.2533 s / √K`` (s their standard deviation; the median's efficiency 2/π for Gaussian estimates).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    sigma_toa : float or ndarray, (n,)
        Standard deviation of a time of arrival [s]: one, or each receiver's.
    batches : int
        K, at least 3.
    max_pings : int
        Most pings of a batch's fit.
    bounds : (float, float)
        The speeds allowed [m/s].
    strict : bool
        False: returned whatever its standard error (for a caller that combines a weak calibration with a prior,
        :func:`~sblsim.models.tracking.sound_speed.combine_speeds`).
    depth, depth_sigma
        The tag's depth per ping (m,) [m] and its standard deviation [m], as :func:`calibrate_sound_speed_robust`.

    Returns
    -------
    Calibration

    Raises
    ------
    ModelError
        ``strict`` and their standard error exceeds :data:`MAX_SIGMA` (the array does not determine the speed: give
        it), or, where
        fewer than 3 stretches can be fitted (a short record: one joint fit of it all is returned then, ``batches``
        empty), that fit fails; a depth given with receivers in 2-D or not one per ping
        (:func:`~sblsim.models.tracking.depth.checked_depth`).
    """
    depth = checked_depth(depth, len(toa), np.shape(receivers)[1])
    values, used = [], 0
    for rows in np.array_split(np.arange(len(toa)), max(int(batches), 3)):
        try:
            c, _, n = calibrate_sound_speed_robust(toa[rows], receivers, sigma_toa, max_pings, bounds=bounds,
                                                   depth=None if depth is None else depth[rows],
                                                   depth_sigma=depth_sigma)
        except ModelError:
            values.append(np.nan)
            continue
        values.append(c)
        used += n
    fitted = np.array([v for v in values if np.isfinite(v)])
    if len(fitted) < 3:  # too short a record for stretches: one joint fit of it all (raises where even that fails)
        c, sigma, used = calibrate_sound_speed_robust(toa, receivers, sigma_toa, bounds=bounds, depth=depth,
                                                      depth_sigma=depth_sigma)
        return Calibration(c, sigma, used, ())
    sigma = float(1.2533 * np.std(fitted, ddof=1) / np.sqrt(len(fitted)))
    c = float(np.median(fitted))
    if strict and sigma > MAX_SIGMA:
        raise ModelError(f"sound speed calibration: the stretches of the record give {np.min(fitted):.1f} to "
                         f"{np.max(fitted):.1f} m/s (standard error {sigma:.2g} m/s, allowed at most {MAX_SIGMA:g}): "
                         "the array does not determine it (give the sound speed)")
    return Calibration(c, sigma, used, tuple(float(v) for v in values))


__all__ = ["BATCHES", "BATCH_PINGS", "JOINT_ITERATIONS", "JOINT_TOLERANCE", "MAX_SIGMA", "ROBUST_SCALE",
           "Calibration", "calibrate_sound_speed", "calibrate_sound_speed_robust"]

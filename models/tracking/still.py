"""A still tag's verdict: did it move beyond what its own error terms let its fixes wander, and from when.

A still tag's single-ping fixes ``x_k`` (at times ``t_k``) are, about its one position ``μ``,

    ``x_k = μ + n(t_k) + e_k``,

``e_k`` each fix's own error (white: its covariance ``R_k`` times a dispersion ``s²`` the fixes show, below) and
``n(t)`` the errors that change slowly and are the same for every ping of an hour: the sound speed's change over the
day (it scales every range, and moves every fix along the array's scale direction), each receiver's clock offset's
error (a synchronisation's offsets are fitted per bin) and multipath at a receiver (a reflection that comes and goes
with the water level). Each is a bias ``β_i(t)`` of receiver i's arrivals, and moves a fix by ``A_k β(t)``, ``A_k``
the fix's sensitivity to its receivers' biases; ``n(t)`` is taken as a Gaussian process of covariance
``C k(t, t')``, ``C = mean_k A_k B A_kᵀ`` (2×2) from the biases' covariance B and ``k`` the squared-exponential
correlation of length :data:`SLOW_TIME_S`, represented by the cosines of its Hilbert-space expansion on the record's
span (the Laplacian's eigenfunctions with Neumann ends, each weighted by the kernel's spectral density at its
frequency: Solin & Särkkä, "Hilbert space methods for reduced-rank Gaussian process regression", Statistics and
Computing 30, 2020, § 3): ``n(t_k) = G_k θ``, ``θ ~ N(0, I)``, a few dozen columns whatever the number of fixes.
The receivers' survey is the same at every ping: it moves the place, not the fixes over time (but through each
ping's receivers heard, which the dispersion takes), and is the place's consider term, not the wander's.

A tag that moved at fix τ adds a step ``δ`` to every fix from τ on. With ``μ`` and ``δ`` unknown, the generalised
likelihood ratio of "a step at τ" against "one position" (the covariance ``Σ = diag(s² R_k) + G Gᵀ`` known) is

    ``Λ(τ) = bᵀ A⁻¹ b``,  ``b = hᵀ W̃ x``,  ``A = hᵀ W̃ h``,

with ``h`` the step's columns, ``W̃`` the precision ``Σ⁻¹`` with ``μ`` profiled out: χ²(2) for one τ under one
position (Willsky & Jones, "A generalized likelihood ratio approach to the detection and estimation of jumps in
linear systems", IEEE Trans. Autom. Control 21(1), 1976; for a change in mean, Csörgő & Horváth, *Limit Theorems in
Change-Point Analysis*, Wiley 1997, § 1.3). ``Σ⁻¹`` by Woodbury, and every τ's ``b`` and ``A`` from reverse
cumulative sums: O(N q²) for N fixes and q columns. The tag moved where the largest ``Λ`` exceeds
``2 ln(K / α)`` (χ²(2)'s tail ``e^(−x/2)`` with Bonferroni's bound over the K steps scanned, α = :data:`LEVEL`);
its change is that τ, and the segment before it is scanned again (binary segmentation: Vostrikova, Soviet Math.
Dokl. 24, 1981) until none is found: the **first** change. Its rows from there on are the ones that moved.

A tag that drifts off (a dead fish carried by a current) moves the fixes' mean slowly, and a step is found only where
that mean has moved by what one fix sees, after the drift's onset. The same statistic with a ramp's columns
``h_k = (t_k − t_τ−1) I`` from τ on (a constant velocity ``δ`` [m/s]; Λ again χ²(2) for one τ) fits the change's
segment with a drift to its end, or one that stops at the step (the step itself its latest onset); where a drift
explains the fixes better than the step by more than χ²(2) at :data:`STEP_LEVEL`, its onset is the change. Where no
step is one a single fix sees, a drift to the record's end past the same threshold whose way by then a single fix
sees is the change (:func:`drift_onset`, :func:`still_verdict`). The ramp's sums are the step's reverse cumulative
sums weighted by ``t_k`` and ``t_k²``, less ``t_τ−1`` times the lower ones: the same O(N q²).

The dispersion ``s²`` is the fixes' own, from successive differences (they cancel ``μ``, ``n(t)`` and a step but at
one pair): the median of ``dᵀ (R_k + R_k−1)⁻¹ d`` over χ²(2)'s median ``2 ln 2`` (a robust von Neumann estimate,
von Neumann, Ann. Math. Stat. 12(4), 1941). A fix far from its neighbours (a reflection the fix kept) is pulled to
within :data:`HUBER` of its dispersion from the running median of :data:`MEDIAN_HALF_WIDTH` fixes each side
(Huber's ψ about a median filter, which keeps a step: Tukey, *Exploratory Data Analysis*, 1977, ch. 7), so that one
gross fix at the record's end is not a step.

Units: metres [m], seconds [s].
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: The slow errors' correlation time [s]: the sound speed follows the water's temperature over hours, a reflection
#: the water level, a synchronisation's offsets their bins.
SLOW_TIME_S = 3600.0
#: The sound speed's change over a record [m/s] (standard deviation): the water's temperature wandering by about
#: 1.5 °C (about 3 m/s per °C at 10 °C, TEOS-10), where the pings do not show more.
SPEED_WANDER = 5.0
#: The verdict's level: a still tag is said to have moved in about this share of records.
LEVEL = 1e-3
#: A change is a move only where a single fix could see it: its step beyond χ²(2) at this level against a fix's own
#: covariance (times the dispersion) and the slow errors' (a step of centimetres the thousands of fixes of a still
#: tag make significant is none).
STEP_LEVEL = 0.99
#: The records drawn from the error model in :func:`wanders` (its level 1 / (DRAWS + 1)), and the most fixes it
#: takes (every j-th beyond).
DRAWS = 199
MAX_ORDERED = 2000
#: The fewest trusted fixes before a change that make a still part (fewer: the tag moved the whole time; about an
#: hour of pings every two minutes).
MIN_STILL = 30
#: The fewest trusted fixes on each side of a change.
MIN_SEGMENT = 5
#: The most cosines of the slow errors' expansion (a longer record takes a longer correlation time).
MAX_BASIS = 48
#: How far a fix may lie from the running median of its neighbours [its own σ times the dispersion].
HUBER = 3.0
#: The running median's fixes each side.
MEDIAN_HALF_WIDTH = 5
#: The spectral density's reach: the cosines up to ``ω T = 4`` (the squared-exponential's density e⁻⁸ of its peak).
SPECTRAL_REACH = 4.0
#: The expansion's domain beyond the record each side [correlation times].
MARGIN = 3.0


@dataclass(frozen=True)
class StillVerdict:
    """What :func:`still_verdict` returns: the trusted ``fixes`` it tested, their dispersion ``white_scale`` (s²),
    the largest step statistic over the whole record ``statistic`` and its ``threshold``, the time-ordered rows of
    the tested fixes ``order`` (indices into the fixes given), and ``change``: the position in ``order`` of the first
    fix after the first change (None: the tag stayed). ``throughout``: the tag moved the whole time (fewer than
    :data:`MIN_STILL` fixes before the change, or those in an order in time its error terms do not make:
    :func:`wanders`). ``detectable`` (2,) [m]: the smallest step a single fix could see, in the best and the worst
    direction (the square roots of χ²(2) at :data:`STEP_LEVEL` times the eigenvalues of a fix's own and slow
    covariance; NaN where undecided): a smaller move is not told from the fixes' scatter. With no ``change``,
    ``throughout`` is the order test asked for (``order_test``). ``drifted``: the change is a drift's onset
    (:func:`drift_onset`), not a step's."""

    fixes: int
    white_scale: float
    statistic: float
    threshold: float
    order: np.ndarray
    change: int | None
    throughout: bool = False
    detectable: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    drifted: bool = False


def white_scale(x: np.ndarray, R: np.ndarray) -> float:
    """The fixes' dispersion s² against their covariances (module docstring).

    Parameters
    ----------
    x : ndarray, (N, 2)
        Time-ordered fixes [m].
    R : ndarray, (N, 2, 2)
        Their covariances [m²].

    Returns
    -------
    float
        s², NaN with fewer than two fixes.
    """
    if len(x) < 2:
        return float("nan")
    d = np.diff(x, axis=0)
    q = np.einsum("ki,ki->k", d, np.linalg.solve(R[1:] + R[:-1], d[..., None])[..., 0])
    return float(np.median(q) / (2.0 * np.log(2.0)))


def slow_columns(t: np.ndarray, slow: np.ndarray, time_scale: float = SLOW_TIME_S) -> np.ndarray:
    """The slow errors' columns ``G`` (q, 2, N): ``n(t_k) = G[:, :, k]ᵀ θ``, θ ~ N(0, I), for ``n`` a Gaussian
    process of covariance ``slow · exp(−(t − t')² / (2 T²))`` (module docstring; the constant left out: the
    position takes it). Laid out column by column, each column's values in time order contiguous.

    Parameters
    ----------
    t : ndarray, (N,)
        [s].
    slow : ndarray, (2, 2)
        C [m²].
    time_scale : float
        T [s]; lengthened where the record needs more than :data:`MAX_BASIS` cosines.
    """
    t = np.asarray(t, float)
    record = float(t.max() - t.min()) if len(t) else 0.0
    # the domain reaches MARGIN correlation times beyond the record each side: the Neumann ends double the variance
    # within a correlation time of them (Solin & Särkkä 2020, § 4)
    scale = max(time_scale, SPECTRAL_REACH * record / (np.pi * MAX_BASIS - 2 * MARGIN * SPECTRAL_REACH))
    span = record + 2 * MARGIN * scale
    j = np.arange(1, max(1, int(SPECTRAL_REACH * span / (np.pi * scale))) + 1)
    w = j * np.pi / span
    density = np.sqrt(2.0 * np.pi) * scale * np.exp(-0.5 * (w * scale) ** 2)
    phi = np.sqrt(2.0 / span * density)[:, None] * np.cos(np.outer(w, t - t.min() + MARGIN * scale))  # (J, N)
    return np.einsum("jk,ab->jbak", phi, _root(slow)).reshape(2 * len(j), 2, len(t))


def _root(C: np.ndarray) -> np.ndarray:
    """The symmetric square root of covariances C (..., d, d), its eigenvalues clipped at 0: ``root rootᵀ = C`` for a
    C positive semi-definite (one singular to rounding included, where a Cholesky factor fails)."""
    vals, vecs = np.linalg.eigh(0.5 * (C + np.swapaxes(C, -1, -2)))
    return vecs * np.sqrt(np.clip(vals, 0.0, None))[..., None, :]


def step_statistics(x: np.ndarray, R: np.ndarray, G: np.ndarray,
                    ramp: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The step statistic Λ(τ) (module docstring) of every τ in [1, N): a step from fix τ on, or, with ``ramp``, a
    drift from fix τ − 1 on (the change's columns ``h_k = (r_k − r_τ−1) I`` for k ≥ τ, 0 before: a fix moving by
    ``δ`` per unit of ``r``; ``r = t`` a drift at a constant velocity to the end, ``r = min(t, t_j)`` one that stops
    at fix j).

    Parameters
    ----------
    x : ndarray, (N, 2)
        [m].
    R : ndarray, (N, 2, 2)
        The fixes' white covariances [m²].
    G : ndarray, (q, 2, N)
        The slow errors' columns [m] (:func:`slow_columns`).
    ramp : ndarray, (N,), optional
        r, non-decreasing (the fixes' times, scaled to about 1 against rounding).

    Returns
    -------
    statistics : ndarray, (N,)
        Λ(τ); NaN at τ = 0.
    steps : ndarray, (N, 2)
        Each τ's ``δ = A⁻¹ b`` [m] (its generalised least-squares estimate; with ``ramp``, per unit of r); NaN at
        τ = 0.
    """
    n, q = len(x), G.shape[0]
    Ri = np.linalg.inv(R)
    RG = np.stack([Ri[:, a, 0] * G[:, 0] + Ri[:, a, 1] * G[:, 1] for a in range(2)], axis=1)  # R_k⁻¹ G_k
    M = np.eye(q) + G.reshape(q, -1) @ RG.reshape(q, -1).T  # M = I + Gᵀ R⁻¹ G = L Lᵀ, L = V √Λ (M ≥ I)
    vals, vecs = np.linalg.eigh(0.5 * (M + M.T))
    Li = vecs.T / np.sqrt(np.maximum(vals, 1.0))[:, None]  # L⁻¹
    P = (Li @ RG.reshape(q, -1)).reshape(q, 2, n)  # L⁻¹ G_kᵀ R_k⁻¹
    Rx = np.einsum("kab,kb->ka", Ri, x)
    y = Li @ (G.reshape(q, -1) @ Rx.T.reshape(-1))  # L⁻¹ Gᵀ R⁻¹ x
    u = Rx - (y @ P.reshape(q, -1)).reshape(2, n).T  # Σ⁻¹ x, fix by fix

    def tail(a: np.ndarray, axis: int) -> np.ndarray:  # the sums from τ to the end
        return a.sum(axis=axis, keepdims=True) - np.cumsum(a, axis=axis) + a

    a, Rc, Z = tail(u, 0), tail(Ri, 0), tail(P, 2)  # Z_τ = L⁻¹ E_τᵀ, E_τ = Σ_k≥τ R_k⁻¹ G_k
    a0, Z1, C = a[0], Z[:, :, 0], Rc[0] - np.einsum("ja,jb->ab", Z[:, :, 0], Z[:, :, 0])  # 1ᵀ Σ⁻¹ x; C = 1ᵀ Σ⁻¹ 1
    Rh = Rh2 = Rc  # Σ_k≥τ h_k R_k⁻¹ and Σ_k≥τ h_k² R_k⁻¹ (h_k = 1: the step)
    if ramp is not None:  # h_k = r_k − s, s = r_τ−1: the sums of r_k v_k and r_k² v_k less s times the lower ones
        r = np.asarray(ramp, float)
        s = np.concatenate([[np.nan], r[:-1]])
        rRi = tail(r[:, None, None] * Ri, 0)
        a = tail(r[:, None] * u, 0) - s[:, None] * a
        Z = tail(r * P, 2) - s * Z
        Rh2 = tail(r[:, None, None] ** 2 * Ri, 0) - 2 * s[:, None, None] * rRi + s[:, None, None] ** 2 * Rc
        Rh = rRi - s[:, None, None] * Rc
    ZZ = np.stack([np.stack([(Z[:, i] * Z[:, j]).sum(axis=0) for j in range(2)], axis=-1) for i in range(2)], axis=1)
    D = Rh2 - ZZ  # hᵀ Σ⁻¹ h
    B = Rh - np.einsum("jak,jb->kab", Z, Z1)  # hᵀ Σ⁻¹ 1
    if ramp is None:
        C = B[0]  # 1ᵀ Σ⁻¹ 1, as the step's first (bit for bit)
    Ci = np.linalg.inv(C)
    b = a - np.einsum("kab,b->ka", B @ Ci, a0)
    A = D - B @ Ci @ B.transpose(0, 2, 1)
    out, steps = np.full(len(x), np.nan), np.full((len(x), 2), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        steps[1:] = np.linalg.solve(A[1:], b[1:, :, None])[..., 0]
        out[1:] = np.einsum("ka,ka->k", b[1:], steps[1:])
    return out, steps


def _cleaned(x: np.ndarray, R: np.ndarray, s2: float) -> np.ndarray:
    """The fixes pulled to within :data:`HUBER` dispersions of their running median (module docstring)."""
    h = MEDIAN_HALF_WIDTH
    padded = np.pad(x, ((h, h), (0, 0)), mode="reflect")  # a gross fix at an end not repeated
    med = np.median(np.lib.stride_tricks.sliding_window_view(padded, 2 * h + 1, axis=0), axis=-1)
    d = x - med
    z = np.sqrt(np.einsum("ki,ki->k", d, np.linalg.solve(R, d[..., None])[..., 0]) / s2)
    return med + d * np.minimum(1.0, HUBER / np.maximum(z, 1e-12))[:, None]


def threshold(candidates: int, level: float = LEVEL) -> float:
    """The largest step statistic of a still tag at ``level`` over ``candidates`` steps: ``2 ln(K / α)`` (module
    docstring)."""
    return 2.0 * float(np.log(max(candidates, 1) / level))


def still_verdict(fixes: np.ndarray, covariances: np.ndarray, times: np.ndarray, trusted: np.ndarray,
                  slow: np.ndarray, multipath: np.ndarray | None = None, time_scale: float = SLOW_TIME_S,
                  level: float = LEVEL, order_test: bool = False, white_floor: float = 0.0) -> StillVerdict:
    """Whether, and from which fix on, a still tag moved beyond what its error terms let its fixes wander (module
    docstring).

    Parameters
    ----------
    fixes : ndarray, (m, ≥2)
        The single-ping fixes [m] (their horizontal coordinates tested), NaN where none.
    covariances : ndarray, (m, ≥2, ≥2)
        Their covariances [m²].
    times : ndarray, (m,)
        [s].
    trusted : ndarray of bool, (m,)
        The fixes to test (:func:`~sblsim.models.tracking.quality.trusted_fixes`).
    slow : ndarray, (2, 2)
        The slow errors' covariance C [m²] (:func:`slow_covariance`).
    multipath : ndarray, (2, 2), optional
        A part of C [m²] in the fixes' own units: multiplied by their dispersion s² (a reflection as large as the
        timing noise the fixes show).
    time_scale : float
        Their correlation time [s].
    level : float
        α.
    order_test : bool
        Where no change is found, whether the fixes lie in an order in time their error terms do not make
        (:func:`wanders`: ``throughout`` with no ``change``; a caller's second input, such as arrivals that fit no
        one place, says when to ask).
    white_floor : float
        The least dispersion s² taken [1]: the share of the fixes' covariances that is the times' rounding, whose
        size at a still tag changes as the clocks drift across the time grid (small while its receivers' arrivals
        round alike, up to a quantum's apart later), so that the fixes' scatter in one period is no measure of it.

    Returns
    -------
    StillVerdict
        Undecided (no change, statistic NaN) with fewer than 2 :data:`MIN_SEGMENT` fixes.
    """
    x = np.asarray(fixes, float)[:, :2]
    R = np.asarray(covariances, float)[:, :2, :2]
    t = np.asarray(times, float)
    ok = np.asarray(trusted, bool) & np.isfinite(x).all(axis=1) & np.isfinite(t) & np.isfinite(R).all(axis=(1, 2))
    k = np.flatnonzero(ok)
    k = k[np.argsort(t[k], kind="stable")]
    if len(k) < 2 * MIN_SEGMENT:
        return StillVerdict(len(k), float("nan"), float("nan"), float("nan"), k, None)
    x, R, t = x[k], R[k], t[k]
    s2 = max(white_scale(x, R), float(white_floor), 1e-6)
    Rw = s2 * R
    x = _cleaned(x, Rw, 1.0)
    C = np.asarray(slow, float) + (0.0 if multipath is None else s2 * np.asarray(multipath, float))
    G = slow_columns(t, C, time_scale)
    # a step a single fix could see: beyond χ²(2) at STEP_LEVEL of a fix's own and slow covariance
    seen_at = -2.0 * np.log(1.0 - STEP_LEVEL)
    single = np.median(Rw, axis=0) + C  # a fix's own and slow covariance
    spread = np.linalg.inv(single)
    detectable = np.sqrt(seen_at * np.clip(np.linalg.eigvalsh(single), 0.0, None))
    first, bound, change, end = np.nan, np.nan, None, len(k)
    while end >= 2 * MIN_SEGMENT:
        stats, steps = step_statistics(x[:end], Rw[:end], G[..., :end])
        stats, steps = stats[MIN_SEGMENT:end - MIN_SEGMENT + 1], steps[MIN_SEGMENT:end - MIN_SEGMENT + 1]
        seen = np.einsum("ka,ab,kb->k", steps, spread, steps) > seen_at
        limit = threshold(len(stats), level)
        candidates = np.where(seen & (stats > limit), stats, -np.inf)
        if change is None:
            first, bound = (float(np.nanmax(stats)) if np.isfinite(stats).any() else np.nan), limit
        if not np.isfinite(candidates).any():
            break
        segment, at_change = end, float(np.max(candidates))
        change = end = MIN_SEGMENT + int(np.argmax(candidates))
    if change is not None:
        change, drifted = drift_onset(x[:segment], Rw[:segment], G[..., :segment], t[:segment], change, at_change)
    else:  # no step one fix sees: a drift to the record's end whose way by then one fix sees
        change = _drift(x, Rw, G, t, spread, seen_at, level)
        drifted = change is not None
    if change is None:
        throughout = order_test and wanders(x, Rw, G)
    else:
        throughout = change < MIN_STILL or wanders(x[:change], Rw[:change], G[..., :change])
    return StillVerdict(len(k), s2, first, bound, k, change, throughout, detectable, drifted)


def _ramp(t: np.ndarray) -> np.ndarray:
    """The times ``t`` (N,) [s] as a drift's ramp for :func:`step_statistics`: from 0 to 1 over the record (scaled
    against rounding)."""
    return (t - t[0]) / max(float(t[-1] - t[0]), 1e-9)


def _drift(x: np.ndarray, R: np.ndarray, G: np.ndarray, t: np.ndarray, spread: np.ndarray, seen_at: float,
           level: float) -> int | None:
    """The first moved fix of a drift at a constant velocity from it to the record's end (:func:`step_statistics`
    with the times as the ramp) whose statistic exceeds :func:`threshold` over the onsets scanned and whose way by the
    record's end a single fix sees (beyond ``seen_at`` in the metric ``spread`` (2, 2) [m⁻²]), in the fit and in the
    fixes themselves (the median of the last quarter of those after the onset against that of those before it: over
    a long record a wander its slow errors' model does not hold fits a ramp whose way is none); None where none does.
    """
    r = _ramp(t)
    stats, rates = step_statistics(x, R, G, r)
    onsets = np.arange(MIN_SEGMENT, len(x) - MIN_SEGMENT + 1)
    way = rates[onsets] * (r[-1] - r[onsets - 1])[:, None]
    seen = np.einsum("ka,ab,kb->k", way, spread, way) > seen_at
    candidates = np.where(seen & (stats[onsets] > threshold(len(onsets), level)), stats[onsets], -np.inf)
    if not np.isfinite(candidates).any():
        return None
    onset = int(onsets[np.argmax(candidates)])
    went = np.median(x[-max(MIN_SEGMENT, (len(x) - onset) // 4):], axis=0) - np.median(x[:onset], axis=0)
    return onset if went @ spread @ went > seen_at else None


def drift_onset(x: np.ndarray, R: np.ndarray, G: np.ndarray, t: np.ndarray, change: int,
                step: float) -> tuple[int, bool]:
    """Where a tag whose fixes step at ``change`` (the binary segmentation's first change, found in the segment
    ``x`` (N, 2) [m] at times ``t`` (N,) [s]; its step statistic ``step``) began to move: the onset of a drift
    (:func:`step_statistics` with a ramp: a constant velocity from the onset to the segment's end, its onset up to
    the segment's last fix but one, or one that stops at ``change``, the step itself its latest onset) where one
    explains the fixes better than the step by more than χ²(2) at :data:`STEP_LEVEL` (a dead fish carried off by a
    current: a step is found where the fixes' mean has moved by what a single fix sees, after its onset; or, where
    the segment ends within :data:`MIN_SEGMENT` fixes of the onset, before it). ``R`` (N, 2, 2) [m²] and ``G``
    (q, 2, N) [m] as in :func:`step_statistics`.

    Returns
    -------
    onset : int
        The first moved fix: ``change`` where no drift explains the fixes better.
    drifted : bool
        Whether a drift explains the fixes better than the step.
    """
    r = _ramp(t)
    best, onset, drifted = step - 2.0 * np.log(1.0 - STEP_LEVEL), change, False
    for ramp, last in ((r, len(x) - 2), (np.minimum(r, r[change]), change)):
        stats = step_statistics(x, R, G, ramp)[0][MIN_SEGMENT:last + 1]
        if np.isfinite(stats).any() and np.nanmax(stats) > best:
            best, onset, drifted = float(np.nanmax(stats)), MIN_SEGMENT + int(np.nanargmax(stats)), True
    return onset, drifted


def order_ratio(x: np.ndarray) -> np.ndarray:
    """The fixes' (..., N, 2) median distance between successive ones over their median distance from their median
    (a robust von Neumann ratio: √2 for independent errors, near 0 for a track; as
    :func:`~sblsim.models.tracking.stationary.moved` takes it)."""
    spread = np.median(np.linalg.norm(x - np.median(x, axis=-2, keepdims=True), axis=-1), axis=-1)
    return np.median(np.linalg.norm(np.diff(x, axis=-2), axis=-1), axis=-1) / np.maximum(spread, 1e-300)


def wanders(x: np.ndarray, R: np.ndarray, G: np.ndarray, draws: int = DRAWS, seed: int = 0) -> bool:
    """Whether time-ordered fixes ``x`` (N, 2) [m] lie in an order in time their error terms do not make: their
    :func:`order_ratio` below that of every one of ``draws`` records drawn from the error model itself (each fix's
    white ``R`` (N, 2, 2) [m²] and the slow errors' columns ``G`` (q, 2, N) [m]; ``numpy.random.default_rng(seed)``):
    a parametric bootstrap of the order test (Davison & Hinkley, *Bootstrap Methods and their Application*, Cambridge
    1997, § 4.2), where the permutation test's exchangeable fixes would call every still tag's slow wander motion.
    Every j-th fix beyond :data:`MAX_ORDERED` (the draws' too)."""
    step = -(-len(x) // MAX_ORDERED)
    x, R, G = x[::step], R[::step], G[..., ::step]
    rng = np.random.default_rng(seed)
    try:
        root = np.linalg.cholesky(R)
    except np.linalg.LinAlgError:  # a fix's covariance singular to rounding (a pseudo-inverse's): its symmetric root
        root = _root(R)
    white = np.einsum("kab,dkb->dka", root, rng.standard_normal((draws, len(x), 2)))
    slow = np.einsum("dq,qak->dka", rng.standard_normal((draws, G.shape[0])), G)
    return bool(order_ratio(x) < order_ratio(white + slow).min())


def slow_covariance(receivers: np.ndarray, position: np.ndarray, c: float, heard: np.ndarray,
                    sigma_toa: np.ndarray, biases: np.ndarray) -> np.ndarray:
    """The slow errors' covariance C (2, 2) [m²] of a still tag's single-ping fixes: ``mean_k A_k B A_kᵀ`` over the
    pings, ``A_k`` ping k's least-squares fix's sensitivity to its receivers' biases at the tag's position (the
    emission time eliminated: the rows centred per ping with the weights ``1/σ_i²``).

    Parameters
    ----------
    receivers : ndarray, (n, dim)
        [m].
    position : ndarray, (dim,)
        The tag's position [m].
    c : float
        [m/s].
    heard : ndarray of bool, (m, n)
        Each ping's arrivals used.
    sigma_toa : ndarray, (n,)
        [s].
    biases : ndarray, (n, n)
        B [s²].

    Returns
    -------
    ndarray, (2, 2)
    """
    receivers = np.asarray(receivers, float)
    diff = np.asarray(position, float)[None, :] - receivers
    unit = diff / np.maximum(np.linalg.norm(diff, axis=1), 1e-9)[:, None] / c  # (n, dim) [s/m]
    heard = np.asarray(heard, bool)
    heard = heard[heard.sum(axis=1) > unit.shape[1]]
    if not len(heard):
        return np.zeros((2, 2))
    w = heard / np.asarray(sigma_toa, float) ** 2  # (m, n)
    mean = (w @ unit) / w.sum(axis=1, keepdims=True)
    J = unit[None] - mean[:, None, :]  # (m, n, dim), 0-weighted where not heard
    normal = np.einsum("kn,kna,knb->kab", w, J, J)
    A = np.linalg.pinv(normal) @ (J * w[..., None]).transpose(0, 2, 1)  # (m, dim, n)
    return np.einsum("kan,nr,kbr->ab", A, biases, A)[:2, :2] / len(A)


__all__ = ["DRAWS", "HUBER", "LEVEL", "MARGIN", "MAX_BASIS", "MAX_ORDERED", "MEDIAN_HALF_WIDTH", "MIN_SEGMENT",
           "MIN_STILL", "SLOW_TIME_S", "SPECTRAL_REACH", "SPEED_WANDER", "STEP_LEVEL", "StillVerdict", "drift_onset",
           "order_ratio", "slow_columns", "slow_covariance", "step_statistics", "still_verdict", "threshold",
           "wanders", "white_scale"]

"""The criteria of a telemetry array's fix of a tag's ping: the positioning yield and the DRMS of a fix with the
emission time unknown; vectorised over points and layouts (the array's sync coverage:
:mod:`~sblsim.models.design.sync_graph`).

A tag emits pings on its own clock; fixed receivers (hydrophones) each hear a ping with the probability of the
detection range curve (:class:`~sblsim.models.design.detection_curve.DetectionCurve`) at their distance, each
independently. At a point p, for receivers r_i heard with probabilities q_i:

* **positioning yield** (:func:`positioning_yield`): the probability that a ping is heard by at least ``needed``
  receivers, dim + 1 without a depth sensor (3 in 2-D, 4 in 3-D: a position and the emission time), dim with one.
  The count heard is Poisson-binomial; its distribution is computed exactly by the recursion over the receivers
  ``P_i(k) = P_{i−1}(k) (1 − q_i) + P_{i−1}(k − 1) q_i`` (:func:`count_distribution`; Chen and Liu,
  "Statistical applications of the Poisson-binomial and conditional Bernoulli distributions", Statistica Sinica
  7:875–892, 1997);

* **DRMS of a fix** (:func:`fix_drms`): a ping's times of arrival at the receivers i that heard it are ranges
  ``ρ_i = ‖p − r_i‖ + o + w_i`` in metres of sound travel (``o = c t_e``, the unknown emission, the same for every
  receiver; ``w_i ~ N(0, σ_i²)``, ``σ_i = c σ_toa`` or a range-dependent law :func:`range_sigma`). With
  ``u_i = (p − r_i) / ‖p − r_i‖`` and weights ``w_i = h_i / σ_i²`` (``h_i`` 1 where heard, 0 where not) the
  Fisher information of ``(p, o)`` is ``[[Σ w_i u_i u_iᵀ, Σ w_i u_i], [Σ w_i u_iᵀ, Σ w_i]]``, and the
  information of the position with the emission removed is its Schur complement (Kay, Fundamentals of Statistical
  Signal Processing: Estimation Theory, Prentice Hall 1993, Section 3.7, the nuisance parameter's bound)

      ``J = Σ w_i u_i u_iᵀ − (Σ w_i u_i)(Σ w_i u_i)ᵀ / Σ w_i``   (:func:`position_information`),

  plus ``e_z e_zᵀ / σ_d²`` with a depth sensor. The DRMS is ``sqrt((J⁻¹)_xx + (J⁻¹)_yy)`` [m], the horizontal
  axes' (in 2-D the whole trace), infinite where J is singular (:func:`drms`).

  Which receivers hear varies from ping to ping, so the prediction at a point is one of three, each named:

  - :func:`fix_drms` with ``heard`` a pattern (booleans): the DRMS of the fix of that pattern; with no pattern,
    **every receiver heard** (the best case, the map of a fixed channel);
  - :func:`expected_information_drms`: ``h_i = q_i``, the information averaged over the patterns (the information
    reduction factor of Niu, Willett and Bar-Shalom, IEEE Trans. Signal Processing 49(7), 2001): the project's
    accuracy map of the inverted LBL (:func:`~sblsim.models.design.information.layout_information` with
    ``emission``), smooth and cheap, a search's criterion; it is optimistic for the fixes actually made (the mean
    of the inverses exceeds the inverse of the mean);
  - :func:`fixed_ping_drms`: **the RMS over the pings that are fixed** of each pattern's DRMS,
    ``sqrt(E[DRMS(H)² | H fixable])`` over the random pattern H (fixable: at least ``needed`` receivers and a
    regular J) — what a Monte Carlo of single-ping fixes at the point measures. Exact by enumerating the patterns
    of the receivers whose q is neither 0 nor 1 when they are at most :data:`ENUMERATE_MAX`, a Monte Carlo of the
    patterns otherwise.

  In 2-D, N receivers equally spaced on a circle around the tag at its centre, all heard with one σ, give
  ``DRMS = 2σ / √N`` (:func:`ring_fix_drms`): the emission costs nothing there.

Units: metres [m], probabilities [0–1].
"""

from __future__ import annotations

import itertools

import numpy as np

from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.errors import ModelError

#: The condition number of J above which a fix's information counts as singular (no fix).
SINGULAR_CONDITION = 1e12
#: The most uncertain receivers (0 < q < 1) at a point whose patterns :func:`fixed_ping_drms` enumerates exactly.
ENUMERATE_MAX = 10
#: The probabilities below this count as never heard, above ``1 −`` it as always heard (the enumeration's).
CERTAIN = 1e-12


def distances(points: np.ndarray, receivers: np.ndarray) -> np.ndarray:
    """The distances between points and receivers.

    Parameters
    ----------
    points : ndarray, shape (M, dim)
        [m].
    receivers : ndarray, shape (..., n, dim)
        [m]; leading axes: layouts.

    Returns
    -------
    ndarray, shape (..., M, n)
        [m].
    """
    points, receivers = np.asarray(points, float), np.asarray(receivers, float)
    return np.linalg.norm(points[:, None, :] - receivers[..., None, :, :], axis=-1)


def range_sigma(distance_m, sigma0_m: float, per_m: float = 0.0) -> np.ndarray:
    """The standard deviation of a time of arrival in metres of travel, ``σ = σ₀ + k · range``.

    ``σ₀ = c σ_toa`` (the timing's, [m]); ``k`` [m/m] the growth with range the designer states (the timing error
    grows as the signal weakens; a range test's residuals against distance give it), 0 for a constant σ. The law
    and its source (Quazi, IEEE Trans. ASSP 29(3):527–533, 1981) are the channel's
    (:func:`~sblsim.models.acoustics.range_law.range_noise_sigma`), checked here for a design's numbers.

    Parameters
    ----------
    distance_m : array_like
        [m].
    sigma0_m : float
        [m], positive.
    per_m : float, optional
        [1], 0 or more.

    Returns
    -------
    ndarray, the shape of ``distance_m``
        [m].

    Raises
    ------
    ModelError
        For σ₀ not positive or k negative.
    """
    if not (np.isfinite(sigma0_m) and sigma0_m > 0.0):
        raise ModelError(f"timing sigma: {sigma0_m!r} m; allowed (0, inf)")
    if not (np.isfinite(per_m) and per_m >= 0.0):
        raise ModelError(f"timing sigma per metre of range: {per_m!r}; allowed [0, inf)")
    return range_noise_sigma({"sigma_range": sigma0_m, "range_k": per_m}, np.asarray(distance_m, float))


def range_noise(toa: np.ndarray, distance_m, sigma0_m: float, per_m: float, sound_speed: float,
                rng: np.random.Generator) -> np.ndarray:
    """Times of arrival drawn with the timing σ₀ alone (``sigma0_m / sound_speed``) given the range-dependent law's
    rest: an independent normal of ``sqrt((σ₀ + k d)² − σ₀²) / c`` [s] added to each, so that an arrival over the
    distance d has the standard deviation :func:`range_sigma` ``σ₀ + k d`` [m] of sound travel in all.

    Where ``per_m`` is 0 the same array is returned and ``rng`` is not drawn from (the constant σ's simulation bit
    for bit).

    Parameters
    ----------
    toa : ndarray, shape (K, n)
        [s]; NaN where not heard (kept).
    distance_m : ndarray, broadcastable to (K, n)
        Each ping's distance to each receiver [m].
    sigma0_m, per_m : float
        :func:`range_sigma`'s [m], [m/m].
    sound_speed : float
        [m/s].
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (K, n)
        [s].

    Raises
    ------
    ModelError
        As :func:`range_sigma`.
    """
    total = range_sigma(distance_m, sigma0_m, per_m)
    if per_m == 0.0:
        return toa
    toa = np.asarray(toa, float)
    extra = np.sqrt(np.maximum(np.broadcast_to(total, toa.shape) ** 2 - sigma0_m ** 2, 0.0)) / sound_speed
    return toa + extra * rng.standard_normal(toa.shape)


def count_distribution(q: np.ndarray) -> np.ndarray:
    """The exact distribution of the number of receivers that hear a ping (Poisson-binomial; module docstring).

    Parameters
    ----------
    q : ndarray, shape (..., n)
        Each receiver's probability of hearing [0–1], independently.

    Returns
    -------
    ndarray, shape (..., n + 1)
        ``P(K = k)`` for k = 0 … n.
    """
    q = np.asarray(q, float)
    out = np.zeros(q.shape[:-1] + (q.shape[-1] + 1,))
    out[..., 0] = 1.0
    for i in range(q.shape[-1]):
        qi = q[..., i:i + 1]
        out[..., 1:i + 2] = out[..., 1:i + 2] * (1.0 - qi) + out[..., 0:i + 1] * qi
        out[..., 0] *= 1.0 - q[..., i]
    return out


def positioning_yield(q: np.ndarray, needed: int) -> np.ndarray:
    """The probability that a ping is heard by at least ``needed`` receivers (the positioning yield).

    Parameters
    ----------
    q : ndarray, shape (..., M, n)
        Each receiver's probability of hearing a ping at each point [0–1].
    needed : int
        dim + 1 without a depth sensor (3 in 2-D, 4 in 3-D), dim with one.

    Returns
    -------
    ndarray, shape (..., M)
        [0–1].
    """
    return np.clip(count_distribution(q)[..., needed:].sum(axis=-1), 0.0, 1.0)


def position_information(points: np.ndarray, receivers: np.ndarray, sigma_m, weights=1.0,
                         depth_sigma_m: float | None = None) -> np.ndarray:
    """The information of the position with the emission removed (module docstring), per point and layout.

    Parameters
    ----------
    points : ndarray, shape (M, dim)
        The tag's positions [m].
    receivers : ndarray, shape (..., n, dim)
        [m]; leading axes: layouts.
    sigma_m : float or ndarray, broadcastable to (..., M, n)
        Each arrival's standard deviation in metres of travel [m].
    weights : float or ndarray, broadcastable to (..., M, n)
        1/0 (heard or not) or the probabilities heard (the expected information).
    depth_sigma_m : float, optional
        A depth sensor's standard deviation [m] (3-D only; None: no depth sensor).

    Returns
    -------
    ndarray, shape (..., M, dim, dim)
        [1/m²]; zero where nothing is heard.

    Raises
    ------
    ModelError
        A depth sensor with points in 2-D.
    """
    points, receivers = np.asarray(points, float), np.asarray(receivers, float)
    d = points[:, None, :] - receivers[..., None, :, :]
    u = d / np.linalg.norm(d, axis=-1, keepdims=True)
    w = np.asarray(weights, float) / np.asarray(sigma_m, float) ** 2
    shape = np.broadcast_shapes(w.shape, u.shape[:-1])
    w, u = np.broadcast_to(w, shape), np.broadcast_to(u, shape + u.shape[-1:])
    jpp = np.einsum("...k,...ki,...kj->...ij", w, u, u)
    jpo = np.einsum("...k,...ki->...i", w, u)
    joo = w.sum(axis=-1)
    safe = np.where(joo > 0.0, joo, 1.0)
    J = jpp - jpo[..., :, None] * jpo[..., None, :] / safe[..., None, None]
    if depth_sigma_m is not None:
        if points.shape[1] != 3:
            raise ModelError(f"depth sensor: the points are in {points.shape[1]}-D; a depth needs 3-D")
        J[..., 2, 2] += 1.0 / depth_sigma_m ** 2
    return J


def drms(J: np.ndarray, horizontal: bool = True) -> np.ndarray:
    """The DRMS of informations J: ``sqrt((J⁻¹)_xx + (J⁻¹)_yy)`` (``horizontal``) or ``sqrt(tr J⁻¹)`` [m].

    Parameters
    ----------
    J : ndarray, shape (..., dim, dim)
        [1/m²].
    horizontal : bool, optional
        The first two axes only (in 2-D the same as the trace).

    Returns
    -------
    ndarray, shape (...)
        [m]; ``inf`` where J is singular (its condition number above :data:`SINGULAR_CONDITION`).
    """
    J = np.asarray(J, float)
    dim = J.shape[-1]
    with np.errstate(all="ignore"):
        regular = np.isfinite(J).all(axis=(-2, -1)) & (np.linalg.cond(J) < SINGULAR_CONDITION)
        inverse = np.linalg.inv(np.where(regular[..., None, None], J, np.eye(dim)))
    axes = 2 if horizontal else dim
    trace = np.einsum("...ii->...", inverse[..., :axes, :axes])
    return np.where(regular & (trace > 0.0), np.sqrt(np.abs(trace)), np.inf)


def fix_drms(points: np.ndarray, receivers: np.ndarray, sigma_m, heard: np.ndarray | None = None,
             depth_sigma_m: float | None = None, horizontal: bool = True) -> np.ndarray:
    """The DRMS of a single-ping fix from the receivers in ``heard`` (default every receiver), emission unknown.

    Parameters
    ----------
    points : ndarray, shape (M, dim)
        [m].
    receivers : ndarray, shape (..., n, dim)
        [m].
    sigma_m : float or ndarray, broadcastable to (..., M, n)
        [m] (:func:`range_sigma`).
    heard : ndarray of bool, broadcastable to (..., M, n), optional
        The pattern of receivers that heard; None: all of them.
    depth_sigma_m : float, optional
        A depth sensor's [m] (3-D).
    horizontal : bool, optional
        :func:`drms`'s.

    Returns
    -------
    ndarray, shape (..., M)
        [m]; ``inf`` where fewer than the receivers a fix needs heard (dim + 1, or dim with a depth sensor) or J is
        singular.
    """
    points = np.asarray(points, float)
    n = np.asarray(receivers).shape[-2]
    heard = np.ones(n, bool) if heard is None else np.asarray(heard, bool)
    J = position_information(points, receivers, sigma_m, heard, depth_sigma_m)
    needed = points.shape[1] + (depth_sigma_m is None)
    count = np.broadcast_to(heard, J.shape[:-2] + (n,)).sum(axis=-1)
    return np.where(count >= needed, drms(J, horizontal), np.inf)


def expected_information_drms(points: np.ndarray, receivers: np.ndarray, sigma_m, q: np.ndarray,
                              depth_sigma_m: float | None = None, horizontal: bool = True) -> np.ndarray:
    """The DRMS of the information averaged over the detection patterns (each receiver's weighted by its
    probability q; module docstring): the accuracy map's convention, optimistic for the fixes made.

    Parameters
    ----------
    points, receivers, sigma_m, depth_sigma_m, horizontal
        As :func:`fix_drms`.
    q : ndarray, broadcastable to (..., M, n)
        [0–1].

    Returns
    -------
    ndarray, shape (..., M)
        [m]; ``inf`` where the averaged information is singular.
    """
    return drms(position_information(points, receivers, sigma_m, q, depth_sigma_m), horizontal)


def fixed_ping_drms(points: np.ndarray, receivers: np.ndarray, sigma_m, q: np.ndarray,
                    rng: np.random.Generator | None = None, samples: int = 400,
                    depth_sigma_m: float | None = None, horizontal: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The RMS over the fixed pings of each detection pattern's DRMS, ``sqrt(E[DRMS(H)² | H fixable])``, and the
    probability that a ping is fixable (module docstring).

    Exact (every pattern of the uncertain receivers, those with ``CERTAIN < q < 1 − CERTAIN``, weighted by its
    probability) where a point has at most :data:`ENUMERATE_MAX` of them; elsewhere a Monte Carlo of ``samples``
    patterns drawn with ``rng`` (its relative error about ``1 / √(2 · samples · P(fixable))``, more where rare
    near-singular patterns dominate).

    Parameters
    ----------
    points : ndarray, shape (M, dim)
        [m].
    receivers : ndarray, shape (n, dim)
        [m] (one layout).
    sigma_m : float or ndarray, broadcastable to (M, n)
        [m].
    q : ndarray, broadcastable to (M, n)
        [0–1].
    rng : numpy.random.Generator, optional
        For the Monte Carlo (default seeded 0: the same numbers every call).
    samples : int, optional
        Monte Carlo patterns per point.
    depth_sigma_m, horizontal
        As :func:`fix_drms`.

    Returns
    -------
    rms : ndarray, shape (M,)
        [m]; ``inf`` where no pattern is fixable.
    fixable : ndarray, shape (M,)
        The probability that a ping gives a fix (at least the receivers needed and a regular J) [0–1]; where
        enumerated at most the positioning yield, elsewhere its Monte Carlo estimate.
    """
    points, receivers = np.asarray(points, float), np.asarray(receivers, float)
    m, n = len(points), len(receivers)
    q = np.broadcast_to(np.asarray(q, float), (m, n))
    sigma = np.broadcast_to(np.asarray(sigma_m, float), (m, n))
    rng = np.random.default_rng(0) if rng is None else rng
    rms, fixable = np.full(m, np.inf), np.zeros(m)
    uncertain = (q > CERTAIN) & (q < 1.0 - CERTAIN)
    exact = uncertain.sum(axis=1) <= ENUMERATE_MAX
    for j in range(m):
        p = points[j:j + 1]
        if exact[j]:
            free = np.flatnonzero(uncertain[j])
            bits = np.array(list(itertools.product((False, True), repeat=len(free))), bool).reshape(2 ** len(free),
                                                                                             len(free))
            patterns = np.broadcast_to(q[j] >= 1.0 - CERTAIN, (len(bits), n)).copy()
            patterns[:, free] = bits
            qf = q[j, free]
            weight = np.prod(np.where(bits, qf, 1.0 - qf), axis=1)
        else:
            patterns = rng.random((samples, n)) < q[j]
            weight = np.full(samples, 1.0 / samples)
        value = fix_drms(p, receivers, sigma[j], patterns[:, None, :], depth_sigma_m, horizontal)[:, 0]
        ok = np.isfinite(value)
        fixable[j] = weight[ok].sum()
        if fixable[j] > 0.0:
            rms[j] = np.sqrt((weight[ok] * value[ok] ** 2).sum() / fixable[j])
    return rms, fixable


def ring_fix_drms(n: int, sigma_m: float) -> float:
    """The DRMS of a fix at the centre of N ≥ 3 receivers equally spaced on a circle (2-D, one σ, every receiver
    heard, emission unknown): ``2σ / √N`` [m] (``2 c σ_toa / √N`` for a timing σ_toa [s]).

    Derivation: with the receivers at bearings ``θ_k = 2πk / N`` the directions from them to the centre are
    ``u_k = −(cos θ_k, sin θ_k)``. For N ≥ 3, ``Σ_k cos 2θ_k = Σ_k sin 2θ_k = 0``, so
    ``Σ_k u_k u_kᵀ = (N / 2) I``; and ``Σ_k u_k = 0`` (N ≥ 2). The cross term of the position and the emission,
    ``Σ_k u_k / σ²``, vanishes, so the Schur complement removes nothing: ``J = N / (2σ²) I``,
    ``J⁻¹ = (2σ² / N) I`` and ``DRMS = sqrt(tr J⁻¹) = sqrt(4σ² / N) = 2σ / √N``, the range-only optimum of Bishop
    et al. (Automatica 46(3):479–492, 2010). Off the centre ``Σ_k u_k u_kᵀ`` keeps its trace ``N / σ²`` but is no
    longer isotropic (a larger trace of its inverse) and the Schur complement subtracts a non-zero term: the DRMS
    grows.
    """
    return 2.0 * sigma_m / np.sqrt(n)


__all__ = ["CERTAIN", "ENUMERATE_MAX", "SINGULAR_CONDITION", "count_distribution", "distances", "drms",
           "expected_information_drms", "fix_drms", "fixed_ping_drms", "position_information", "positioning_yield",
           "range_noise", "range_sigma", "ring_fix_drms"]

"""A layout's Fisher information at a point: one cycle of ranges (one per transducer) plus the depth, each range
weighted by the probability that it is heard.

For a vehicle at ``p`` and transducers at ``b_i`` (lever arms ``a_i`` in NED), the information about the position
of one cycle is

``J(p) = Σ_i q_i g_i g_iᵀ / σ_i² + e_z e_zᵀ / σ_d²``,

``g_i = ∂‖p − b_i‖/∂p`` from the ranges' measurement model (casadi's derivative,
:class:`~sblsim.models.receiver.measurement.RangeDepthModel`), ``σ_i²`` the effective variance of transducer i's
range (its noise, the broadcast position's error and the attitude error through its lever arm:
:func:`~sblsim.models.bound.effective_range_variance`) and ``q_i`` the probability that its packet is heard
(1 with the paper's fixed channel; the site's detection by signal-to-noise otherwise): the expected information of
a range received with probability q_i (the information reduction factor of Niu, Willett and Bar-Shalom, IEEE
Trans. Signal Processing 49(7), 2001). A transducer that is never heard (a shadow zone, beyond detection)
contributes nothing. With the range law (``acoustics.range_k`` k > 0) the range's own noise is
``σ₀ + k ‖p − b_i‖`` per point (:func:`law_range_variance`, given to the function as a variance per point and
transducer). With every q_i = 1 it is the map's information of one round of fresh ranges
(:func:`sblsim.models.fisher.fix_information`), the same numbers.

From J: the horizontal DRMS ``sqrt((J⁻¹)_NN + (J⁻¹)_EE)``, its 3-D form ``sqrt(tr J⁻¹)`` and ``log det J`` [m],
[m], [log 1/m⁶] (Kay, Fundamentals of Statistical Signal Processing: Estimation Theory, Prentice Hall 1993,
Section 3.7).

The function is written once (:func:`layout_information`); the accuracy map evaluates it with casadi, the design's
search runs the same function compiled, for a layout padded to a few slot counts (:data:`SLOTS`: an unused slot
is a transducer :data:`FAR` away that is never heard, which adds an exact zero).
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from sblsim.models.acoustics.range_law import range_noise_sigma
from sblsim.models.bound import MODEL, effective_range_variance, state_at
from sblsim.models.fisher import horizontal_drms, per_point, position_information

#: The transducer counts of the compiled functions; a layout is padded to the smallest that holds it.
SLOTS = (4, 8, 16)
#: Where an unused slot's transducer stands [m] (North and East; never heard, so its range adds nothing).
FAR = 1e7
#: The per-point numbers of :func:`layout_information` after J, in its output order.
OUTPUTS = ("drms", "drms_3d", "log_det")


@lru_cache(maxsize=None)
def layout_information(n: int, model=MODEL, emission: bool = False) -> ca.Function:
    """casadi Function of a layout's Fisher information at a point (module docstring).

    With ``emission``, the ranges are the times of arrival of one ping of the vehicle at the transducers (an
    inverted LBL), whose emission epoch is unknown: each range carries the same unknown offset ``o`` (the
    emission epoch's, times the sound speed), a nuisance parameter removed by the Schur complement of the
    information of ``(p, o)``, ``J = J_pp − j_po j_poᵀ / j_oo`` with ``j_po = Σ_i q_i g_i / σ_i²`` and
    ``j_oo = Σ_i q_i / σ_i²`` (Kay 1993, Section 3.7, the nuisance parameters' bound).

    ``(p[3], beacons[3 n], arms[3 n], heard[n], noise_variance[n], attitude_variance, depth_variance) ->
    (J (3, 3), drms, drms_3d, log_det)``.

    Parameters
    ----------
    n : int
        The number of transducers (slots).
    model : RangeDepthModel, optional
        The ranges' measurement model (default the receivers').

    Notes
    -----
    Inputs: the vehicle's position ``p`` (NED [m]), the transducers' positions and their lever arms in NED [m]
    (a fixed array's lever arms are its positions), per transducer the probability that it is heard [0–1] and
    its range's own variance ``σ_r² + σ_pos²`` [m²] (the broadcast position's isotropic error folded in, as
    :func:`~sblsim.models.bound.effective_range_variance` takes it), the attitude variance per axis [rad²] and
    the depth sensor's variance [m²] (``inf``: no depth sensor). Outputs: J [1/m²], the horizontal DRMS and its
    3-D form [m] (infinite or NaN where J is singular) and ``log det J``.

    References
    ----------
    Kay 1993, Section 3.7; Niu, Willett, Bar-Shalom, IEEE Trans. Signal Processing 49(7), 2001.
    """
    p, b, a = ca.SX.sym("p", 3), ca.SX.sym("beacons", 3 * n), ca.SX.sym("arms", 3 * n)
    heard, noise = ca.SX.sym("heard", n), ca.SX.sym("noise_variance", n)
    attitude, d_var = ca.SX.sym("attitude_variance"), ca.SX.sym("depth_variance")
    beacons = [b[3 * i:3 * i + 3] for i in range(n)]
    variances = ca.vertcat(*[effective_range_variance(p, beacon, a[3 * i:3 * i + 3], noise[i], attitude, model)
                             for i, beacon in enumerate(beacons)], d_var)
    J = position_information(model, p, beacons, variances, ca.vertcat(heard, 1.0))
    if emission:  # the ping's unknown emission: the offset common to every range removed
        x, index = state_at(model.motion, p), list(model.motion.position_index)
        weights = [heard[i] / variances[i] for i in range(n)]
        j_po = sum(w * model.range_row(x, beacon)[1][index].T for w, beacon in zip(weights, beacons))
        j_oo = sum(weights)
        heard_any = j_oo > 0
        J = J - ca.if_else(heard_any, ca.mtimes(j_po, j_po.T) / ca.if_else(heard_any, j_oo, 1.0), ca.SX.zeros(3, 3))
    inverse = ca.inv(J)
    name = f"sblsim_layout_information_{n}" + ("_toa" if emission else "")
    return ca.Function(name, [p, b, a, heard, noise, attitude, d_var],
                       [J, horizontal_drms(J), ca.sqrt(ca.trace(inverse)), ca.log(ca.det(J))],
                       ["p", "beacons", "arms", "heard", "noise_variance", "attitude_variance", "depth_variance"],
                       ["J", *OUTPUTS])


def slots_for(n: int) -> int:
    """The smallest of :data:`SLOTS` that holds ``n`` transducers.

    Raises
    ------
    ValueError
        If ``n`` is above the largest.
    """
    for slots in SLOTS:
        if n <= slots:
            return slots
    raise ValueError(f"{n} transducers: at most {SLOTS[-1]}")


def padded(beacons: np.ndarray, arms: np.ndarray, heard: np.ndarray, noise_variance: np.ndarray,
           slots: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A layout padded to ``slots`` transducers: the unused ones :data:`FAR` away, never heard, of unit variance.

    Parameters
    ----------
    beacons, arms : ndarray, shape (..., n, 3)
        Positions and lever arms, NED [m].
    heard, noise_variance : ndarray, shape (..., M, n)
        Per point and transducer [0–1], [m²].
    slots : int

    Returns
    -------
    beacons, arms : ndarray, shape (..., slots, 3)
    heard, noise_variance : ndarray, shape (..., M, slots)
    """
    beacons, arms = np.asarray(beacons, dtype=float), np.asarray(arms, dtype=float)
    heard, noise_variance = np.asarray(heard, dtype=float), np.asarray(noise_variance, dtype=float)
    extra = slots - beacons.shape[-2]
    far = np.zeros(beacons.shape[:-2] + (extra, 3))
    far[..., 0], far[..., 1] = FAR, FAR
    return (np.concatenate([beacons, far], axis=-2), np.concatenate([arms, np.zeros_like(far)], axis=-2),
            _widened(heard, slots, 0.0), _widened(noise_variance, slots, 1.0))


def _widened(values: np.ndarray, slots: int, fill: float) -> np.ndarray:
    """``values`` (..., n) in the first n of ``slots`` columns, the rest ``fill``: numpy's pad, the same arrays,
    without its overhead a call (the design's search pads every candidate layout; a few per cent of a layout's
    evaluation in ``benchmarks/bench_design.py``)."""
    out = np.full(values.shape[:-1] + (slots,), fill)
    out[..., :values.shape[-1]] = values
    return out


def layout_values(points: np.ndarray, beacons: np.ndarray, arms: np.ndarray, heard, noise_variance,
                  attitude_variance, depth_variance, model=MODEL, emission: bool = False) -> dict[str, np.ndarray]:
    """:func:`layout_information` at each point (casadi's evaluation, mapped over the points).

    Parameters
    ----------
    points : ndarray, shape (M, 3)
        Vehicle positions, NED [m].
    beacons, arms : ndarray, shape (n, 3)
        Transducer positions and lever arms, NED [m].
    heard : float or ndarray, shape (n,) or (M, n)
        The probability that each transducer is heard [0–1].
    noise_variance : float or ndarray, shape (M,) or (M, n)
        Each range's own variance with the position error folded in [m²].
    attitude_variance, depth_variance : float or ndarray, shape (M,)
        [rad²], [m²].
    model : RangeDepthModel, optional
    emission : bool, optional
        The ranges are one ping's times of arrival, its emission epoch unknown (an inverted LBL,
        :func:`layout_information`).

    Returns
    -------
    dict
        ``J`` (M, 3, 3) [1/m²] and each of :data:`OUTPUTS`, (M,).
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    beacons, arms = np.asarray(beacons, dtype=float), np.asarray(arms, dtype=float)
    m, n = points.shape[0], beacons.shape[0]
    heard = np.broadcast_to(np.asarray(heard, dtype=float), (m, n))
    noise = np.asarray(noise_variance, dtype=float)
    noise = np.broadcast_to(noise[:, None] if noise.ndim == 1 else noise, (m, n))
    f = layout_information(n, model, emission).map(m)
    out = f(points.T, beacons.reshape(-1, 1), arms.reshape(-1, 1), heard.T, noise.T, per_point(attitude_variance),
            per_point(depth_variance))
    values = {"J": np.asarray(out[0]).reshape(3, m, 3).transpose(1, 0, 2)}
    values.update({name: np.asarray(v).ravel() for name, v in zip(OUTPUTS, out[1:])})
    return values


def law_range_variance(points: np.ndarray, transducers: np.ndarray, sigma_range: float,
                       range_k: float) -> np.ndarray:
    """The range law's variance of each range at each point, ``(σ₀ + k ‖p − b_i‖)²`` [m²]
    (:func:`~sblsim.models.acoustics.range_law.range_noise_sigma`: the noise the channel draws, at the true range).

    Parameters
    ----------
    points : ndarray, shape (M, 3)
        Vehicle positions, NED [m].
    transducers : ndarray, shape (..., n, 3)
        Transducer positions, NED [m] (leading axes: several layouts).
    sigma_range, range_k : float
        σ₀ [m] and k [m/m].

    Returns
    -------
    ndarray, shape (..., M, n)
        [m²].

    References
    ----------
    Quazi, IEEE Trans. ASSP 29(3):527–533, 1981 (the law's source, :mod:`sblsim.models.acoustics.range_law`).
    """
    points, transducers = np.asarray(points, dtype=float), np.asarray(transducers, dtype=float)
    distance = np.linalg.norm(points[:, None, :] - transducers[..., None, :, :], axis=-1)
    return range_noise_sigma({"sigma_range": float(sigma_range), "range_k": float(range_k)}, distance) ** 2


def layout_horizontal_std(points: np.ndarray, beacons: np.ndarray, arms: np.ndarray, heard, noise_variance,
                          attitude_variance, depth_variance, model=MODEL) -> np.ndarray:
    """Horizontal DRMS [m] of one cycle of heard ranges plus the depth at each point, (M,): :func:`layout_values`'
    ``drms``, infinite where J is singular (a point no transducer is heard at, with a depth sensor alone)."""
    drms = layout_values(points, beacons, arms, heard, noise_variance, attitude_variance, depth_variance,
                         model)["drms"]
    return np.where(np.isfinite(drms), drms, np.inf)

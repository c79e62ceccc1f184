"""The offsets reflected arrivals give a fix with detection by signal-to-noise: a USBL's one-packet fix
(:func:`echo_spread`) and a ranging system's (SBL, LBL: :func:`range_echo_spread`), each the mean square
over the first detected eigenrays of the legs of the exchange.
"""

from __future__ import annotations

import numpy as np

from sblsim.fmus.compiled_functions import compiled_family_levels
from sblsim.models.acoustics.channel.site_levels import site_levels
from sblsim.models.acoustics.detection import first_shares
from sblsim.models.acoustics.ray_inversion import ray_bending, slant_range
from sblsim.models.acoustics.rays import profile_arrays
from sblsim.models.acoustics.sound_speed import PROFILE
from sblsim.orchestrator.cosim.plan import RunPlan

#: The most horizontal distances per depth at which :func:`echo_spread` places the reflected arrivals' fixes (the
#: other points interpolate in the horizontal distance: the site is range-independent).
ECHO_DISTANCES = 24


def echo_spread(plan: RunPlan, points: np.ndarray, bound: dict, sigma, echo: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """USBL with detection by signal-to-noise: the mean square of the one-packet fix's horizontal and 3-D offsets
    that reflected arrivals give at each point [m²], over the arrivals a cycle may take.

    Each leg of the exchange the range is timed over (the interrogation and the reply) takes its first detected
    eigenray, family j with the probability :func:`~sblsim.models.acoustics.detection.first_shares` gives (given
    that the leg is heard; the legs independent); the packet then carries the mean of the two legs' travel
    times and the reply's grazing angle at the transceiver as its elevation. The receiver processes it as a
    direct arrival: the range is the channel's assumed speed times that travel time, which a receiver with a
    measured profile (``sound_speed_model = profile``) turns into the slant range of the direct eigenray of that
    time (:func:`~sblsim.models.acoustics.ray_inversion.slant_range`) and whose elevation it turns by the direct
    eigenray's bending (:func:`~sblsim.models.acoustics.ray_inversion.ray_bending`), each where the direct eigenray
    exists (:func:`~sblsim.models.receiver.profile.profile_range`). That places the diver at a point ``seen`` along its
    azimuth, and the fix of that packet with the diver's own depth reading is off by
    :meth:`~sblsim.models.systems.usbl.USBL.seen_offsets`. The direct pair's offset is 0 (the map's geometry);
    the mean square is over the other pairs with their probabilities. Computed at up to :data:`ECHO_DISTANCES`
    horizontal distances per depth among the points where ``echo`` > 0, interpolated in between; 0 elsewhere.

    Parameters
    ----------
    plan : RunPlan
    points : ndarray, shape (M, 3)
        NED [m].
    bound : dict
        The error levels of the fix's R (:attr:`RunPlan.bound`, as :func:`point_accuracy` grew them).
    sigma : float or ndarray, shape (M,)
        The range noise σ_r of the fix's R [m] (one per point where the SNR grew it).
    echo : ndarray, shape (M,)
        The probability that a point's fix takes a reflected arrival (:func:`packet_probabilities`).

    Returns
    -------
    horizontal, total : ndarray, each (M,)
        [m²].
    """
    m = points.shape[0]
    spread = np.zeros((2, m))
    where = np.flatnonzero(echo > 0.0)
    if where.size == 0:
        return spread[0], spread[1]
    b = np.asarray(plan.lever_arms[0], dtype=float)
    horizontal = np.hypot(points[:, 0] - b[0], points[:, 1] - b[1])
    for depth in np.unique(points[where, 2]):
        at = where[points[where, 2] == depth]
        distances = _sampled(horizontal[at])
        geometry = np.column_stack([b[0] + distances, np.full(distances.size, b[1]), np.full(distances.size, depth)])
        # the error levels that are one per point (grown by the SNR): a point's own at each distance
        own = at[[np.flatnonzero(horizontal[at] == d)[0] for d in distances]]
        levels = _taken({**bound, "sigma_range": sigma}, own, m)
        squares = _reflected_offsets(plan, geometry, levels)
        for row, values in enumerate(squares):
            spread[row, at] = np.interp(horizontal[at], distances, values)
    return spread[0], spread[1]


def range_echo_spread(plan: RunPlan, points: np.ndarray, bound: dict, heard: np.ndarray, echo: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Ranging systems (SBL, LBL) with detection by signal-to-noise: the mean square of a cycle's fix's horizontal
    and 3-D offsets that reflected arrivals give at each point [m²].

    Each leg of a range (OWTT's one, TWTT's two) takes its first detected eigenray with the probability
    :func:`~sblsim.models.acoustics.detection.first_shares` gives (given that it is heard; legs and transducers
    independent); the receiver turns the legs' mean travel time into a range as for a direct arrival
    (:func:`_received_as_direct`), so that transducer k's range is off by δ_k from the direct ray's, with mean
    μ_k and variance v_k over the pairs. The fix of the ranges and the depth moves by ``G δ``, ``G = J⁻¹ Hᵀ W``
    (H the ranges' straight-line unit vectors from the transducers, W each range's probability of being heard over
    its variance, J = Hᵀ W H plus the depth's information: the map's expected information, Niu et al. 2001), whose
    second moment is ``G (μ μᵀ + diag(v)) Gᵀ``: a bias common to every range moves a short baseline's fix little,
    a difference between them moves it by the baseline's leverage. The legs' offsets are computed at up to
    :data:`ECHO_DISTANCES` horizontal distances per pair of depths among the pairs where ``echo`` > 0, interpolated
    in between (the site is range-independent).

    Parameters
    ----------
    plan : RunPlan
    points : ndarray, shape (M, 3)
        NED [m].
    bound : dict
        The error levels (``noise_variance`` [m²], per point and transducer where the SNR grew it;
        ``depth_variance`` [m²]).
    heard, echo : ndarray, each (M, n)
        Each transducer's probability of being heard and of its range being a reflection's
        (:func:`packet_probabilities`).

    Returns
    -------
    horizontal, total : ndarray, each (M,)
        [m²].
    """
    m = points.shape[0]
    spread = np.zeros((2, m))
    rows = np.flatnonzero((echo > 0.0).any(axis=1))
    if rows.size == 0:
        return spread[0], spread[1]
    arms = np.asarray(plan.lever_arms, dtype=float)
    n = arms.shape[0]
    p = points[rows]
    mean, variance = np.zeros((rows.size, n)), np.zeros((rows.size, n))
    horizontal = np.hypot(p[:, None, 0] - arms[None, :, 0], p[:, None, 1] - arms[None, :, 1])  # (R, n)
    legs = 2 if plan["acoustics"]["ranging"] == "twtt" else 1
    for zt in np.unique(arms[:, 2]):
        for depth in np.unique(p[:, 2]):
            pair = (p[:, None, 2] == depth) & (arms[None, :, 2] == zt) & (echo[rows] > 0.0)
            if not pair.any():
                continue
            distances = _sampled(horizontal[pair])
            moments = _range_offsets(plan, zt, depth, distances, legs)
            for out, values in zip((mean, variance), moments):  # each smooth in the distance (not s = v + μ²)
                out[pair] = np.interp(horizontal[pair], distances, values)
    # the fix's gain: straight-line unit vectors, each range weighted by its probability over its variance
    u = p[:, None, :] - arms[None, :, :]
    u = u / np.linalg.norm(u, axis=2, keepdims=True)  # (R, n, 3)
    noise = np.broadcast_to(np.asarray(bound["noise_variance"], float), (m, n))[rows] \
        if np.ndim(bound["noise_variance"]) == 2 else np.full((rows.size, n), float(bound["noise_variance"]))
    w = heard[rows] / noise
    # sums over the transducers in their order: one never heard (weight 0) adds exact zeros, the map is then the
    # map without it bit for bit
    information = np.zeros((rows.size, 3, 3))
    for k in range(n):
        information += w[:, k, None, None] * u[:, k, :, None] * u[:, k, None, :]
    information[:, 2, 2] += 1.0 / float(bound["depth_variance"])
    # where the ranges heard do not fix the position (J singular: the map is infinite there) no offset is added
    eigen = np.linalg.eigvalsh(information)
    fixed = eigen[:, 0] > 1e-12 * eigen[:, -1]
    information[~fixed] = np.eye(3)
    w = np.where(fixed[:, None], w, 0.0)
    bias, offset = np.zeros((rows.size, 3)), np.zeros((rows.size, 3, 3))
    for k in range(n):
        g = np.linalg.solve(information, (w[:, k, None] * u[:, k, :])[..., None])[..., 0]  # (R, 3): k's gain
        bias += g * mean[:, k, None]
        offset += variance[:, k, None, None] * g[:, :, None] * g[:, None, :]
    offset += bias[:, :, None] * bias[:, None, :]
    spread[0, rows] = offset[:, 0, 0] + offset[:, 1, 1]
    spread[1, rows] = np.trace(offset, axis1=1, axis2=2)
    return spread[0], spread[1]


def _range_offsets(plan: RunPlan, zt: float, depth: float, distances: np.ndarray, legs: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The mean and the variance [m, m²] of a range's offset from the direct ray's (:func:`range_echo_spread`)
    between a transducer at depth ``zt`` and a diver at ``depth`` at the horizontal ``distances`` (K,), over the
    first detected eigenrays of its ``legs`` (1: OWTT, 2: TWTT), each (K,)."""
    k = distances.size
    sources = np.column_stack([np.zeros(k), np.zeros(k), np.full(k, zt)])
    divers = np.column_stack([distances, np.zeros(k), np.full(k, depth)])
    levels, weight = _first_arrivals(plan, sources, divers)
    tau = np.where(levels["valid"] > 0.5, levels["tau"], np.nan)
    zr = np.full(k, float(depth))
    chord = np.hypot(distances, depth - zt)
    direct = np.isfinite(tau[:, 0])
    reference = chord.copy()
    if direct.any():
        reference[direct] = _received_as_direct(plan, zt, zr[direct], tau[direct, 0], np.zeros(direct.sum()))[0]
    rays = range(tau.shape[1])  # the eigenrays of each leg (detection.family_levels: direct, surface, bottom, other)
    combos = [(j,) for j in rays] if legs == 1 else [(j, i) for j in rays for i in rays]
    offsets = []  # (weights, offsets) of each pair whose range is not the direct ray's
    for combo in combos:
        w = np.prod([weight[:, j] for j in combo], axis=0)
        sel = np.flatnonzero((w > 0.0) & np.isfinite(tau[:, list(combo)]).all(axis=1)) if any(combo) else []
        if len(sel) == 0:
            continue
        one_way = np.mean(tau[sel][:, list(combo)], axis=1)
        seen = _received_as_direct(plan, zt, zr[sel], one_way, np.zeros(len(sel)))[0]
        offsets.append((sel, w[sel], seen - reference[sel]))
    mean, variance = np.zeros(k), np.zeros(k)
    for sel, w, delta in offsets:
        mean[sel] += w * delta
    direct = 1.0 - sum(np.bincount(sel, w, k) for sel, w, _ in offsets) if offsets else np.ones(k)
    variance += direct * mean**2  # the direct pairs' offset is 0
    for sel, w, delta in offsets:
        variance[sel] += w * (delta - mean[sel]) ** 2
    return mean, variance


def _reflected_offsets(plan: RunPlan, geometry: np.ndarray, bound: dict) -> tuple[np.ndarray, np.ndarray]:
    """The mean squares of :func:`echo_spread` at points (K, 3) North of the transceiver [m²], each (K,), with the
    error levels ``bound`` (and ``sigma_range``) of those points."""
    b = np.asarray(plan.lever_arms[0], dtype=float)
    k = geometry.shape[0]
    levels, weight = _first_arrivals(plan, np.repeat(b[None, :], k, axis=0), geometry)
    out = np.zeros((2, k))
    rays = range(levels["tau"].shape[1])  # direct, surface, bottom, the direct family's other eigenray
    for up in rays:
        for reply in rays:
            w = weight[:, up] * weight[:, reply]
            sel = np.flatnonzero(w > 0.0) if (up, reply) != (0, 0) else np.zeros(0, dtype=int)
            if sel.size == 0:
                continue
            one_way = 0.5 * (levels["tau"][sel, up] + levels["tau"][sel, reply])
            rho, chord = _received_as_direct(plan, b[2], geometry[sel, 2], one_way, levels["launch"][sel, reply])
            seen = b + np.column_stack([rho * np.cos(chord), np.zeros(sel.size), rho * np.sin(chord)])
            taken = _taken(bound, sel, k)
            offset = plan.system.seen_offsets(geometry[sel], seen, plan["platform"], taken, taken["sigma_range"])
            out[0, sel] += w[sel] * np.sum(offset[:, :2] ** 2, axis=1)
            out[1, sel] += w[sel] * np.sum(offset ** 2, axis=1)
    return out[0], out[1]


def _sampled(distances: np.ndarray) -> np.ndarray:
    """The distinct ``distances``, or at most :data:`ECHO_DISTANCES` of them evenly spread over their span (each
    the nearest given distance at or above its place), increasing [m]."""
    distinct = np.unique(distances)
    if distinct.size <= ECHO_DISTANCES:
        return distinct
    wanted = np.linspace(distinct[0], distinct[-1], ECHO_DISTANCES)
    return distinct[np.unique(np.clip(np.searchsorted(distinct, wanted), 0, distinct.size - 1))]


def _first_arrivals(plan: RunPlan, sources: np.ndarray, receivers: np.ndarray) -> tuple[dict, np.ndarray]:
    """The site's eigenrays between pairs of points (:func:`~sblsim.models.acoustics.core.site_levels`) and each
    family's probability of being a heard leg's first detected arrival, (K, 4)
    (:func:`~sblsim.models.acoustics.detection.first_shares`, given that the leg is heard; 0 where none is)."""
    levels = site_levels(plan.component_parameters("acoustics"), sources, receivers, compiled_family_levels())
    shares = first_shares(levels["tau"], levels["pd"])
    total = shares.sum(axis=1, keepdims=True)
    return levels, shares / np.where(total > 0.0, total, 1.0)


def _taken(bound: dict, index: np.ndarray, size: int) -> dict:
    """The error levels ``bound`` at the points ``index`` of ``size``: a level that is one per point (an array of
    that size) taken there, the others as they are."""
    return {key: (np.asarray(v)[index] if np.ndim(v) == 1 and np.size(v) == size else v) for key, v in bound.items()}


def _received_as_direct(plan: RunPlan, zt: float, depth: np.ndarray, one_way: np.ndarray, elevation: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The slant range [m] and elevation [rad] a receiver takes from a packet of one-way travel time ``one_way``
    [s] arriving at the elevation ``elevation``, as if direct (:func:`echo_spread`), each (K,)."""
    rng = plan["acoustics"]["sound_speed_assumed"] * one_way
    receiver = plan.component_parameters("receiver")
    if receiver.get("sound_speed_model") != "profile":
        return rng, elevation
    nodes, speeds = profile_arrays(PROFILE.rows(receiver, "sound_speed_rows"))
    zs, zr = np.full((1, depth.size), float(zt)), depth.reshape(1, -1)
    rho, found = slant_range(zs, zr, (rng / receiver["sound_speed_assumed"]).reshape(1, -1), rng.reshape(1, -1),
                             nodes, speeds)
    found = np.asarray(found).ravel() > 0.5
    rho = np.where(found, np.asarray(rho).ravel(), rng)
    bending, bent = ray_bending(zs, zr, rho.reshape(1, -1), nodes, speeds)
    turned = found & (np.asarray(bent).ravel() > 0.5)
    return rho, np.where(turned, elevation + np.asarray(bending).ravel(), elevation)

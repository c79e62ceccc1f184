"""``sblsim map``: where the system meets an accuracy prescription.

For a configuration, the horizontal standard deviation (DRMS) of a position
fix from one round of fresh ranges (one per beacon) plus the depth, from
their Fisher information ``Σ_k H_kᵀ H_k / r_k`` over the rows of the
measurement model (:func:`sblsim.models.bound.fisher_information`, H from the
model's casadi Jacobian; the model is the receivers' ranges-plus-depth
:class:`~sblsim.models.receiver.measurement.RangeDepthModel`, given to
:func:`sblsim.models.bound.horizontal_std` as an object), on a
grid around the platform at the diver's depth: the platform level at its
mean heading, its reference at the origin, the beacons at their lever arms,
with the configured range noise, GPS, IMU and depth-sensor errors
(:func:`sblsim.orchestrator.cosim.plan.bound_parameters`). It is the accuracy of one
round of ranges without a motion model (a filter does better by averaging;
the PCRB of a run says how much), and it is the design question of the
paper: which baseline and sensors keep the diver within a required accuracy
over the working area.

The systems (``platform.system``): LBL maps the same way, the beacons the
seafloor transponders (their positions, :func:`~sblsim.models.platform.geometry.lever_arms`),
with the survey error in place of the GPS and no attitude term
(:func:`~sblsim.orchestrator.cosim.plan.bound_parameters`). USBL maps one packet
of slant range, azimuth and elevation from the transceiver plus the depth
(:func:`sblsim.models.systems.usbl.horizontal_std`), with the receivers' R:
``σ_r²`` for the range, ``σ_a² = (σ_θ / max(cos φ, 0.1))² + σ_att²`` for each
angle (φ the line of sight's angle off the vertical), plus the transceiver
position's error ``σ_b² = σ_GPS² + (σ_att h)²`` per axis along the range and
across both angles; computed from the packet's polar-fix covariance
``J diag(σ_r², σ_a², σ_a²) Jᵀ + σ_b² I``, finite everywhere (straight below the
transceiver too) and never below ``√2 σ_b``. What no receiver's R holds is not
in a map either (the USBL array's misalignment, the TWTT turnaround jitter). ``--compare
platform.system=sbl,lbl,usbl`` maps each system from the defaults of
``sblsim compare --systems`` (each system object's
:attr:`~sblsim.models.systems.System.compare_defaults`), the user's ``--set`` over them. Each
system's map is its object's :meth:`~sblsim.models.systems.System.horizontal_std`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import casadi as ca
import numpy as np
import pandas as pd

from sblsim.fmus.native import compiled_family_levels
from sblsim.models.acoustics.channel.site_levels import site_levels
from sblsim.models.acoustics.detection import direct_first, first_shares, packet_probability
from sblsim.models.acoustics.rays import profile_arrays, ray_bending, slant_range
from sblsim.models.acoustics.sonar import accuracy_scale
from sblsim.models.acoustics.sound_speed import PROFILE
from sblsim.models.bound import MODEL
from sblsim.models.declarations import ModelError
from sblsim.models.design.criteria import ECHO_LIMIT
from sblsim.models.design.information import law_range_variance
from sblsim.models.target.core import file_waypoints
from sblsim.orchestrator.cosim.config import check_site_keys, scenario_system
from sblsim.orchestrator.cosim.plan import Config, RunPlan, as_plan, load_plan, thaw
from sblsim.orchestrator.cosim.systems import check_diver, compared
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.io.progress import Progress, ProgressSpec

MAX_POINTS = 1_000_000
#: The largest half-width of a map's grid [m].
MAX_EXTENT = 1e5
#: With detection by signal-to-noise an accuracy map is blank (NaN) where the probability of a fix is below this.
MIN_AVAILABILITY = 0.5
#: A point whose fixes take a reflected arrival at least this often is echo-only (``map.csv``'s ``echo_only``).
ECHO_ONLY = 0.99
#: The most horizontal distances per depth at which :func:`echo_spread` places the reflected arrivals' fixes (the
#: other points interpolate in the horizontal distance: the site is range-independent).
ECHO_DISTANCES = 24


def parse_levels(text: str, option: str = "--levels") -> list[float]:
    """``0.5,1,2`` -> increasing positive accuracy levels [m].

    Raises
    ------
    ModelError
        Naming ``option`` and what is allowed.
    """
    try:
        levels = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ModelError(f"{option}: expected comma-separated accuracies in metres, e.g. 0.5,1,2; got {text!r}") \
            from None
    if not levels or not all(np.isfinite(v) and v > 0 for v in levels):
        raise ModelError(f"{option}: expected positive accuracies in metres, e.g. 0.5,1,2; got {text!r}")
    return sorted(set(levels))


def grid(extent: float, step: float, options: tuple[str, str] = ("--extent", "--step")
         ) -> tuple[np.ndarray, np.ndarray]:
    """East and North coordinates of the grid, ``−extent … extent`` every ``step`` [m].

    Raises
    ------
    ModelError
        If the extent (at most :data:`MAX_EXTENT`) or step is out of range or the grid too large, naming
        ``options``.
    """
    if not (np.isfinite(extent) and 0 < extent <= MAX_EXTENT):
        raise ModelError(f"{options[0]}: {extent!r} m is outside the allowed range (0, {MAX_EXTENT:g}]")
    if not (np.isfinite(step) and 0 < step <= extent):
        raise ModelError(f"{options[1]}: {step!r} m is outside the allowed range (0, extent = {extent:g}]")
    n = int(np.floor(2 * extent / step + 1e-9)) + 1
    if n * n > MAX_POINTS:
        raise ModelError(f"{options[1]}: {step:g} m gives {n}×{n} points over ±{extent:g} m; at most {MAX_POINTS} "
                         f"(use a step of at least {2 * extent / (np.sqrt(MAX_POINTS) - 1):.3g} m)")
    axis = -extent + step * np.arange(n)
    return axis, axis.copy()


def diver_depth(cfg: dict) -> tuple[float, str]:
    """The depth a map is drawn at when none is given [m], and where it comes from.

    ``target.depth`` for the built-in paths; for a trajectory file (or waypoints) the median depth of its
    waypoints, since ``target.depth`` does not apply to it.
    """
    target = cfg["target"]
    if target.get("trajectory") == "file":
        return float(np.median(file_waypoints(target)[:, 3])), "the median depth of the trajectory's waypoints"
    return float(target["depth"]), "target.depth"


def accuracy_map(cfg: RunPlan | dict, east: np.ndarray, north: np.ndarray, model=MODEL,
                 depth: float | None = None) -> np.ndarray:
    """Horizontal DRMS [m] of one round of fresh ranges (USBL: one packet) plus depth, shape (len(north), len(east)).

    Parameters
    ----------
    cfg : RunPlan or dict
        The plan of the configuration (geometry and error levels; a configuration: its plan is made once).
    east, north : ndarray
        Grid coordinates [m].
    model : RangeDepthModel, optional
        The measurement model whose Fisher information is mapped (default the
        receivers'; its context is the beacons, its motion model the state layout).
        Not used for a system whose packet is not ranges (USBL: :func:`sblsim.models.systems.usbl.horizontal_std`).
    depth : float, optional
        The diver's depth [m]; default :func:`diver_depth`.

    References
    ----------
    Kay, Fundamentals of Statistical Signal Processing: Estimation Theory,
    Prentice Hall 1993, Section 3.7.
    """
    return site_maps(cfg, east, north, model, depth)[0]


def site_maps(cfg: RunPlan | dict, east: np.ndarray, north: np.ndarray, model=MODEL,
              depth: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The accuracy map (:func:`accuracy_map`), the availability map (:func:`availability_map`) and the share of
    the fixes that take a reflected arrival of a configuration, its packets' probabilities computed once
    (:func:`point_accuracy` at the grid's points).

    Returns
    -------
    drms, availability, echo : ndarray, each (len(north), len(east))
        [m], the probability of a fix in one cycle [0–1] and the probability that a fix takes a reflected
        arrival [0–1] (0 with fixed detection).
    """
    plan = as_plan(cfg)
    values = point_accuracy(plan, _points(plan, east, north, depth), model)
    return tuple(values[key].reshape(len(north), len(east)) for key in ("drms", "availability", "echo"))


def point_accuracy(plan: RunPlan, points: np.ndarray, model=MODEL,
                   detection: tuple[np.ndarray, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """The accuracy of one cycle's fix at points: what a map holds there.

    The system's :meth:`~sblsim.models.systems.System.fix_accuracy` with the plan's error levels
    (:attr:`RunPlan.bound`). With detection by signal-to-noise (``acoustics.detection = "snr"``) the accuracy
    accounts for what is heard: the range noise (and the USBL angle noise) of each transducer grows with its
    :func:`~sblsim.models.acoustics.sonar.accuracy_scale`, each range's information is weighted by the probability
    that its packet is heard (:func:`~sblsim.models.design.information.layout_information`: a transducer in a
    shadow zone or beyond detection adds nothing; a USBL's fix is its one packet's, unweighted), and the accuracy
    is NaN where the probability of a fix is below :data:`MIN_AVAILABILITY`. With the range law
    (``acoustics.range_k`` > 0) each range's own noise is ``σ₀ + k ‖p − b_i‖`` at each point
    (:func:`~sblsim.models.design.information.law_range_variance`; the broadcast position's error as it is).

    Parameters
    ----------
    plan : RunPlan
    points : ndarray, shape (M, 3)
        NED [m].
    model : RangeDepthModel, optional
        The ranges' measurement model (default the receivers').
    detection : tuple of ndarray, optional
        Each packet's probability of being received, its accuracy scale and the probability that its range is of
        reflections, each (M, n), where they are known (a design's search interpolates them): default
        :func:`packet_probabilities`.

    Returns
    -------
    dict
        ``drms`` and ``drms_3d`` [m] (NaN: no fix in half of the cycles), ``log_det`` (``log det J``),
        ``availability``, the probability of a fix in one cycle [0–1], and ``echo``, the probability that a cycle's
        fix takes a range of reflections [0–1] (:func:`packet_probabilities`: there the accuracy, of the direct
        rays, does not describe the fix), each (M,).
    """
    bound, sigma = dict(plan.bound), plan["acoustics"]["sigma_range"]
    probability, scale, echo = packet_probabilities(plan, points, echo=True) if detection is None else detection
    available = fix_probability(probability, plan.system.fix_packets)
    heard, own = None, sigma ** 2  # a range's own variance: σ₀², or the range law's per point and transducer
    range_k = float(plan["acoustics"].get("range_k", 0.0))
    if range_k > 0.0:  # σ₀ + k ‖p − b_i‖ in place of σ₀ (the broadcast position's error stays)
        own = law_range_variance(points, plan.lever_arms, sigma, range_k)
        if plan.system.takes_ranges:
            bound["noise_variance"] = bound["noise_variance"] - sigma ** 2 + own
        else:  # one packet's range, from the transceiver
            own = own[:, 0]
            for key in ("noise_variance", "range_variance"):
                if key in bound:
                    bound[key] = bound[key] - sigma ** 2 + own
            sigma = np.sqrt(own)
    if plan["acoustics"]["detection"] == "snr" and plan.system.takes_ranges:  # each range its own noise and weight
        heard = probability
        bound["noise_variance"] = grown_noise(bound["noise_variance"], own, probability, scale)
    elif plan["acoustics"]["detection"] == "snr":  # one packet's noise grown below the reference SNR, per point
        grown = np.sqrt(np.mean(scale ** 2, axis=1))
        for key in ("noise_variance", "range_variance"):
            if key in bound:
                bound[key] = bound[key] + own * (grown ** 2 - 1.0)
        if "angle_sigma_deg" in bound:
            bound["angle_sigma_deg"] = bound["angle_sigma_deg"] * grown
        sigma = sigma * grown
    values = plan.system.fix_accuracy(points, plan["platform"], bound, sigma, model=model, heard=heard)
    fix_echo = 1.0 - np.prod(1.0 - probability * echo, axis=1)
    if plan["acoustics"]["detection"] == "snr":
        # where a fix takes a reflected arrival more often than the prediction holds for (ECHO_LIMIT, a design's),
        # the offsets the reflections give: their mean square joins the noise's
        echoes = np.where((fix_echo > ECHO_LIMIT)[:, None], echo, 0.0)
        if plan.system.measures_direction:
            spread = echo_spread(plan, points, bound, sigma, echoes[:, 0])
        else:
            spread = range_echo_spread(plan, points, bound, probability, echoes)
        values = {**values, "drms": np.sqrt(values["drms"] ** 2 + spread[0]),
                  "drms_3d": np.sqrt(values["drms_3d"] ** 2 + spread[1])}
    out = {}
    for key in ("drms", "drms_3d"):
        out[key] = np.where(np.isfinite(values[key]), values[key], np.inf)
        if plan["acoustics"]["detection"] == "snr":  # no fix there at least half of the cycles
            out[key] = np.where(available < MIN_AVAILABILITY, np.nan, out[key])
    out["log_det"] = np.where(np.isnan(out["drms"]), np.nan, values["log_det"])
    out["availability"] = available
    out["echo"] = fix_echo
    return out


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
    time (:func:`~sblsim.models.acoustics.rays.slant_range`) and whose elevation it turns by the direct eigenray's
    bending (:func:`~sblsim.models.acoustics.rays.ray_bending`), each where the direct eigenray exists
    (:func:`~sblsim.models.receiver.profile.profile_range`). That places the diver at a point ``seen`` along its
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


def grown_noise(noise_variance, range_variance, probability: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Each range's variance where the site decides what is heard [m²]: the range noise ``range_variance`` (σ_r²,
    or the range law's per point and transducer; part of ``noise_variance``, which holds the transducer position's
    error too) grown by the square of the
    accuracy scale of the packet's SNR; a packet never heard keeps ``noise_variance`` (its weight is 0)."""
    return np.where(probability > 0.0, noise_variance + range_variance * (scale ** 2 - 1.0), noise_variance)


def packet_probabilities(plan: RunPlan, points: np.ndarray, arms: np.ndarray | None = None,
                         echo: bool = False) -> tuple[np.ndarray, ...]:
    """Per point and transducer: the probability that one packet is received, and the accuracy scale.

    With fixed detection a packet is received with ``1 − loss_pct`` per draw (USBL: the reply and the
    downlink, two draws) and the scale is 1. With detection by signal-to-noise (``acoustics.detection = "snr"``)
    each leg of the exchange is the eigenrays between the point and the transducer (a leg and its reverse
    are the same path: reciprocity), the legs' fluctuations independent: every leg before the last must be
    heard (``1 − Π (1 − P_j)``: TWTT's interrogation; USBL's interrogation and reply), the last one's first
    detected arrival decoded (:func:`~sblsim.models.acoustics.detection.packet_probability`); the scale is
    :func:`~sblsim.models.acoustics.sonar.accuracy_scale` at the SNR of the earliest eigenray.

    With ``echo``, a third array: the probability that a received packet's range is not the direct rays' (a leg
    of the range, TWTT's and USBL's interrogation and reply, or OWTT's one, had a reflection as its first detected
    arrival: :func:`~sblsim.models.acoustics.detection.direct_first`), where the map's geometry of the direct ray
    does not describe the range (0 with fixed detection).

    Parameters
    ----------
    plan : RunPlan
    points : ndarray, shape (M, 3)
        NED [m].
    arms : ndarray, shape (n, 3), optional
        The transducers' positions when the platform is at the origin, NED [m] (default the plan's,
        :attr:`RunPlan.lever_arms`; a design's candidate layout).
    echo : bool
        Return the probability of a range of reflections too.

    Returns
    -------
    probability, scale[, echo] : ndarray, each (M, n)
        n the system's transducers.
    """
    acoustics, system = plan["acoustics"], plan.system
    arms = np.asarray(plan.lever_arms if arms is None else arms, dtype=float)
    m, n = points.shape[0], arms.shape[0]
    if acoustics["detection"] != "snr":
        keep = (1.0 - acoustics["loss_pct"] / 100.0) ** (2 if system.measures_direction else 1)
        return (np.full((m, n), keep), np.ones((m, n))) + ((np.zeros((m, n)),) if echo else ())
    legs = 3 if system.measures_direction else (2 if acoustics["ranging"] == "twtt" else 1)
    levels = site_levels(plan.component_parameters("acoustics"), np.repeat(arms, m, axis=0), np.tile(points, (n, 1)),
                         compiled_family_levels())
    pd, snr, tau = levels["pd"], levels["snr"], np.where(levels["valid"] > 0.5, levels["tau"], np.inf)
    heard = 1.0 - np.prod(1.0 - pd, axis=1)
    data = packet_probability(tau, pd, snr, acoustics["detection_threshold"], acoustics["decoding_margin"],
                              acoustics["fluctuation"])
    first = np.take_along_axis(snr, np.argmin(tau, axis=1)[:, None], 1)[:, 0]
    scale = np.asarray(accuracy_scale(ca.DM(first), acoustics["reference_snr"])).ravel()  # the channel's form
    out = (heard ** (legs - 1) * data).reshape(n, m).T, scale.reshape(n, m).T
    if not echo:
        return out
    direct_heard = np.where(heard > 0.0, direct_first(tau, pd) / np.where(heard > 0.0, heard, 1.0), 1.0)
    decoded = direct_first(tau, pd, snr, acoustics["detection_threshold"], acoustics["decoding_margin"],
                           acoustics["fluctuation"])
    direct_data = np.where(data > 0.0, decoded / np.where(data > 0.0, data, 1.0), 1.0)
    direct = direct_heard ** 2 if system.measures_direction else direct_heard ** (legs - 1) * direct_data
    return out + (np.clip(1.0 - direct, 0.0, 1.0).reshape(n, m).T,)


def fix_probability(probability: np.ndarray, needed: int) -> np.ndarray:
    """The probability that at least ``needed`` of a cycle's packets are received (independent packets).

    Parameters
    ----------
    probability : ndarray, shape (M, n)
        Each packet's probability of being received.
    needed : int
        The packets a fix needs (:attr:`~sblsim.models.systems.System.fix_packets`).

    Returns
    -------
    ndarray, shape (M,)
        The upper tail of the Poisson-binomial distribution (the count's distribution, one packet at a time).
    """
    count = np.zeros((probability.shape[0], probability.shape[1] + 1))
    count[:, 0] = 1.0
    for j in range(probability.shape[1]):
        p = probability[:, j:j + 1]
        count[:, 1:] = count[:, 1:] * (1.0 - p) + count[:, :-1] * p
        count[:, 0] *= 1.0 - p[:, 0]
    return count[:, needed:].sum(axis=1)


def availability_map(cfg: RunPlan | dict, east: np.ndarray, north: np.ndarray,
                     depth: float | None = None) -> np.ndarray:
    """The probability of a fix in one cycle [0–1], shape (len(north), len(east)): at least the system's
    :attr:`~sblsim.models.systems.System.fix_packets` packets received (:func:`packet_probabilities`,
    :func:`fix_probability`)."""
    plan = as_plan(cfg)
    probability = packet_probabilities(plan, _points(plan, east, north, depth))[0]
    return fix_probability(probability, plan.system.fix_packets).reshape(len(north), len(east))


def _points(plan: RunPlan, east: np.ndarray, north: np.ndarray, depth: float | None) -> np.ndarray:
    """The grid's points (M, 3), NED [m], at the diver's depth (default :func:`diver_depth`), north-major."""
    E, N = np.meshgrid(east, north)
    depth = diver_depth(plan)[0] if depth is None else float(depth)
    return np.column_stack([N.ravel(), E.ravel(), np.full(E.size, depth)])


def system_line(plan: RunPlan | dict) -> str:
    """The geometry of a plan's system in a few words (a panel's title; a configuration: its plan is made)."""
    plan = as_plan(plan)
    return plan.system.describe(plan["platform"])


def check_depth(cfg: dict, depth: float, option: str = "--depth") -> None:
    """Refuse a diver's depth of a map that the site cannot hold: at or below the water depth
    (``acoustics.water_depth``; 0: none), or where the system has no diver
    (:func:`~sblsim.orchestrator.cosim.systems.check_diver`: LBL's transponders stand on the seafloor).

    Raises
    ------
    ModelError
        Naming ``option`` (the option or argument that gave the depth) and the allowed range.
    """
    water = float(cfg["acoustics"]["water_depth"])
    if water > 0.0 and not depth < water:
        raise ModelError(f"{option}: {depth:g} m is outside the allowed range [0, {water:g}) m: the site's water is "
                         f"{water:g} m deep (acoustics.water_depth)")
    try:
        check_diver(cfg, depth)
    except ModelError as exc:
        raise ModelError(f"{option}: {depth:g} m is not above the seafloor: {exc}") from None


def make_maps(scenario: str, overrides: Sequence[str] = (), seed: int | None = None, extent: float = 30.0,
              step: float = 0.5, compare: tuple[str, list[str]] | None = None,
              depth: float | None = None, progress: ProgressSpec = False,
              options: tuple[str, str, str] = ("--extent", "--step", "--depth")
              ) -> tuple[list[str], list[dict], np.ndarray, np.ndarray, list[np.ndarray]]:
    """The accuracy map of a configuration, or one per value of a compared key (each configuration resolved
    once into its plan).

    ``progress`` reports each map made (:class:`sblsim.orchestrator.io.progress.Progress`); default silent.

    ``depth`` [m] is the diver's depth of every map (default :func:`diver_depth` of each configuration); the
    configurations returned hold it as ``target.depth``, which the table and the figure show. It is checked
    against each configuration's site (:func:`check_depth`). Errors name the extent, step and depth as
    ``options`` (the command's options, or the API's arguments).

    Returns
    -------
    labels : list of str
        Panel titles (``platform.baseline = 1`` or the scenario).
    configs : list of MapConfig
        Each map's configuration (a dict, ``target.depth`` the map's depth) and its plan (``.plan()``).
    east, north : ndarray
    maps : list of ndarray, each (len(north), len(east)) [m]

    Raises
    ------
    ConfigError, ModelError
        On a bad option or configuration value (nothing is computed).
    """
    east, north = grid(extent, step, options[:2])
    option = options[2]
    if compare is None:
        plans, labels = [load_plan(scenario, overrides, seed=seed)], [str(scenario)]
    else:  # a compared system starts from its defaults, the user's --set over them
        key, values = compare
        plans = [load_plan(scenario, items, seed=seed)
                 for items in compared(key, values, overrides, scenario_system(scenario))]
        labels = [f"{key} = {v}" for v in values]
    if depth is not None and not 0.0 <= depth <= 11000.0:
        raise ModelError(f"{option}: {depth!r} is outside the allowed range [0, 11000] m")
    check_site_keys(plans, overrides, str(scenario))  # a key no panel's site reads: refused (given) or noted
    configs = []
    for plan in plans:
        configs.append(MapConfig(plan, diver_depth(plan)[0] if depth is None else float(depth)))
        check_depth(configs[-1], configs[-1]["target"]["depth"], option if depth is not None else "target.depth")
    with Progress(len(configs), "map", "map", progress) as bar:
        maps = []
        for c in configs:
            drms, c.availability, c.echo = site_maps(c.plan(), east, north, depth=c["target"]["depth"])
            maps.append(drms)
            bar.update(1)
    return labels, configs, east, north, maps


class MapConfig(Config):
    """The configuration of one map: its plan's configuration (a changeable copy) with ``target.depth`` the
    map's diver depth [m]; :meth:`plan` is the plan the map was made of (resolved once: a map does not
    simulate, its depth is not resolved again)."""

    def __init__(self, plan: RunPlan, depth: float) -> None:
        config = thaw(plan.config)
        config["target"]["depth"] = depth
        super().__init__(config)
        self._plan = plan
        #: The map's probability of a fix in one cycle (:func:`availability_map`), once made.
        self.availability: np.ndarray | None = None
        #: The map's probability that a fix takes a reflected arrival (:func:`site_maps`), once made.
        self.echo: np.ndarray | None = None

    def plan(self) -> RunPlan:
        """The plan the map was made of (its ``target.depth`` the configuration's, not the map's)."""
        return self._plan


def table(labels: Sequence[str], configs: Sequence[dict], east: np.ndarray, north: np.ndarray,
          maps: Sequence[np.ndarray], compare: tuple[str, list[str]] | None = None) -> pd.DataFrame:
    """Long table of the maps: (compared value,) east, north, depth [m], drms [m] (NaN: no fix), availability
    (the probability of a fix in one cycle, when the map has it) and, with detection by signal-to-noise, echo (the
    probability that a fix takes a reflected arrival) and echo_only (true where it is at least
    :data:`ECHO_ONLY`: only echoes are heard first there)."""
    E, N = np.meshgrid(east, north)
    frames = []
    for label, cfg, m in zip(labels, configs, maps):
        frame = pd.DataFrame({"east": E.ravel(), "north": N.ravel(), "depth": float(cfg["target"]["depth"]),
                              "drms": m.ravel()})
        available = getattr(cfg, "availability", None)
        if available is not None:
            frame["availability"] = available.ravel()
        echo = getattr(cfg, "echo", None)
        if echo is not None and cfg["acoustics"]["detection"] == "snr":
            frame["echo"] = echo.ravel()
            frame["echo_only"] = echo.ravel() >= ECHO_ONLY
        if compare is not None:
            frame.insert(0, compare[0], label.split(" = ", 1)[1])
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def plot(labels: Sequence[str], configs: Sequence[dict], east: np.ndarray, north: np.ndarray,
         maps: Sequence[np.ndarray], levels: Sequence[float]):
    """Heat maps (shared logarithmic colour scale) with contours at the accuracy prescriptions."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm
    from matplotlib.ticker import LogLocator, ScalarFormatter

    finite = np.concatenate([m[np.isfinite(m)] for m in maps])
    if finite.size == 0:  # no fix anywhere (detection by signal-to-noise): any scale
        finite = np.array([1e-4, 1.0])
    norm = LogNorm(vmin=max(float(finite.min()), 1e-4), vmax=float(finite.max()))
    plans = [cfg.plan() if isinstance(cfg, MapConfig) else as_plan(cfg) for cfg in configs]
    # detection by signal-to-noise: the probability of a fix beside (below) each accuracy map
    heard = [getattr(cfg, "availability", None) if p["acoustics"]["detection"] == "snr" else None
             for cfg, p in zip(configs, plans)]
    rows = 2 if any(a is not None for a in heard) else 1
    fig, axes = plt.subplots(rows, len(maps), figsize=(5.2 * len(maps) + 0.8, 4.8 * rows), squeeze=False)
    systems = [p.system for p in plans]
    step = float(east[1] - east[0]) if len(east) > 1 else 1.0
    for k, (ax, label, cfg, m) in enumerate(zip(axes[0], labels, configs, maps)):
        mesh = ax.pcolormesh(east, north, m, norm=norm, cmap="viridis", shading="nearest")
        lines = ax.contour(east, north, m, levels=list(levels), colors="w", linewidths=1.2)
        ax.clabel(lines, fmt=lambda v: f"{v:g} m", fontsize=8)
        echo = getattr(cfg, "echo", None)
        hatched = heard[k] is not None and echo is not None and bool((echo >= ECHO_ONLY).any())
        if hatched:  # where only echoes come first
            ax.contourf(east, north, (echo >= ECHO_ONLY).astype(float), levels=[0.5, 1.5], colors="none",
                        hatches=["//"])
            ax.plot([], [], " ", label="/// echo-only")
        arms = plans[k].lever_arms
        inside = (np.abs(arms[:, 1]) <= east.max()) & (np.abs(arms[:, 0]) <= north.max())
        ax.plot(arms[inside, 1], arms[inside, 0], "r^", ms=6, label=systems[k].marker)
        if not inside.all():  # the grid, not the far markers, sets the axes
            ax.set_xlim(east.min() - step / 2, east.max() + step / 2)
            ax.set_ylim(north.min() - step / 2, north.max() + step / 2)
        ax.set_aspect("equal")
        ax.set_xlabel("East [m]")
        if k == 0:
            ax.set_ylabel("North [m]")
        what = f"{system_line(plans[k])}\n" if label.startswith("platform.system = ") else ""
        off = ("" if inside.all() else f", the {systems[k].marker} off the map" if not inside.any()
               else f", {int((~inside).sum())} of the {len(arms)} {systems[k].marker} off the map")
        ax.set_title(f"{label}\n({what}diver at {cfg['target']['depth']:g} m depth{off})", fontsize=9)
        if (inside.any() and (k == 0 or systems[k] != systems[0])) or hatched:
            ax.legend(loc="upper right", fontsize=8)
    what = "measurements" if any(not s.takes_ranges for s in systems) else "ranges"
    bar = fig.colorbar(mesh, ax=axes[0].tolist(), label=f"horizontal DRMS of one round of {what} + depth [m]")
    bar.locator = LogLocator(subs=(1.0, 2.0, 5.0))  # 0.1, 0.2, 0.5, 1, 2, 5 ... labelled, not only the decades
    bar.formatter = ScalarFormatter()
    bar.update_ticks()
    if rows == 2:
        for k, (ax, available) in enumerate(zip(axes[1], heard)):
            if available is None:  # fixed detection: no site to hear at
                ax.set_axis_off()
                continue
            shade = ax.pcolormesh(east, north, available, vmin=0.0, vmax=1.0, cmap="magma", shading="nearest")
            if np.ptp(available) > 0:
                lines = ax.contour(east, north, available, levels=[0.5, 0.9, 0.99], colors="c", linewidths=1.0)
                ax.clabel(lines, fmt=lambda v: f"{v:g}", fontsize=8)
            ax.set_aspect("equal")
            ax.set_xlabel("East [m]")
            if k == 0:
                ax.set_ylabel("North [m]")
            ax.set_title("probability of a fix in one cycle\n(the map above is blank where it is below "
                         f"{MIN_AVAILABILITY:g})", fontsize=9)
        fig.colorbar(shade, ax=axes[1].tolist(), label="availability [0-1]")
    return fig


def write(labels, configs, east, north, maps, levels, out: Path | str,
          compare: tuple[str, list[str]] | None = None) -> Path:
    """Write ``map.csv`` and ``map.png`` into ``out`` atomically; return ``out``."""
    import matplotlib.pyplot as plt

    with staged_directory(out) as tmp:
        table(labels, configs, east, north, maps, compare).to_csv(tmp / "map.csv", index=False)
        fig = plot(labels, configs, east, north, maps, levels)
        fig.savefig(tmp / "map.png", dpi=120, bbox_inches="tight")
        plt.close(fig)
    return Path(out)


__all__ = ["ECHO_ONLY", "MAX_EXTENT", "MapConfig", "accuracy_map", "check_depth", "echo_spread", "grid", "grown_noise",
           "make_maps", "parse_levels", "plot", "point_accuracy", "range_echo_spread", "system_line", "table", "write"]

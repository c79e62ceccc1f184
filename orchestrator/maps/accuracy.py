"""The accuracy of one cycle's fix at points (:func:`point_accuracy`: what a map holds there) and the maps
of a configuration on a grid: accuracy, availability and the share of fixes taking a reflection
(:func:`site_maps`, :func:`accuracy_map`, :func:`availability_map`).
"""

from __future__ import annotations

import numpy as np

from sblsim.models.bound import MODEL
from sblsim.models.design.criteria import ECHO_LIMIT
from sblsim.models.design.information import law_range_variance
from sblsim.orchestrator.cosim.plan import RunPlan, as_plan
from sblsim.orchestrator.maps.detection import fix_probability, grown_noise, packet_probabilities
from sblsim.orchestrator.maps.echoes import echo_spread, range_echo_spread
from sblsim.orchestrator.maps.map_grid import grid_points

#: With detection by signal-to-noise an accuracy map is blank (NaN) where the probability of a fix is below this.
MIN_AVAILABILITY = 0.5


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
    values = point_accuracy(plan, grid_points(plan, east, north, depth), model)
    return tuple(values[key].reshape(len(north), len(east)) for key in ("drms", "availability", "echo"))


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
        Not used for a system whose packet is not ranges (USBL: :func:`sblsim.models.systems.usbl_map.horizontal_std`).
    depth : float, optional
        The diver's depth [m]; default :func:`diver_depth`.

    References
    ----------
    Kay, Fundamentals of Statistical Signal Processing: Estimation Theory,
    Prentice Hall 1993, Section 3.7.
    """
    return site_maps(cfg, east, north, model, depth)[0]


def availability_map(cfg: RunPlan | dict, east: np.ndarray, north: np.ndarray,
                     depth: float | None = None) -> np.ndarray:
    """The probability of a fix in one cycle [0–1], shape (len(north), len(east)): at least the system's
    :attr:`~sblsim.models.systems.System.fix_packets` packets received (:func:`packet_probabilities`,
    :func:`fix_probability`)."""
    plan = as_plan(cfg)
    probability = packet_probabilities(plan, grid_points(plan, east, north, depth))[0]
    return fix_probability(probability, plan.system.fix_packets).reshape(len(north), len(east))

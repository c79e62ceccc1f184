"""A leg of an exchange: the travel time and length between a beacon (or fixed receiver) and the diver, and what is
heard of it.

The diver moves while the packet travels: the one-way travel time τ of a leg to the diver at reception solves
``τ = ‖p + v τ − b‖ / c̄`` (:data:`~sblsim.models.acoustics.channel.interface.OWTT_ITERATIONS` fixed-point
iterations; c̄ the harmonic-mean sound speed along the path, p and v the target's position and velocity at the
step's start, b the beacon), so **the true range refers to the target's position at reception**; a leg that starts
later (a reply) takes the diver where it is then. With ``propagation = "ray"`` the travel time is the earliest
eigenray's through the profile (interpolated in the run's eigenray table where it holds; a shadow zone loses the
packet), and with ``detection = "snr"`` the first **detected** of the leg's eigenrays (:func:`_hear`). Every travel
time of a leg is stretched by the moving ocean (:mod:`~sblsim.models.acoustics.channel.ocean`).

The exchanges put legs together: :mod:`~sblsim.models.acoustics.channel.exchange` (one way, two way, USBL) and
:mod:`~sblsim.models.acoustics.channel.toa` (a ping heard at the fixed receivers).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca

from sblsim.models.acoustics.channel.interface import OWTT_ITERATIONS
from sblsim.models.acoustics.channel.ocean import ocean_perturbation
from sblsim.models.acoustics.detection import family_levels_grid, first_detected
from sblsim.models.acoustics.ray_tables import RAY_TABLE_ROWS, first_arrival_grid
from sblsim.models.acoustics.sound_speed import harmonic_mean
from sblsim.models.expressions import only_where


@dataclass(frozen=True)
class _Slot:
    """What the legs of a slot share: how travel times are computed, the slot's epoch ``t_k`` [s], the beacon
    (3, 1) [m, NED], the diver's position and velocity at the step's start (3, 1) [m, m/s], the channel's state,
    parameters and derived data, and the detection uniforms of an ``snr`` run (None: fixed detection)."""

    propagation: str
    t_k: Any
    beacon: Any
    position: Any
    velocity: Any
    x: Any
    p: Any
    d: Any
    draws: Any


def _leg(e: _Slot, offset, solve: bool, draw: int = 0):
    """A leg of the slot ``e``: travel time and length between the beacon and the diver at ``t_k + offset`` [s]
    (None: 0), plus the travel time itself when ``solve`` (fixed-point iterations), the eigenray's ``(launch,
    arrival, kind)`` from the beacon (``ray``; the chord's angles and 1 when straight) and the SNR and detection
    probability of that arrival (``snr``: the first **detected** of the leg's eigenrays with the uniforms
    ``draw … draw + 2``, kind 0 when none is; else 0, 0), and the travel time of its latest detected arrival
    (``snr``; else the travel time)."""
    x, p, d, beacon, position, velocity = e.x, e.p, e.d, e.beacon, e.position, e.velocity
    # the moving ocean at the leg's start: every travel time of the leg scaled by 1 + ε
    # (a steady ocean's ε, 0 · Σ cos = ±0, is an exact 0 without its cosines: 1 + ε is 1 either way)
    ppm = p["ntd_sigma_ppm"]
    slower = 1.0 + only_where("sblsim_ocean", ppm > 0,
                              lambda t: ocean_perturbation(t, ppm * 1e-6, x["ocean_frequency"], x["ocean_phase"]),
                              e.t_k - x["t0"] + (0.0 if offset is None else offset))

    def path(tau):
        receive = position + velocity * (tau if offset is None else offset + tau)
        distance = ca.norm_2(receive - beacon)
        horizontal = ca.norm_2(receive[:2] - beacon[:2])
        chord = ca.atan2(receive[2] - beacon[2], horizontal)
        speed = harmonic_mean(beacon[2], receive[2], p["sound_speed_true"], p["sound_speed_rows"],
                              d["nodes"], d["slowness"])
        if e.propagation == "straight":
            return distance / speed * slower, distance, receive, (chord, chord, 1.0)
        # ray: the earliest eigenray (interpolated in the run's eigenray table where it holds); a shadow zone (no
        # arrival) loses the packet, and the straight line keeps the rest finite
        r_tau, r_launch, r_arrival, r_kind = first_arrival_grid(
            p["ray_table_rows"] == RAY_TABLE_ROWS, beacon[2], receive[2], horizontal,
            p["water_depth"], p["sound_speed_rows"] > 0, p["sound_speed_true"], d["nodes"],
            d["speeds"], d["ray_bounds"], d["ray_grid"], d["ray_values"])
        found = r_kind > 0
        tau = ca.if_else(found, r_tau, distance / speed) * slower
        angles = (ca.if_else(found, r_launch, chord), ca.if_else(found, r_arrival, chord), r_kind)
        return tau, distance, receive, angles

    tau, distance, receive, angles = path(0.0)
    for _ in range(OWTT_ITERATIONS if solve else 0):
        tau, distance, receive, angles = path(tau)
    if e.draws is None:
        return tau, distance, receive, angles, 0.0, 0.0, tau
    heard = _hear(beacon, receive, p, d, e.draws[draw:draw + 3])
    return heard[0] * slower, distance, receive, heard[1:4], heard[4], heard[5], heard[6] * slower


def _hear(source, receive, p, d, draws):
    """The first detected eigenray from ``source`` to ``receive`` (3, 1) [m, NED] with the uniforms
    ``draws`` (3: one per family): :func:`~sblsim.models.acoustics.detection.first_detected` (the families
    interpolated in the run's family table where it holds)."""
    families = family_levels_grid()(
        p["ray_family_rows"] == RAY_TABLE_ROWS, source[2], receive[2], ca.norm_2(receive[:2] - source[:2]),
        p["water_depth"], p["sound_speed_rows"] > 0, p["sound_speed_true"], d["nodes"], d["speeds"],
        d["site"], d["ray_bounds"], d["ray_grid"], d["family_values"])
    return first_detected(*families, draws)

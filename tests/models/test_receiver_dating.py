"""A one-way range refers to its reception: the receivers date it there, and mid-flight dating is inconsistent.

A diver swims at 1 m/s 10 m below the surface over four transponders on a 1,000 m deep seafloor (a 500 m
circle): a one-way travel time is about 0.7 s, over which the diver moves 0.7 m. The ranges are made here, in
numpy, as the channel makes them (the travel time solved to the diver where the packet arrives, range = c τ plus
white noise), with their arrival epochs. ``ekf-seq`` with ``ranging = "owtt"`` dates each range at its reception
(``rx_time``) and is consistent (mean NEES over 20 runs in [1.5, 4.5]); the same receiver told the ranges are
two-way (``ranging = "twtt"``: dated at the middle of the flight, ``(tx + rx) / 2``, as a two-way range refers
to the mean of its legs) is not, on the same packets.
"""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.receiver import SequentialReceiver
from tests.helpers import Core
from tests.models.test_receiver import packet

C = 1500.0
BEACONS = np.array([[500.0 * np.cos(a), 500.0 * np.sin(a), 1000.0] for a in np.radians([0, 90, 180, 270])])
SIGMA_RANGE, SIGMA_DEPTH, T, STEPS, RUNS = 0.05, 0.01, 1.0, 200, 20
VELOCITY = np.array([1.0, 0.0, 0.0])
START = np.array([-100.0, 20.0, 10.0])


def one_way(t_k: float, beacon: np.ndarray) -> tuple[float, float]:
    """Travel time from ``beacon`` at ``t_k`` to the diver where the packet arrives [s], and the true range [m]."""
    tau = 0.0
    for _ in range(20):
        tau = np.linalg.norm(START + VELOCITY * (t_k + tau) - beacon) / C
    return tau, C * tau


def nees_of(ranging: str) -> float:
    params = dict(sigma_range=SIGMA_RANGE, sigma_depth=SIGMA_DEPTH, q_horizontal=1e-4, q_vertical=1e-4,
                  p0_position=0.5, p0_velocity=0.1, beacon_gps_sigma=0.0, beacon_attitude_sigma_deg=0.0,
                  beacon_arm=0.0, gate_probability=1.0, ranging=ranging, communication_step=T,
                  **{f"x0_{a}": v for a, v in zip(("x", "y", "z"), START)},
                  **{f"x0_v{a}": v for a, v in zip("xyz", VELOCITY)})
    core = Core(SequentialReceiver, params, replicates=range(RUNS)).initialize(0.0)
    rng = np.random.default_rng(7)
    nees = []
    for k in range(1, STEPS + 1):
        t_k = (k - 1) * T
        beacon = BEACONS[(k - 1) % 4]
        tau, true_range = one_way(t_k, beacon)
        measured = true_range + SIGMA_RANGE * rng.normal(size=RUNS)
        now = k * T  # the receiver's step that reaches the arrival t_k + τ (< T)
        depth = (START + VELOCITY * now)[2] + SIGMA_DEPTH * rng.normal(size=RUNS)
        core.set_inputs(packet(k, (k - 1) % 4 + 1, t_k, measured, beacon, depth, rx_time=t_k + tau))
        out = core.step(now - T, T)
        if k > 20:  # after the start's transient
            error = START + VELOCITY * now - np.column_stack([out[f"est_{a}"] for a in "xyz"])
            names = (("xx", "xy", "xz"), ("xy", "yy", "yz"), ("xz", "yz", "zz"))
            cov = np.stack([[out[f"cov_{ab}"] for ab in row] for row in names]).transpose(2, 0, 1)
            nees.append(np.einsum("bi,bij,bj->b", error, np.linalg.inv(cov), error))
    return float(np.mean(nees))


def test_one_way_ranges_dated_at_reception_are_consistent_and_mid_flight_dating_is_not():
    reception, mid_flight = nees_of("owtt"), nees_of("twtt")
    assert 1.5 <= reception <= 4.5, reception
    assert mid_flight > 4.5, mid_flight
    assert mid_flight > 2.0 * reception


@pytest.mark.parametrize("ranging", ["owtt", "twtt"])
def test_the_ranging_parameter_is_the_channels(ranging):
    """The receiver's ``ranging`` is tied to ``acoustics.ranging`` (its plan's FMU parameter)."""
    from sblsim.orchestrator.cosim.config import load_config
    from sblsim.orchestrator.cosim.plan import make_plan

    plan = make_plan(load_config("random-walk", ["simulation.receiver=ekf-seq", f"acoustics.ranging={ranging}"]))
    assert plan.component_parameters("receiver")["ranging"] == ranging

"""The sampling time a design runs with: the scenario's, or a slot period long enough that no packet stays in flight
beyond what the acoustic channel holds (:data:`~sblsim.models.acoustics.channel.interface.FLIGHT_CAPACITY`), and
the overrides that set it.
"""

from __future__ import annotations

import math

import numpy as np

from sblsim.models.acoustics.channel.interface import FLIGHT_CAPACITY
from sblsim.orchestrator.cosim.plan import RunPlan

#: The slowest sound speed a slot period is sized for [m/s] (any water; the eigenrays' bending on top: a margin).
SLOWEST_SOUND = 1400.0


def slot_period(plan: RunPlan, transducers: np.ndarray, points: np.ndarray) -> float:
    """The sampling time a design runs with [s]: the scenario's, or longer where a packet from the farthest
    transducer to the farthest work-area point would stay in flight beyond what the channel holds
    (:data:`~sblsim.models.acoustics.core.FLIGHT_CAPACITY` slots; the straight path at :data:`SLOWEST_SOUND`, two
    legs for two-way ranging and a USBL, the turnaround and three of its jitter's standard deviations on top)."""
    acoustics = plan["acoustics"]
    period = float(plan["simulation"]["sampling_time"])
    legs = 2 if (acoustics["ranging"] == "twtt" or plan.system.measures_direction) else 1
    distance = float(np.max(np.linalg.norm(points[:, None, :] - transducers[None, :, :], axis=-1)))
    turnaround = acoustics["turnaround"] + 3.0 * acoustics["turnaround_sigma"] if legs == 2 else 0.0
    flight = 1.1 * (legs * distance / SLOWEST_SOUND + turnaround)
    return max(period, flight / (FLIGHT_CAPACITY - 1))


def _sampling_items(plan: RunPlan, period: float) -> list[str]:
    """The overrides of a design's longer sampling time ``period`` [s]: it, and the scenario's duration made a whole
    number of it (the next one up), as the run requires."""
    if period == plan["simulation"]["sampling_time"]:
        return []
    items = [f"simulation.sampling_time={period!r}"]
    ratio = float(plan["simulation"]["duration"]) / period
    if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):  # not whole already: the next whole number of them
        items.append(f"simulation.duration={math.ceil(ratio) * period!r}")
    return items


__all__ = ["SLOWEST_SOUND", "slot_period"]

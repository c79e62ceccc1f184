"""The site's levels between pairs of points (the maps' channel): pairs of the same depths and horizontal distance
are solved once, with the numbers of solving every pair."""

from __future__ import annotations

import numpy as np

from sblsim.models.acoustics.channel.site_levels import site_levels
from sblsim.models.acoustics.detection import family_levels
from sblsim.orchestrator.cosim.plan import load_plan


class _Counting:
    """``family_levels`` that records how many geometries each evaluation asks for."""

    def __init__(self) -> None:
        self.sizes: list[int] = []

    def map(self, n: int):
        self.sizes.append(n)
        return family_levels().map(n)


def test_pairs_of_one_geometry_are_solved_once_with_the_same_numbers():
    plan = load_plan("lbl-field", ["acoustics.water_depth=60", "platform.seafloor_depth=55", "target.depth=20"])
    parameters = plan.component_parameters("acoustics")
    axis = np.arange(-40.0, 41.0, 20.0)  # a grid symmetric about both axes, as a map's
    east, north = np.meshgrid(axis, axis)
    points = np.column_stack([north.ravel(), east.ravel(), np.full(east.size, 20.0)])
    arms = np.asarray(plan.lever_arms)  # four transponders on a circle: the grid's symmetries map them onto each other
    sources, receivers = np.repeat(arms, len(points), axis=0), np.tile(points, (len(arms), 1))
    counting = _Counting()
    levels = site_levels(parameters, sources, receivers, counting)
    horizontal = np.hypot(*(receivers[:, :2] - sources[:, :2]).T)
    distinct = len({(a, b, c) for a, b, c in zip(sources[:, 2], receivers[:, 2], horizontal)})
    assert counting.sizes == [distinct] and distinct * 4 <= len(sources)
    # every pair on its own, as the channel solves a leg
    one_by_one = [site_levels(parameters, sources[k:k + 1], receivers[k:k + 1]) for k in range(0, len(sources), 7)]
    for name in ("tau", "valid", "snr", "pd"):
        np.testing.assert_array_equal(levels[name][::7], np.vstack([o[name] for o in one_by_one]))

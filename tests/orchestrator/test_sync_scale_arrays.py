"""The receivers table's scale against the sync tags' travel times
(:func:`sblsim.orchestrator.sync.declared.sync_scale`) taken from the arrivals' arrays alone: the same factor as the
arrivals filtered and numbered in a table of names (pandas, in the test), whatever the table's order, with echoes, a
receiver the table lacks and a tag whose home it lacks left out."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.models.sync import scale
from sblsim.models.sync.simulate import simulate_sync
from sblsim.orchestrator.sync.declared import sync_scale


@pytest.fixture(scope="module")
def sim():
    return simulate_sync(n_receivers=8, hours=6.0, seed=5, offset=1.0, drift=10e-6, echo_share=0.05)


def _by_names(sim, names, tag_names, table: pd.DataFrame):
    """The factor from a frame of named arrivals: echoes, receivers not in ``table`` and tags whose home is not in it
    dropped, receivers numbered by the table's rows and tags by their names' order."""
    arrivals = pd.DataFrame({"receiver": np.asarray(names)[sim.receiver], "tag": np.asarray(tag_names)[sim.tag],
                             "home": np.asarray(names)[sim.tag], "emission": sim.emission, "time": sim.time,
                             "echo": sim.echo})
    rows = {n: k for k, n in enumerate(table["receiver"])}
    use = arrivals[~arrivals["echo"] & arrivals["receiver"].isin(rows) & arrivals["home"].isin(rows)]
    numbers = {t: k for k, t in enumerate(sorted(use["tag"].unique()))}
    xy = table[["x", "y"]].to_numpy(float)
    at, home = use["receiver"].map(rows).to_numpy(), use["home"].map(rows).to_numpy()
    return scale.distance_scale(*scale.double_differences(
        at, use["tag"].map(numbers).to_numpy(), use["emission"].to_numpy(), use["time"].to_numpy(),
        np.linalg.norm(xy[home] - xy[at], axis=1), sim.sound_speed))


def test_the_scale_from_arrays_is_the_named_arrivals_one(sim):
    """Tags named against their numbers' order, the table shuffled and one receiver (a tag's home too) missing from
    it: the factor equals the named frame's bit for bit, and is 1 within the timing noise on the true positions."""
    n = len(sim.positions)
    names = [f"R{k}" for k in range(n)]
    tag_names = [f"T{n - k:02d}" for k in range(n)]  # (sorted by name: the reverse of their numbers)
    table = pd.DataFrame({"receiver": names, "x": sim.positions[:, 0], "y": sim.positions[:, 1], "z": np.nan})
    table = table.drop(index=3).sample(frac=1.0, random_state=2).reset_index(drop=True)
    arrays = (sim.receiver, sim.tag, sim.emission, sim.time, sim.echo, names, tag_names, np.arange(n))
    found = sync_scale(*arrays, table, sim.sound_speed)
    assert sim.echo.any() and found is not None and found.items >= 20
    assert found == _by_names(sim, names, tag_names, table)
    assert found.scale == pytest.approx(1.0, abs=1e-3)
    wide = table.assign(x=table["x"] * 2.0, y=table["y"] * 2.0)  # every distance doubled
    assert sync_scale(*arrays, wide, sim.sound_speed).scale == pytest.approx(found.scale / 2.0, rel=1e-9)
    assert sync_scale(*arrays[:4], np.ones(len(sim.time), bool), *arrays[5:], table, sim.sound_speed) is None

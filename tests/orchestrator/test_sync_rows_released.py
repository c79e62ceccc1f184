"""The synchronisation lets its caller's rows go when asked (:func:`sblsim.orchestrator.sync.run.synchronise`'s
``release_rows``: a season's rows not held through the fit): the rows emptied, their columns and dtypes kept, and the
same clocks, residuals, sync tags and count of rows read as a synchronisation that keeps them."""

from __future__ import annotations

import numpy as np
import pandas as pd

from sblsim.models.sync.simulate import simulate_sync
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.sync.run import synchronise

EPOCH = 1_700_000_000


def test_the_rows_let_go_once_taken_and_the_same_synchronisation():
    sim = simulate_sync(n_receivers=5, hours=1.0, seed=7)
    frame = pd.DataFrame({"receiver": [f"R{j}" for j in sim.receiver], "tag": [f"S{i}" for i in sim.tag],
                          "time": sim.time + EPOCH, "line": np.arange(2, len(sim.time) + 2)})
    hydrophones = pd.DataFrame({"receiver": [f"R{j}" for j in range(5)], "sync_tag": [f"S{j}" for j in range(5)],
                                "x": sim.positions[:, 0], "y": sim.positions[:, 1], "z": np.nan})
    kept, released = Detections(frame.copy(), "simulated", "yaps"), Detections(frame.copy(), "simulated", "yaps")
    options = {"sound_speed": sim.sound_speed, "reference": "R0"}
    expected = synchronise(kept, hydrophones, **options)
    got = synchronise(released, hydrophones, release_rows=True, **options)
    assert len(kept.frame) == len(frame) and len(released.frame) == 0
    assert released.frame.dtypes.to_dict() == frame.dtypes.to_dict()
    for name in ("offsets", "residuals", "sync_tags"):
        pd.testing.assert_frame_equal(getattr(got, name), getattr(expected, name))
    assert got.summary["detections"] == expected.summary["detections"]  # the rows read counted before let go
    assert got.summary["detections"]["rows"] == len(frame)


def test_rows_that_are_all_the_sync_tags_are_used_as_they_are_and_give_the_same_synchronisation():
    """A study's rows (the sync tags' alone, the synchronisation's columns alone) are used without a copy of them;
    the same rows with another tag's and another column beside them (selected and copied) give the same
    synchronisation."""
    sim = simulate_sync(n_receivers=5, hours=1.0, seed=8)
    frame = pd.DataFrame({"receiver": [f"R{j}" for j in sim.receiver], "tag": [f"S{i}" for i in sim.tag],
                          "time": sim.time + EPOCH, "line": np.arange(2, len(sim.time) + 2)})
    hydrophones = pd.DataFrame({"receiver": [f"R{j}" for j in range(5)], "sync_tag": [f"S{j}" for j in range(5)],
                                "x": sim.positions[:, 0], "y": sim.positions[:, 1], "z": np.nan})
    animal = frame.iloc[::7].assign(tag="A1", line=frame["line"].iloc[::7] + 10**6)
    mixed = pd.concat([frame, animal], ignore_index=True).assign(sensor_value=np.nan)
    options = {"sound_speed": sim.sound_speed, "reference": "R0"}
    own = synchronise(Detections(frame, "simulated", "yaps"), hydrophones, **options)
    selected = synchronise(Detections(mixed, "simulated", "yaps"), hydrophones, **options)
    for name in ("offsets", "residuals", "sync_tags"):
        pd.testing.assert_frame_equal(getattr(own, name), getattr(selected, name))

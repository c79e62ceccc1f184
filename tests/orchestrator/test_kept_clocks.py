"""A study's synchronisation kept across runs (orchestrator/telemetry/kept_clocks.py): kept, it gives back the same
clocks, fit, tables, summary and notes without synchronising again; a detection changed by a microsecond is
synchronised again; clocks given as a folder are not kept."""

from __future__ import annotations

from dataclasses import fields
from types import SimpleNamespace

import numpy as np
import pandas as pd

from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.simulate import simulate_sync
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.telemetry import kept_clocks
from sblsim.orchestrator.tracks.resume import Resume, resume_folder

EPOCH = 1_700_000_000


def _assigned(shift: float = 0.0):
    """A small simulated array's detections and receivers (5 receivers, each with its sync tag, 3 hours, a receiver's
    clock set ahead by 0.5 s half way) as the study assigns them; ``shift`` [s] added to the first detection's time."""
    sim = simulate_sync(n_receivers=5, hours=3.0, seed=2, offset=2.0, drift=20e-6, noise=0.15e-3, echo_share=0.0,
                        jump=(3, 1.5 * 3600, 0.5))
    t = sim.time + EPOCH
    t[0] += shift
    frame = pd.DataFrame({"receiver": [f"R{j}" for j in sim.receiver], "tag": [f"S{i}" for i in sim.tag], "time": t,
                          "sensor_value": np.nan, "sensor_unit": "", "line": np.arange(len(t)) + 2})
    hydrophones = pd.DataFrame({"receiver": [f"R{j}" for j in range(5)], "sync_tag": [f"S{j}" for j in range(5)],
                                "x": sim.positions[:, 0], "y": sim.positions[:, 1], "z": np.nan})
    return SimpleNamespace(detections=Detections(frame, "simulated", "yaps"), hydrophones=hydrophones), sim


DEPLOYMENTS = SimpleNamespace(source="deployments.csv", alternatives=lambda: {})


def test_a_kept_synchronisation_is_given_back_whole_without_synchronising_again(tmp_path, monkeypatch):
    assigned, sim = _assigned()
    notes: list[str] = []
    made = kept_clocks.kept_study_clocks(Resume(tmp_path / "o"), None, assigned, DEPLOYMENTS, sim.sound_speed, None,
                                         1.0, notes)
    assert made[2]["source"] == "synchronised here" and len(made[3].fit.breaks) == 1

    def never(*args, **kwargs):
        raise AssertionError("synchronised again")

    monkeypatch.setattr(kept_clocks, "study_clocks", never)
    again: list[str] = []
    clocks, table, info, outcome = kept_clocks.kept_study_clocks(Resume(tmp_path / "o"), None, assigned, DEPLOYMENTS,
                                                                 sim.sound_speed, None, 1.0, again)
    assert again == notes and info == made[2] and table is assigned.hydrophones
    assert clocks.receivers == made[0].receivers
    for name in kept_clocks.TABLES:
        mine, theirs = getattr(outcome, name), getattr(made[3], name)
        assert (mine is None) == (theirs is None), name
        if mine is not None:
            assert mine.to_csv(index=False) == theirs.to_csv(index=False), name
    assert outcome.summary == made[3].summary and outcome.origin == made[3].origin
    for item in fields(ClockFit):
        mine, theirs = getattr(outcome.fit, item.name), getattr(made[3].fit, item.name)
        if isinstance(theirs, np.ndarray):
            np.testing.assert_array_equal(mine, theirs)
            assert mine.dtype == theirs.dtype, item.name
        else:
            assert mine == theirs, item.name


def test_a_changed_detection_is_synchronised_again_and_given_clocks_are_not_kept(tmp_path, monkeypatch):
    assigned, sim = _assigned()
    kept_clocks.kept_study_clocks(Resume(tmp_path / "o"), None, assigned, DEPLOYMENTS, sim.sound_speed, None, 1.0, [])
    moved, _ = _assigned(shift=1e-6)
    assert kept_clocks.clocks_key(moved, sim.sound_speed, None, 1.0) != \
        kept_clocks.clocks_key(assigned, sim.sound_speed, None, 1.0)
    assert kept_clocks.clocks_key(assigned, sim.sound_speed, None, 0.5) != \
        kept_clocks.clocks_key(assigned, sim.sound_speed, None, 1.0)
    calls = []
    monkeypatch.setattr(kept_clocks, "study_clocks", lambda *args: calls.append(args) or (None, None, {}, None))
    kept_clocks.kept_study_clocks(Resume(tmp_path / "o"), None, moved, DEPLOYMENTS, sim.sound_speed, None, 1.0, [])
    kept_clocks.kept_study_clocks(Resume(tmp_path / "o"), tmp_path / "sync", assigned, DEPLOYMENTS,
                                  sim.sound_speed, None, 1.0, [])
    assert len(calls) == 2
    assert len([p for p in resume_folder(tmp_path / "o").iterdir() if len(p.name) == 64]) == 1

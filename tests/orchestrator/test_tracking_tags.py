"""Many tags at one array tracked in parallel (orchestrator/tracks/many.py, ``sblsim replay FOLDER --format toa``):
each tag's track is the one its file gives alone, a refused file is a row saying why, and the folder is written all
or nothing."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.receiver import toa_tracking as tt
from sblsim.orchestrator.io.manifest import MANIFEST
from sblsim.orchestrator.tracks.variants import write_toa

RECEIVERS = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0]])
NAMES = [f"R{k + 1}" for k in range(len(RECEIVERS))]


def _array(tmp_path: Path, tags: int = 3) -> tuple[Path, Path]:
    """``tags`` simulated tags' files (60 pings each, seeded) and one file that is not a TOA matrix."""
    folder = tmp_path / "tags"
    folder.mkdir()
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-3)
    for k in range(tags):
        toa, _, _ = tt.simulate_pings(RECEIVERS, 60, s, np.random.default_rng(k), speed=0.3, detection=0.8)
        write_toa(folder / f"tag{k}.txt", toa, NAMES)
    (folder / "broken.txt").write_text("R1 R2\n1.0 not-a-time\n")
    receivers = tmp_path / "receivers.csv"
    receivers.write_text("name,x_m,y_m\n" + "\n".join(f"{n},{x:g},{y:g}" for n, (x, y) in zip(NAMES, RECEIVERS)))
    return folder, receivers


@pytest.mark.slow
def test_each_tag_is_tracked_as_alone_and_a_refused_file_is_a_row(tmp_path):
    """In one process: every tag's track equal to replay_toa's of its file alone; the broken file a refused row with
    its one-line reason; tags.csv and one folder per tracked tag written."""
    folder, receivers = _array(tmp_path)
    result = sblsim.replay_toa_tags(folder, receivers=receivers, workers=1, sound_speed=1480.0, smooth=True,
                                    out=tmp_path / "out")
    table = result.table.set_index("tag")
    assert list(result.table["tag"]) == ["broken", "tag0", "tag1", "tag2"]
    assert table.loc["broken", "status"] == "refused" and "not-a-time" in table.loc["broken", "reason"]
    for k in range(3):
        alone = sblsim.replay_toa(folder / f"tag{k}.txt", receivers=receivers, sound_speed=1480.0, smooth=True)
        pd.testing.assert_frame_equal(result.tracks[f"tag{k}"].track, alone.track)
        assert table.loc[f"tag{k}", "pings"] == 60 and table.loc[f"tag{k}", "positioned"] == len(alone.track)
    written = pd.read_csv(tmp_path / "out" / "tags.csv")
    assert list(written["tag"]) == list(result.table["tag"])
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == sorted(
        [MANIFEST, "tag0", "tag1", "tag2", "tags.csv"])
    assert (tmp_path / "out" / "tag1" / "track.csv").is_file()


@pytest.mark.parametrize("options,message", [
    (["--truth", "x.txt"], "--truth: not with a folder of tags"),
    (["--workers", "0"], "--workers"),
    (["--scheduler", "nowhere"], "--scheduler: 'nowhere' is not a scheduler address"),
])
def test_bad_folder_options_are_refused_in_one_line(tmp_path, capsys, options, message):
    """One line, exit 2, no folder written."""
    from sblsim.orchestrator.cli import main

    folder, receivers = _array(tmp_path, tags=1)
    code = main(["replay", str(folder), "--format", "toa", "--receivers", str(receivers), "--out",
                 str(tmp_path / "o"), *options])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "o").exists()


def test_workers_are_refused_for_one_file(tmp_path, capsys):
    from sblsim.orchestrator.cli import main

    folder, receivers = _array(tmp_path, tags=1)
    code = main(["replay", str(folder / "tag0.txt"), "--format", "toa", "--receivers", str(receivers), "--workers",
                 "2", "--out", str(tmp_path / "o")])
    assert code == 2 and "--workers: only with a folder of tags" in capsys.readouterr().err


@pytest.mark.slow
@pytest.mark.parametrize("how", [["--workers", "2"], ["--workers", "2", "--scheduler", "local"]])
def test_worker_processes_and_a_dask_cluster_give_the_tracks_of_one_process(tmp_path, capsys, how):
    """The command line in two worker processes, and on a local Dask cluster (each worker sent its tag's files):
    the same files to the byte as in one process (but each tag's time), a line per tag as it ends."""
    from sblsim.orchestrator.cli import main

    folder, receivers = _array(tmp_path, tags=4)
    base = ["replay", str(folder), "--format", "toa", "--receivers", str(receivers), "--sound-speed", "1480"]
    assert main(base + ["--workers", "1", "--out", str(tmp_path / "one")]) == 0
    capsys.readouterr()
    assert main(base + how + ["--out", str(tmp_path / "many")]) == 0
    out = capsys.readouterr().out
    assert out.count("pings,") == 4 and "refused" not in out
    for k in range(4):  # bit for bit: the files' bytes
        for name in ("track.csv", "estimates.csv", "summary.json"):
            one = (tmp_path / "one" / f"tag{k}" / name).read_text()
            many = (tmp_path / "many" / f"tag{k}" / name).read_text()
            if name == "summary.json":  # but the time each took
                one, many = (re.sub(r'"wall_time_s": [0-9.e+-]+', "", t) for t in (one, many))
            assert one == many, (k, name)


@pytest.mark.slow
def test_two_worker_processes_call_back_as_each_tag_ends(tmp_path):
    """run_tracks in two worker processes: each tag's callback called once with its outcome, the results those of
    one process (a local variable named as the callback had made every multi-worker study fail)."""
    from sblsim.orchestrator.tracks.many import run_tracks

    folder, receivers = _array(tmp_path, tags=2)
    options = {"sound_speed": 1480.0, "other_filters": False}
    jobs = [(f"tag{k}", folder / f"tag{k}.txt", receivers, options) for k in range(2)]
    called: list[str] = []
    many = run_tracks(jobs, workers=2, ended=lambda name, result: called.append(name))
    one = run_tracks(jobs, workers=1)
    assert sorted(called) == ["tag0", "tag1"] and set(many) == {"tag0", "tag1"}
    for name in many:
        pd.testing.assert_frame_equal(many[name].track, one[name].track)


@pytest.mark.slow
def test_an_ended_tags_outcome_is_not_held_while_the_next_are_awaited(tmp_path, monkeypatch):
    """run_tracks in two worker processes: each tag's outcome, once its callback has ended, is held by nothing (no
    future keeps it) while the tags still under way are awaited (a season's outcomes are tens of MiB each)."""
    import gc
    import weakref

    from sblsim.orchestrator.tracks import many

    folder, receivers = _array(tmp_path, tags=3)
    options = {"sound_speed": 1480.0, "other_filters": False}
    jobs = [(f"tag{k}", folder / f"tag{k}.txt", receivers, options) for k in range(3)]
    ended, alive_at_wait = [], []
    real_wait = many.wait

    def watched(futures, *args, **kwargs):  # one ended future given at a time: a wait after each tag, however fast
        gc.collect()
        alive_at_wait.append(sum(r() is not None for r in ended))
        finished, pending = real_wait(futures, *args, **kwargs)
        one = next(iter(finished))
        return {one}, (set(finished) - {one}) | set(pending)

    monkeypatch.setattr(many, "wait", watched)
    results = many.run_tracks(jobs, workers=2, ended=lambda name, result: ended.append(weakref.ref(result)) or name)
    assert len(ended) == 3 and set(results.values()) == {"tag0", "tag1", "tag2"}  # what the callback returned kept
    assert len(alive_at_wait) == 3 and max(alive_at_wait) == 0, alive_at_wait


@pytest.mark.slow
def test_a_dask_cluster_holds_no_ended_tags_result(tmp_path, monkeypatch):
    """run_tracks on a local Dask cluster: when a tag's callback runs, the client holds only the futures of the tags
    not yet ended (an ended tag's result is let go on its worker, not kept there to the study's end)."""
    import gc

    from sblsim.orchestrator.campaign import executors
    from sblsim.orchestrator.tracks import many

    folder, receivers = _array(tmp_path, tags=3)
    options = {"sound_speed": 1480.0, "other_filters": False}
    jobs = [(f"tag{k}", folder / f"tag{k}.txt", receivers, options) for k in range(3)]
    clients, held = [], []
    real_connect = executors.connect
    monkeypatch.setattr(executors, "connect", lambda *a, **k: clients.append(real_connect(*a, **k)) or clients[-1])

    def ended(name, result):
        gc.collect()
        held.append(len(clients[0].futures))  # the futures this client still holds (their results on the workers)
        return None

    results = many.run_tracks(jobs, workers=2, scheduler="local", ended=ended)
    assert set(results) == {"tag0", "tag1", "tag2"}
    assert held[-1] == 0 and held == sorted(held, reverse=True), held

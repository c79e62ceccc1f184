"""Finished tags kept across runs (orchestrator/tracks/resume.py) and sent to a worker that shares no filesystem
(orchestrator/tracks/many.py ``track_sent``): an entry gives back the outcome it kept, to the byte of its files; a
changed input is tracked again; a damaged or foreign entry is never taken; a full disk is said and the run goes on;
a run stopped part way and made again tracks only the tags it had not finished; a study killed mid-way (slow) and
run again writes the uninterrupted study's tracks."""

from __future__ import annotations

import errno
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pandas as pd
import pytest

from sblsim.orchestrator.tracks import many, resume
from sblsim.orchestrator.tracks.outputs import written_light
from sblsim.orchestrator.tracks.resume import MARKER, Resume, job_key, resume_folder
from tests.orchestrator.test_tracking_tags import _array

OPTIONS = {"sound_speed": 1480.0, "other_filters": False}


@pytest.fixture(scope="module")
def tracked(tmp_path_factory):
    """Two simulated tags' files and the first one's outcome (tracked once for the module)."""
    folder, receivers = _array(tmp_path_factory.mktemp("tags"), tags=2)
    return folder, receivers, many.track_tag(folder / "tag0.txt", receivers, OPTIONS)


def test_a_kept_outcome_writes_the_same_files_as_the_outcome(tracked, tmp_path):
    folder, receivers, outcome = tracked
    keep = Resume(tmp_path / "out")
    key = job_key(folder / "tag0.txt", receivers, OPTIONS)
    assert keep.load(key, folder) is None
    keep.save(key, outcome, folder)
    back = Resume(tmp_path / "out").load(key, folder)
    pd.testing.assert_frame_equal(back.track, outcome.track, check_exact=True)
    pd.testing.assert_frame_equal(back.estimates, outcome.estimates, check_exact=True)
    assert back.summary == outcome.summary and back.array[0] == outcome.array[0]
    assert (back.array[1] == outcome.array[1]).all()
    for table in ("track", "estimates"):  # the files the study writes of them, to the byte
        assert getattr(back, table).to_csv(index=False) == getattr(outcome, table).to_csv(index=False)
    assert json.dumps(back.summary, indent=2) == json.dumps(outcome.summary, indent=2)
    assert sorted(p.name for p in resume_folder(tmp_path / "out").iterdir()) == sorted([MARKER, key])


def test_a_refusal_is_kept_with_its_folder_named_as_in_the_new_run(tmp_path):
    keep = Resume(tmp_path / "out")
    old, new = tmp_path / ".out.111.abc" / "tagA", tmp_path / ".out.222.def" / "tagA"
    keep.save("k", f"toa: {str(old / 'toa.txt')!r} holds no ping", old)
    assert keep.load("k", new) == f"toa: {str(new / 'toa.txt')!r} holds no ping"


def test_the_key_is_the_inputs_bytes_not_their_paths(tracked, tmp_path):
    folder, receivers, _ = tracked
    copy = tmp_path / "elsewhere.txt"
    copy.write_bytes((folder / "tag0.txt").read_bytes())
    key = job_key(folder / "tag0.txt", receivers, OPTIONS)
    assert job_key(copy, receivers, OPTIONS) == key
    assert job_key(folder / "tag1.txt", receivers, OPTIONS) != key
    assert job_key(folder / "tag0.txt", receivers, OPTIONS | {"sound_speed": 1481.0}) != key
    series = tmp_path / "speed.csv"
    series.write_text("t,sound_speed_m_s\n0,1480\n")
    with_file = job_key(folder / "tag0.txt", receivers, OPTIONS | {"sound_speed_path": series})
    series.write_text("t,sound_speed_m_s\n0,1481\n")  # the same path, other bytes: another key
    assert job_key(folder / "tag0.txt", receivers, OPTIONS | {"sound_speed_path": series}) != with_file


def test_a_damaged_entry_is_tracked_again(tracked, tmp_path):
    folder, receivers, outcome = tracked
    keep = Resume(tmp_path / "out")
    keep.save("k", outcome, folder)
    entry = resume_folder(tmp_path / "out") / "k" / "track.parquet"
    entry.write_bytes(entry.read_bytes()[: entry.stat().st_size // 2])
    assert keep.load("k", folder) is None and keep.kept == 0


def test_a_folder_that_is_not_ours_is_neither_used_nor_removed(tracked, tmp_path):
    folder, receivers, outcome = tracked
    theirs = resume_folder(tmp_path / "out")
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    with pytest.warns(UserWarning, match="not sblsim's resume folder"):
        keep = Resume(tmp_path / "out")
    keep.save("k", outcome, folder)
    keep.remove()
    assert sorted(p.name for p in theirs.iterdir()) == ["notes.txt"]
    linked = resume_folder(tmp_path / "linked")
    linked.symlink_to(theirs)
    with pytest.warns(UserWarning, match="a link"):
        assert not Resume(tmp_path / "linked").usable


def test_a_full_disk_is_said_once_and_leaves_no_entry(tracked, tmp_path, monkeypatch):
    folder, receivers, outcome = tracked

    def full(entry, result, where):
        (entry / "track.parquet").write_bytes(b"PAR1")  # written in part, then the disk is full
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(resume, "_write", full)
    keep = Resume(tmp_path / "out")
    with pytest.warns(UserWarning, match="no longer kept"):
        keep.save("k", outcome, folder)
    keep.save("k2", outcome, folder)  # not tried again
    assert sorted(p.name for p in resume_folder(tmp_path / "out").iterdir()) == [MARKER]
    assert keep.load("k", folder) is None


def test_a_run_stopped_part_way_tracks_only_the_unfinished_tags_again(tracked, tmp_path, monkeypatch):
    folder, receivers, outcome = tracked
    jobs = [(f"tag{k}", folder / ("tag0.txt" if k == 0 else "tag1.txt"), receivers, OPTIONS | {"seed": k})
            for k in range(4)]
    calls: list[int] = []

    def tracked_once(toa, rec, options):
        calls.append(options["seed"])
        if options["seed"] == 2 and len(calls) == 3:
            raise KeyboardInterrupt
        return outcome if options["seed"] % 2 == 0 else f"toa: {str(toa)!r} refused ({options['seed']})"

    monkeypatch.setattr(many, "track_tag", tracked_once)
    keep = Resume(tmp_path / "out")
    with pytest.raises(KeyboardInterrupt):
        many.run_tracks(jobs, workers=1, resume=keep)
    assert calls == [0, 1, 2]
    again = Resume(tmp_path / "out")
    ended: list[str] = []
    results = many.run_tracks(jobs, workers=1, resume=again, ended=lambda name, _: ended.append(name))
    assert calls == [0, 1, 2, 2, 3] and again.kept == 2 and sorted(ended) == ["tag0", "tag1", "tag2", "tag3"]
    assert results["tag1"] == f"toa: {str(jobs[1][1])!r} refused (1)"
    pd.testing.assert_frame_equal(results["tag0"].track, outcome.track, check_exact=True)
    again.remove()
    assert not resume_folder(tmp_path / "out").exists()


def test_a_worker_tracks_copies_of_the_files_and_names_them_as_sent(tracked, tmp_path, monkeypatch):
    folder, receivers, outcome = tracked
    series = tmp_path / "speed.csv"
    series.write_text("t,sound_speed_m_s\n0,1480\n")
    seen: dict[str, Path] = {}

    def on_worker(toa, rec, options):
        seen.update(toa=toa, receivers=rec, speed=options["sound_speed_path"])
        return f"toa: {str(toa)!r}, speed {str(options['sound_speed_path'])!r}"

    monkeypatch.setattr(many, "track_tag", on_worker)
    sent = many.sent_files(folder / "tag0.txt", receivers, {"sound_speed_path": series, "seed": 1})
    line = many.track_sent(sent, {"sound_speed_path": series, "seed": 1})
    assert line == f"toa: {str(folder / 'tag0.txt')!r}, speed {str(series)!r}"
    assert seen["toa"] != folder / "tag0.txt" and seen["toa"].name == "tag0.txt" and not seen["toa"].exists()
    assert sent["receivers"] == (str(receivers), receivers.read_bytes()) and seen["speed"].name == "speed.csv"
    moved = many._relocated(outcome, {str(folder): "/there"})
    assert moved.track is outcome.track and moved.summary.keys() == outcome.summary.keys()


@pytest.mark.slow
def test_a_study_killed_mid_way_and_run_again_writes_the_uninterrupted_tracks(tmp_path):
    """``sblsim track`` killed (SIGKILL) once its synchronisation and first tag are kept, then run again with the
    same ``--out``: neither is made again (study.json's ``resumed``), and every track and the synchronisation's files
    are the uninterrupted run's."""
    from sblsim.orchestrator.telemetry.simulate import simulate_study

    sim = simulate_study(n_receivers=9, n_tags=3, days=0.25, redeployed=1, seed=4)
    files = sim.write(tmp_path / "vue", "vue")
    command = [sys.executable, "-m", "sblsim.orchestrator.cli", "track", str(files["detections"]), "--receivers",
               str(files["deployments"]), "--tags", str(files["tags"]), "--workers", "1"]
    subprocess.run(command + ["--out", str(tmp_path / "whole")], check=True, capture_output=True)
    stopped = subprocess.Popen(command + ["--out", str(tmp_path / "out")], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    kept = resume_folder(tmp_path / "out")
    deadline = time.monotonic() + 300
    while stopped.poll() is None and time.monotonic() < deadline:
        if kept.is_dir() and sum(len(p.name) == 64 for p in kept.iterdir()) >= 2:  # the synchronisation, a tag
            break
        time.sleep(0.05)
    assert stopped.poll() is None, "the study ended before a tag was kept"
    stopped.send_signal(signal.SIGKILL)
    stopped.wait()
    assert not (tmp_path / "out").exists()
    again = subprocess.run(command + ["--out", str(tmp_path / "out")], check=True, capture_output=True, text=True)
    assert "tags and the synchronisation kept from an interrupted run" in again.stdout
    summary = json.loads((tmp_path / "out" / "study.json").read_text())
    assert summary["resumed"]["tags_kept"] >= 1 and summary["resumed"]["taken"] == ["the synchronisation"]
    assert not kept.exists()
    for name in ("sync.json", "offsets.csv", "residuals.csv", "sync_tags.csv"):  # the kept synchronisation's files
        mine, whole_run = ((folder / "sync" / name).read_text() for folder in (tmp_path / "out", tmp_path / "whole"))
        if name == "sync.json":  # but the time the synchronisation took
            mine, whole_run = (re.sub(r'"wall_time_s": [0-9.e+-]+', "", t) for t in (mine, whole_run))
        assert mine == whole_run, name
    whole = pd.read_csv(tmp_path / "whole" / "tracks.csv")
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "out" / "tracks.csv"), whole)
    tags = [p.name for p in (tmp_path / "whole" / "tags").iterdir()]
    for tag in tags:
        assert (tmp_path / "out" / "tags" / tag / "track.csv").read_bytes() == \
            (tmp_path / "whole" / "tags" / tag / "track.csv").read_bytes()


def test_what_ended_returns_is_kept_and_a_written_outcome_keeps_its_track_alone(tracked, tmp_path, monkeypatch):
    """A study written to a folder writes each tag's files as it ends and keeps its track alone
    (:func:`~sblsim.orchestrator.tracks.outputs.written_light`): the files those of the whole outcome."""
    folder, receivers, outcome = tracked
    monkeypatch.setattr(many, "track_tag", lambda toa, rec, options: outcome)
    jobs = [(f"tag{k}", folder / "tag0.txt", receivers, OPTIONS | {"seed": k}) for k in range(2)]
    results = many.run_tracks(jobs, workers=1, ended=lambda name, result: written_light(result, tmp_path / name)
                              if name == "tag0" else None)
    light = results["tag0"]
    assert results["tag1"] is outcome and outcome.estimates is not None  # None returned: the outcome kept whole
    assert light.estimates is None and light.errors is None and light.bound is None and light.set_aside is None
    assert light.track is outcome.track and light.summary is outcome.summary
    for name in ("track", "estimates"):  # as the whole outcome's are written
        assert (tmp_path / "tag0" / f"{name}.csv").read_text() == getattr(outcome, name).to_csv(index=False)
    assert json.loads((tmp_path / "tag0" / "summary.json").read_text()) == outcome.summary


def test_an_entry_written_elsewhere_is_kept_whole_or_said_once(tracked, tmp_path):
    """:meth:`Resume.staging`, :func:`~sblsim.orchestrator.tracks.resume.write_entry` (as a worker writes it) and
    :meth:`Resume.adopt`: the entry read back as the outcome; an entry that could not be written is said and leaves
    nothing, a disk's failure once (not tried again), an entry's alone (the others still kept)."""
    folder, _, outcome = tracked
    keep = Resume(tmp_path / "out")
    staged = keep.staging("k")
    assert not staged.exists() and staged.parent == resume_folder(tmp_path / "out")
    keep.adopt("k", staged, resume.write_entry(staged, outcome, folder))
    back = keep.load("k", folder)
    pd.testing.assert_frame_equal(back.estimates, outcome.estimates)
    pd.testing.assert_frame_equal(back.track, outcome.track)
    with pytest.warns(UserWarning, match=r"not kept for a rerun \(ValueError: a table"):
        keep.adopt("e", keep.staging("e"), ("entry", "ValueError: a table"))
    assert keep.usable
    staged = keep.staging("d")
    staged.mkdir()
    (staged / "track.parquet").write_bytes(b"PAR1")  # written in part, then the disk was full
    with pytest.warns(UserWarning, match="no longer kept"):
        keep.adopt("d", staged, ("disk", os.strerror(errno.ENOSPC)))
    assert not keep.usable and keep.staging("d2") is None
    late = resume_folder(tmp_path / "out") / ".late"  # a worker's entry ending after the disk's failure: not kept,
    late.mkdir()  # not said again
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        keep.adopt("late", late, None)
    assert not late.exists()
    assert sorted(p.name for p in resume_folder(tmp_path / "out").iterdir()) == sorted([MARKER, "k"])


def test_written_main_writes_the_whole_outcomes_files_and_sends_back_its_tracks_rows(tracked, tmp_path):
    """:func:`~sblsim.orchestrator.tracks.outputs.written_main`: the files of the whole outcome; what is sent back its
    track estimator's rows alone (its ``tags.csv`` row the whole outcome's), no other table; a refusal as it is."""
    from sblsim.orchestrator.telemetry.tag_rows import tracked_row
    from sblsim.orchestrator.tracks.outputs import written_main

    _, _, outcome = tracked
    sent = written_main(outcome, tmp_path / "t")
    for name in ("track", "estimates"):
        assert (tmp_path / "t" / f"{name}.csv").read_text() == getattr(outcome, name).to_csv(index=False)
    main = outcome.summary["track"]
    assert set(sent.estimates["estimator"]) == {main} and outcome.estimates["estimator"].nunique() > 1
    assert len(sent.estimates) == int((outcome.estimates["estimator"] == main).sum())
    assert sent.errors is None and sent.bound is None and sent.set_aside is None and sent.track is outcome.track
    row = {"pings": 60, "pings_at_once": 60}
    assert tracked_row(sent, 1.0, row) == tracked_row(outcome, 1.0, row)
    assert written_main("refused: a line", tmp_path / "r") == "refused: a line" and not (tmp_path / "r").exists()


@pytest.mark.slow
def test_worker_processes_keep_and_finish_each_tag_as_one_process_does(tracked, tmp_path):
    """run_tracks in two worker processes with ``finish`` and a resume folder: each tag kept whole for a rerun by its
    worker (no folder of a temporary name left), finished there (what ``ended`` sees, its files), the files those of
    one process's; run again, every tag taken from the folder and finished here, to the same files."""
    from functools import partial

    from sblsim.orchestrator.tracks.outputs import written_main

    (tmp_path / "in").mkdir()
    folder, receivers = _array(tmp_path / "in", tags=3)
    jobs = [(f"tag{k}", folder / f"tag{k}.txt", receivers, OPTIONS) for k in range(3)]

    def run(out: Path, workers: int) -> dict:
        seen: dict = {}
        finish = {name: partial(written_main, out=out / name) for name, *_ in jobs}
        many.run_tracks(jobs, workers=workers, resume=Resume(out), finish=finish,
                        ended=lambda name, result: seen.setdefault(name, result) and None)
        return seen

    one = run(tmp_path / "one", 1)
    seen = run(tmp_path / "many", 2)
    kept = resume_folder(tmp_path / "many")
    assert sorted(p.name for p in kept.iterdir()) == sorted([MARKER] + [job_key(*j[1:]) for j in jobs])
    shutil.rmtree(tmp_path / "many" / "tag0")
    again = Resume(tmp_path / "many")
    seen_again = {}
    many.run_tracks(jobs, workers=2, resume=again, ended=lambda name, result: seen_again.setdefault(name, result),
                    finish={name: partial(written_main, out=tmp_path / "many" / name) for name, *_ in jobs})
    assert again.kept == 3
    for name, *_ in jobs:
        for sent in (seen[name], seen_again[name]):
            pd.testing.assert_frame_equal(sent.estimates, one[name].estimates)
            assert set(sent.estimates["estimator"]) == {sent.summary["track"]}
        for file in ("track.csv", "estimates.csv"):
            assert (tmp_path / "many" / name / file).read_bytes() == (tmp_path / "one" / name / file).read_bytes()

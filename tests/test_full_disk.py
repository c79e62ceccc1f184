"""A full disk during the work: one line, exit 2, nothing half-written; a campaign resumes afterwards.

The disk is a small tmpfs mounted for the test; where the machine does not allow mounting (not root,
or no privilege in the container) the test is skipped.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

STUDY = """[study]
name = "tiny"
scenarios = ["semicircle"]
replicates = 40
seed = 3
set = ["simulation.duration=5"]
[[factors]]
name = "gps"
key = "platform.gps_sigma"
low = 0.1
high = 3.5
"""


@pytest.fixture
def small_disk(tmp_path):
    """A tmpfs of 64 KiB at ``tmp_path/disk``; yields (path, resize)."""
    disk = tmp_path / "disk"
    disk.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(disk)], capture_output=True)
    if done.returncode != 0:
        pytest.skip("this machine does not allow mounting a tmpfs")

    def resize(size: str) -> None:
        subprocess.run(["mount", "-o", f"remount,size={size}", str(disk)], check=True, capture_output=True)

    try:
        yield disk, resize
    finally:
        subprocess.run(["umount", str(disk)], capture_output=True)


def _sblsim(*args, cwd):
    return subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def _one_line(proc) -> str:
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-2000:])
    assert "Traceback" not in proc.stderr
    lines = [line for line in proc.stderr.splitlines() if not line.startswith("campaign: ")]  # progress lines
    assert len(lines) == 1 and lines[0].startswith("sblsim: error:"), proc.stderr
    return lines[0]


@pytest.mark.slow
def test_run_on_a_full_disk_writes_nothing(small_disk, tmp_path):
    disk, _ = small_disk
    line = _one_line(_sblsim("run", "semicircle", "--out", disk / "r", cwd=tmp_path))
    assert "No space left on device" in line
    assert list(disk.iterdir()) == []  # no half-written results, no staging folder


@pytest.mark.slow
def test_campaign_on_a_full_disk_resumes_to_the_same_runs(small_disk, tmp_path):
    disk, resize = small_disk
    (tmp_path / "tiny.toml").write_text(STUDY)
    line = _one_line(_sblsim("campaign", "tiny.toml", "--out", disk / "c", "--workers", "1", "--batch", "10",
                             cwd=tmp_path))
    assert "--resume" in line
    resize("64m")
    resumed = _sblsim("campaign", "tiny.toml", "--out", disk / "c", "--workers", "1", "--batch", "10", "--resume",
                      cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    whole = _sblsim("campaign", "tiny.toml", "--out", tmp_path / "whole", "--workers", "1", "--batch", "10",
                    cwd=tmp_path)
    assert whole.returncode == 0, whole.stderr[-2000:]
    a = pd.read_parquet(disk / "c" / "runs.parquet").drop(columns=["wall_time"], errors="ignore")
    b = pd.read_parquet(tmp_path / "whole" / "runs.parquet").drop(columns=["wall_time"], errors="ignore")
    pd.testing.assert_frame_equal(a.sort_values(list(a.columns[:4])).reset_index(drop=True),
                                  b.sort_values(list(b.columns[:4])).reset_index(drop=True))
    assert not [p.name for p in Path(disk / "c").iterdir() if p.name.endswith(".tmp")]


@pytest.mark.slow
def test_export_log_on_a_full_disk_leaves_no_run_folder(small_disk, tmp_path):
    """The run's own files (on another disk) move into place only once its log is written: a log that does not fit
    leaves neither a partial log nor the run's folder, and the error says so."""
    disk, _ = small_disk
    line = _one_line(_sblsim("run", "semicircle", "--out", tmp_path / "o", "--export-log", disk / "log.csv",
                             cwd=tmp_path))
    assert line.startswith("sblsim: error: --export-log: No space left on device; neither the log nor")
    assert f"nor were the run's results ({str(tmp_path / 'o')!r} is as it was)" in line, line
    assert not (tmp_path / "o").exists()
    assert list(disk.iterdir()) == []


@pytest.mark.slow
def test_export_log_into_a_new_folder_on_a_full_disk_leaves_no_folder(small_disk, tmp_path):
    """The folder made for the log goes with the failed write: nothing half-written is left on the disk."""
    disk, _ = small_disk
    line = _one_line(_sblsim("run", "semicircle", "--out", tmp_path / "o", "--export-log", disk / "logs" / "a.csv",
                             cwd=tmp_path))
    assert line.startswith("sblsim: error: --export-log: No space left on device; neither the log nor")
    assert list(disk.iterdir()) == []


def test_the_log_and_its_truth_track_are_written_together(tmp_path):
    """A failure writing the second file (the truth track) replaces neither: the earlier pair stays whole."""
    import errno

    from sblsim.orchestrator.io.output import write_together

    old = {tmp_path / "log.csv": "old log", tmp_path / "log_truth.csv": "old truth"}
    for path, text in old.items():
        path.write_text(text)

    def full(tmp):
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(OSError):
        write_together({tmp_path / "log.csv": lambda tmp: tmp.write_text("new log"), tmp_path / "log_truth.csv": full})
    assert {p: p.read_text() for p in old} == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "log_truth.csv"]  # no temporary file left
    with pytest.raises(OSError):
        write_together({tmp_path / "new" / "deeper" / "a.csv": full})
    assert not (tmp_path / "new").exists()  # the folders made for it went with it


@pytest.mark.slow
def test_calibrate_a_log_on_a_full_disk_is_one_line(small_disk, tmp_path):
    """A log's calibration has a note (its a-priori positions are guessed): it is said after the write, so that a
    write that fails says one line."""
    from sblsim.orchestrator.surveys.log import write_log
    from sblsim.orchestrator.surveys.simulate import load_simulated, replicate

    disk, _ = small_disk
    write_log(replicate(load_simulated("box-in", ["survey.duration_s=200"]), 0)[0].log, tmp_path / "survey.csv")
    line = _one_line(_sblsim("calibrate", "survey.csv", "--out", disk / "c", cwd=tmp_path))
    assert "No space left on device" in line
    assert list(disk.iterdir()) == []
    done = _sblsim("calibrate", "survey.csv", "--out", tmp_path / "c", cwd=tmp_path)
    assert done.returncode == 0 and done.stderr.startswith("note: the a-priori positions are guessed"), done.stderr


#: A small design problem (seconds): an LBL of 3 or 4 transponders under a 30 m work area on the paper's channel.
DESIGN = """[design]
name = "small"
scenario = "semicircle"
[work_area]
radius_m = 30.0
depths_m = [5.0]
points = 7
[candidates]
systems = ["lbl"]
transponders = [3, 4]
[seafloor]
radius_m = 60.0
depth_m = 20.0
[search]
generations = 10
[monte_carlo]
replicates = 10
path = false
"""


@pytest.mark.slow
def test_design_on_a_full_disk_writes_nothing(small_disk, tmp_path):
    """The design's files (its json, its table, its scenario files and figures) are written at once: a full disk
    leaves none of them."""
    disk, _ = small_disk
    (tmp_path / "small.toml").write_text(DESIGN)
    line = _one_line(_sblsim("design", "small.toml", "--out", disk / "d", cwd=tmp_path))
    assert "No space left on device" in line
    assert list(disk.iterdir()) == []


@pytest.mark.slow
def test_a_study_on_a_full_disk_keeps_its_tracked_tags_and_resumes_to_the_same_tracks(small_disk, tmp_path):
    """``sblsim track`` whose disk fills as it writes its output (1.2 MB: the tags tracked and kept, the study's
    1.8 MB of files not): one line, exit 2, no output; run again on a larger disk, every tag taken from the kept
    ones, and the tracks those of a study on a disk with room."""
    from sblsim.orchestrator.telemetry.simulate import simulate_study
    from sblsim.orchestrator.tracks.resume import resume_folder

    disk, resize = small_disk
    files = simulate_study(n_receivers=9, n_tags=3, days=0.25, redeployed=1, seed=4).write(tmp_path / "vue", "vue")
    args = ("track", files["detections"], "--receivers", files["deployments"], "--tags", files["tags"],
            "--workers", "1", "--out")
    resize("1200k")
    line = _one_line(_sblsim(*args, disk / "o", cwd=tmp_path))
    assert "No space left on device" in line
    assert [p.name for p in disk.iterdir()] == [resume_folder(disk / "o").name]
    resize("64m")
    resumed = _sblsim(*args, disk / "o", cwd=tmp_path)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert "resumed: 3 of 3 tags and the synchronisation kept" in resumed.stdout
    whole = _sblsim(*args, tmp_path / "whole", cwd=tmp_path)
    assert whole.returncode == 0, whole.stderr[-2000:]
    assert (disk / "o" / "tracks.csv").read_bytes() == (tmp_path / "whole" / "tracks.csv").read_bytes()
    assert sorted(p.name for p in disk.iterdir()) == ["o"]

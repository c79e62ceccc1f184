"""Stray rows and a wrong interval through ``sblsim replay --format toa`` and ``sblsim toa`` (issue 87): rows the
stated random interval shows to be no pings set aside (counted on the console, listed in ``set_aside.csv``, kept in
``track.csv`` with no estimate and their reason), a stated interval the data contradict as a whole refused in one
line with exit 2 and nothing written, taken with ``--force-interval`` and said.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking.strays import SET_ASIDE_REASON
from sblsim.orchestrator.cli import main

RECEIVERS = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0]])
NAMES = [f"R{k}" for k in range(len(RECEIVERS))]
BOATS = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


@pytest.fixture(scope="module")
def record(tmp_path_factory):
    """A random-interval tag (20-40 s) heard by 6 receivers, 4 stray codes inserted between its pings (each at one
    receiver, at a uniform time between two pings); the files, the matrix and which rows were inserted."""
    folder = tmp_path_factory.mktemp("strays")
    settings = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=30.0, acceleration_psd=1e-4)
    rng = np.random.default_rng(3)
    toa, _, _ = tt.simulate_pings(RECEIVERS, 100, settings, rng, speed=0.3, detection=0.9, ping_type="rbi",
                                  burst_interval=(20.0, 40.0))
    toa = toa[np.isfinite(toa).any(axis=1)]
    first = np.nanmin(toa, axis=1)
    rows = np.full((4, len(RECEIVERS)), np.nan)
    for row, a in zip(rows, rng.choice(len(toa) - 1, 4, replace=False)):
        row[rng.integers(len(RECEIVERS))] = rng.uniform(first[a], first[a + 1])
    matrix = np.vstack([toa, rows])
    inserted = np.r_[np.zeros(len(toa), bool), np.ones(4, bool)]
    order = np.argsort(np.nanmin(matrix, axis=1))
    matrix, inserted = matrix[order], inserted[order]
    pd.DataFrame({"name": NAMES, "x_m": RECEIVERS[:, 0], "y_m": RECEIVERS[:, 1]}).to_csv(folder / "r.csv", index=False)
    pd.DataFrame(matrix, columns=NAMES).to_csv(folder / "toa.csv", index=False, na_rep="NA", float_format="%.9f")
    return folder, matrix, inserted


def _replay(folder: Path, out: Path, interval: str, *extra: str) -> int:
    return main(["replay", str(folder / "toa.csv"), "--format", "toa", "--receivers", str(folder / "r.csv"),
                 "--sound-speed", "1480", "--ping-type", "rbi", "--burst-interval", interval, "--out", str(out),
                 *extra])


@pytest.mark.slow
def test_stray_rows_are_set_aside_listed_and_kept_in_the_track_with_their_reason(tmp_path, capsys, record):
    folder, matrix, inserted = record
    assert _replay(folder, tmp_path / "out", "20:40", "--smooth") == 0
    out = capsys.readouterr().out
    listed = pd.read_csv(tmp_path / "out" / "set_aside.csv")
    assert listed["ping"].tolist() == np.flatnonzero(inserted).tolist()  # every stray, and nothing else
    assert listed["receivers_heard"].tolist() == [1] * 4 and set(listed["reason"]) == {SET_ASIDE_REASON}
    assert np.allclose(listed["time"], np.nanmin(matrix[inserted], axis=1), atol=1e-9)
    assert "4 rows set aside as no pings of the tag's schedule" in out, out
    track = pd.read_csv(tmp_path / "out" / "track.csv")
    assert len(track) == len(matrix)  # the robust smoother's rows: one per row of the matrix, the numbering kept
    aside = (track["quality_reason"] == SET_ASIDE_REASON).to_numpy()
    assert np.array_equal(aside, inserted) and track.loc[aside, ["x", "y", "time"]].isna().all().all()
    assert track.loc[~aside, ["x", "y"]].notna().all().all()


@pytest.mark.slow
def test_an_interval_the_rows_contradict_is_refused_in_one_line_and_taken_with_force(tmp_path, capsys, record):
    folder, matrix, _ = record
    assert _replay(folder, tmp_path / "no", "30:60") == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sblsim: error: burst interval: 30:60 s stated, but the rows' first arrivals") and \
        "\n" not in err and "--force-interval" in err, err
    assert not (tmp_path / "no").exists()
    assert _replay(folder, tmp_path / "yes", "30:60", "--force-interval") == 0
    captured = capsys.readouterr()
    listed = pd.read_csv(tmp_path / "yes" / "set_aside.csv")
    warning = [line for line in captured.err.splitlines() if "--force-interval" in line]
    assert len(warning) == 1 and f"{len(listed)} of {len(matrix)} heard rows set aside" in warning[0], captured.err
    # the rows set aside are the rows the stated min shows, from the data alone: a step below it to the last kept
    first = np.nanmin(matrix, axis=1)
    kept = first[~np.isin(np.arange(len(matrix)), listed["ping"])]
    assert (np.diff(kept) >= 30.0 - ps.crossing_time(RECEIVERS, 1700.0)).all()


@pytest.mark.slow
def test_the_boats_cod_with_a_wrong_interval_is_refused_in_one_line(tmp_path, capsys):
    """The issue's case: the cod (it pings every 61-119 s) given 150:300 s dropped 6,594 of its detections as
    echoes, silently; now refused before the echo filter, and with --force-interval said."""
    sync = tmp_path / "sync"
    assert main(["sync", str(BOATS / "detections.csv"), "--receivers", str(BOATS / "hydrophones.csv"),
                 "--sound-speed-file", str(BOATS / "sound_speed.csv"), "--out", str(sync)]) == 0
    capsys.readouterr()
    args = ["toa", str(BOATS / "detections.csv"), "--receivers", str(BOATS / "hydrophones.csv"), "--sync", str(sync),
            "--tag", "4555", "--ping-type", "rbi", "--burst-interval"]
    assert main([*args, "150:300", "--out", str(tmp_path / "no")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("sblsim: error: burst interval: 150:300 s stated, but the detections' steps at one "
                          "receiver show ") and "\n" not in err, err
    low, high = (float(v) for v in err.split(" show ")[1].split(" s ")[0].split("-"))
    assert 55 <= low <= 70 and 110 <= high <= 125, err  # the cod's 60-120 s
    assert not (tmp_path / "no").exists()
    assert main([*args, "150:300", "--force-interval", "--out", str(tmp_path / "yes")]) == 0
    assert "multipath echoes by it" in capsys.readouterr().err
    assert main([*args, "60:120", "--out", str(tmp_path / "right")]) == 0
    assert "0 multipath echoes dropped" in capsys.readouterr().out


def test_a_tags_table_counts_the_set_aside_rows_apart(tmp_path, record):
    """``replay FOLDER --format toa``'s tags.csv (the study's has the same rule): the set-aside rows in
    ``set_aside``, in neither ``positioned`` nor ``flagged`` (counted from the tag's own track here)."""
    from sblsim.orchestrator.tracks.many import replay_toa_tags

    folder, matrix, inserted = record
    tags = tmp_path / "tags"
    tags.mkdir()
    (tags / "T1.csv").write_bytes((folder / "toa.csv").read_bytes())
    result = replay_toa_tags(tags, receivers=folder / "r.csv", workers=1, sound_speed=1480.0, ping_type="rbi",
                             burst_interval="20:40", smooth=False)
    row = result.table.set_index("tag").loc["T1"]
    track = result.tracks["T1"].track
    estimated = track["x"].notna().to_numpy()
    assert row["set_aside"] == inserted.sum() == (~estimated).sum()
    assert row["positioned"] == estimated.sum() == len(matrix) - inserted.sum()
    assert row["flagged"] == int((track["quality"][estimated] == "flagged").sum())


@pytest.mark.slow
@pytest.mark.parametrize("seed", [5, 6, 7])
def test_a_stable_interval_s_strays_are_set_aside_too(tmp_path, capsys, seed):
    """A stable-interval tag (``--ping-type sbi``, 30 s, 2 % of its pings missed at every receiver) with 3 % stray
    codes between its pings (each at one receiver): every stray set aside, every real ping kept (the rows against
    the simulation's own record of which are which); the same record without strays: nothing set aside."""
    settings = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=30.0, acceleration_psd=1e-4)
    rng = np.random.default_rng(seed)
    toa, _, _ = tt.simulate_pings(RECEIVERS, 300, settings, rng, speed=0.3, detection=0.9, ping_type="sbi")
    toa = toa[np.isfinite(toa).any(axis=1)]
    first = np.nanmin(toa, axis=1)
    count = int(0.03 * len(toa))
    rows = np.full((count, len(RECEIVERS)), np.nan)
    for row, a in zip(rows, rng.choice(len(toa) - 1, count, replace=False)):
        row[rng.integers(len(RECEIVERS))] = rng.uniform(first[a] + 1.0, first[a + 1] - 1.0)
    matrix = np.vstack([toa, rows])
    inserted = np.r_[np.zeros(len(toa), bool), np.ones(count, bool)]
    order = np.argsort(np.nanmin(matrix, axis=1))
    matrix, inserted = matrix[order], inserted[order]
    pd.DataFrame({"name": NAMES, "x_m": RECEIVERS[:, 0], "y_m": RECEIVERS[:, 1]}).to_csv(tmp_path / "r.csv",
                                                                                       index=False)
    for name, data in (("strays", matrix), ("plain", toa)):
        pd.DataFrame(data, columns=NAMES).to_csv(tmp_path / f"{name}.csv", index=False, na_rep="NA",
                                                 float_format="%.9f")
        assert main(["replay", str(tmp_path / f"{name}.csv"), "--format", "toa", "--receivers", str(tmp_path / "r.csv"),
                     "--sound-speed", "1480", "--ping-type", "sbi", "--out", str(tmp_path / name)]) == 0
    capsys.readouterr()
    listed = pd.read_csv(tmp_path / "strays" / "set_aside.csv")
    assert listed["ping"].tolist() == np.flatnonzero(inserted).tolist()
    assert not (tmp_path / "plain" / "set_aside.csv").exists() or pd.read_csv(
        tmp_path / "plain" / "set_aside.csv").empty

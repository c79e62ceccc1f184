"""``sblsim toa`` and ``sblsim.toa``: one tag's raw detections on drifting receiver clocks grouped into the times-of-
arrival matrix, checked against the simulator's own matrix (:func:`sblsim.models.tracking.simulate.simulate_pings`)
for each ping type, with and without multipath echoes; hostile or bad input refused in one line, exit 2, nothing
written.

The fast tests read a synchronisation written from the simulated clocks themselves (``offsets.csv`` with the true
offsets: the grouping alone is under test); the slow one synchronises the clocks with ``sblsim sync`` from simulated
sync tags first (:func:`sblsim.models.sync.simulate.simulate_sync`), so the whole chain is checked.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.sync.pings import build_pings, multipath_echoes
from sblsim.models.sync.simulate import simulate_sync, tag_detections
from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.simulate import simulate_pings
from sblsim.orchestrator.cli import main

#: The files' epoch [s since 1970 UTC] (the simulations' τ = 0), the receivers' square [m] and the tag's noise [s].
EPOCH = 1_700_000_000
SIDE = 600.0
NOISE = 0.15e-3
PING_TYPES = {"sbi": {}, "rbi": {"burst_interval": (20.0, 40.0)},
              "pbi": {"burst_sequence": np.array([15.0, 25.0, 20.0, 30.0, 18.0, 22.0])}}


def _yaps(path: Path, receiver: np.ndarray, time: np.ndarray, tag: np.ndarray, names: list[str]) -> None:
    """Detections as a YAPS table (``epo``, ``frac`` to the nanosecond), sorted by time (each receiver's rows in
    its own order)."""
    t = time + EPOCH
    order = np.argsort(t, kind="stable")
    t, receiver, tag = t[order], receiver[order], tag[order]
    epo = np.floor(t).astype(np.int64)
    pd.DataFrame({"epo": epo, "frac": [f"{v:.9f}" for v in np.clip(t - epo, 0, 0.999999999)],
                  "tag": tag, "serial": [names[j] for j in receiver]}).to_csv(path, index=False)


def _hydrophones(path: Path, positions: np.ndarray, names: list[str], sync_tags: list[str] | None = None) -> None:
    pd.DataFrame({"serial": names, "sync_tag": sync_tags or [""] * len(names), "x_m": positions[:, 0],
                  "y_m": positions[:, 1]}).to_csv(path, index=False)


def _true_sync(folder: Path, names: list[str], offset0: np.ndarray, drift: np.ndarray, hours: float) -> None:
    """``offsets.csv`` of the true clocks against receiver 0's (linear in each receiver's own time, so exact at
    hourly knots): what a perfect synchronisation writes."""
    folder.mkdir()
    edges = np.arange(int(np.ceil(hours)) + 2) * 3600.0 - 3600.0  # on each receiver's own clock, from τ = -1 h
    rows = []
    for j, name in enumerate(names):
        tau = (edges - offset0[j]) / (1 + drift[j])
        knots = edges - (tau + offset0[0] + drift[0] * tau)
        for k in range(len(edges) - 1):
            rows.append((name, k, edges[k] + EPOCH, edges[k + 1] + EPOCH, knots[k], knots[k + 1]))
    pd.DataFrame(rows, columns=["receiver", "bin", "start", "end", "offset_start_s", "offset_end_s"]).to_csv(
        folder / "offsets.csv", index=False)


def _tag(kind: str, seed: int, receivers: np.ndarray, n_pings: int = 300):
    settings = TrackerSettings(sound_speed=1480.0, sigma_toa=NOISE, interval=5.0)
    rng = np.random.default_rng(seed)
    toa, _, _ = simulate_pings(receivers, n_pings, settings, rng, speed=0.5, detection=0.7, first_emission=600.0,
                               ping_type=kind, **PING_TYPES[kind])
    return toa[np.isfinite(toa).any(axis=1)]  # the pings somebody heard: the rows a matrix from detections has


@pytest.fixture(scope="module")
def array():
    rng = np.random.default_rng(11)
    positions = rng.uniform(0, SIDE, (8, 2))
    offset0 = np.r_[0.0, rng.uniform(-2, 2, 7)]  # receiver 0 keeps true time: the reference
    drift = np.r_[0.0, rng.uniform(-20e-6, 20e-6, 7)]
    return positions, offset0, drift, [f"R{j}" for j in range(8)]


@pytest.mark.parametrize("kind", list(PING_TYPES))
@pytest.mark.parametrize("echoes", [0.0, 0.05])
def test_every_ping_grouped_as_emitted(tmp_path, array, kind, echoes):
    positions, offset0, drift, names = array
    truth = _tag(kind, 5, positions)
    rng = np.random.default_rng(7)
    d = tag_detections(truth, offset0, drift, rng, echo_share=echoes)
    _yaps(tmp_path / "d.csv", d.receiver, d.time, np.full(len(d.time), "T1"), names)
    _hydrophones(tmp_path / "h.csv", positions, names)
    hours = (np.nanmax(truth) + 10) / 3600
    _true_sync(tmp_path / "sync", names, offset0, drift, hours)
    options = {"ping_type": kind}
    if kind == "rbi":
        options["burst_interval"] = "20:40"
    if kind == "pbi":
        np.savetxt(tmp_path / "seq.txt", PING_TYPES["pbi"]["burst_sequence"])
        options["burst_sequence"] = tmp_path / "seq.txt"
    r = sblsim.toa(tmp_path / "d.csv", receivers=tmp_path / "h.csv", sync=tmp_path / "sync", tag="T1",
                   out=tmp_path / "out", **options)
    origin = r.summary["origin_epoch_s"]
    assert r.receivers == names
    assert r.toa.shape == truth.shape  # no ping split or merged
    assert np.array_equal(np.isfinite(r.toa), np.isfinite(truth))  # each ping's receivers as emitted
    heard = np.isfinite(truth)
    error = r.toa[heard] + origin - EPOCH - truth[heard]
    assert np.abs(error).max() < 2e-6  # the clocks undone: the simulator's own times (to the files' rounding)
    assert r.summary["detections"]["multipath"] == d.echo.sum()
    assert (d.echo.sum() > 0) == (echoes > 0)
    written = np.loadtxt(tmp_path / "out" / "toa.txt", skiprows=1, dtype=str)
    assert written.shape == truth.shape and np.array_equal(written == "NA", ~heard)
    pings = pd.read_csv(tmp_path / "out" / "pings.csv")
    assert np.array_equal(pings["receivers"], heard.sum(axis=1))
    assert np.allclose(pings["time_toa"], np.nanmin(r.toa, axis=1))
    summary = json.loads((tmp_path / "out" / "toa.json").read_text())
    assert summary["pings"] == len(truth)
    assert summary["shortest_interval_source"] == ("inferred" if kind == "sbi" else "given")  # sbi: no bounds given


def test_the_shortest_interval_inferred_and_the_replay_reads_the_matrix(tmp_path, array):
    positions, offset0, drift, names = array
    truth = _tag("rbi", 9, positions, n_pings=120)
    d = tag_detections(truth, offset0, drift, np.random.default_rng(1), echo_share=0.05)
    _yaps(tmp_path / "d.csv", d.receiver, d.time, np.full(len(d.time), "T1"), names)
    _hydrophones(tmp_path / "h.csv", positions, names)
    _true_sync(tmp_path / "sync", names, offset0, drift, (np.nanmax(truth) + 10) / 3600)
    r = sblsim.toa(tmp_path / "d.csv", receivers=tmp_path / "h.csv", sync=tmp_path / "sync", tag="T1",
                   out=tmp_path / "out")
    assert r.summary["shortest_interval_source"] == "inferred" and 15 < r.summary["shortest_interval_s"] < 20
    assert r.toa.shape == truth.shape and r.summary["detections"]["multipath"] == d.echo.sum()
    from sblsim.orchestrator.readers.receivers_file import read_receivers
    from sblsim.orchestrator.readers.toa_matrix import read_toa

    matrix, table = read_toa(tmp_path / "out" / "toa.txt"), read_receivers(tmp_path / "out" / "receivers.csv")
    assert matrix.names == names == table.names and np.allclose(table.positions, positions, atol=1e-4)
    assert np.allclose(matrix.toa, r.toa, equal_nan=True, atol=1e-8)


def test_echoes_and_pings_at_the_model_level():
    # receiver 0: an arrival, its echo 3 ms later and an echo of the echo; the next ping 30 s later
    receiver = np.array([0, 0, 0, 1, 0, 1])
    time = np.array([100.0, 100.003, 100.02, 100.2, 130.0, 130.1])
    assert multipath_echoes(receiver, time, 10.0).tolist() == [False, True, True, False, False, False]
    p = build_pings(receiver, time, 2, 0.7, 20.0)
    assert p.toa.shape == (2, 2) and p.toa[0].tolist() == [100.0, 100.2] and p.toa[1].tolist() == [130.0, 130.1]
    with pytest.raises(Exception, match="not longer than twice"):
        build_pings(receiver, time, 2, 0.7, 1.0)


@pytest.mark.slow
def test_the_synchronised_matrix_equals_the_simulators_within_the_noise(tmp_path):
    """``sblsim sync`` from simulated sync tags (12 receivers, 12 h), then ``sblsim toa`` of a tag heard on the same
    clocks: the matrix is the simulator's on the reference receiver's clock, within the timing noise."""
    sim = simulate_sync(n_receivers=12, hours=12.0, seed=4, side=800.0, noise=NOISE)
    names = [f"R{j}" for j in range(12)]
    truth = _tag("rbi", 3, sim.positions, n_pings=900)
    truth = truth[np.nanmax(truth, axis=1) < 11.5 * 3600]
    d = tag_detections(truth, sim.offset0, sim.drift, np.random.default_rng(2), echo_share=0.05)
    receiver = np.r_[sim.receiver, d.receiver]
    time = np.r_[sim.time, d.time]
    tags = np.r_[[f"S{i}" for i in sim.tag], np.full(len(d.time), "T1")]
    _yaps(tmp_path / "d.csv", receiver, time, tags, names)
    _hydrophones(tmp_path / "h.csv", sim.positions, names, [f"S{j}" for j in range(12)])
    assert main(["sync", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "h.csv"), "--sound-speed",
                 str(sim.sound_speed), "--reference", "R0", "--out", str(tmp_path / "sync")]) == 0
    assert main(["toa", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "h.csv"), "--sync",
                 str(tmp_path / "sync"), "--tag", "T1", "--ping-type", "rbi", "--burst-interval", "20:40", "--out",
                 str(tmp_path / "toa")]) == 0
    summary = json.loads((tmp_path / "toa" / "toa.json").read_text())
    got = np.loadtxt(tmp_path / "toa" / "toa.txt", skiprows=1, dtype=str)
    got = np.where(got == "NA", "nan", got).astype(float) + summary["origin_epoch_s"] - EPOCH
    assert got.shape == truth.shape and np.array_equal(np.isfinite(got), np.isfinite(truth))
    heard = np.isfinite(truth)
    on_reference = truth + sim.offset0[0] + sim.drift[0] * truth  # the true arrivals read on R0's clock
    error = got[heard] - on_reference[heard]
    print(f"synchronised TOA matrix: {heard.sum()} arrivals, error RMS {np.sqrt(np.mean(error ** 2)) * 1e6:.1f} us, "
          f"max {np.abs(error).max() * 1e6:.1f} us (the timing noise itself is not in it: {NOISE * 1e6:.0f} us)")
    assert np.sqrt(np.mean(error ** 2)) < NOISE / 2 and np.abs(error).max() < 3 * NOISE
    assert summary["detections"]["multipath"] == d.echo.sum()


# --------------------------------------------------------------------------- bad input

def _case(tmp_path: Path, array) -> tuple[Path, Path, Path]:
    positions, offset0, drift, names = array
    truth = _tag("sbi", 2, positions, n_pings=40)
    d = tag_detections(truth, offset0, drift, np.random.default_rng(3))
    _yaps(tmp_path / "d.csv", d.receiver, d.time, np.full(len(d.time), "T1"), names)
    _hydrophones(tmp_path / "h.csv", positions, names)
    _true_sync(tmp_path / "sync", names, offset0, drift, 1.0)
    return tmp_path / "d.csv", tmp_path / "h.csv", tmp_path / "sync"


def _spoil(folder: Path, text: str) -> None:
    (folder / "offsets.csv").write_text(text)


@pytest.mark.parametrize("change, args, found", [
    (None, ["--tag", "nope"], "tag: 'nope' is never detected"),
    (None, ["--tag", "T1", "--burst-interval", "20:40"], "--burst-interval: only with --ping-type rbi"),
    (None, ["--tag", "T1", "--ping-type", "rbi", "--burst-interval", "40:20"], "--burst-interval: '40:20'"),
    (None, ["--tag", "T1", "--ping-type", "rbi", "--burst-interval", "0.5:1"], "not longer than twice"),
    (None, ["--tag", "../x"], "tag: '../x' is not allowed"),
    ("receiver,bin,start,end,offset_start_s,offset_end_s\nR0,0,1e9,1.1e9,abc,0\n", ["--tag", "T1"],
     "column offset_start_s: 'abc' is not allowed"),
    ("receiver,bin,start,end,offset_start_s,offset_end_s\n/etc/passwd,0,1e9,1.1e9,0,0\n", ["--tag", "T1"],
     "column receiver: '/etc/passwd' is not allowed"),
    ("receiver,bin,start,end,offset_start_s,offset_end_s\nR0,0,1e9,1.1e9,0,0\nR0,1,1.2e9,1.3e9,0,0\n",
     ["--tag", "T1"], "not the same increasing edges"),
    ("receiver,bin,start,end,offset_start_s,offset_end_s\nR0,0,1e9,1.1e9,0,0\nR0,1,1.1e9,1.2e9,1,0\n",
     ["--tag", "T1"], "not continuous"),
    ("receiver,bin\nR0,0\n", ["--tag", "T1"], "needs the columns"),
    ("missing", ["--tag", "T1"], "holds no offsets.csv"),
])
def test_bad_input_exits_2_in_one_line_and_writes_nothing(tmp_path, capsys, array, change, args, found):
    detections, hydrophones, sync = _case(tmp_path, array)
    if change == "missing":
        (sync / "offsets.csv").unlink()
    elif change is not None:
        _spoil(sync, change)
    out = tmp_path / "out"
    code = main(["toa", str(detections), "--receivers", str(hydrophones), "--sync", str(sync), "--out", str(out),
                 *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and found in err[0], err
    assert not out.exists()


def test_a_sync_folder_naming_paths_is_not_followed(tmp_path, array):
    """Only ``offsets.csv`` is read, by its own name: a ``sync.json`` naming files (or a device) changes nothing."""
    detections, hydrophones, sync = _case(tmp_path, array)
    (sync / "sync.json").write_text(json.dumps({"detections": {"file": "/dev/zero"}, "offsets": "/etc/passwd"}))
    r = sblsim.toa(detections, receivers=hydrophones, sync=sync, tag="T1")
    assert r.toa.shape[0] > 30 and r.out is None
    with pytest.raises(sblsim.ConfigError, match="sync"):
        sblsim.toa(detections, receivers=hydrophones, sync=None, tag="T1")
    with pytest.raises(sblsim.SblsimError, match="is not a folder"):
        sblsim.toa(detections, receivers=hydrophones, sync=sync / "offsets.csv", tag="T1")


@pytest.mark.slow
def test_replay_of_raw_detections_is_toa_then_the_tracker(tmp_path, capsys, array):
    """``sblsim replay DETECTIONS --format detections --sync DIR --tag ID``: the matrix ``sblsim toa`` writes,
    tracked as ``replay --format toa`` tracks that file."""
    detections, hydrophones, sync = _case(tmp_path, array)
    common = ["--receivers", str(hydrophones), "--sound-speed", "1480", "--acceleration-psd", "0.01"]
    assert main(["replay", str(detections), "--format", "detections", "--sync", str(sync), "--tag", "T1",
                 "--out", str(tmp_path / "track"), *common]) == 0
    assert main(["toa", str(detections), "--receivers", str(hydrophones), "--sync", str(sync), "--tag", "T1",
                 "--out", str(tmp_path / "toa")]) == 0
    assert main(["replay", str(tmp_path / "toa" / "toa.txt"), "--format", "toa", "--out", str(tmp_path / "alone"),
                 *common[:1], str(tmp_path / "toa" / "receivers.csv"), *common[2:]]) == 0
    one, two = (pd.read_csv(tmp_path / f / "track.csv") for f in ("track", "alone"))
    assert len(one) > 30 and np.allclose(one[["x", "y"]], two[["x", "y"]])
    assert "times of arrival of tag T1" in capsys.readouterr().out


@pytest.mark.parametrize("said, taken", [("seen", 2.2), ("stated", None)])
def test_the_survey_error_a_synchronisation_took_is_each_receivers_sigma_m(tmp_path, capsys, array, said, taken):
    """A synchronisation that took the survey error it saw (``sync.json``: ``survey_sigma_from`` ``seen``) gives it
    to the matrix's receivers (``receivers.csv``'s ``sigma_m``, which the tracker's σ take) and says so; one the
    user stated is not taken again (the user states it to the tracker)."""
    from sblsim.orchestrator.readers.receivers_file import read_receivers

    detections, hydrophones, sync = _case(tmp_path, array)
    (sync / "sync.json").write_text(json.dumps({"survey_sigma_m": 2.2, "survey_sigma_from": said}))
    assert main(["toa", str(detections), "--receivers", str(hydrophones), "--sync", str(sync), "--tag", "T1",
                 "--out", str(tmp_path / "toa")]) == 0
    table = read_receivers(tmp_path / "toa" / "receivers.csv")
    printed = capsys.readouterr().out
    if taken is None:
        assert table.sigma is None and "survey error" not in printed
    else:
        assert np.array_equal(table.sigma, np.full(len(table.names), taken))
        assert "survey error the synchronisation saw in its residuals between receivers: 2.2 m per axis" in printed
    assert json.loads((tmp_path / "toa" / "toa.json").read_text())["survey_sigma_m"] == taken


@pytest.mark.parametrize("stated", [None, "0", "1.5"])
def test_replay_of_raw_detections_takes_the_error_seen_unless_one_is_stated(tmp_path, capsys, array, stated):
    """``replay --format detections --sync DIR``: the matrix it tracks carries the error the folder's
    synchronisation saw (``sigma_m``), as ``sblsim toa``'s does; ``--survey-sigma`` states another in its place
    (the tracker then takes it for every receiver without a ``sigma_m``: none), said in a note."""
    from sblsim.orchestrator.cli import _parser
    from sblsim.orchestrator.readers.receivers_file import read_receivers
    from sblsim.orchestrator.tracks.replay_detections import replay_matrix

    detections, hydrophones, sync = _case(tmp_path, array)
    (sync / "sync.json").write_text(json.dumps({"survey_sigma_m": 2.2, "survey_sigma_from": "seen"}))
    argv = ["replay", str(detections), "--format", "detections", "--receivers", str(hydrophones), "--sync",
            str(sync), "--tag", "T1"] + ([] if stated is None else ["--survey-sigma", stated])
    with replay_matrix(_parser().parse_args(argv)) as toa_args:
        table = read_receivers(toa_args.receivers)
    err = capsys.readouterr().err
    if stated is None:
        assert np.array_equal(table.sigma, np.full(len(table.names), 2.2)) and "stated in place" not in err
    else:
        assert table.sigma is None and toa_args.survey_sigma == float(stated)
        assert f"--survey-sigma {float(stated):g} m stated in place of the survey error the synchronisation saw " \
               "(2.2 m per axis)" in err


def _refine(sync: Path, positions: np.ndarray, names: list[str], sigmas: dict[str, float]) -> None:
    """The folder as ``sblsim sync --refine-positions`` leaves it: ``positions.csv`` with the receivers in
    ``sigmas`` refined (each moved 1 m east, its error its ``position_sigma_m``), the others at the table's (3 m,
    the prior)."""
    refined = np.array([n in sigmas for n in names])
    pd.DataFrame({"serial": names, "x_m": positions[:, 0] + refined, "y_m": positions[:, 1], "refined": refined,
                  "position_sigma_m": [sigmas.get(n, 3.0) for n in names]}).to_csv(sync / "positions.csv",
                                                                                   index=False)


@pytest.mark.parametrize("stated", [None, "0", "1.5"])
def test_refined_positions_carry_each_ones_error_to_the_tracker(tmp_path, capsys, array, stated):
    """A synchronisation's refined positions reach the matrix with each one's error (``sigma_m``: its
    ``position_sigma_m``), as a study given that folder takes them;
    said on the console and in ``toa.json``. The replay from raw detections carries the same unless
    ``--survey-sigma`` states another in its place (a note)."""
    from sblsim.orchestrator.cli import _parser
    from sblsim.orchestrator.readers.receivers_file import read_receivers
    from sblsim.orchestrator.tracks.replay_detections import replay_matrix

    positions, _, _, names = array
    detections, hydrophones, sync = _case(tmp_path, array)
    sigmas = {"R0": 0.3, "R3": 0.6, "R5": 0.15}
    _refine(sync, positions, names, sigmas)
    expected = np.array([sigmas.get(n, 3.0) for n in names])
    argv = ["replay", str(detections), "--format", "detections", "--receivers", str(hydrophones), "--sync",
            str(sync), "--tag", "T1"] + ([] if stated is None else ["--survey-sigma", stated])
    with replay_matrix(_parser().parse_args(argv)) as toa_args:
        table = read_receivers(toa_args.receivers)
    said = capsys.readouterr()
    np.testing.assert_allclose(table.positions[:, 0], positions[:, 0] + np.isin(names, list(sigmas)), atol=1e-4)
    if stated is None:
        np.testing.assert_allclose(table.sigma, expected)
        assert "each one's error in the tracker's σ (receivers.csv's sigma_m): 0.15 to 3 m per axis" in said.out
        assert main(["toa", str(detections), "--receivers", str(hydrophones), "--sync", str(sync), "--tag", "T1",
                     "--out", str(tmp_path / "toa")]) == 0
        written = json.loads((tmp_path / "toa" / "toa.json").read_text())["positions"]["sigma_m"]
        assert written == pytest.approx(dict(zip(names, expected)))
    else:
        assert table.sigma is None and toa_args.survey_sigma == float(stated)
        assert f"--survey-sigma {float(stated):g} m stated in place of each refined position's error (0.15 to 3 m " \
               "per axis)" in said.err


@pytest.mark.parametrize("survey", [None, 1.5, np.array([0.4, 3.0])])
def test_receivers_csv_carries_each_receivers_survey_error(tmp_path, survey):
    """``sigma_m``: one error for every receiver (the synchronisation's seen), each receiver's own (a study's refined
    positions), or none; read back by the receivers' reader as the tracker reads it."""
    from sblsim.orchestrator.readers.receivers_file import read_receivers
    from sblsim.orchestrator.sync.matrix_files import write_matrix
    from sblsim.orchestrator.sync.toa import ToaOutcome

    matrix = ToaOutcome(np.array([[0.1, 0.2], [10.1, 10.3]]), ["A", "B"], np.array([[0.0, 0.0], [100.0, 0.0]]),
                        pd.DataFrame({"ping": [0, 1]}), {"tag": "T9"}, EPOCH, survey_sigma=survey)
    _, receivers = write_matrix(matrix, tmp_path)
    read = read_receivers(receivers).sigma
    if survey is None:
        assert read is None
    else:
        np.testing.assert_array_equal(read, np.broadcast_to(survey, (2,)))


@pytest.mark.slow
def test_replay_tracks_with_the_error_seen_as_with_it_stated(tmp_path, array):
    """The error a synchronisation took, tracked from raw detections: the same track and σ as the same replay with
    it stated (``--survey-sigma``), the same places with larger σ than with the positions exact (0)."""
    detections, hydrophones, sync = _case(tmp_path, array)
    (sync / "sync.json").write_text(json.dumps({"survey_sigma_m": 2.2, "survey_sigma_from": "seen"}))
    common = ["replay", str(detections), "--format", "detections", "--sync", str(sync), "--tag", "T1",
              "--receivers", str(hydrophones), "--sound-speed", "1480", "--acceleration-psd", "0.01"]
    for name, extra in (("seen", []), ("stated", ["--survey-sigma", "2.2"]), ("exact", ["--survey-sigma", "0"])):
        assert main([*common, *extra, "--out", str(tmp_path / name)]) == 0
    seen, stated, exact = (pd.read_csv(tmp_path / f / "track.csv") for f in ("seen", "stated", "exact"))
    pd.testing.assert_frame_equal(seen, stated)
    sigmas = [c for c in seen.columns if c.startswith("sigma")]
    assert sigmas and np.allclose(seen[["x", "y"]], exact[["x", "y"]])
    assert (seen[sigmas].to_numpy() > exact[sigmas].to_numpy()).all()


def test_replay_refuses_a_survey_sigma_out_of_range_before_reading(tmp_path, capsys, array):
    detections, hydrophones, sync = _case(tmp_path, array)
    code = main(["replay", str(detections), "--format", "detections", "--receivers", str(hydrophones), "--sync",
                 str(sync), "--tag", "T1", "--survey-sigma", "-1", "--out", str(tmp_path / "out")])
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--survey-sigma" in err[0], err
    assert "times of arrival" not in captured.out and not (tmp_path / "out").exists()


@pytest.mark.parametrize("args, found", [
    (["--format", "detections", "--tag", "T1"], "--sync: required with --format detections"),
    (["--format", "toa", "--tag", "T1", "--receivers", "x.csv"],
     "--tag: only with --format detections, yaps, vue, fathom, glatos, otn, actel, thelma"),
    (["--sync", "somewhere"], "--sync: only with --format detections"),
])
def test_replay_refuses_detection_options_out_of_place(tmp_path, capsys, array, args, found):
    detections, hydrophones, _ = _case(tmp_path, array)
    extra = [] if "--receivers" in args else ["--receivers", str(hydrophones)]
    code = main(["replay", str(detections), *args, *extra, "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and found in err[0], err
    assert not (tmp_path / "out").exists()


def test_a_depth_sensors_readings_reach_the_tracker_in_3d_and_are_said_left_out_in_2d(tmp_path, array):
    """``sblsim toa``'s ``toa.txt`` takes the readings in metres (``pings``' ``depth_m``) as its first column where
    the receivers are in 3-D (what ``replay --format toa`` reads as the tag's depth), the same values per ping;
    in 2-D none, and a note says they stay in ``pings.csv``; without readings neither."""
    from sblsim.orchestrator.readers.toa_matrix import DEPTH_COLUMN
    from sblsim.orchestrator.sync.matrix_files import sensor_depth, write_toa_folder
    from sblsim.orchestrator.sync.toa import ToaOutcome

    reading = np.array([3.0, np.nan, 4.5])
    toa = np.array([[0.1, 0.2], [10.1, np.nan], [20.3, 20.2]])
    flat = ToaOutcome(toa, ["A", "B"], np.array([[0.0, 0.0], [100.0, 0.0]]),
                      pd.DataFrame({"ping": [0, 1, 2], "depth_m": reading}), {"tag": "T9"}, EPOCH)
    deep = ToaOutcome(toa, ["A", "B"], np.array([[0.0, 0.0, 5.0], [100.0, 0.0, 6.0]]), flat.pings, {"tag": "T9"},
                      EPOCH)
    depth, note = sensor_depth(flat)
    assert depth is None and "T9" in note and "pings.csv" in note
    assert sensor_depth(ToaOutcome(toa, ["A", "B"], deep.positions, flat.pings[["ping"]], {"tag": "T9"}, EPOCH)) == (
        None, None)
    write_toa_folder(deep, tmp_path / "out")
    written = pd.read_csv(tmp_path / "out" / "toa.txt", sep=" ")
    assert list(written.columns) == [DEPTH_COLUMN, "A", "B"]
    np.testing.assert_array_equal(written[DEPTH_COLUMN].to_numpy(), reading)

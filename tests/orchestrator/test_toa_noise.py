"""The timing noise taken from a synchronisation (issue 87): ``sblsim sync`` measures each receiver's noise from its
sync-tag residuals (``offsets.csv``'s ``toa_sigma_s``) against the noise a simulated study drew (one receiver ten
times noisier); ``sblsim toa`` carries it into the matrix's ``receivers.csv``, which the replay takes and says so; a
synchronisation written before the column still reads (the default taken, said); ``--toa-sigma`` outside its range
is refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.tracking.timing import SIGMA_TOA
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.sync.clocks import read_clocks
from sblsim.orchestrator.telemetry.simulate import simulate_study

#: Each simulated receiver's timing noise [s]: 0.1 ms, one receiver ten times that, one 0.5 ms and one 2 ms.
NOISE = np.full(12, 1e-4)
NOISE[3], NOISE[7], NOISE[10] = 1e-3, 5e-4, 2e-3
#: The pings of the tag's matrix the replays here track (the first ones: the tracking is not under test).
PINGS = 40


@pytest.fixture(scope="module")
def synchronised(tmp_path_factory):
    """A 12-hour study of 12 receivers with the noise :data:`NOISE` and one tag, written, synchronised by ``sblsim
    sync`` and the tag's matrix built by ``sblsim toa`` from it (its first :data:`PINGS` pings kept)."""
    folder = tmp_path_factory.mktemp("noise")
    sim = simulate_study(n_receivers=len(NOISE), n_tags=1, days=0.5, redeployed=0, seed=3, sigma_toa=NOISE)
    files = sim.write(folder / "files", "vue")
    result = sblsim.sync(files["detections"], receivers=files["deployments"], out=folder / "sync")
    tag = sim.sheet["transmitter"].iloc[0]
    sblsim.toa(files["detections"], receivers=files["deployments"], sync=folder / "sync", tag=tag,
               out=folder / "toa")
    matrix = folder / "toa" / "toa.txt"
    (folder / "toa_whole.txt").write_text(matrix.read_text())  # (the tag's every ping, for the clock term)
    matrix.write_text("".join(matrix.read_text().splitlines(keepends=True)[:PINGS]))
    return sim, files, result, folder, tag


@pytest.mark.slow
def test_the_sync_measures_each_receivers_noise(synchronised):
    """Each receiver's ``toa_sigma_s`` is its simulated noise within 20 % (its residuals' part alone too), the
    noisier receiver's ten times the others' as drawn, the same on every row of the receiver in ``offsets.csv``."""
    sim, _, result, folder, _ = synchronised
    serials = sim.clocks["serial"].tolist()
    offsets = pd.read_csv(folder / "sync" / "offsets.csv", dtype={"receiver": str})
    per_receiver = offsets.groupby("receiver")["toa_sigma_s"]
    assert (per_receiver.nunique() == 1).all()
    measured = per_receiver.first()
    drawn = NOISE[[serials.index(r) for r in measured.index]]
    assert np.all(np.abs(measured.to_numpy() / drawn - 1) < 0.2), measured.to_numpy() / drawn
    parts = np.array([result.summary["toa_noise"][r]["residuals_s"] for r in measured.index])
    assert np.all(np.abs(parts / drawn - 1) < 0.2), parts / drawn
    quiet = np.median(measured[[serials[k] for k in np.flatnonzero(NOISE == 1e-4)]])
    assert 8 < measured[serials[3]] / quiet < 12


@pytest.mark.slow
def test_the_matrix_carries_it_and_the_tracker_takes_it(synchronised, tmp_path, capsys):
    """The matrix's ``receivers.csv`` holds each receiver's ``toa_sigma_s`` as the synchronisation measured it, the
    replay takes it per receiver (``summary["toa_noise"]``) and says so in one line; ``--toa-sigma`` given is taken
    instead, and said."""
    _, _, _, folder, _ = synchronised
    offsets = pd.read_csv(folder / "sync" / "offsets.csv", dtype={"receiver": str}).groupby("receiver").first()
    receivers = pd.read_csv(folder / "toa" / "receivers.csv", dtype={"name": str}).set_index("name")
    assert np.allclose(receivers["toa_sigma_s"], offsets.loc[receivers.index, "toa_sigma_s"], rtol=1e-5)
    assert main(["replay", str(folder / "toa" / "toa.txt"), "--format", "toa", "--receivers",
                 str(folder / "toa" / "receivers.csv"), "--sound-speed", "1480", "--out", str(tmp_path / "t")]) == 0
    out = capsys.readouterr().out
    assert "TOA noise per receiver from the synchronisation's residuals" in out
    summary = json.loads((tmp_path / "t" / "summary.json").read_text())
    taken = summary["toa_noise"]
    assert taken["source"] == "synchronisation"
    heard = list(taken["per_receiver_s"])
    assert np.allclose([taken["per_receiver_s"][n] for n in heard], receivers.loc[heard, "toa_sigma_s"])
    given = sblsim.replay_toa(folder / "toa" / "toa.txt", receivers=folder / "toa" / "receivers.csv",
                              sound_speed=1480.0, toa_sigma=3e-4)
    assert given.summary["toa_noise"] == {"source": "given", "sigma_s": 3e-4}


@pytest.mark.slow
def test_an_old_sync_folder_without_the_column_still_reads(synchronised, tmp_path, capsys):
    """A synchronisation written before ``toa_sigma_s`` (the column taken out) reads to the same clocks, its matrix
    has no ``toa_sigma_s`` and the replay takes the default 0.15 ms, said in one line."""
    _, files, _, folder, tag = synchronised
    old = tmp_path / "old"
    old.mkdir()
    pd.read_csv(folder / "sync" / "offsets.csv").drop(columns="toa_sigma_s").to_csv(old / "offsets.csv", index=False)
    clocks, new = read_clocks(old), read_clocks(folder / "sync")
    assert clocks.toa_sigma is None and new.toa_sigma is not None
    assert clocks.receivers == new.receivers and np.array_equal(clocks.knots, new.knots)
    assert main(["toa", str(files["detections"]), "--receivers", str(files["deployments"]), "--sync", str(old),
                 "--tag", tag, "--out", str(tmp_path / "toa")]) == 0
    assert "offsets.csv gives none" in capsys.readouterr().out
    assert "toa_sigma_s" not in pd.read_csv(tmp_path / "toa" / "receivers.csv").columns
    matrix = tmp_path / "toa" / "toa.txt"
    matrix.write_text("".join(matrix.read_text().splitlines(keepends=True)[:PINGS]))
    assert main(["replay", str(matrix), "--format", "toa", "--receivers", str(tmp_path / "toa" / "receivers.csv"),
                 "--sound-speed", "1480", "--out", str(tmp_path / "t")]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if "TOA noise" in line]
    assert lines == ["  TOA noise: 0.15 ms assumed (no synchronisation residuals); give --toa-sigma"]
    taken = json.loads((tmp_path / "t" / "summary.json").read_text())["toa_noise"]
    assert taken == {"source": "assumed", "sigma_s": SIGMA_TOA}


@pytest.mark.parametrize("value", ["0", "2", "1e-7", "nan"])
def test_toa_sigma_outside_its_range_is_refused_in_one_line(synchronised, tmp_path, capsys, value):
    """``--toa-sigma`` outside [1 µs, 1 s] is refused in one line naming it and the range, exit 2, nothing written:
    by ``sblsim replay --format toa`` and ``sblsim track``; ``sblsim.replay_toa`` and ``sblsim.track`` raise."""
    _, files, _, folder, _ = synchronised
    code = main(["replay", str(folder / "toa" / "toa.txt"), "--format", "toa", "--receivers",
                 str(folder / "toa" / "receivers.csv"), "--toa-sigma", value, "--out", str(tmp_path / "t")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--toa-sigma" in err[0] and "[1e-06, 1] s" in err[0], err
    code = main(["track", str(files["detections"]), "--receivers", str(files["deployments"]), "--toa-sigma", value,
                 "--out", str(tmp_path / "s")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--toa-sigma" in err[0], err
    assert not (tmp_path / "t").exists() and not (tmp_path / "s").exists()
    with pytest.raises(ConfigError, match="toa_sigma"):
        sblsim.replay_toa(folder / "toa" / "toa.txt", receivers=folder / "toa" / "receivers.csv",
                          toa_sigma=float(value))
    with pytest.raises(ConfigError, match="toa_sigma"):
        sblsim.track(files["detections"], receivers=files["deployments"], toa_sigma=float(value))


def test_a_receivers_files_noise_outside_its_range_is_refused(synchronised, tmp_path):
    """A receivers file's ``toa_sigma_s`` outside [1 µs, 1 s] is refused in one line naming the file, its line and
    the column."""
    _, _, _, folder, _ = synchronised
    table = pd.read_csv(folder / "toa" / "receivers.csv", dtype=str)
    table.loc[1, "toa_sigma_s"] = "5"
    table.to_csv(tmp_path / "receivers.csv", index=False)
    with pytest.raises(sblsim.SblsimError) as error:
        sblsim.replay_toa(folder / "toa" / "toa.txt", receivers=tmp_path / "receivers.csv", sound_speed=1480.0)
    text = str(error.value)
    assert "line 3" in text and "toa_sigma_s" in text and "\n" not in text


def test_each_receivers_clock_sigma_is_carried_to_the_matrix(synchronised):
    """``offsets.csv``'s ``clock_sigma_s`` is each receiver's offsets' own RMS sigma (``toa_noise``'s ``clock_s``,
    the same on every row of the receiver; 0 at the reference), within its ``toa_sigma_s`` (the two in quadrature
    with the residuals' part); the matrix's ``receivers.csv`` carries it (the still verdict's clock term: one fix sees
    one bin's error) and, for the stationary fix's clock term (``clock_mean_sigma_s``), each receiver's offset error
    averaged over the tag's arrivals at it: ``√(aᵀ C a)``, ``a`` the arrivals' mean weights
    on the bins' edges and C the edges' covariance from ``offsets.csv``'s sigmas (neighbours' from the drift's σ,
    farther ones the product of the correlations between: written out densely here), below the RMS of the edges'
    sigmas it leans on."""
    _, _, result, folder, _ = synchronised
    offsets = pd.read_csv(folder / "sync" / "offsets.csv", dtype={"receiver": str})
    per_receiver = offsets.groupby("receiver")
    assert (per_receiver["clock_sigma_s"].nunique() == 1).all()
    first = per_receiver.first()
    clock = np.array([result.summary["toa_noise"][r]["clock_s"] for r in first.index])
    np.testing.assert_allclose(first["clock_sigma_s"], clock)
    parts = np.array([result.summary["toa_noise"][r]["residuals_s"] for r in first.index])
    np.testing.assert_allclose(first["toa_sigma_s"], np.hypot(parts, clock), rtol=1e-9)
    assert (clock == 0).sum() == 1 and (clock[clock > 0] < first["toa_sigma_s"].to_numpy()[clock > 0]).all()
    receivers = pd.read_csv(folder / "toa" / "receivers.csv", dtype={"name": str}).set_index("name")
    np.testing.assert_allclose(receivers["clock_sigma_s"], first.loc[receivers.index, "clock_sigma_s"], rtol=1e-5)
    origin = json.loads((folder / "toa" / "toa.json").read_text())["origin_epoch_s"]
    whole = pd.read_csv(folder / "toa_whole.txt", sep=r"\s+", header=None, na_values="NA").to_numpy(float) + origin
    edges = np.r_[offsets.groupby("bin")["start"].first().to_numpy(), offsets["end"].max()]
    for k, name in enumerate(receivers.index):
        rows = offsets[offsets["receiver"] == name].sort_values("bin")
        sigma = np.r_[rows["offset_start_sigma_s"].to_numpy(), rows["offset_end_sigma_s"].to_numpy()[-1]]
        step = (np.diff(edges) * rows["drift_sigma"].to_numpy()) ** 2
        rho = (sigma[:-1] ** 2 + sigma[1:] ** 2 - step) / np.maximum(sigma[:-1] * sigma[1:], 1e-300)
        rho = np.where((sigma[:-1] > 0) & (sigma[1:] > 0), np.clip(rho / 2, -1, 1), 0.0)
        covariance = np.diag(sigma ** 2)
        for i in range(len(sigma)):
            for j in range(i + 1, len(sigma)):
                covariance[i, j] = covariance[j, i] = sigma[i] * sigma[j] * np.prod(rho[i:j])
        heard = whole[np.isfinite(whole[:, k]), k]
        bins = np.clip(np.searchsorted(edges, heard, side="right") - 1, 0, len(edges) - 2)
        f = (heard - edges[bins]) / np.diff(edges)[bins]
        a = (np.bincount(bins, 1 - f, len(edges)) + np.bincount(bins + 1, f, len(edges))) / len(heard)
        expected = np.sqrt(a @ covariance @ a)
        assert np.isclose(receivers.loc[name, "clock_mean_sigma_s"], expected, rtol=1e-4, atol=1e-9), name
        assert expected <= np.sqrt(a @ sigma ** 2) + 1e-12

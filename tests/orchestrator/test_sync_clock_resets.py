"""A receiver whose time goes back in the detections file's order (its clock reset at a download, its rows kept in the
order it logged them): read, not refused; ``sblsim sync`` splits its clock there (a new clock segment, its place
known from the file) and says it in one line with the line and the step; the offsets as good as without the reset;
``sblsim toa`` puts each detection in its own part's segment (two parts read the same times)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.sync.simulate import simulate_sync
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.readers.detections import MAX_CLOCK_RESETS, read_detections

#: The files' time of τ = 0 [s since 1970 UTC], the timing noise [s], the array and the reset's true time [s] (the
#: first gap of R2's detections under 10 s after it).
EPOCH = 1_700_000_000
NOISE = 0.15e-3
N, HOURS, AT = 6, 4.0, 2 * 3600.0


def _study(folder: Path, size: float | None):
    """Sync tags every 60 to 120 s (:func:`simulate_sync`) and a tag ``T1`` inside the array every 20 to 40 s, on the
    receivers' clocks, R2's reset by ``size`` soon after 2 h (None: no reset); written as a YAPS table in each
    receiver's logging order (receiver by receiver). Returns the simulation, T1's true arrivals (pings × receivers,
    NaN unheard) [s from τ = 0] and the file's line of R2's first row after the reset (None: none)."""
    sim = simulate_sync(n_receivers=N, hours=HOURS, seed=21, side=700.0, noise=NOISE, interval=(60.0, 120.0))
    rng = np.random.default_rng(8)
    emitted = 300.0 + np.cumsum(rng.uniform(20.0, 40.0, 800))
    emitted = emitted[emitted < HOURS * 3600 - 300]
    where = sim.positions.mean(axis=0) + [30.0, -20.0]
    truth = emitted[:, None] + np.linalg.norm(sim.positions - where, axis=1)[None] / sim.sound_speed
    truth = truth + rng.normal(0, NOISE, truth.shape)
    truth[rng.random(truth.shape) > 0.8] = np.nan
    ping, rec = np.nonzero(np.isfinite(truth))
    at = AT
    if size is not None:  # the reset between two of R2's detections less than 10 s apart (the draws the same)
        heard = np.sort(np.r_[sim.true_time(sim.receiver, sim.time)[sim.receiver == 2], truth[ping, rec][rec == 2]])
        k = np.flatnonzero((heard[:-1] > AT) & (np.diff(heard) < 10.0))[0]
        at = 0.5 * (heard[k] + heard[k + 1])
        sim = simulate_sync(n_receivers=N, hours=HOURS, seed=21, side=700.0, noise=NOISE, interval=(60.0, 120.0),
                            jump=(2, at, size))
    receiver = np.r_[sim.receiver, rec]
    tau = np.r_[sim.true_time(sim.receiver, sim.time, sim.after), truth[ping, rec]]
    time = sim.reading(receiver, tau) + EPOCH
    order = np.lexsort((tau, receiver))  # each receiver's rows in the order it logged them
    epo = np.floor(time[order]).astype(np.int64)
    names = np.array([f"R{j}" for j in range(N)])
    pd.DataFrame({"epo": epo, "frac": [f"{v:.9f}" for v in np.clip(time[order] - epo, 0, 0.999999999)],
                  "tag": np.r_[[f"S{i}" for i in sim.tag], np.full(len(rec), "T1")][order],
                  "serial": names[receiver][order]}).to_csv(folder / "d.csv", index=False)
    pd.DataFrame({"serial": names, "sync_tag": [f"S{j}" for j in range(N)], "x_m": sim.positions[:, 0],
                  "y_m": sim.positions[:, 1]}).to_csv(folder / "h.csv", index=False)
    first = None
    if size is not None:  # the header is line 1
        first = int(np.flatnonzero((receiver[order] == 2) & (tau[order] >= at))[0]) + 2
    return sim, truth, first


def _offset_errors(sim, folder: Path) -> np.ndarray:
    """[s] the clocks' offsets at each sync-tag arrival's own time less the truth (residuals.csv's ``time_sync``
    less R0's reading at the arrival's true time: the offset's error alone, the timing noise in both; R2's second
    segment read after the reset)."""
    residuals = pd.read_csv(folder / "residuals.csv")
    residuals = residuals[np.isfinite(residuals["time_sync"])]
    j = residuals["receiver"].str[1:].astype(int).to_numpy()
    after = (residuals["segment"].to_numpy() == 2) if "segment" in residuals else None
    tau = sim.true_time(j, residuals["time"].to_numpy() - EPOCH, after)
    return residuals["time_sync"].to_numpy() - EPOCH - (tau + sim.offset0[0] + sim.drift[0] * tau)


def _sync(folder: Path, capsys) -> list[str]:
    """``sblsim sync`` on the study: its warning lines."""
    capsys.readouterr()
    assert main(["sync", str(folder / "d.csv"), "--receivers", str(folder / "h.csv"), "--sound-speed", "1480",
                 "--reference", "R0", "--out", str(folder / "sync")]) == 0
    return [line for line in capsys.readouterr().err.splitlines() if "warning" in line]


@pytest.mark.slow
@pytest.mark.parametrize("size", [-20.0, -86400.0])
def test_a_reset_in_the_files_order_split_said_and_read_back(tmp_path, capsys, size):
    """R2's times after 2 h shifted by −20 s or −1 day, its rows in its logging order: one line names R2, the line of
    its first row after the reset and the step; the fitted size within 1 ms of the truth; nothing set aside; the
    offsets at the sync-tag arrivals within 1.1 times the RMS error of the same study without the reset; T1's
    arrivals on R0's clock within three times the timing noise, every one kept."""
    plain = tmp_path / "plain"
    plain.mkdir()
    _study(plain, None)
    assert not [line for line in _sync(plain, capsys) if "clock" in line]
    baseline = np.sqrt(np.mean(_offset_errors(simulate_sync(n_receivers=N, hours=HOURS, seed=21, side=700.0,
                                                            noise=NOISE, interval=(60.0, 120.0)),
                                              plain / "sync") ** 2))
    sim, truth, first = _study(tmp_path, size)
    lines = [line for line in _sync(tmp_path, capsys) if "clock" in line]
    assert len(lines) == 1 and "receiver R2" in lines[0] and f"at line {first} " in lines[0], lines
    step = float(re.search(r"its time goes back ([0-9.e+]+) s", lines[0])[1])
    assert abs(size) - 3600 < step <= abs(size) + 1e-6  # the file's step: the jump less the time between the rows
    fitted = re.search(r"fitted: it went back ([0-9.e+]+) s", lines[0])
    assert fitted and abs(float(fitted[1]) - abs(size)) < 1e-3 * max(1, abs(size) / 1e4)
    written = json.loads((tmp_path / "sync" / "sync.json").read_text())
    (b,) = written["clock_breaks"]
    assert b["receiver"] == "R2" and b["clock_part"] == 2 and b["reset"]["line"] == first
    assert abs(b["size_s"] - size) < 1e-3 and b["set_aside_from_s"] is None and b["synchronised"]
    errors = _offset_errors(sim, tmp_path / "sync")
    assert np.sqrt(np.mean(errors ** 2)) < 1.1 * baseline
    offsets = pd.read_csv(tmp_path / "sync" / "offsets.csv")
    assert sorted(offsets.loc[offsets["receiver"] == "R2", "clock_part"].unique()) == [1, 2]
    assert main(["toa", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "h.csv"), "--sync",
                 str(tmp_path / "sync"), "--tag", "T1", "--ping-type", "rbi", "--burst-interval", "20:40", "--out",
                 str(tmp_path / "toa")]) == 0
    summary = json.loads((tmp_path / "toa" / "toa.json").read_text())
    got = np.loadtxt(tmp_path / "toa" / "toa.txt", skiprows=1, dtype=str)
    got = np.where(got == "NA", "nan", got).astype(float) + summary["origin_epoch_s"] - EPOCH
    assert got.shape == truth.shape and summary["detections"]["at_clock_breaks"] == 0
    assert (np.isfinite(got) == np.isfinite(truth)).all()
    error = got[np.isfinite(got)] - (truth + sim.offset0[0] + sim.drift[0] * truth)[np.isfinite(truth)]
    assert np.abs(error).max() < 3 * NOISE


def test_resets_are_kept_as_parts_and_rows_out_of_order_refused(tmp_path):
    """A receiver going back twice: three parts, each reset with its line and step; a file sorted by tag (each
    receiver's parts sharing no tag) and one with more than MAX_CLOCK_RESETS back-steps refused in one line."""
    path = tmp_path / "d.csv"
    path.write_text("epo,frac,tag,serial\n100,0.5,7,A\n99,0.1,7,B\n3700,0,7,A\n90,0,7,A\n102,0.25,7,B\n"
                    "80,0,8,A\n96,0,7,A\n")
    d = read_detections(path)
    assert d.frame["clock_part"].tolist() == [1, 1, 1, 2, 1, 3, 3]
    assert [(r["receiver"], r["line"], r["previous_line"], r["step_s"], r["clock_part"]) for r in d.clock_resets] == [
        ("A", 5, 4, -3610.0, 2), ("A", 7, 5, -10.0, 3)]
    path.write_text("epo,frac,tag,serial\n100,0,7,A\n200,0,7,A\n50,0,8,A\n150,0,8,A\n")
    with pytest.raises(ModelError, match=r"line 4: receiver A's clock goes back 150 s from line 3 .*sorted by tag"):
        read_detections(path)
    rows = "".join(f"{1000 - 10 * k},0,{7 + k % 2},A\n{1005 - 10 * k},0,{7 + (k + 1) % 2},A\n"
                   for k in range(MAX_CLOCK_RESETS + 2))  # MAX_CLOCK_RESETS + 1 steps back
    path.write_text("epo,frac,tag,serial\n" + rows)
    with pytest.raises(ModelError, match=f"{MAX_CLOCK_RESETS + 1} such steps") as caught:
        read_detections(path)
    assert "\n" not in str(caught.value)
    assert read_detections(_plain(tmp_path)).clock_resets == [] and "clock_part" not in read_detections(
        _plain(tmp_path)).frame


def _plain(folder: Path) -> Path:
    path = folder / "plain.csv"
    path.write_text("epo,frac,tag,serial\n100,0.5,7,A\n99,0.1,7,B\n100,0.4995,7,A\n101,0,7,A\n")  # back 0.5 ms
    return path


@pytest.mark.slow
def test_a_time_logged_after_a_reset_is_corrected_in_its_clock_part(tmp_path):
    """``SyncResult.correct(receiver, times, part)``: R2's readings of T1's arrivals an hour after its −20 s reset,
    corrected in clock part 2, are the true arrivals on R0's clock (the simulation's) within three times the timing
    noise; read as part 1 (the default), the clock before the reset, they come out the reset's 20 s early (NaN outside
its span); a part R2 does not have refused in one line."""
    import sblsim

    sim, truth, _ = _study(tmp_path, -20.0)
    result = sblsim.sync(tmp_path / "d.csv", receivers=tmp_path / "h.csv", sound_speed=1480.0, reference="R0")
    tau = truth[:, 2][np.isfinite(truth[:, 2])]
    tau = tau[tau > AT + 3600.0]
    logged = sim.reading(np.full(len(tau), 2), tau) + EPOCH
    expected = tau + sim.offset0[0] + sim.drift[0] * tau
    assert len(tau) > 20
    assert np.abs(result.correct("R2", logged, part=2) - EPOCH - expected).max() < 3 * NOISE
    as_first = result.correct("R2", logged) - EPOCH - expected  # read on the clock before the reset: 20 s early
    as_first = as_first[np.isfinite(as_first)]
    assert len(as_first) and np.allclose(as_first, -20.0, atol=0.01)
    with pytest.raises(sblsim.ConfigError, match=r"^part: 3 is not a clock part of receiver R2; allowed: 1, 2 "):
        result.correct("R2", logged, part=3)


@pytest.mark.slow
def test_the_simulators_logging_order_goes_back_once_and_is_read_as_a_reset(tmp_path, capsys):
    """``simulate_sync(order="logging")`` with R2's clock going back 20 s: R2's times go back exactly once, at its
    first row after the jump (the truth's ``after``), by the jump less the true time between the two rows on its
    clock; every other receiver's never; the default order is the same rows by clock time; an unknown order
    refused in one line. Written in that order, the reader makes R2's rows from there its clock part 2, and
    ``sblsim sync`` names the reset with the file's line and fits it as a 20 s jump back."""
    plain = simulate_sync(n_receivers=N, hours=HOURS, seed=21, side=700.0, noise=NOISE, interval=(60.0, 120.0))
    heard = np.sort(plain.true_time(plain.receiver, plain.time)[plain.receiver == 2])
    k = np.flatnonzero((heard[:-1] > AT) & (np.diff(heard) < 10.0))[0]  # two of R2's rows < 10 s apart: it goes back
    at = 0.5 * (heard[k] + heard[k + 1])
    sim = simulate_sync(n_receivers=N, hours=HOURS, seed=21, side=700.0, noise=NOISE, interval=(60.0, 120.0),
                        jump=(2, at, -20.0), order="logging")
    for j in range(N):
        back = np.flatnonzero(np.diff(sim.time[sim.receiver == j]) < 0)
        if j != 2:
            assert len(back) == 0
            continue
        after = sim.after[sim.receiver == 2]
        (k,) = back
        assert not after[k] and after[k + 1] and after[k + 1:].all()
        tau = sim.true_time(sim.receiver, sim.time, sim.after)[sim.receiver == 2]
        step = np.diff(sim.time[sim.receiver == 2])[k]
        assert step == pytest.approx(-20.0 + (tau[k + 1] - tau[k]) * (1 + sim.drift[2]), abs=1e-9)
    default = simulate_sync(n_receivers=N, hours=HOURS, seed=21, side=700.0, noise=NOISE, interval=(60.0, 120.0),
                            jump=(2, at, -20.0))
    by_clock = np.lexsort((sim.time, sim.receiver))
    assert np.array_equal(default.time, sim.time[by_clock]) and np.array_equal(default.tag, sim.tag[by_clock])
    with pytest.raises(ModelError, match=r"^order: 'file' is not a rows' order; allowed: clock, logging$"):
        simulate_sync(n_receivers=3, hours=0.5, order="file")
    epo = np.floor(sim.time + EPOCH).astype(np.int64)
    names = np.array([f"R{j}" for j in range(N)])
    pd.DataFrame({"epo": epo, "frac": [f"{v:.9f}" for v in np.clip(sim.time + EPOCH - epo, 0, 0.999999999)],
                  "tag": [f"S{i}" for i in sim.tag], "serial": names[sim.receiver]}).to_csv(tmp_path / "d.csv",
                                                                                            index=False)
    pd.DataFrame({"serial": names, "sync_tag": [f"S{j}" for j in range(N)], "x_m": sim.positions[:, 0],
                  "y_m": sim.positions[:, 1]}).to_csv(tmp_path / "h.csv", index=False)
    first = int(np.flatnonzero(sim.after)[0]) + 2  # the header is line 1
    (reset,) = read_detections(tmp_path / "d.csv").clock_resets
    assert reset["receiver"] == "R2" and reset["line"] == first and reset["clock_part"] == 2
    lines = [line for line in _sync(tmp_path, capsys) if "clock" in line]
    assert len(lines) == 1 and "receiver R2" in lines[0] and f"at line {first} " in lines[0], lines
    fitted = re.search(r"fitted: it went back ([0-9.e+]+) s", lines[0])
    assert fitted and abs(float(fitted[1]) - 20.0) < 1e-3

"""``sblsim sync`` on an array whose receiver's clock jumps mid-record (:mod:`sblsim.models.sync.breaks`): the break
found, named in one console line with its time (UTC) and size, the clock split into segments in ``offsets.csv``,
and ``sblsim toa`` reading the segments back: a tag's times of arrival through the break on the reference clock
within the timing noise; a segments table that contradicts itself refused in one line."""

from __future__ import annotations

import json
import re
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.declarations import ModelError
from sblsim.models.sync.simulate import simulate_sync
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.sync.clocks import offsets_clocks, read_clocks

#: The files' time of τ = 0 [s since 1970 UTC], the timing noise [s] and the array.
EPOCH = 1_700_000_000
NOISE = 0.15e-3
N, HOURS = 6, 4.0


def _study(folder: Path, jump: tuple[int, float, float]):
    """The array's sync tags (:func:`simulate_sync`) and a tag ``T1`` at a fixed place inside it emitting every 20
    to 40 s, each heard with a probability of 0.8, all read on the receivers' clocks (the jump included), written as
    a YAPS table sorted by time (where a clock went back its rows interleave) and a receivers table. Returns the
    simulation and the tag's true arrivals (pings × receivers, NaN unheard) [s from τ = 0]."""
    sim = simulate_sync(n_receivers=N, hours=HOURS, seed=21, side=700.0, noise=NOISE, jump=jump)
    rng = np.random.default_rng(8)
    emitted = 300.0 + np.cumsum(rng.uniform(20.0, 40.0, 600))
    emitted = emitted[emitted < HOURS * 3600 - 300]
    where = sim.positions.mean(axis=0) + [30.0, -20.0]
    truth = emitted[:, None] + np.linalg.norm(sim.positions - where, axis=1)[None] / sim.sound_speed
    truth = truth + rng.normal(0, NOISE, truth.shape)
    truth[rng.random(truth.shape) > 0.8] = np.nan
    ping, rec = np.nonzero(np.isfinite(truth))
    time = np.r_[sim.time, sim.reading(rec, truth[ping, rec])] + EPOCH
    order = np.argsort(time, kind="stable")
    epo = np.floor(time[order]).astype(np.int64)
    names = np.array([f"R{j}" for j in range(N)])
    pd.DataFrame({"epo": epo, "frac": [f"{v:.9f}" for v in np.clip(time[order] - epo, 0, 0.999999999)],
                  "tag": np.r_[[f"S{i}" for i in sim.tag], np.full(len(rec), "T1")][order],
                  "serial": names[np.r_[sim.receiver, rec]][order]}).to_csv(folder / "d.csv", index=False)
    pd.DataFrame({"serial": names, "sync_tag": [f"S{j}" for j in range(N)], "x_m": sim.positions[:, 0],
                  "y_m": sim.positions[:, 1]}).to_csv(folder / "h.csv", index=False)
    return sim, truth


@pytest.mark.parametrize("size", [0.5, pytest.param(-20.0, marks=pytest.mark.slow)])
def test_a_clock_jump_found_named_split_and_read_back_by_toa(tmp_path, capsys, size):
    """Receiver R2's clock jumps by +0.5 s (or goes back 20 s) at 2 h: one warning line names R2, the jump
    and its time in UTC (the true instant within the interval it gives); sync.json's ``clock_breaks`` and
    offsets.csv's two segments of R2 say the same; ``sblsim toa --sync`` puts the tag's arrivals at every receiver
    on R0's clock within three times the timing noise, those between R2's segments set aside and counted."""
    tau = 2 * 3600.0
    sim, truth = _study(tmp_path, (2, tau, size))
    out = tmp_path / "sync"
    assert main(["sync", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "h.csv"), "--sound-speed",
                 str(sim.sound_speed), "--reference", "R0", "--out", str(out)]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if "clock break" in line]
    assert len(lines) == 1 and "receiver R2" in lines[0]
    said = re.search(r"(jumped ahead|went back) ([0-9.]+) s", lines[0])
    assert said[1] == ("jumped ahead" if size > 0 else "went back") and abs(float(said[2]) - abs(size)) < 0.5e-3
    instant = EPOCH + tau + sim.offset0[0] + sim.drift[0] * tau  # on R0's clock
    assert datetime.fromtimestamp(instant, timezone.utc).strftime("%Y-%m-%dT%H:") in lines[0]
    written = json.loads((out / "sync.json").read_text())
    (b,) = written["clock_breaks"]
    assert written["receivers"]["R2"]["clock_segments"] == 2 and "clock_segments" not in written["receivers"]["R1"]
    assert b["receiver"] == "R2" and abs(b["size_s"] - size) < 0.5e-3 and abs(b["time_s"] - instant) <= b["within_s"]
    offsets = pd.read_csv(out / "offsets.csv")
    assert {"segment", "clock_from", "clock_to"} <= set(offsets.columns)
    assert sorted(offsets.loc[offsets["receiver"] == "R2", "segment"].unique()) == [1, 2]
    assert (offsets.loc[offsets["receiver"] != "R2", "segment"] == 1).all()
    assert offsets.loc[offsets["receiver"] != "R2", ["clock_from", "clock_to"]].isna().all().all()
    clocks = read_clocks(out)
    assert clocks.receivers == [f"R{j}" for j in range(N)] and len(clocks.knots) == N + 1
    np.testing.assert_allclose(offsets_clocks(offsets).knots, clocks.knots, rtol=0, atol=1e-9)  # the study's way
    assert main(["toa", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "h.csv"), "--sync", str(out),
                 "--tag", "T1", "--ping-type", "rbi", "--burst-interval", "20:40", "--out",
                 str(tmp_path / "toa")]) == 0
    summary = json.loads((tmp_path / "toa" / "toa.json").read_text())
    got = np.loadtxt(tmp_path / "toa" / "toa.txt", skiprows=1, dtype=str)
    got = np.where(got == "NA", "nan", got).astype(float) + summary["origin_epoch_s"] - EPOCH
    assert got.shape == truth.shape
    on_reference = truth + sim.offset0[0] + sim.drift[0] * truth
    both = np.isfinite(got) & np.isfinite(truth)
    assert (np.isfinite(got) <= np.isfinite(truth)).all()
    missing = int((np.isfinite(truth) & ~np.isfinite(got)).sum())
    assert missing == summary["detections"]["at_clock_breaks"] <= 3
    error = got[both] - on_reference[both]
    assert np.abs(error).max() < 3 * NOISE and np.sqrt(np.mean(error ** 2)) < NOISE


@pytest.mark.slow
def test_the_correction_of_a_broken_receivers_times(tmp_path):
    """``SyncResult.correct`` on R2's own times either side of its +0.5 s jump: each on R0's clock (the truth's
    within 0.5 ms), NaN in the stretch set aside."""
    tau = 2 * 3600.0
    sim, _ = _study(tmp_path, (2, tau, 0.5))
    result = sblsim.sync(tmp_path / "d.csv", receivers=tmp_path / "h.csv", sound_speed=sim.sound_speed,
                         reference="R0")
    true = np.array([3600.0, tau - 900.0, tau + 900.0, 3.5 * 3600.0])
    logged = sim.reading(np.full(4, 2), true)
    corrected = result.correct("R2", logged + EPOCH) - EPOCH
    assert np.abs(corrected - (true + sim.offset0[0] + sim.drift[0] * true)).max() < 0.5e-3
    b = result.summary["clock_breaks"][0]
    assert np.isnan(result.correct("R2", [0.5 * (b["set_aside_from_s"] + b["set_aside_to_s"])])).all()


def test_segments_that_overlap_are_refused_in_one_line(tmp_path):
    """An offsets.csv whose receiver's two clock segments hold for overlapping times (the first to 100 s, the
    second from 50 s) is refused, naming the receiver."""
    t0 = 1e9
    frame = pd.DataFrame([("A", k, t0 + 3600 * k, t0 + 3600 * (k + 1), 0.0, 0.0, segment, low, high)
                          for segment, low, high in ((1, np.nan, t0 + 100), (2, t0 + 50, np.nan)) for k in range(2)],
                         columns=["receiver", "bin", "start", "end", "offset_start_s", "offset_end_s", "segment",
                                  "clock_from", "clock_to"])
    folder = tmp_path / "sync"
    folder.mkdir()
    frame.to_csv(folder / "offsets.csv", index=False)
    with pytest.raises(ModelError, match="receiver A's clock segments hold for times that overlap") as caught:
        read_clocks(folder)
    assert "\n" not in str(caught.value)
    frame.loc[frame["segment"] == 2, "clock_from"] = t0 + 150  # apart: read, two clocks of one receiver
    frame.to_csv(folder / "offsets.csv", index=False)
    clocks = read_clocks(folder)
    assert clocks.receivers == ["A"] and clocks.rows(np.zeros(3, np.int64), t0 + np.array([0.0, 120.0, 200.0])
                                                     ).tolist() == [0, -1, 1]


@pytest.mark.slow
def test_a_jump_near_the_records_end_said_in_one_line_and_set_aside(tmp_path, capsys):
    """R2's clock goes back 20 s with 5 of its sync-tag arrivals after it (too few to fit a segment): one warning
    line names R2, says it went back 20 s, the 5 arrivals and that its times from there are set aside; those 5
    arrivals (and no other) are ``clock break`` in residuals.csv; offsets.csv's R2 clock holds up to its last
    reading before the jump less the 20 s its clock went back (the readings both clocks make set aside)."""
    sim, _ = _study(tmp_path, (2, 0.0, 0.0))
    tau = np.sort(sim.true_time(sim.receiver, sim.time)[sim.receiver == 2])
    at = 0.5 * (tau[-6] + tau[-5])
    sim, _ = _study(tmp_path, (2, at, -20.0))
    capsys.readouterr()
    assert main(["sync", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "h.csv"), "--sound-speed",
                 str(sim.sound_speed), "--reference", "R0", "--out", str(tmp_path / "sync")]) == 0
    lines = [line for line in capsys.readouterr().err.splitlines() if "clock break" in line]
    said = re.search(r"receiver R2 went back ([0-9.]+) s .* 5 sync-tag arrivals after it: too near its clock's end "
                     r"to fit a segment; its own times from .* set aside", lines[0]) if len(lines) == 1 else None
    assert said and abs(float(said[1]) - 20.0) < 1e-3, lines
    residuals = pd.read_csv(tmp_path / "sync" / "residuals.csv")
    aside = residuals["reason"] == "clock break"
    assert (residuals.loc[aside, "receiver"] == "R2").all() and aside.sum() == 5
    assert (residuals.loc[aside, "time"] > EPOCH + sim.reading(np.array([2]), np.array([at]))[0] - 20.0 - 1).all()
    # offsets.csv: R2's clock holds up to its last reading before the jump less the 20 s (then read again after it)
    offsets = pd.read_csv(tmp_path / "sync" / "offsets.csv")
    (to,) = offsets.loc[offsets["receiver"] == "R2", "clock_to"].unique()
    last = EPOCH + sim.time[(sim.receiver == 2) & ~sim.after].max()
    assert last - 20.0 - 2e-3 <= to <= last - 20.0 + 2e-3 < EPOCH + sim.time[(sim.receiver == 2) & sim.after].min()
    assert offsets.loc[offsets["receiver"] != "R2", "clock_to"].isna().all()

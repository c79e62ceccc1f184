"""``sblsim sync`` over a season in windows (``--window-days``, :mod:`sblsim.models.sync.windows`) against the same
synchronisation in one fit (``--window-days 0``): the console and ``sync.json`` say the windows, ``offsets.csv`` is
read back (its offsets continuous across every bin's edge: :func:`~sblsim.orchestrator.sync.clocks.read_clocks`
refuses them otherwise) and gives the sync arrivals' offsets within a tenth of their sigma in RMS, the sync tags'
leave-one-out the same tags within a tenth of their median error; a window outside its range refused."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from sblsim.models.sync.simulate import simulate_sync
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.sync.clocks import read_clocks

EPOCH = 1_700_000_000
N, DAYS = 6, 5.0


def _write(folder, sim, time, order) -> None:
    """The simulated sync detections at ``time`` [s since 1970 UTC] as a YAPS table ``d.csv`` in ``order``, and the
    receivers table ``h.csv`` (receiver ``Rj`` with sync tag ``Sj``)."""
    epo = np.floor(time[order]).astype(np.int64)
    names = np.array([f"R{j}" for j in range(N)])
    pd.DataFrame({"epo": epo, "frac": [f"{v:.9f}" for v in np.clip(time[order] - epo, 0, 0.999999999)],
                  "tag": np.array([f"S{i}" for i in sim.tag])[order],
                  "serial": names[sim.receiver][order]}).to_csv(folder / "d.csv", index=False)
    pd.DataFrame({"serial": names, "sync_tag": [f"S{j}" for j in range(N)], "x_m": sim.positions[:, 0],
                  "y_m": sim.positions[:, 1]}).to_csv(folder / "h.csv", index=False)


def _array(folder, hours: float):
    """``hours`` of the simulated array of :data:`N` receivers (sync tags every 20 to 30 min) written in time order
    (:func:`_write`); returns the simulation."""
    sim = simulate_sync(n_receivers=N, hours=hours, seed=5, side=700.0, interval=(1200.0, 1800.0))
    time = sim.time + EPOCH
    _write(folder, sim, time, np.argsort(time, kind="stable"))
    return sim


@pytest.fixture(scope="module")
def season(tmp_path_factory):
    """5 days of a simulated array of 6 receivers (sync tags every 20 to 30 min) as a YAPS table and a receivers
    table, synchronised in windows of 2 days and in one fit."""
    folder = tmp_path_factory.mktemp("season")
    sim = _array(folder, DAYS * 24)
    said = {}
    for days in ("2", "0"):
        out = folder / f"sync{days}"
        code = main(["sync", str(folder / "d.csv"), "--receivers", str(folder / "h.csv"), "--sound-speed",
                     str(sim.sound_speed), "--reference", "R0", "--window-days", days, "--out", str(out)])
        assert code == 0
        said[days] = out
    return sim, said


@pytest.mark.slow
def test_a_season_in_windows_as_in_one_fit(season, capsys):
    sim, out = season
    windowed, whole = (json.loads((out[d] / "sync.json").read_text()) for d in ("2", "0"))
    assert windowed["windows"]["count"] == 2 and windowed["windows"]["days"] == 2.0 and "windows" not in whole
    assert windowed["bin_edges"] == whole["bin_edges"]
    a, b = read_clocks(out["2"]), read_clocks(out["0"])
    assert a.receivers == b.receivers and a.owner is None
    rows = np.array([a.receivers.index(f"R{j}") for j in sim.receiver])
    time = sim.time + EPOCH
    offsets = pd.read_csv(out["0"] / "offsets.csv")
    sigma = offsets.groupby("receiver")["offset_start_sigma_s"].median()
    on = sim.receiver != 0
    ratio = (a.offset(rows, time) - b.offset(rows, time))[on] / sigma[[f"R{j}" for j in sim.receiver[on]]].to_numpy()
    assert np.sqrt(np.mean(ratio ** 2)) <= 0.1
    tags = [pd.read_csv(out[d] / "sync_tags.csv").set_index("tag") for d in ("2", "0")]
    assert set(tags[0].index) == set(tags[1].index) and len(tags[0]) == N
    assert np.allclose(tags[0]["median_error_m"], tags[1].loc[tags[0].index, "median_error_m"], rtol=0.1, atol=0.01)


def test_the_console_says_the_windows_and_a_window_out_of_range_is_refused(tmp_path, capsys):
    """On two days of the array (the season's fixture is the slow tier's): windows of 0.75 days."""
    folder = tmp_path
    _array(folder, 48.0)
    main(["sync", str(folder / "d.csv"), "--receivers", str(folder / "h.csv"), "--sound-speed", "1480",
          "--window-days", "0.75", "--out", str(tmp_path / "s")])
    count = int(np.ceil(48.0 / (0.75 * 24.0)))  # the record's two days in windows of 18 h
    assert f"fitted in {count} windows of 0.75 days (12 h overlap each side)" in capsys.readouterr().out
    for days in ("-1", "400", "nan"):
        code = main(["sync", str(folder / "d.csv"), "--receivers", str(folder / "h.csv"), "--window-days", days,
                     "--out", str(tmp_path / f"r{days}")])
        err = capsys.readouterr().err
        assert code == 2 and "--window-days" in err and "[0, 366]" in err and not (tmp_path / f"r{days}").exists()


@pytest.mark.slow
def test_a_clock_reset_in_the_files_order_at_a_windows_edge(tmp_path, capsys):
    """Receiver R2's time going back 3000 s at day 2 of 5 (a reset at a download, its rows in the order it logged
    them: a clock part of the reader's), at the edge of windows of 1 day: the same break said, the same clock
    segments and parts in ``offsets.csv``, every sync arrival's synchronised time within 0.1 ms of one fit's (the
    jump's sigma each fit's own)."""
    sim = simulate_sync(n_receivers=N, hours=DAYS * 24, seed=21, side=700.0, interval=(900.0, 1500.0),
                        jump=(2, 2 * 86400.0, -3000.0))
    tau = sim.true_time(sim.receiver, sim.time, sim.after)
    time = sim.reading(sim.receiver, tau) + EPOCH
    _write(tmp_path, sim, time, np.lexsort((tau, sim.receiver)))  # each receiver's rows as it logged them
    said = []
    for days in ("1", "0"):
        assert main(["sync", str(tmp_path / "d.csv"), "--receivers", str(tmp_path / "h.csv"), "--sound-speed",
                     str(sim.sound_speed), "--reference", "R0", "--window-days", days, "--out",
                     str(tmp_path / days)]) == 0
        said.append([line for line in capsys.readouterr().err.splitlines() if "clock break" in line])
    assert len(said[0]) == len(said[1]) == 1 and "goes back" in said[0][0]
    plain = [re.sub(r"± [0-9.]+ ms", "", lines[0]) for lines in said]  # the jump's sigma: each fit's own
    assert plain[0] == plain[1]
    a, b = read_clocks(tmp_path / "1"), read_clocks(tmp_path / "0")
    assert list(a.owner) == list(b.owner) == [0, 1, 2, 2, 3, 4, 5] and list(a.parts) == list(b.parts)
    assert np.allclose(a.spans, b.spans)
    synced = [pd.read_csv(tmp_path / d / "residuals.csv")["time_sync"].to_numpy() for d in ("1", "0")]
    assert np.nanmax(np.abs(synced[0] - synced[1])) < 1e-4


@pytest.mark.slow
def test_a_studys_season_synchronised_in_windows_tracks_as_one_fit(tmp_path, monkeypatch):
    """A simulated study of 9 days (5 receivers redeployed, one tag) tracked with ``sblsim track``: its sync in 2
    windows of 7 days (said in ``study.json``'s clocks), its track against the study whose sync is one fit (the
    windows refused by a patch): every ping positioned in both, the positions' RMS difference within a twentieth of
    their sigma and each within half of it (an arrival the sync rejected otherwise moves the clocks about it)."""
    import sblsim
    from sblsim.orchestrator.sync import run
    from sblsim.orchestrator.telemetry.simulate import simulate_study

    sim = simulate_study(n_receivers=5, n_tags=1, days=9, seed=2)
    files = sim.write(tmp_path / "study", "vue")
    windowed = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=1,
                            out=tmp_path / "windows")
    monkeypatch.setattr(run, "season_windows", lambda *args: None)
    whole = sblsim.track(files["detections"], receivers=files["deployments"], tags=files["tags"], workers=1,
                         out=tmp_path / "whole")
    assert windowed.summary["clocks"]["windows"]["count"] == 2 and "windows" not in whole.summary["clocks"]
    a, b = windowed.tracks, whole.tracks
    assert len(a) == len(b) == windowed.tags["pings"].sum() == whole.tags["pings"].sum()
    assert np.allclose(a["epoch_s"], b["epoch_s"], rtol=0, atol=1e-4)
    ratio = np.hypot(a["x"] - b["x"], a["y"] - b["y"]) / np.hypot(b["sigma_x"], b["sigma_y"])
    assert np.sqrt(np.mean(ratio ** 2)) <= 0.05 and ratio.max() <= 0.5


def test_a_season_whose_water_changes_gives_each_window_its_speed_and_the_season_their_spread(tmp_path, capsys):
    """Six simulated days of four receivers with their sync tags (the telemetry simulator) in water whose sound speed
    runs 1,470 → 1,500 → 1,470 m/s, synchronised in windows of 1.5 days with the speed estimated: ``sync.json``'s
    windows each say their own speed, each within 3 m/s of its window's true mean (a window fits one speed to water
    that changes within it); the season's speed lies within its σ of the season's true mean, and that σ counts
    each window as one draw of the season's water (at least 0.7 of the truth's standard deviation over time over √W;
    the windows' σ alone, about a tenth of a m/s, would be tens of times too small); the windows' spread (within a
    fifth of the truth's standard deviation) in ``sync.json`` and on the console."""
    from sblsim.orchestrator.telemetry.simulate import simulate_study

    days = 6.0
    span = days * 86400.0

    def water(t):
        return 1485.0 - 15.0 * np.cos(2 * np.pi * t / span)

    sim = simulate_study(n_receivers=4, n_tags=0, days=days, redeployed=0, seed=5, offset=0.01, drift=1e-7,
                         sound_speed=water)
    files = sim.write(tmp_path / "in", "glatos")
    assert main(["sync", str(files["detections"]), "--receivers", str(files["deployments"]), "--window-days", "1.5",
                 "--out", str(tmp_path / "sync")]) == 0
    said = capsys.readouterr().out
    summary = json.loads((tmp_path / "sync" / "sync.json").read_text())
    windows, speed = summary["windows"], summary["sound_speed"]
    edges = np.asarray(windows["edges"]) - sim.origin  # [s from the start] on the reference clock (within 0.01 s)
    edges[0], edges[-1] = 0.0, span
    assert windows["count"] == len(windows["sound_speed_m_s"]) == len(edges) - 1 >= 3
    for lo, hi, estimated in zip(edges[:-1], edges[1:], windows["sound_speed_m_s"]):
        true = water(np.linspace(lo, hi, 2001)).mean()
        assert abs(estimated - true) < 3.0, (lo, hi, estimated, true)
    truth = water(np.linspace(0.0, span, 20001))
    assert abs(speed["sound_speed_m_s"] - truth.mean()) < speed["sound_speed_sigma_m_s"], speed
    assert speed["sound_speed_sigma_m_s"] >= 0.7 * truth.std() / np.sqrt(windows["count"]), speed
    assert speed["windows_spread_m_s"] == pytest.approx(truth.std(), rel=0.2), speed
    assert max(windows["sound_speed_sigma_m_s"]) < 0.05 * speed["sound_speed_sigma_m_s"]
    assert "with the windows' spread" in said and f"rescaled by the {windows['count']} windows' own speeds" in said

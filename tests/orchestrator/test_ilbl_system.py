"""The inverted LBL (``platform.system = "ilbl"``): the target pings on its own clock, fixed hydrophones time the
arrivals, the emission epochs are unknown to the receivers.

* The channel's times of arrival against one-way times computed here with numpy from the recorded truth: every
  arrival of a ping leaves at one emission epoch, its travel time is the straight line from the diver where it was
  then to the hydrophone, the pseudo-range is ``c (rx_time − tx_time)`` against the ping's nominal epoch, and the
  intervals are the nominal one stretched by the drift plus a uniform jitter of the configured std.
* ``ekf-seq`` and ``ukf`` with the emission offset as their clock state, on a random walk drawn from their own motion
  model (the PCRB a true bound) with the pinger's jitter and drift: consistent over 20 seeds (3-D NEES in
  [1.5, 4.5], 2-D in [1, 3]) and within 1.3 of the bound.
* The map of one ping with the emission removed (the Schur complement) against the Fisher information written here
  in numpy with the offset as a fourth unknown, and against a Monte Carlo of a static diver's fixes.
* compare, map, budget and campaign take the system.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy.stats import chi2

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.acoustics.channel.lanes import lane_name
from sblsim.models.platform.geometry import lever_arms
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.metrics import new_on_lane
from sblsim.orchestrator.cosim.run import run_batch, with_replicates
from sblsim.orchestrator.maps import accuracy_map

#: An inverted LBL of four hydrophones on a 50 m circle at 50 m, tracked by ekf-seq.
ILBL = ["platform.system=ilbl", "platform.layout=circle", "platform.baseline=50", "simulation.receiver=ekf-seq"]
SPEED = 1500.0


def arrivals(ts: pd.DataFrame) -> pd.DataFrame:
    """Every packet a run delivered, on every lane of its deliveries, once: one row per (replicate, packet_seq)."""
    fields = ("packet_seq", "beacon_id", "packet_valid", "tx_time", "rx_time", "range", "travel_time", "range_true",
              "beacon_x", "beacon_y", "beacon_z")
    rows = []
    for replicate, series in ts.groupby("replicate"):
        for m in range(1, LANES + 1):
            if lane_name(m, "packet_seq") not in series:
                break
            seq = series[lane_name(m, "packet_seq")].to_numpy()
            new = (seq != np.r_[0, seq[:-1]]) & (seq > 0) if m == 1 else new_on_lane(seq)
            lane = series.loc[new, [lane_name(m, f) for f in fields]].set_axis(list(fields), axis=1)
            rows.append(lane.assign(replicate=replicate, lane=m))
    return pd.concat(rows).drop_duplicates(["replicate", "packet_seq"]).sort_values(["replicate", "packet_seq"])


def test_the_times_of_arrival_are_one_way_times_from_the_diver_at_the_emission():
    """60 s of a random walk with a 20 ms jitter and 50 ppm of drift, no range noise, loss or survey error: each
    ping's four arrivals share one emission epoch, each travel time is ``‖p(e) − b_i‖ / c`` with ``p(e)`` the recorded
    truth at the emission (its straight line within a step exact, the walk interpolated to 2 mm), each range
    ``c (rx_time − tx_time)`` (to 1 nm), the nominal epochs ``t0 + c P`` of P = 4 × 0.1 s; the intervals are
    ``P (1 + δ)`` plus a jitter inside ``±√3 σ`` whose sample std is inside its 99.9 % χ² interval and whose mean is 0
    within 4 standard errors."""
    jitter, ppm = 0.02, 50.0
    cfg = load_config("random-walk", ILBL + ["simulation.duration=60", "acoustics.sigma_range=0",
                                             "platform.survey_sigma=0", f"acoustics.ping_jitter={jitter}",
                                             f"acoustics.clock_drift_ppm={ppm}"], seed=4)
    assert cfg["acoustics"]["ranging"] == "toa"  # the system's one ranging
    ts = run_batch(with_replicates(cfg, range(2)), "local", timeseries=True).timeseries
    packets = arrivals(ts)
    assert packets["packet_valid"].all() and len(packets) > 1000
    n, period = 4, 4 * cfg["simulation"]["sampling_time"]
    hydrophones = lever_arms(cfg["platform"])
    ping = np.ceil(packets["packet_seq"].to_numpy() / n).astype(int)
    np.testing.assert_array_equal(packets["beacon_id"], (packets["packet_seq"] - 1) % n + 1)
    np.testing.assert_allclose(packets["tx_time"], ping * period, rtol=0, atol=1e-9)
    emission = (packets["rx_time"] - packets["travel_time"]).to_numpy()
    intervals = []
    for replicate, series in ts.groupby("replicate"):
        mine = (packets["replicate"] == replicate).to_numpy()
        epochs = pd.Series(emission[mine]).groupby(ping[mine]).agg(["min", "max", "size"])
        assert (epochs["size"] == n).all() and np.all(epochs["max"] - epochs["min"] < 1e-12)  # one emission
        truth = series[["true_x", "true_y", "true_z"]].to_numpy()
        b = hydrophones[packets["beacon_id"].to_numpy()[mine] - 1]
        # the diver at the emission: the truth at the end of the step that reached it, moved back along its
        # velocity (the channel's straight line within a step: exact), and the truth interpolated (the walk's
        # curve within a step: to 2 mm)
        after = np.searchsorted(series["time"].to_numpy(), emission[mine] - 1e-9)
        ends = series.iloc[after]
        back = ends[["true_x", "true_y", "true_z"]].to_numpy() + ends[["true_vx", "true_vy", "true_vz"]].to_numpy() \
            * (emission[mine] - ends["time"].to_numpy())[:, None]
        np.testing.assert_allclose(packets["travel_time"].to_numpy()[mine], np.linalg.norm(back - b, axis=1) / SPEED,
                                   rtol=0, atol=1e-9 / SPEED)
        at = np.stack([np.interp(emission[mine], series["time"], truth[:, k]) for k in range(3)], axis=1)
        np.testing.assert_allclose(packets["travel_time"].to_numpy()[mine], np.linalg.norm(at - b, axis=1) / SPEED,
                                   rtol=0, atol=2e-3 / SPEED)
        intervals.append(np.diff(np.r_[0.0, epochs["min"].to_numpy()]))
    np.testing.assert_allclose(packets["range"], SPEED * (packets["rx_time"] - packets["tx_time"]), rtol=0, atol=1e-9)
    step = np.concatenate(intervals) - period * (1.0 + ppm * 1e-6)
    assert np.abs(step).max() <= math.sqrt(3.0) * jitter
    low, high = (jitter * math.sqrt(chi2.ppf(q, step.size - 1) / (step.size - 1)) for q in (0.0005, 0.9995))
    assert low < step.std(ddof=1) < high, (step.std(ddof=1), low, high)
    assert abs(step.mean()) < 4.0 * jitter / math.sqrt(step.size)
    # the offset from the nominal schedule walks: the receivers cannot take the nominal epoch as the emission
    offset = emission - packets["tx_time"].to_numpy()
    assert np.ptp(offset) > 5 * jitter


@pytest.mark.parametrize("multipath", [0, 10])
@pytest.mark.parametrize("receiver", ["ekf-seq", "ukf"])
def test_the_receivers_are_consistent_and_reach_their_bound(receiver, multipath):
    """A random walk drawn from the receivers' own motion model (the PCRB a true bound), with the pinger's 50 ms
    jitter and 20 ppm of drift, 20 seeds: 3-D NEES in [1.5, 4.5], 2-D NEES (North, East) in [1, 3], and the RMS error
    within 1.3 of the bound with the emission offset as a state (the bound with error states). With 10 % of
    multipath arrivals (late by 2 m on average: a ping's first update, which sets its emission, cannot be judged, so
    the arrival least late is taken first; an arrival far earlier than predicted re-anchors the epoch) on the
    scenario's own layout, the consistency benchmark's, and on the 50 m circle: NEES in the band, no track lost."""
    layout = ILBL if not multipath else ["platform.system=ilbl"]
    pinger = [f"simulation.receiver={receiver}", "acoustics.ping_jitter=0.05", "acoustics.clock_drift_ppm=20",
              f"acoustics.outlier_pct={multipath}"]
    cfg = load_config("random-walk", layout + pinger, seed=1)
    assert cfg["receiver"]["clock_states"] and cfg["receiver"]["ping_jitter"] == 0.05
    result = run_batch(with_replicates(cfg, range(20)), "local", timeseries=True)
    nees = float(result.metrics["nees_mean"].mean())
    assert 1.5 <= nees <= 4.5, nees
    ts = result.timeseries
    fixed = ts[np.isfinite(ts["e_x"].to_numpy())]  # the steps with an estimate (none before a receiver's first fix)
    e = fixed[["e_x", "e_y"]].to_numpy()
    cov = np.stack([fixed[["cov_xx", "cov_xy"]].to_numpy(), fixed[["cov_xy", "cov_yy"]].to_numpy()], axis=1)
    nees_2d = float(np.mean(np.einsum("ki,kij,kj->k", e, np.linalg.inv(cov), e)))
    assert 1.0 <= nees_2d <= 3.0, nees_2d
    ratio = math.sqrt(np.mean(result.metrics["e_tot_rms"] ** 2) / np.mean(result.metrics["pcrb_rms"] ** 2))
    assert 1.0 <= ratio <= 1.3, ratio
    assert not result.metrics["diverged"].any()
    if multipath:
        assert ts["outlier"].sum() > 500  # late arrivals there were
        # on the 50 m circle (one ping fixes the position tightly) a late arrival taken first would set the ping's
        # emission: the least late is taken first, and no seed loses the track (RMS 1.49 times the bound there, as
        # LBL's 1.38: docs/receivers.md)
        wide = run_batch(with_replicates(load_config("random-walk", ILBL + pinger, seed=1), range(20)), "local",
                         timeseries=False).metrics
        assert 1.5 <= float(wide["nees_mean"].mean()) <= 4.5 and not wide["diverged"].any()
        assert wide["nees_mean"].max() < 15.0
        return
    # the jitter costs accuracy: the same walks with a pinger on its schedule have a lower bound
    exact = run_batch(with_replicates(load_config("random-walk", ILBL + [f"simulation.receiver={receiver}"], seed=1),
                                      range(20)), "local", timeseries=False).metrics
    assert np.mean(exact["pcrb_rms"]) < np.mean(result.metrics["pcrb_rms"])


def numpy_drms(point: np.ndarray, hydrophones: np.ndarray, range_variance: float, depth_variance: float) -> float:
    """The horizontal DRMS of one ping heard by every hydrophone plus the depth, with the emission offset a fourth
    unknown: the inverse of the 4 × 4 Fisher information of (North, East, Down, offset)."""
    J = np.zeros((4, 4))
    for b in hydrophones:
        row = np.r_[(point - b) / np.linalg.norm(point - b), 1.0]
        J += np.outer(row, row) / range_variance
    J[2, 2] += 1.0 / depth_variance
    C = np.linalg.inv(J)
    return math.sqrt(C[0, 0] + C[1, 1])


def test_the_map_removes_the_emission_and_is_what_a_static_divers_fixes_get():
    """The map of an inverted LBL equals the numpy information with the offset as an unknown (to 1e-9) at a grid of
    points, lies above LBL's map of the same field at every one (the unknown emission costs information), and at a
    static diver's point is the horizontal RMS of 150 replicates' instrumentation fixes of every ping (the
    least-squares fix of its four arrivals and the depth, the offset eliminated) within 10 %."""
    cfg = load_config("semicircle", ILBL + ["target.speed=1e-9", "platform.beaufort=0", "simulation.duration=6",
                                            "platform.survey_sigma=0.05"], seed=3)
    hydrophones = lever_arms(cfg["platform"])
    variance = cfg["acoustics"]["sigma_range"] ** 2 + cfg["platform"]["survey_sigma"] ** 2
    depth_variance = cfg["target"]["depth_sigma"] ** 2
    east, north = np.linspace(-80.0, 80.0, 5), np.linspace(-60.0, 70.0, 4)
    drms = accuracy_map(cfg, east, north, depth=5.0)
    lbl = accuracy_map(load_config("semicircle", ["platform.system=lbl", "platform.layout=circle",
                                                  "platform.baseline=50", "platform.survey_sigma=0.05"]),
                       east, north, depth=5.0)
    for i, n_ in enumerate(north):
        for j, e_ in enumerate(east):
            expected = numpy_drms(np.array([n_, e_, 5.0]), hydrophones, variance, depth_variance)
            assert drms[i, j] == pytest.approx(expected, rel=1e-9)
    assert np.all(drms > lbl)
    ts = run_batch(with_replicates(cfg, range(150)), "local", timeseries=True).timeseries
    seq = ts["packet_seq"].to_numpy()
    new = (seq != np.r_[0, seq[:-1]]) & (seq > 0) & ts["instr_valid"].to_numpy(bool)
    # a ping's four arrivals reach the receiver in one step (on four lanes): its fix at that step takes them all
    assert (ts.loc[new, lane_name(4, "packet_seq")] > 0).all()
    fix, truth = ts.loc[new, ["instr_x", "instr_y"]].to_numpy(), ts.loc[new, ["true_x", "true_y"]].to_numpy()
    point = ts.loc[new, ["true_x", "true_y", "true_z"]].to_numpy()[0]
    assert np.ptp(truth, axis=0).max() < 1e-6 and len(fix) > 1500
    rms = math.sqrt(np.mean(np.sum((fix - truth) ** 2, axis=1)))
    mapped = float(accuracy_map(cfg, np.array([point[1]]), np.array([point[0]]), depth=float(point[2]))[0, 0])
    assert rms == pytest.approx(mapped, rel=0.10), (rms, mapped)


@pytest.mark.slow
def test_compare_map_budget_and_campaign_take_the_inverted_lbl(tmp_path, monkeypatch):
    """``compare --systems`` runs the inverted LBL beside the others (its defaults: LBL's field and ekf-seq), ``map
    --compare platform.system`` maps it, ``budget`` finds the pinger's jitter among the error sources, and a
    campaign crosses it with a factor."""
    monkeypatch.chdir(tmp_path)
    assert main(["compare", "random-walk", "--systems", "lbl,ilbl", "--receivers", "ekf,ekf-seq", "--replicates",
                 "2", "--set", "simulation.duration=20", "--out", "cmp"]) == 0
    table = pd.read_csv(tmp_path / "cmp" / "compare.csv")  # the paper's EKF left out of the inverted LBL's rows
    assert list(zip(table["system"], table["receiver"])) == [("lbl", "ekf"), ("lbl", "ekf-seq"),
                                                             ("ilbl", "ekf-seq")]
    # honest (NEES) and near its bound over the steps with an estimate. (Not "worse than LBL's ekf-seq" over these
    # 20 s: LBL's first fix is one range from its prior, 1.6-2.7 m off, its first steps dominate its RMS (0.16-0.22 m
    # against 0.11 from its tenth on), while the inverted LBL's first fix waits for a whole ping, 0.15 m off: 0.115
    # m, 0.114 from its tenth on. Both have no estimate before their first fix, f1d05a4.)
    assert 1.0 < table["nees"].iloc[2] < 6.0 and 1.0 < table["ratio_to_pcrb"].iloc[2] < 1.5
    assert main(["compare", "random-walk", "--systems", "lbl,ilbl", "--receivers", "lsq", "--out", "none"]) == 2
    assert main(["map", "random-walk", "--compare", "platform.system=lbl,ilbl", "--out", "map"]) == 0
    maps = pd.read_csv(tmp_path / "map" / "map.csv")
    assert set(maps["platform.system"]) == {"lbl", "ilbl"}
    assert main(["budget", "random-walk", *sum((["--set", s] for s in ILBL + ["acoustics.ping_jitter=0.05",
                                                                              "simulation.duration=20"]), []),
                 "--replicates", "10", "--out", "budget"]) == 0
    rows = pd.read_csv(tmp_path / "budget" / "budget.csv").set_index("source")
    assert rows.loc["ping_jitter", "status"] == "on" and rows.loc["ping_jitter", "contribution"] > 0
    study = tmp_path / "study.toml"
    study.write_text('[study]\nname = "ilbl"\nscenarios = ["random-walk"]\nreplicates = 2\n'
                     'set = ["platform.system=ilbl", "simulation.receiver=ukf", "simulation.duration=10"]\n'
                     '[[factors]]\nname = "jitter"\nkey = "acoustics.ping_jitter"\nlow = 0.0\nhigh = 0.05\n')
    assert main(["campaign", str(study), "--out", "campaign"]) == 0
    runs = pd.read_parquet(tmp_path / "campaign" / "runs.parquet")
    assert len(runs) == 4 and runs["e_tot_rms"].notna().all() and (runs["nees_mean"] > 0).all()
    assert SYSTEMS["ilbl"].designed is False  # sblsim design does not propose it


@pytest.mark.slow
def test_an_exported_log_replays_to_the_run(tmp_path, monkeypatch):
    """``run --export-log`` of an inverted LBL (its rows at each ping's nominal epoch, arrivals before it and negative
    pseudo-ranges where a ping left early) replays through ``sblsim replay`` to the run's estimate at every step
    both have (to 1e-9 m)."""
    monkeypatch.chdir(tmp_path)
    sets = sum((["--set", s] for s in ILBL + ["acoustics.ping_jitter=0.05", "simulation.duration=30"]), [])
    assert main(["run", "random-walk", *sets, "--export-log", "log.csv", "--out", "run"]) == 0
    log = pd.read_csv(tmp_path / "log.csv", comment="#")
    assert (log["rx_time"] < log["time_s"]).any() and (log["range_m"] < 0).any()
    assert main(["replay", "log.csv", "--receiver", "ekf-seq", "--truth", "log_truth.csv", "--out", "replay"]) == 0
    run, replay = (pd.read_parquet(tmp_path / d / "timeseries.parquet") for d in ("run", "replay"))
    both = run.merge(replay, on="time", suffixes=("_run", "_replay"))
    assert len(both) >= len(run) - 2
    for a in ("x", "y", "z"):
        np.testing.assert_allclose(both[f"est_{a}_replay"], both[f"est_{a}_run"], rtol=0, atol=1e-9)

"""A measurement is used no earlier than it arrives (docs/model.md, "Timing"), and the channel never loses one.

The receiver of a co-simulation is watched step by step: after each of its communication steps, the packet it
took in that step (its ``last_seq`` state changed) is written down with the step's end (its use). Independently of
the ``rx_time`` the channel announces, a packet's arrival is its transmit epoch plus the travel time the channel
recorded for it (the true one-way travel time, or the whole round trip with the turnaround), read from the
channel's record at the step that delivered it. Checked: every used packet arrived by its use (and in a
Gauss-Seidel run at the receiver's first step end after it), none is used twice, every delivered one is used,
and every packet sent was delivered or is still in flight at the end.
"""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.acoustics.channel.interface import FLIGHT_CAPACITY
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.connections import default_connections
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.limits import step_count
from sblsim.orchestrator.cosim.master import simulate
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import merge_params, run, with_replicates
from tests.orchestrator.test_fmus import assert_same_frames

SLACK = 1e-9  # the receivers' slot slack [s]


class Watched:
    """A receiver handle that writes down, after each of its steps, the packet each replicate took in it.

    Its class has no ``native_batch``: the master's Python loop steps it, one communication step at a time."""

    def __init__(self, handle):
        self.handle, self.uses, self.u = handle, [], None

    def __getattr__(self, name):
        return getattr(self.handle, name)

    def set_input_vector(self, u):
        self.u = np.array(u, dtype=float)
        self.handle.set_input_vector(u)

    def do_step(self, t, h):
        before = self.handle.states()["last_seq"][:, 0].copy()
        self.handle.do_step(t, h)
        after = self.handle.states()["last_seq"][:, 0]
        rows = {n: k for k, n in enumerate(self.handle.input_names)}
        for b in np.flatnonzero(after != before):
            assert self.u[rows["packet_seq"], b] == after[b]  # the packet it took is the one on its inputs
            self.uses.append((int(b), int(after[b]), t + h, float(self.u[rows["rx_time"], b])))


def watched_run(cfg, replicates=(0, 1)):
    """The record, the receiver's uses (replicate, seq, use time, rx_time) and the channel's final state."""
    plan = make_plan(cfg)
    cfgs = with_replicates(plan, list(replicates))
    n, sim = plan.n_beacons, cfg["simulation"]
    handles = make_handles("local", None, n, dict(plan.sources))
    try:
        for name, handle in handles.items():
            handle.setup(*merge_params(cfgs, name, handle.parameters))
        handles["receiver"] = watched = Watched(handles["receiver"])
        record = simulate(handles, default_connections(n), {"receiver": sim["ekf_rate_ratio"]},
                          sim["sampling_time"], step_count(sim["duration"], sim["sampling_time"]),
                          algorithm=sim["master"])
        channel = handles["acoustics"].states()
        return record, watched.uses, {k: channel[k].copy() for k in ("k", "q_used", "overflow_travel_time")}
    finally:
        handles["receiver"] = getattr(handles["receiver"], "handle", handles["receiver"])
        close_handles(handles)


def check_uses(cfg, replicates=(0, 1)):
    """Run ``cfg`` watched and check every use against its arrival; returns the ages (use − arrival) [s]."""
    record, uses, channel = watched_run(cfg, replicates)
    T, ratio = cfg["simulation"]["sampling_time"], cfg["simulation"]["ekf_rate_ratio"]
    jacobi = cfg["simulation"]["master"] == "jacobi"
    ages = []
    for b in range(len(replicates)):
        seq = record["acoustics.packet_seq"][:, b]
        delivered = np.flatnonzero((seq != np.concatenate([[0], seq[:-1]])) & (seq > 0))
        # the arrival of each delivered packet, from its transmit epoch and the travel time the channel recorded
        arrival = {int(seq[k]): record["acoustics.tx_time"][k, b] + record["acoustics.travel_time"][k, b]
                   for k in delivered}
        assert all(record["time"][k] >= arrival[int(seq[k])] - SLACK for k in delivered)  # delivered once arrived
        mine = [(s, used, rx) for r, s, used, rx in uses if r == b]
        used = [s for s, _, _ in mine]
        assert len(used) == len(set(used)), "a packet used twice"
        # every packet delivered before the receiver's last step is used (Jacobi: the last macro step's is not)
        assert set(used) == set(arrival) - ({int(seq[-1])} if jacobi else set())
        for s, when, rx in mine:
            assert rx == pytest.approx(arrival[s], abs=1e-12)
            assert when >= arrival[s] - SLACK, f"packet {s} used at {when} s before it arrived at {arrival[s]} s"
            ages.append(when - arrival[s])
        # the queue lost nothing: every packet sent was delivered or is still in flight at the end
        assert channel["overflow_travel_time"][b, 0] == 0.0
        assert channel["k"][b, 0] == len(arrival) + channel["q_used"][b].sum()
    ages = np.array(ages)
    if not jacobi:  # used at the receiver's first step that reaches the arrival
        assert ages.max() < T / ratio + SLACK
    else:  # the Jacobi master hands the packet over one macro step later
        assert ages.max() < T + T / ratio + SLACK
    return ages


@pytest.mark.parametrize("system", ["sbl", "lbl"])
def test_a_turnaround_of_three_sampling_times_is_used_after_the_reply(system):
    """TWTT with a 3 T turnaround: every range would be used 3 T before its reply with the packet used at its
    transmit epoch; here each is used at the receiver's first step (T / 20) after the reply arrived."""
    T = 0.1
    cfg = load_config("semicircle", [f"platform.system={system}", "acoustics.ranging=twtt",
                                     f"acoustics.turnaround={3 * T}", "simulation.duration=20",
                                     "simulation.ekf_rate_ratio=20", "acoustics.loss_pct=20"], seed=2)
    ages = check_uses(cfg)
    assert ages.size > 300
    # and the reply does take longer than the turnaround: several steps of the receiver after the transmission
    record, _, channel = watched_run(cfg, (0,))
    trip = record["acoustics.travel_time"][record["acoustics.packet_seq"][:, 0] > 0, 0]
    assert trip.min() > 3 * T and channel["q_used"].sum() >= 3  # replies in flight at the end


@pytest.mark.parametrize("master", ["gauss-seidel", "jacobi"])
def test_one_way_ranges_are_used_after_they_arrive_for_both_masters(master):
    cfg = load_config("semicircle", [f"simulation.master={master}", "simulation.duration=20",
                                     "simulation.ekf_rate_ratio=20", "acoustics.loss_pct=10"], seed=4)
    ages = check_uses(cfg)
    assert ages.size > 300 and ages.min() >= -SLACK


def test_a_12_km_lbl_range_is_refused_at_a_short_sampling_time_and_used_after_it_arrives_at_a_long_one(
        tmp_path, capsys):
    """Transponders 12 km down: a range travels 8 s one way, 80 packets in flight at T = 0.1 s, which the
    channel cannot hold: one line naming the sampling time, the turnaround and the travel time, exit 2, nothing
    written. At T = 2 s (one-way) and 2.5 s (two-way) every range is used after it arrived."""
    deep = ["platform.system=lbl", "platform.seafloor_depth=12000"]
    out = tmp_path / "deep"
    assert main(["run", "semicircle", "--out", str(out), "--set", *deep[:1], "--set", deep[1],
                 "--set", "simulation.duration=30"]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and not out.exists()
    for name in ("simulation.sampling_time: 0.1 s is too short for a travel time of 7.99",
                 f"the channel holds {FLIGHT_CAPACITY}", "give a simulation.sampling_time above 1.14"):
        assert name in err, err
    assert "turnaround" not in err  # one-way ranging: no turnaround to blame
    for ranging, T in (("owtt", 2.0), ("twtt", 2.5)):
        cfg = load_config("semicircle", deep + [f"acoustics.ranging={ranging}", f"simulation.sampling_time={T}",
                                               f"simulation.duration={40 * T}"], seed=1)
        ages = check_uses(cfg, (0,))
        assert ages.size >= 30 and ages.min() >= -SLACK


def test_a_turnaround_jitter_the_channel_cannot_hold_is_named(capsys, tmp_path):
    """acoustics.turnaround_sigma at its documented maximum (1 s) at T = 0.1 s: replies 3 s late, refused after
    the run in one line that names the jitter (not a travel time of 3 s) and what holds it."""
    jitter = ["acoustics.ranging=twtt", "acoustics.turnaround_sigma=1", "simulation.duration=20"]
    assert main(["run", "semicircle", "--out", str(tmp_path / "j"), *[a for k in jitter for a in ("--set", k)]]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and not (tmp_path / "j").exists(), err
    assert ("too short for acoustics.turnaround = 0.05 s, its jitter acoustics.turnaround_sigma = 1 s, the travel "
            "time: a packet arrives" in err), err
    assert err.rstrip().endswith("or a smaller acoustics.turnaround or a smaller acoustics.turnaround_sigma"), err


def test_a_turnaround_the_channel_cannot_hold_is_refused_before_the_run():
    with pytest.raises(ConfigError, match=r"^simulation\.sampling_time: 0\.1 s is too short for "
                                          r"acoustics\.turnaround = 0\.71 s") as info:
        load_config("semicircle", ["acoustics.ranging=twtt", "acoustics.turnaround=0.71"])
    assert "\n" not in str(info.value) and "above 0.1014 s" in str(info.value)
    load_config("semicircle", ["acoustics.ranging=twtt", "acoustics.turnaround=0.69"])  # 7 T less a little: held
    load_config("semicircle", ["acoustics.turnaround=5"])  # one-way ranging waits for no turnaround


def test_the_local_and_fmu_engines_agree_with_replies_in_flight(fmu_dir):
    cfg = load_config("random", ["platform.system=lbl", "acoustics.ranging=twtt", "acoustics.turnaround=0.3",
                                 "simulation.duration=10", "simulation.ekf_rate_ratio=2", "receiver=ekf-seq"],
                      seed=3)
    local, fmu = run(cfg, "local"), run(cfg, "fmu", fmu_dir=fmu_dir)
    assert (local.timeseries["rx_time"] - local.timeseries["tx_time"]).max() > 0.3
    assert_same_frames(local.timeseries, fmu.timeseries)

"""Replies in the order they arrive (docs/model.md, "Timing"): with a turnaround jitter, a two-way reply reaches the
receiver at the first step end after its arrival, never before it, and never before its interrogation; replies
that arrive in one step all reach it at that step's end, on the lanes of the delivery.

Everything is read from the run's own time series, independently of the channel's code: a packet is delivered at
the row where ``packet_seq`` changes to it (the row's ``time`` is the step's end), its arrival is its transmit
epoch plus the travel time of the exchange the channel recorded (``tx_time + travel_time``: the up leg, the
turnaround with its jitter, the reply), and the first step end after it is the first row ``time`` that reaches it.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.acoustics.channel.interface import FLIGHT_CAPACITY

SLACK = 1e-9  # [s]


def lanes_of(ts):
    """The lanes a run's time series holds: 1 (the packet columns themselves) and each ``lane<m>_`` it has."""
    return [1] + sorted({int(c[4:c.index("_")]) for c in ts.columns if c.startswith("lane") and "_" in c})


def deliveries(ts):
    """Per delivered packet of every replicate: ``(seq, transmit, arrival, delivered, first step end after
    arrival)`` [s], from a run's time series; also checks that each is delivered once and that none is lost on
    the way (a packet missing from the deliveries is one of the last ``FLIGHT_CAPACITY`` sent, still in flight).

    A packet is delivered on a lane at the row where the lane's ``packet_seq`` changes to it (lane 1: the packet
    columns; lane m: ``lane<m>_*``, ``packet_seq`` 0 when empty). Its arrival is its transmit epoch plus the travel
    time of the exchange the channel recorded, and its ``rx_time`` must equal it (USBL: follow it, by the
    downlink)."""
    rows = []
    lanes = lanes_of(ts)
    for _, g in ts.groupby("replicate"):
        t = g["time"].to_numpy()
        seen = []
        for m in lanes:
            prefix = "" if m == 1 else f"lane{m}_"
            seq, tx = g[prefix + "packet_seq"].to_numpy(), g[prefix + "tx_time"].to_numpy()
            rx = g[prefix + "rx_time"].to_numpy()
            arrival = tx + g[prefix + "travel_time"].to_numpy()
            started = seq > 0
            if "doa_x" in g:  # USBL: the downlink's travel time after the reply's arrival at the surface
                assert np.all(rx[started] >= arrival[started] - SLACK), "rx_time before the reply arrived"
            else:
                assert np.allclose(rx[started], arrival[started], rtol=0, atol=SLACK), "rx_time is not the arrival"
            new = np.flatnonzero((seq != np.concatenate([[0], seq[:-1]])) & (seq > 0))
            for k in new:
                after = np.searchsorted(t, arrival[k] - SLACK)
                first = t[after] if after < len(t) else np.inf
                rows.append((seq[k], tx[k], arrival[k], t[k], first))
            seen += seq[new].tolist()
        assert len(set(seen)) == len(seen), "a packet delivered twice"
        missing = set(range(1, len(t) + 1)) - set(seen)
        assert all(s > len(t) - FLIGHT_CAPACITY for s in missing), f"packets never delivered: {sorted(missing)}"
    return np.array(rows)


def jittered(system, T, replicates=3, extra=()):
    """A TWTT run with ``acoustics.turnaround_sigma = 1`` s (its documented maximum) at the sampling time T."""
    sets = [f"platform.system={system}", "acoustics.ranging=twtt", "acoustics.turnaround_sigma=1",
            f"simulation.sampling_time={T}", f"simulation.duration={150 * T}", *extra]
    return sblsim.run("semicircle", seed=1, set=sets, replicates=replicates).timeseries


@pytest.mark.parametrize("system", ["sbl", "lbl", "usbl"])
def test_no_jittered_reply_arrives_before_its_interrogation(system):
    """A Gaussian jitter of 1 s on a 0.05 s turnaround would draw a negative turnaround about half of the time:
    a reply before the interrogation it answers (measured: 284 of 594 replies before the turnaround was kept at
    or above 0). None is, and none is delivered before it arrives."""
    d = deliveries(jittered(system, 5.0))
    seq, tx, arrival, delivered = d[:, 0], d[:, 1], d[:, 2], d[:, 3]
    assert len(seq) > 400
    assert np.all(arrival > tx), f"{np.sum(arrival <= tx)} replies arrived before their interrogation"
    assert np.all(delivered >= arrival - SLACK)
    # the jitter is there: replies spread over seconds after their interrogation
    assert np.ptp(arrival - tx) > 2.0


@pytest.mark.parametrize("system", ["sbl", "lbl"])
@pytest.mark.parametrize("T, sigma, turnaround", [(5.0, 1.0, 0.05), (0.1, 0.0, 0.3)], ids=["jitter-1s", "no-jitter"])
def test_a_reply_reaches_the_receiver_at_the_first_step_end_after_it_arrives(system, T, sigma, turnaround):
    """A sampling time the jitter cannot reorder (T = 5 s: each reply arrives within its own step), and replies
    three sampling times in flight without jitter: every reply is delivered at the first step end that reaches its
    arrival, not later (measured before the turnaround was kept at or above 0: 47 % of the jittered replies a step
    late), not earlier."""
    ts = jittered(system, T, extra=[f"acoustics.turnaround_sigma={sigma}", f"acoustics.turnaround={turnaround}"])
    d = deliveries(ts)
    arrival, delivered, first = d[:, 2], d[:, 3], d[:, 4]
    assert len(d) > 400
    assert np.all(delivered >= arrival - SLACK)
    late = delivered > first + SLACK
    assert not late.any(), (f"{late.sum()} of {len(d)} replies delivered after the first step end after their "
                            f"arrival, by up to {np.max(delivered - first):.3g} s")


@pytest.mark.parametrize("system", ["sbl", "lbl"])
def test_replies_that_arrive_in_one_step_all_reach_the_receiver_at_its_end(system):
    """T = 2 s with a 1 s jitter: replies often arrive two in a step; each must be delivered at the first
    step end after its arrival, on a lane of its own (measured when the channel delivered one packet per step: 78 %
    (SBL) and 85 % (LBL) of the replies a step late, up to 3.98 s after they arrived)."""
    ts = jittered(system, 2.0)
    assert len(lanes_of(ts)) >= 2, "no step delivered two packets"
    d = deliveries(ts)
    arrival, delivered, first = d[:, 2], d[:, 3], d[:, 4]
    assert np.all(delivered >= arrival - SLACK)
    late = delivered > first + SLACK
    assert not late.any(), (f"{late.sum()} of {len(d)} replies delivered after the first step end after their "
                            f"arrival, by up to {np.max(delivered - first):.3g} s")


@pytest.mark.parametrize("system", ["lbl", "usbl"])
def test_a_run_without_its_time_series_counts_the_lanes_as_one_with_it(system):
    """A batch run for its metrics alone records lane 2's counter only; where a step delivered two packets it runs
    again recording the lanes (the same numbers): its metrics, the bound's among them, equal those of the run that
    keeps its time series (every output recorded), and differ from the metrics of lane 1 alone."""
    from sblsim.orchestrator.cosim.config import load_config
    from sblsim.orchestrator.cosim.metrics import run_flags
    from sblsim.orchestrator.cosim.plan import make_plan, with_replicates
    from sblsim.orchestrator.cosim.run import run_batch

    cfg = load_config("semicircle", [f"platform.system={system}", "acoustics.ranging=twtt",
                                     "acoustics.turnaround_sigma=1", "simulation.sampling_time=2",
                                     "simulation.duration=300"], seed=1)
    plans = with_replicates(make_plan(cfg), [0, 1, 2])
    full = run_batch(plans, "local", timeseries=True)
    alone = run_batch(plans, "local", timeseries=False)
    assert len(lanes_of(full.timeseries)) >= 2
    pd.testing.assert_frame_equal(alone.metrics, full.metrics)
    # lane 1 alone would count fewer updates: the lanes are in the metrics
    ts = full.timeseries
    lane1 = run_flags({c: ts[c].to_numpy().reshape(3, -1).T for c in ("packet_seq", "packet_valid", "beacon_id",
                                                                      "gated", "instr_valid", "true_x", "true_y")},
                      np.ones(3), 4 if system == "lbl" else 1)
    assert np.all(full.metrics["updates"].to_numpy() > lane1["updates"])

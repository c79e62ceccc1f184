"""The inverted LBL's pinger types (``acoustics.ping_type``; Baktoft et al. 2017, YAPS's names), each against a truth
computed here from the recorded arrivals:

* ``rbi``, each interval a uniform draw ``U(min, max)`` on the pinger's clock: every emission interval (the arrival
  less the travel time) inside ``[min, max] (1 + δ)``, their mean and variance the uniform's within 4 standard
  errors (the sample variance's from the uniform's fourth moment), a Kolmogorov-Smirnov test against the
  uniform, the nominal epochs ``t0 + c (min + max) / 2``.
* ``pbi``, a known table of intervals cycled: the nominal epochs follow the table in order, the emission intervals
  are the table's stretched by the drift plus a uniform jitter of the configured std.
* ``ekf-seq`` and ``ukf`` consistent on a random walk drawn from their own motion model with each type (NEES over
  12 seeds in the band of the stable pinger's test, tests/orchestrator/test_ilbl_system.py), their per-ping process
  noise of the emission offset the uniform's std ``(max − min) / √12`` for ``rbi`` and the jitter for ``pbi``.
* Bad keys refused in one line naming the key and what is allowed.
"""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest
from scipy.stats import chi2, kstest

from sblsim.models.errors import ModelError
from sblsim.orchestrator.cosim.config import load_config, resolve, to_toml
from sblsim.orchestrator.cosim.run import run_batch, with_replicates
from tests.orchestrator.test_ilbl_system import ILBL, arrivals

#: Four hydrophones, one ping heard by all of them per ping.
N = 4
PPM = 50.0
RBI = ["acoustics.ping_type=rbi", "acoustics.burst_interval_min=0.3", "acoustics.burst_interval_max=0.7"]
TABLE = (0.3, 0.5, 0.8, 0.4, 0.35)
PBI = ["acoustics.ping_type=pbi", "acoustics.burst_sequence=" + " ".join(map(str, TABLE))]


def _pings(overrides: list[str], replicates: int = 4, seed: int = 4):
    """The nominal and the emission epochs of every ping of a 120 s run per replicate (no range noise, loss or
    survey error), each ping's arrivals checked to share one emission: lists of (pings,) arrays [s]."""
    cfg = load_config("random-walk", ILBL + ["simulation.duration=120", "acoustics.sigma_range=0",
                                             "platform.survey_sigma=0", f"acoustics.clock_drift_ppm={PPM}"]
                      + overrides, seed=seed)
    packets = arrivals(run_batch(with_replicates(cfg, range(replicates)), "local", timeseries=True).timeseries)
    assert packets["packet_valid"].all()
    nominal, emitted = [], []
    for _, mine in packets.groupby("replicate"):
        ping = np.ceil(mine["packet_seq"].to_numpy() / N).astype(int)
        emission = (mine["rx_time"] - mine["travel_time"]).groupby(ping).agg(["min", "max", "size"])
        tx = mine["tx_time"].groupby(ping).agg(["min", "max"])
        if emission["size"].iloc[-1] < N:  # the last ping's arrivals after the run's end: left out
            emission, tx = emission.iloc[:-1], tx.iloc[:-1]
        assert (emission["size"] == N).all() and np.all(emission["max"] - emission["min"] < 1e-12)
        assert np.all(tx["max"] == tx["min"])
        np.testing.assert_array_equal(emission.index, np.arange(1, len(emission) + 1))  # no ping missing
        nominal.append(tx["min"].to_numpy())
        emitted.append(emission["min"].to_numpy())
    return cfg, nominal, emitted


def test_a_random_burst_interval_draws_each_interval_from_its_uniform():
    """rbi of U(0.3, 0.7) s and 50 ppm of drift, 4 × 120 s (about 960 intervals): every interval inside
    ``[min, max] (1 + δ)``, the mean ``(min + max) / 2 (1 + δ)`` within 4 standard errors, the sample variance
    ``(max − min)² / 12`` within 4 of its standard errors (``√((μ₄ − σ⁴) / n)``, ``μ₄ = (max − min)⁴ / 80``), the
    intervals uniform (Kolmogorov-Smirnov, p > 0.001); the nominal epochs ``c (min + max) / 2`` and the receivers'
    per-ping step the uniform's std."""
    low, high, stretch = 0.3, 0.7, 1.0 + PPM * 1e-6
    cfg, nominal, emitted = _pings(RBI)
    assert cfg["receiver"]["ping_jitter"] == pytest.approx((high - low) / math.sqrt(12.0), rel=1e-12)
    for tx in nominal:
        np.testing.assert_allclose(tx, np.arange(1, len(tx) + 1) * 0.5 * (low + high), rtol=0, atol=1e-9)
    intervals = np.concatenate([np.diff(np.r_[0.0, e]) for e in emitted])
    assert intervals.size > 800
    assert intervals.min() >= low * stretch - 1e-9 and intervals.max() <= high * stretch + 1e-9
    n, width = intervals.size, high - low
    variance = width ** 2 / 12.0
    assert abs(intervals.mean() - 0.5 * (low + high) * stretch) < 4.0 * math.sqrt(variance / n)
    spread = math.sqrt((width ** 4 / 80.0 - variance ** 2) / n)
    assert abs(intervals.var(ddof=1) - variance) < 4.0 * spread, (intervals.var(ddof=1), variance, spread)
    assert kstest(intervals, "uniform", args=(low * stretch, width * stretch)).pvalue > 1e-3
    # the spread covers the range: not a narrower draw
    assert intervals.min() < low + 0.01 and intervals.max() > high - 0.01


def test_a_pseudo_random_burst_interval_follows_its_table():
    """pbi of a five-interval table with a 10 ms jitter and 50 ppm of drift: the nominal epochs are the table's
    running sums in order, cycled (to 1 ns); each emission interval is the table's (the same row) stretched by the
    drift plus a jitter inside ``±√3 σ`` whose sample std is inside its 99.9 % χ² interval and whose mean is 0
    within 4 standard errors."""
    jitter, stretch = 0.01, 1.0 + PPM * 1e-6
    cfg, nominal, emitted = _pings(PBI + [f"acoustics.ping_jitter={jitter}"])
    assert cfg["receiver"]["ping_jitter"] == jitter
    steps = []
    for tx, e in zip(nominal, emitted):
        table = np.resize(np.array(TABLE), len(tx))  # the table cycled from its first interval
        np.testing.assert_allclose(tx, np.cumsum(table), rtol=0, atol=1e-9)
        steps.append(np.diff(np.r_[0.0, e]) - table * stretch)
    step = np.concatenate(steps)
    assert step.size > 800
    assert np.abs(step).max() <= math.sqrt(3.0) * jitter
    low, high = (jitter * math.sqrt(chi2.ppf(q, step.size - 1) / (step.size - 1)) for q in (0.0005, 0.9995))
    assert low < step.std(ddof=1) < high, (step.std(ddof=1), low, high)
    assert abs(step.mean()) < 4.0 * jitter / math.sqrt(step.size)


def test_a_pseudo_random_burst_interval_without_jitter_is_its_table_stretched():
    """pbi without jitter: every emission interval is the table's times ``1 + δ`` (to 1 ns), so the emission's
    offset from the nominal schedule is the drift's alone."""
    _, nominal, emitted = _pings(PBI, replicates=1)
    table = np.resize(np.array(TABLE), len(nominal[0]))
    np.testing.assert_allclose(np.diff(np.r_[0.0, emitted[0]]), table * (1.0 + PPM * 1e-6), rtol=0, atol=1e-9)
    np.testing.assert_allclose(emitted[0] - nominal[0], nominal[0] * PPM * 1e-6, rtol=0, atol=1e-9)


@pytest.mark.parametrize("kind", ["rbi", "pbi"])
@pytest.mark.parametrize("receiver", ["ekf-seq", "ukf"])
def test_the_receivers_are_consistent_with_each_ping_type(receiver, kind):
    """A random walk drawn from the receivers' own motion model with 20 ppm of drift, 12 seeds, on the 50 m circle:
    rbi of U(0.3, 0.5) s (the offset's step of std 58 mm, 87 m of range) and pbi of the table with a 50 ms jitter;
    the 3-D NEES in [1.5, 4.5] (the stable pinger's band), no track lost, and the RMS error within 1.3 of the bound
    with error states (the same per-ping step)."""
    pinger = (["acoustics.ping_type=rbi", "acoustics.burst_interval_min=0.3", "acoustics.burst_interval_max=0.5"]
              if kind == "rbi" else PBI + ["acoustics.ping_jitter=0.05"])
    cfg = load_config("random-walk", ILBL + pinger + [f"simulation.receiver={receiver}",
                                                      "acoustics.clock_drift_ppm=20"], seed=1)
    assert cfg["receiver"]["clock_states"]
    metrics = run_batch(with_replicates(cfg, range(12)), "local", timeseries=False).metrics
    nees = float(metrics["nees_mean"].mean())
    assert 1.5 <= nees <= 4.5, nees
    assert not metrics["diverged"].any()
    ratio = math.sqrt(np.mean(metrics["e_tot_rms"] ** 2) / np.mean(metrics["pcrb_rms"] ** 2))
    assert 0.8 <= ratio <= 1.3, ratio


def test_a_receiver_told_the_wrong_step_is_not_consistent():
    """The check above can fail: an rbi pinger whose receivers take a 1 ms step per ping (as if the pinger were
    stable) is far from consistent."""
    cfg = load_config("random-walk", ILBL + RBI + ["simulation.receiver=ekf-seq", "receiver.ping_jitter=0.001"],
                      seed=1)
    metrics = run_batch(with_replicates(cfg, range(4)), "local", timeseries=False).metrics
    assert float(metrics["nees_mean"].mean()) > 10.0 or metrics["diverged"].any()


@pytest.mark.parametrize("overrides, key, allowed", [
    (["acoustics.ping_type=rbi"], "acoustics.burst_interval_min", "allowed (0, burst_interval_max) s"),
    (["acoustics.ping_type=rbi", "acoustics.burst_interval_min=0.5", "acoustics.burst_interval_max=0.5"],
     "acoustics.burst_interval_max", "allowed (0.5, 3600] s"),
    (["acoustics.ping_type=rbi", "acoustics.burst_interval_min=0.3", "acoustics.burst_interval_max=4000"],
     "acoustics.burst_interval_max", "[0, 3600] s"),
    (["acoustics.ping_type=rbi", "acoustics.burst_interval_min=-1", "acoustics.burst_interval_max=1"],
     "acoustics.burst_interval_min", "[0, 3600] s"),
    (["acoustics.burst_interval_min=0.3"], "acoustics.burst_interval_min", "its default 0.0, or ping_type = 'rbi'"),
    (["acoustics.burst_sequence=0.3 0.4"], "acoustics.burst_sequence", "ping_type = 'pbi'"),
    (RBI + ["acoustics.ping_jitter=0.01"], "acoustics.ping_jitter", "ping_type = 'sbi' or 'pbi'"),
    (PBI + ["acoustics.ping_interval=1"], "acoustics.ping_interval", "ping_type = 'sbi'"),
    (["acoustics.ping_type=pbi"], "acoustics.burst_sequence", "allowed 1 to 64 intervals"),
    (["acoustics.ping_type=pbi", "acoustics.burst_sequence=0.3 x"], "acoustics.burst_sequence", "not a number"),
    (["acoustics.ping_type=pbi", "acoustics.burst_sequence=0.3 0"], "acoustics.burst_sequence", "[0.001, 3600] s"),
    (["acoustics.ping_type=pbi", "acoustics.burst_sequence=" + " ".join(["0.5"] * 65)], "acoustics.burst_sequence",
     "at most 64"),
    (PBI + ["acoustics.ping_jitter=0.2"], "acoustics.ping_jitter", "allowed [0, 0.173205) s"),
    (["acoustics.ping_type=yaps"], "acoustics.ping_type", "one of sbi, rbi, pbi"),
])
def test_bad_pinger_keys_are_refused_in_one_line(overrides, key, allowed):
    with pytest.raises(ModelError) as refused:
        load_config("semicircle", ["platform.system=ilbl", "simulation.receiver=ukf"] + overrides)
    message = str(refused.value)
    assert "\n" not in message and message.startswith(f"{key}:") and allowed in message, message


def test_a_resolved_configuration_runs_again():
    """A run's resolved configuration lists every key (those of the other types at their defaults): it is taken
    back as it is, and gives the same pinger."""
    for overrides in (RBI, PBI):
        cfg = load_config("semicircle", ["platform.system=ilbl", "simulation.receiver=ukf"] + overrides)
        again = resolve(tomllib.loads(to_toml(cfg)))
        assert again["acoustics"] == cfg["acoustics"] and again["receiver"] == cfg["receiver"]

"""Tests of the acoustic channel: slot clock, round robin, noise, loss, multipath, sound speed, travel time.

The channel is stepped through its compiled program (:class:`tests.helpers.Core`).
References are independent: numpy distances, the numpy Philox reference of
:mod:`sblsim.models.philox` (the random numbers of each slot, so that ranges, losses
and outliers are checked exactly), chi-square / binomial confidence
intervals, a numpy piecewise-linear slowness integral, scipy quadrature of
the CTD cast read straight from its CSV (with an error bound derived from
the trapezoid and interpolation errors), the closed-form root of the
moving-target travel-time quadratic, Mackenzie's (1981) sound-speed
equation, and the two sound speeds quoted in ``models/acoustics/data/README.md``.
"""

from __future__ import annotations

import csv
import math
from importlib import resources

import casadi as ca
import numpy as np
import pytest
from scipy import integrate, stats

from sblsim.models.acoustics import Acoustics, profile_table
from sblsim.models.acoustics.channel.interface import FLIGHT_CAPACITY, LANES, PROPAGATION, RANGING, TOA
from sblsim.models.acoustics.channel.lanes import lane_name
from sblsim.models.acoustics.sound_speed import MAX_PROFILE_ROWS, NODES, harmonic_mean, read_cast_csv
from sblsim.models.declarations import ModelError
from sblsim.models.philox import normals, uniforms
from sblsim.models.platform.core import beacon_names
from sblsim.models.program import ProgramBuilder
from tests.helpers import Core

CONF = 0.999
Z = stats.norm.ppf(0.5 + CONF / 2)

TRUE_BEACONS = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [-1.0, 0.0, 1.0], [0.0, -1.0, 1.0]])
SENT_BEACONS = TRUE_BEACONS + np.array([[0.05, -0.02, 0.01], [0.03, 0.04, -0.02],
                                        [-0.01, 0.02, 0.03], [0.02, -0.03, 0.0]])
TARGET = np.array([12.0, -5.0, 8.0])
TARGET_NAMES = ("target_x", "target_y", "target_z", "target_vx", "target_vy", "target_vz")
COMPONENT = 1  # the channel's component index in the seed tree (sblsim.models.philox, "Randomness")
CAST = "11E101663_20120821_122817"


def channel_inputs(target=TARGET, velocity=(0.0, 0.0, 0.0), true=TRUE_BEACONS, sent=SENT_BEACONS):
    inputs = {}
    for kind, pos in (("true", true), ("broadcast", sent)):
        for name, value in zip(beacon_names(4, kind), np.asarray(pos).reshape(12, *np.shape(pos)[2:])):
            inputs[name] = value
    for name, value in zip(TARGET_NAMES, list(target) + list(velocity)):
        inputs[name] = value
    return inputs


def make(params, replicates=(0,), target=TARGET, velocity=(0.0, 0.0, 0.0), t0=0.0):
    core = Core(Acoustics, params, replicates=list(replicates))
    core.initialize(t0)
    core.set_inputs(channel_inputs(target, velocity))
    return core


def slots(core, T, n, t0=0.0):
    """Step the channel by T from t0 until it has delivered slots 1 … n (each in the step that reaches its
    arrival, one per step); their outputs, in slot order. Every replicate delivers the same slot at once here."""
    got, t = {}, t0
    for _ in range(n + 8):
        out = core.step(t, T)
        t += T
        seq = out["packet_seq"]
        assert np.all(seq == seq[0])
        if seq[0] and int(seq[0]) not in got:
            assert np.all(out["rx_time"] <= t + 1e-9)  # delivered no earlier than its arrival
            got[int(seq[0])] = {name: v.copy() for name, v in out.items()}
        if len(got) == n:
            break
    assert sorted(got) == list(range(1, n + 1))
    return [got[k] for k in range(1, n + 1)]


def std_ci_contains(x, sigma, conf=CONF):
    x = np.ravel(x)
    ss = float(np.sum(x * x))
    lo = math.sqrt(ss / stats.chi2.ppf(0.5 + conf / 2, x.size))
    hi = math.sqrt(ss / stats.chi2.ppf(0.5 - conf / 2, x.size))
    return lo <= sigma <= hi, math.sqrt(ss / x.size)


def binomial_ci_contains(k, n, p, conf=CONF):
    lo, hi = stats.binom.interval(conf, n, p)
    return lo <= k <= hi


def slot_draws(seed, scenario_key, cell, replicate, k):
    """The channel's random numbers of slot k (draw k - 1): (u_loss, u_outlier, u_excess), normal."""
    u = uniforms(seed, scenario_key, cell, replicate, COMPONENT, 0, k - 1, 3)
    w = normals(seed, scenario_key, cell, replicate, COMPONENT, 1, k - 1, 1)[0]
    return u, w


# ----------------------------------------------------------------------------
# Slot clock and round robin
# ----------------------------------------------------------------------------

def test_round_robin_order_sequence_and_tx_time():
    T = 0.25
    core = make(dict(sigma_range=0.0, slot_period=T), replicates=(0, 1))
    assert core.outputs["packet_seq"].tolist() == [0, 0]
    assert core.outputs["beacon_id"].tolist() == [0, 0]
    assert not core.outputs["packet_valid"].any()
    for k, out in enumerate(slots(core, T, 10)):
        t = k * T
        bid = k % 4 + 1
        assert out["beacon_id"].tolist() == [bid, bid]
        assert out["packet_seq"].tolist() == [k + 1, k + 1]
        np.testing.assert_allclose(out["tx_time"], t + T, rtol=0, atol=1e-12)
        # it arrives a travel time later (then the next step delivers it)
        np.testing.assert_allclose(out["rx_time"], t + T + out["travel_time"], rtol=0, atol=1e-12)
        assert out["packet_valid"].all()
        # the packet carries the broadcast position of the transmitting beacon ...
        np.testing.assert_array_equal(np.column_stack([out[f"beacon_{a}"] for a in "xyz"]),
                                      np.tile(SENT_BEACONS[bid - 1], (2, 1)))
        # ... and the range is measured from its true position
        np.testing.assert_allclose(out["range_true"], np.linalg.norm(TARGET - TRUE_BEACONS[bid - 1]), rtol=1e-13)
        np.testing.assert_allclose(out["range"], np.linalg.norm(TARGET - TRUE_BEACONS[bid - 1]), rtol=1e-12)
        np.testing.assert_allclose(out["travel_time"], np.linalg.norm(TARGET - TRUE_BEACONS[bid - 1]) / 1500.0,
                                   rtol=1e-13)


def test_step_reaching_several_slots_sends_each_and_delivers_every_arrived_packet_on_its_lane():
    """Slot k ends at t0 + k T whatever the host step; a step that reaches several sends each (with its own
    random draws); at its end the channel delivers every packet that has arrived, on the lanes of the delivery in
    the order of arrival (lane 1: the packet outputs; lane m: ``lane<m>_*``; an empty lane shows packet_seq 0),
    keeps the others in flight, and shows the last delivery until the next (a step within a slot adds nothing).
    The expectation is stepped here: the slots sent, the eight in-flight places, the arrivals."""
    T, t0 = 0.125, 10.0  # binary fractions: the slot counts below are exact
    params = dict(sigma_range=0.4, loss_pct=30.0, outlier_pct=30.0, slot_period=T, seed=5, scenario_key=2, cell=3)
    reps = list(range(40))
    core = make(params, replicates=reps, t0=t0)
    d = np.linalg.norm(TARGET - TRUE_BEACONS, axis=1)

    def arrival(j):
        return t0 + j * T + d[(j - 1) % 4] / 1500.0

    t, sent, flight, shown, lanes_seen = t0, 0, [], [], 1
    for h in (0.3125, 0.0625, 0.03125, 0.5, 0.125, 0.875, 2.0):
        core.step(t, h)
        t += h
        k = int(math.floor((t - t0) / T + 1e-9))  # slots whose epoch the step reached: all sent
        assert np.all(core.state["k"][:, 0] == k), (t, k)
        for j in range(sent + 1, k + 1):  # each into a free in-flight place, none free: refused
            if len(flight) < FLIGHT_CAPACITY:
                flight.append(j)
        sent = k
        arrived = sorted((j for j in flight if arrival(j) <= t), key=lambda j: (arrival(j), j))
        flight = [j for j in flight if j not in arrived]
        out = core.outputs
        if arrived:
            shown = arrived
        for m in range(1, LANES + 1):
            seq = shown[m - 1] if m <= len(shown) else 0
            name = (lambda n: n) if m == 1 else (lambda n, m=m: f"lane{m}_{n}")
            assert np.all(out[name("packet_seq")] == seq), (t, m, seq)
            if seq == 0:
                assert np.all(out[name("packet_valid")] == 0) and np.all(out[name("range")] == 0.0)
                continue
            lanes_seen = max(lanes_seen, m)
            assert np.all(out[name("beacon_id")] == (seq - 1) % 4 + 1)
            np.testing.assert_allclose(out[name("tx_time")], t0 + seq * T, rtol=0, atol=1e-12)
            np.testing.assert_allclose(out[name("rx_time")], arrival(seq), rtol=0, atol=1e-12)
            for r in reps:  # the packet of slot seq, with the random numbers of draw seq - 1
                u, w = slot_draws(5, 2, 3, r, seq)
                valid = u[0] >= 0.3
                excess = -2.0 * math.log1p(-u[2]) if u[1] < 0.3 else 0.0
                want = 1500.0 * d[(seq - 1) % 4] / 1500.0 + 0.4 * w + excess
                assert out[name("packet_valid")][r] == valid
                assert out[name("range")][r] == pytest.approx(want if valid else 0.0, rel=1e-12, abs=1e-12)
        # the last step sends slots 16 … 31, of which 8 find a place: the refusal keeps the longest flight
        refused = np.max(d) / 1500.0 if k == 31 else 0.0
        np.testing.assert_allclose(out["overflow_travel_time"], refused, rtol=1e-13)
    assert lanes_seen == LANES  # a delivery filled every lane
    assert np.all(core.state["q_used"].sum(axis=1) == len(flight))


def test_packets_do_not_depend_on_host_step():
    """Every packet of a fine, irregular host schedule equals the packet of a one-slot-per-step schedule."""
    T = 0.2
    params = dict(sigma_range=0.5, loss_pct=20.0, outlier_pct=20.0, slot_period=T, seed=9)
    coarse = make(params, replicates=range(30))
    fine = make(params, replicates=range(30))
    want = dict(enumerate(slots(coarse, T, 11), 1))
    steps = np.tile([0.03, 0.07, 0.05, 0.11, 0.02, 0.09, 0.03], 40)
    t, got = 0.0, {}
    for h in steps:
        if t + h > 12 * T - 0.01:
            break
        fine.step(t, h)
        t += h
        got[int(fine.outputs["packet_seq"][0])] = {n: v.copy() for n, v in fine.outputs.items()}
    assert set(got) - {0} == set(range(1, 12))  # every slot seen (a host step < T never skips one)
    for k in range(1, 12):
        for name in want[k]:
            np.testing.assert_array_equal(got[k][name], want[k][name], err_msg=f"slot {k} {name}")


# ----------------------------------------------------------------------------
# Noise, loss, multipath: exact against the Philox reference, then statistics
# ----------------------------------------------------------------------------

def test_ranges_losses_outliers_match_philox_reference_exactly():
    seeds = dict(seed=11, scenario_key=3, cell=7)
    c_a, c_t, sigma, theta, drift, T = 1490.0, 1500.0, 0.3, 3.0, 50.0, 0.5
    params = dict(sound_speed_assumed=c_a, sound_speed_true=c_t, sigma_range=sigma, loss_pct=30.0,
                  outlier_pct=40.0, outlier_excess=theta, clock_drift_ppm=drift, slot_period=T, **seeds)
    reps = list(range(100, 160))
    core = make(params, replicates=reps)
    d = np.linalg.norm(TARGET - TRUE_BEACONS, axis=1)
    n_lost = n_out = 0
    for k, out in enumerate(slots(core, T, 8), 1):
        b = (k - 1) % 4
        tau = d[b] / c_t
        for j, r in enumerate(reps):
            u, w = slot_draws(11, 3, 7, r, k)
            valid, outlier = u[0] >= 0.3, u[1] < 0.4
            excess = -theta * math.log1p(-u[2]) if outlier else 0.0
            want = c_a * (tau + drift * 1e-6 * (k * T + tau)) + sigma * w + excess
            assert out["packet_valid"][j] == valid
            assert out["outlier"][j] == (outlier and valid)
            if valid:
                assert out["range"][j] == pytest.approx(want, rel=1e-13)
                np.testing.assert_array_equal([out[f"beacon_{a}"][j] for a in "xyz"], SENT_BEACONS[b])
            else:
                assert out["range"][j] == 0.0
                assert [out[f"beacon_{a}"][j] for a in "xyz"] == [0.0, 0.0, 0.0]
            n_lost += not valid
            n_out += outlier and valid
        np.testing.assert_allclose(out["travel_time"], tau, rtol=1e-14)
    assert 0 < n_lost < 8 * len(reps) and 0 < n_out  # both branches exercised


def test_range_noise_std():
    sigma = 0.2
    core = make(dict(sigma_range=sigma, seed=3, slot_period=1.0), replicates=range(4000))
    errors = []
    for k, out in enumerate(slots(core, 1.0, 2)):
        true = np.linalg.norm(TARGET - TRUE_BEACONS[k])
        np.testing.assert_allclose(out["range_true"], true, rtol=1e-13)
        errors.append(out["range"] - true)
    e = np.concatenate(errors)
    ok, est = std_ci_contains(e, sigma)
    assert ok, f"range noise std {est} vs {sigma}"
    assert abs(e.mean()) <= Z * sigma / math.sqrt(e.size)
    # two successive ranges of one replicate are independent
    r = np.corrcoef(errors[0], errors[1])[0, 1]
    assert abs(math.atanh(r)) <= Z / math.sqrt(errors[0].size - 3)
    # and so are the ranges of neighbouring replicates
    r = np.corrcoef(errors[0][:-1], errors[0][1:])[0, 1]
    assert abs(math.atanh(r)) <= Z / math.sqrt(errors[0].size - 4)


def test_packet_loss_rate_and_lost_packet_fields():
    loss = 20.0
    core = make(dict(loss_pct=loss, sigma_range=0.1, outlier_pct=50.0, seed=4, slot_period=1.0),
                replicates=range(3000))
    valid = []
    for k, out in enumerate(slots(core, 1.0, 2)):
        v = out["packet_valid"]
        valid.append(v)
        # a lost packet has range and position 0 (no NaN anywhere)
        assert np.all(out["range"][~v] == 0.0)
        for a in "xyz":
            assert np.all(out[f"beacon_{a}"][~v] == 0.0)
            assert np.all(out[f"beacon_{a}"][v] == SENT_BEACONS[k]["xyz".index(a)])
        clean = v & ~out["outlier"]
        assert np.all(np.abs(out["range"][clean] - np.linalg.norm(TARGET - TRUE_BEACONS[k])) < 6 * 0.1)
        assert not np.any(out["outlier"][~v])
        # slot bookkeeping and the true geometry continue for lost packets
        assert np.all(out["packet_seq"] == k + 1) and np.all(out["beacon_id"] == k + 1)
        np.testing.assert_allclose(out["range_true"], np.linalg.norm(TARGET - TRUE_BEACONS[k]), rtol=1e-13)
        for name, value in out.items():
            assert np.all(np.isfinite(value.astype(float))), name
    v = np.concatenate(valid)
    lost = int(np.sum(~v))
    assert binomial_ci_contains(lost, v.size, loss / 100.0), f"{lost} lost of {v.size}"


def test_loss_extremes():
    out = slots(make(dict(loss_pct=100.0), replicates=range(50)), 0.1, 1)[0]
    assert not out["packet_valid"].any()
    assert np.all(out["range"] == 0.0)
    assert slots(make(dict(loss_pct=0.0), replicates=range(50)), 0.1, 1)[0]["packet_valid"].all()


def test_outliers_only_lengthen_ranges_with_exponential_excess():
    p_out, mean_excess = 30.0, 2.0
    core = make(dict(outlier_pct=p_out, outlier_excess=mean_excess, sigma_range=0.0, clock_drift_ppm=0.0,
                     sound_speed_assumed=1500.0, sound_speed_true=1500.0, seed=8), replicates=range(4000))
    out = slots(core, 0.1, 1)[0]
    true = np.linalg.norm(TARGET - TRUE_BEACONS[0])
    excess = out["range"] - true
    assert np.all(excess >= -1e-9)
    flag = out["outlier"]
    np.testing.assert_allclose(excess[~flag], 0.0, atol=1e-9)
    assert np.all(excess[flag] > 0.0)
    n = int(flag.sum())
    assert binomial_ci_contains(n, flag.size, p_out / 100.0), f"{n} outliers of {flag.size}"
    # exponential mean θ: 2 Σx / θ ~ chi2(2n)
    s = float(excess[flag].sum())
    lo = 2 * s / stats.chi2.ppf(0.5 + CONF / 2, 2 * n)
    hi = 2 * s / stats.chi2.ppf(0.5 - CONF / 2, 2 * n)
    assert lo <= mean_excess <= hi, f"mean excess {s / n} vs {mean_excess}"
    # exponential shape: Kolmogorov-Smirnov against Exp(mean_excess)
    assert stats.kstest(excess[flag], "expon", args=(0, mean_excess)).pvalue > 1 - CONF


def test_sound_speed_mismatch_scales_range():
    c_a, c_t = 1480.0, 1525.0
    core = make(dict(sound_speed_assumed=c_a, sound_speed_true=c_t, sigma_range=0.0, slot_period=0.5))
    for k, out in enumerate(slots(core, 0.5, 4)):
        d = np.linalg.norm(TARGET - TRUE_BEACONS[k])
        assert out["range"][0] == pytest.approx(d * c_a / c_t, rel=1e-13)
        assert out["travel_time"][0] == pytest.approx(d / c_t, rel=1e-13)


def test_clock_drift_adds_drift_times_reception_epoch():
    drift_ppm, c = 200.0, 1500.0
    T = 2.0
    core = make(dict(clock_drift_ppm=drift_ppm, sigma_range=0.0, sound_speed_assumed=c, sound_speed_true=c,
                     slot_period=T))
    for k, out in enumerate(slots(core, T, 3)):
        d = np.linalg.norm(TARGET - TRUE_BEACONS[k])
        tau = d / c
        expected = c * (tau + drift_ppm * 1e-6 * ((k + 1) * T + tau))
        assert out["range"][0] == pytest.approx(expected, rel=1e-13)
        # the drift term is not negligible at this tolerance
        assert abs(expected - d) > 1e-6 * d


def test_channel_replicate_alone_equals_replicate_in_batch():
    params = dict(sigma_range=0.3, loss_pct=10.0, outlier_pct=10.0, seed=17, cell=4, slot_period=1.0)
    batch = make(params, replicates=range(5))
    alone = make(params, replicates=[2])
    for k in range(20):
        batch.step(k * 1.0, 1.0)
        alone.step(k * 1.0, 1.0)
        for name in batch.outputs:
            np.testing.assert_array_equal(alone.outputs[name], batch.outputs[name][2:3], err_msg=name)
    assert len(np.unique(batch.outputs["range"])) > 1  # the replicates differ


# ----------------------------------------------------------------------------
# Sound-speed profile
# ----------------------------------------------------------------------------

def read_cast_raw():
    """Depth and sound-speed columns of the shipped cast, parsed with the csv module."""
    text = (resources.files("sblsim.models.acoustics") / "data" / f"{CAST}.csv").read_text()
    rows = [r for r in csv.reader(line for line in text.splitlines() if not line.startswith("%"))]
    header, data = rows[0], rows[1:]
    i_depth = header.index("Depth (Meter)")
    i_speed = header.index("Sound velocity (Meters per Second)")
    depth = np.array([float(r[i_depth]) for r in data])
    speed = np.array([float(r[i_speed]) for r in data])
    return depth, speed


def _harmonic_mean_function() -> ca.Function:
    z1, z2, c0, n = (ca.SX.sym(s) for s in ("z1", "z2", "c0", "n"))
    nodes, slowness = ca.SX.sym("nodes", NODES), ca.SX.sym("slowness", NODES)
    return ca.Function("hm", [z1, z2, c0, n, nodes, slowness], [harmonic_mean(z1, z2, c0, n, nodes, slowness)])


HM = _harmonic_mean_function()


def model_harmonic_mean(params, z1, z2):
    """The model's harmonic mean: ``prepare`` on the FMU parameters of a configuration, then the expression."""
    config = dict(sound_speed_profile="constant", sound_speed_table="", temperature=15.0, salinity=35.0)
    config.update(params)
    values = Acoustics.fmu_parameters(config)
    d = np.array(Acoustics.program().prepare(Acoustics.parameter_vector(values))).ravel()
    constant = values.get("sound_speed_true", 1500.0)
    return np.array([float(HM(a, b, constant, values["sound_speed_rows"], d[:NODES], d[NODES:2 * NODES]))
                     for a, b in zip(np.atleast_1d(z1), np.atleast_1d(z2))])


def reference_harmonic_mean(depth, speed, z1, z2):
    """Independent numpy form of the documented scheme: nodes extended by 10 km with the end speeds,
    trapezoid slowness at the nodes, S linear between them; a level path takes the limit 1 / S' at its
    mid depth (the interval starting at a node when the depth is one)."""
    nodes = np.concatenate([[depth[0] - 1e4], depth, [depth[-1] + 1e4]])
    speeds = np.concatenate([[speed[0]], speed, [speed[-1]]])
    S = np.concatenate([[0.0], np.cumsum(0.5 * (1 / speeds[1:] + 1 / speeds[:-1]) * np.diff(nodes))])
    z1, z2 = np.broadcast_arrays(np.asarray(z1, float), np.asarray(z2, float))
    dz = z2 - z1
    level = np.abs(dz) < 1e-9
    k = np.clip(np.searchsorted(nodes, 0.5 * (z1 + z2), side="right") - 1, 0, nodes.size - 2)
    limit = 2.0 / (1.0 / speeds[k] + 1.0 / speeds[k + 1])
    ds = np.interp(z2, nodes, S) - np.interp(z1, nodes, S)
    return np.where(level, limit, dz / np.where(level, 1.0, ds))


def slowness_quad(depth, speed, z1, z2):
    """∫_{z1}^{z2} dz / c(z), c linearly interpolated (constant beyond the ends), by scipy quad."""
    lo, hi = min(z1, z2), max(z1, z2)
    knots = np.concatenate([[lo], depth[(depth > lo) & (depth < hi)], [hi]])
    total = 0.0
    for a, b in zip(knots[:-1], knots[1:]):
        val, _ = integrate.quad(lambda z: 1.0 / np.interp(z, depth, speed), a, b, epsabs=0, epsrel=1e-13)
        total += val
    return total if z2 >= z1 else -total


def slowness_error_bound(depth, speed, z1, z2):
    """Bound on |S_model(z2) − S_model(z1) − ∫ dz/c| for c linear on each table interval (slope g):
    trapezoid error h³ max|(1/c)''| / 12 = h³ g² / (6 c³) on every interval the path touches, plus the
    error of interpolating S linearly inside the two end intervals, h² max|S''| / 8 = h² |g| / (8 c²)."""
    lo, hi = min(z1, z2), max(z1, z2)
    h, g = np.diff(depth), np.diff(speed) / np.diff(depth)
    c = np.minimum(speed[1:], speed[:-1])
    touched = (depth[1:] > lo) & (depth[:-1] < hi)
    ends = touched & (((depth[:-1] < lo) & (depth[1:] > lo)) | ((depth[:-1] < hi) & (depth[1:] > hi)))
    return float(np.sum((h**3 * g**2 / (6 * c**3))[touched]) + np.sum((h**2 * np.abs(g) / (8 * c**2))[ends])) + 1e-13


def test_cast_table_is_the_csv_columns_and_matches_data_readme():
    depth, speed = read_cast_raw()
    assert np.all(np.diff(depth) > 0) and depth.size <= MAX_PROFILE_ROWS
    table = profile_table(f"ctd:{CAST}", "", 15.0, 35.0)
    np.testing.assert_array_equal(table, np.column_stack([depth, speed]))
    # "Sound speed falls from about 1512.6 m/s at the surface to about 1491.5 m/s at 22 m"
    assert np.interp(0.0, depth, speed) == pytest.approx(1512.6, abs=0.1)
    assert np.interp(22.0, depth, speed) == pytest.approx(1491.5, abs=0.2)
    # and the channel's level paths there see it (the limit over the interval below each depth)
    c = model_harmonic_mean({"sound_speed_profile": f"ctd:{CAST}"}, [0.0, 22.0], [0.0, 22.0])
    assert c[0] == pytest.approx(1512.6, abs=0.1)
    assert c[1] == pytest.approx(1491.5, abs=0.2)
    # a level path at a table depth takes the limit over the interval below it: 2 / (1/c_k + 1/c_k+1)
    np.testing.assert_allclose(model_harmonic_mean({"sound_speed_profile": f"ctd:{CAST}"}, depth[:-1:7], depth[:-1:7]),
                               2.0 / (1.0 / speed[:-1:7] + 1.0 / speed[1::7]), rtol=1e-10)  # S differenced


@pytest.mark.parametrize("z1,z2", [(0.0, 22.0), (1.0, 8.0), (15.3, 3.7), (0.5, 0.9), (2.0, 30.0), (-1.0, 5.0),
                                   (6.2, 6.2), (40.0, 25.0)])
def test_harmonic_mean_matches_numpy_scheme_and_quadrature(z1, z2):
    depth, speed = read_cast_raw()
    got = model_harmonic_mean({"sound_speed_profile": f"ctd:{CAST}"}, z1, z2)[0]
    # the documented scheme, computed independently
    assert got == pytest.approx(float(reference_harmonic_mean(depth, speed, z1, z2)), rel=1e-11)
    # symmetric in its ends
    assert model_harmonic_mean({"sound_speed_profile": f"ctd:{CAST}"}, z2, z1)[0] == pytest.approx(got, rel=1e-11)
    if z1 == z2:  # the level limit lies between the speeds of the interval
        k = np.searchsorted(depth, z1, side="right") - 1
        assert min(speed[k], speed[k + 1]) <= got <= max(speed[k], speed[k + 1])
        return
    # the exact slowness integral, within the trapezoid and interpolation error of the scheme
    exact = slowness_quad(depth, speed, z1, z2)
    bound = slowness_error_bound(depth, speed, z1, z2)
    ds = (z2 - z1) / got
    assert abs(ds - exact) <= bound, (ds - exact, bound)
    assert got == pytest.approx((z2 - z1) / exact, rel=max(2 * bound / abs(exact), 1e-12))
    assert bound / abs(exact) < 1e-4  # the bound is tight enough to mean something


def test_harmonic_mean_hand_worked_linear_profile():
    # c(z) = 1500 + z on [0, 100]: ∫ dz / c = ln(c2 / c1), harmonic mean (z2 - z1) / ln(c2 / c1)
    z = np.linspace(0.0, 100.0, 201)
    text = "; ".join(f"{float(a)!r} {1500.0 + float(a)!r}" for a in z)
    params = {"sound_speed_profile": "table", "sound_speed_table": text}
    z1, z2 = np.array([10.0, 0.0, 33.3, 90.0]), np.array([60.0, 100.0, 33.9, 1.0])
    got = model_harmonic_mean(params, z1, z2)
    exact = np.log((1500.0 + z2) / (1500.0 + z1))
    for k in range(z1.size):
        # within the trapezoid and interpolation error of the scheme for this table
        bound = slowness_error_bound(z, 1500.0 + z, z1[k], z2[k])
        assert abs((z2[k] - z1[k]) / got[k] - exact[k]) <= bound
        assert bound / abs(exact[k]) < 1e-4
    np.testing.assert_allclose(got, (z2 - z1) / exact, rtol=1e-4)
    # a level path takes the limit of the interval it lies in: 2 / (1/1525 + 1/1525.5)
    assert model_harmonic_mean(params, 25.0, 25.0)[0] == pytest.approx(2.0 / (1 / 1525.0 + 1 / 1525.5), rel=1e-12)
    assert model_harmonic_mean(params, 25.25, 25.25)[0] == pytest.approx(2.0 / (1 / 1525.0 + 1 / 1525.5), rel=1e-12)


def test_constant_profile_harmonic_mean_is_the_constant_exactly():
    got = model_harmonic_mean({"sound_speed_true": 1487.0}, [0.0, 3.0, 7.0, -50.0], [10.0, 3.0, -2.0, 2e4])
    assert np.all(got == 1487.0)


@pytest.mark.parametrize("spec", ["ctd", "csv", "table"])
def test_channel_travel_time_uses_profile(spec, tmp_path):
    """The compiled channel's travel time is the distance over the profile's harmonic mean (numpy scheme)."""
    depth, speed = read_cast_raw()
    rows = "; ".join(f"{float(a)!r}, {float(b)!r}" for a, b in zip(depth, speed))
    params = {"ctd": {"sound_speed_profile": f"ctd:{CAST}"},
              "table": {"sound_speed_profile": "table", "sound_speed_table": rows}}.get(spec)
    if spec == "csv":
        path = tmp_path / "cast.csv"
        path.write_text("depth,sound_speed\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(depth, speed)))
        params = {"sound_speed_profile": str(path)}
    c_a = 1500.0
    rng = np.random.default_rng(4)
    B = 12
    target = [rng.uniform(-30, 30, B), rng.uniform(-30, 30, B), rng.uniform(0.5, 21.0, B)]
    true = np.broadcast_to(TRUE_BEACONS[:, :, None], (4, 3, B)).copy()
    true[:, 2, :] = rng.uniform(0.2, 3.0, (4, B))
    core = Core(Acoustics, dict(sigma_range=0.0, sound_speed_assumed=c_a, **params), replicates=range(B))
    core.initialize(0.0)
    core.set_inputs(channel_inputs(target, (0.0, 0.0, 0.0), true=true, sent=true))
    for k, out in enumerate(slots(core, 0.1, 4)):
        b = true[k]
        distance = np.linalg.norm(np.array(target) - b, axis=0)
        c_bar = reference_harmonic_mean(depth, speed, b[2], target[2])
        np.testing.assert_allclose(out["range_true"], distance, rtol=1e-13)
        np.testing.assert_allclose(out["travel_time"], distance / c_bar, rtol=1e-10)
        np.testing.assert_allclose(out["range"], c_a * distance / c_bar, rtol=1e-10)
    # the profile matters at this tolerance: the paths' mean speeds differ from each other and from 1500 m/s
    assert np.max(np.abs(c_bar - 1500.0)) > 2.0 and np.ptp(c_bar) > 2.0


def test_teos10_profile_against_mackenzie_equation():
    """TEOS-10 uniform water vs Mackenzie (1981), whose fit differs from the modern equations by a few tenths of m/s."""
    for T, S in [(2.0, 30.0), (15.0, 35.0), (25.0, 38.0)]:
        table = profile_table("teos10", "", T, S)
        D = table[:, 0]
        mackenzie = (1448.96 + 4.591 * T - 5.304e-2 * T**2 + 2.374e-4 * T**3 + 1.340 * (S - 35) + 1.630e-2 * D
                     + 1.675e-7 * D**2 - 1.025e-2 * T * (S - 35) - 7.139e-13 * T * D**3)
        np.testing.assert_allclose(table[:, 1], mackenzie, rtol=0, atol=0.5)
        assert D[0] == 0.0 and np.all(np.diff(D) > 0)
    # the channel uses it: a level path at 50 m takes the limit over the TEOS-10 interval [50, 51] m
    table = profile_table("teos10", "", 10.0, 34.0)
    c = model_harmonic_mean({"sound_speed_profile": "teos10", "temperature": 10.0, "salinity": 34.0}, 50.0, 50.0)
    k = int(np.flatnonzero(table[:, 0] == 50.0)[0])
    assert c[0] == pytest.approx(2.0 / (1.0 / table[k, 1] + 1.0 / table[k + 1, 1]), rel=1e-12)


def test_config_values_round_trip_the_table():
    depth, speed = read_cast_raw()
    values = Acoustics.fmu_parameters({"sound_speed_profile": f"ctd:{CAST}", "sound_speed_table": "",
                                       "temperature": 15.0, "salinity": 35.0})
    assert values["sound_speed_rows"] == depth.size
    assert values["sound_speed_depth[1]"] == depth[0] and values[f"sound_speed[{depth.size}]"] == speed[-1]
    config = Acoustics.config_values(values)
    assert config["sound_speed_profile"] == "table"
    np.testing.assert_array_equal(profile_table("table", config["sound_speed_table"], 15.0, 35.0),
                                  np.column_stack([depth, speed]))
    assert Acoustics.config_values(Acoustics.fmu_parameters({"sound_speed_profile": "constant"}))[
        "sound_speed_profile"] == "constant"


# ----------------------------------------------------------------------------
# Reading casts
# ----------------------------------------------------------------------------

def test_read_cast_csv_columns_by_name_comments_and_repeats(tmp_path):
    path = tmp_path / "cast.csv"
    path.write_text("% a comment\n# another\n\nTemperature,Sound Velocity (m/s),Depth (m)\n"
                    "11.0,1501.0,1.0\n9.0,1499.0,2.5\n12.0,1500.5,3.0\n\n10.0,1502.0,3.0\n")
    table = read_cast_csv(path)
    # the two rows at 3 m averaged
    np.testing.assert_array_equal(table, [[1.0, 1501.0], [2.5, 1499.0], [3.0, (1500.5 + 1502.0) / 2]])


def test_read_cast_csv_resamples_long_casts(tmp_path):
    z = np.arange(1000) * 0.1
    path = tmp_path / "long.csv"
    path.write_text("depth,sound_speed\n" + "".join(f"{float(a)!r},{1500.0 + 0.25 * float(a)!r}\n" for a in z))
    table = read_cast_csv(path)
    assert table.shape == (MAX_PROFILE_ROWS, 2)
    assert table[0, 0] == z[0] and table[-1, 0] == pytest.approx(z[-1], rel=1e-15)
    np.testing.assert_allclose(np.diff(table[:, 0]), z[-1] / (MAX_PROFILE_ROWS - 1), rtol=1e-9)
    # a linear profile resampled linearly is the same line
    np.testing.assert_allclose(table[:, 1], 1500.0 + 0.25 * table[:, 0], rtol=1e-13)


@pytest.mark.parametrize("text,match", [
    ("depth,sound_speed\n1,1500\n2,nan\n", r"line 3, column 'sound_speed'.*not finite"),
    ("depth,sound_speed\n1,1500\n2,inf\n", r"line 3.*not finite"),
    ("depth,sound_speed\n1,1500\n2,fast\n", r"line 3, column 'sound_speed': 'fast' is not a number"),
    ("depth,sound_speed\n1,1500\n2,1800\n", r"line 3.*outside the allowed range \[1300, 1700\]"),
    ("depth,sound_speed\n-1,1500\n", r"line 2, column 'depth'.*outside the allowed range \[0, 11000\]"),
    ("depth,sound_speed\n1,1500\n2\n", r"line 3, column 'sound_speed': '' is not a number"),
    ("depth,temperature\n1,10\n", r"needs a header line"),
    ("% only a comment\n", r"holds no header and no data"),
    ("depth,sound_speed\n", r"holds no data rows"),
    ("depth,sound_speed\n0,1510\n100,1489\n30,1508\n", r"line 4, column 'depth': depth 30 m is above line 3's 100 m"),
])
def test_read_cast_csv_refuses_malformed_files(tmp_path, text, match):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ModelError, match=match) as info:
        read_cast_csv(path)
    assert "\n" not in str(info.value)
    # the profile setting reports the same through the configuration
    with pytest.raises(ModelError, match=r"acoustics\.sound_speed_profile"):
        Acoustics.fmu_parameters({"sound_speed_profile": str(path)})


def test_profile_table_refusals_and_file_versions(tmp_path):
    with pytest.raises(ModelError, match="no such file"):
        profile_table(str(tmp_path / "missing.csv"), "", 15.0, 35.0)
    with pytest.raises(ModelError, match="is a directory"):
        profile_table(str(tmp_path), "", 15.0, 35.0)
    with pytest.raises(ModelError, match="unknown cast 'nope'"):
        profile_table("ctd:nope", "", 15.0, 35.0)
    with pytest.raises(ModelError, match="needs rows"):
        profile_table("table", "", 15.0, 35.0)
    with pytest.raises(ModelError, match="greater than the row before"):
        profile_table("table", "1 1500; 1 1501", 15.0, 35.0)
    assert profile_table("constant", "", 15.0, 35.0).shape == (0, 2)
    # a file is read again when it changes
    path = tmp_path / "cast.csv"
    path.write_text("depth,sound_speed\n1,1500\n2,1501\n")
    np.testing.assert_array_equal(profile_table(str(path), "", 15.0, 35.0), [[1, 1500], [2, 1501]])
    path.write_text("depth,sound_speed\n1,1490\n2,1491\n3,1492\n")
    np.testing.assert_array_equal(profile_table(str(path), "", 15.0, 35.0), [[1, 1490], [2, 1491], [3, 1492]])


# ----------------------------------------------------------------------------
# Travel time with a moving target
# ----------------------------------------------------------------------------

def _positive_root(d, v, c):
    """Positive root τ of |d + v τ|² = c² τ²: (v·v − c²) τ² + 2 (d·v) τ + d·d = 0 (a < 0 < d·d)."""
    a = np.sum(v * v, axis=-1) - c * c
    b = 2 * np.sum(d * v, axis=-1)
    cc = np.sum(d * d, axis=-1)
    return (-b - np.sqrt(b * b - 4 * a * cc)) / (2 * a)


def _travel_times(c, beacon, position, velocity):
    """One slot of the compiled channel, beacon 1 at a per-replicate position: (travel time, path length)."""
    B = beacon.shape[0]
    true = np.broadcast_to(TRUE_BEACONS[:, :, None], (4, 3, B)).copy()
    true[0] = beacon.T
    core = Core(Acoustics, dict(sound_speed_true=c, sound_speed_assumed=c, sigma_range=0.0), replicates=range(B))
    core.initialize(0.0)
    core.set_inputs(channel_inputs(position.T, velocity.T, true=true, sent=true))
    core.step(0.0, 0.1)  # slot 1 at 0.1 s, delivered in the step that reaches its arrival
    out = core.step(0.1, max(0.1, float(np.max(np.linalg.norm(position - beacon, axis=1))) / 1000.0))
    assert np.all(out["beacon_id"] == 1)
    np.testing.assert_allclose(out["rx_time"], 0.1 + out["travel_time"], rtol=1e-14)
    return out["travel_time"], out["range_true"], out["range"]


def test_travel_time_moving_target_solves_quadratic():
    rng = np.random.default_rng(2024)
    c = 1500.0
    B = 50
    beacon = rng.uniform(-2, 2, (B, 3))
    position = rng.uniform(-40, 40, (B, 3))
    velocity = rng.uniform(-8, 8, (B, 3))
    tau, distance, rng_measured = _travel_times(c, beacon, position, velocity)
    d = position - beacon
    root = _positive_root(d, velocity, c)
    assert np.all(root > 0)
    # residual of the defining equation |p + v τ − b| = c τ
    gap = np.abs(np.linalg.norm(d + velocity * tau[:, None], axis=1) - c * tau)
    # The fixed point τ = |d + v τ| / c is a contraction of factor q = |v| / c;
    # three iterations from τ = 0 plus the final evaluation give |τ − τ*| ≤ q⁴ τ*.
    q = np.linalg.norm(velocity, axis=1) / c
    bound = q**4 * root
    assert np.all(np.abs(tau - root) <= 1.01 * bound + 1e-14 * root)
    assert np.all(gap <= c * (1 + q) * (1.01 * bound + 1e-14 * root))
    np.testing.assert_allclose(tau, root, rtol=1e-8)
    # the path length is the one the travel time was computed from (constant c)
    np.testing.assert_allclose(distance, c * tau, rtol=1e-13)
    np.testing.assert_allclose(rng_measured, c * tau, rtol=1e-13)
    # the moving target is not at the transmit-time distance: the test is not trivial
    assert np.min(np.abs(tau - np.linalg.norm(d, axis=1) / c) / bound) > 1e3


def test_travel_time_diver_speed_is_exact():
    """At diver speeds (≤ 2 m/s) the fixed point is converged to rounding."""
    rng = np.random.default_rng(7)
    c = 1490.0
    beacon = rng.uniform(-2, 2, (30, 3))
    position = rng.uniform(-30, 30, (30, 3))
    velocity = rng.uniform(-1.15, 1.15, (30, 3))
    tau, _, _ = _travel_times(c, beacon, position, velocity)
    np.testing.assert_allclose(tau, _positive_root(position - beacon, velocity, c), rtol=1e-11)


def test_step_with_moving_target_reports_reception_distance():
    c = 1500.0
    v = np.array([1.5, -1.0, 0.3])
    core = make(dict(sound_speed_true=c, sound_speed_assumed=c, sigma_range=0.0), velocity=v)
    out = slots(core, 0.1, 1)[0]
    d = TARGET - TRUE_BEACONS[0]
    tau = float(_positive_root(d, v, c))
    assert out["travel_time"][0] == pytest.approx(tau, rel=1e-11)
    assert out["range_true"][0] == pytest.approx(np.linalg.norm(d + v * tau), rel=1e-11)
    assert out["range"][0] == pytest.approx(c * tau, rel=1e-11)
    # and differs from the distance at transmit by about the radial motion v·u τ
    u = d / np.linalg.norm(d)
    assert out["range_true"][0] - np.linalg.norm(d) == pytest.approx(v @ u * tau, rel=1e-3)


@pytest.mark.parametrize("propagation", PROPAGATION)
@pytest.mark.parametrize("ranging", RANGING[:TOA])
def test_each_ranging_runs_its_own_slot_event_once_per_slot(ranging, propagation):
    """SBL and LBL have a slot event per (ranging, propagation), each in the runs of its pair only
    (``Event.when``; the inverted LBL's pings an event of their own, below): a step that reaches one slot epoch
    emits one packet (not none, not one per event), timed as that ranging times it: OWTT ``τ = d / c``, TWTT the
    round trip ``2 d / c + t_ta`` of a diver at rest (the eigenray of isovelocity water is the straight line)."""
    pairs = [dict(e.when) for e in Acoustics.program(4).events if e.when]
    assert sorted((w["ranging"], w["propagation"]) for w in pairs if w["detection"] == ("fixed",)) == sorted(
        ((r,), (q,)) for r in RANGING for q in PROPAGATION)  # every pair, each once (and detection by snr's
    assert sorted(w["ranging"] for w in pairs if w["detection"] == ("snr",)) == sorted((r,) for r in RANGING)  # own)
    T, turnaround = 0.25, 0.05
    core = make(dict(sigma_range=0.0, slot_period=T, ranging=ranging, turnaround=turnaround,
                     propagation=propagation), replicates=(0, 1))
    for k, out in enumerate(slots(core, T, 4)):
        assert out["packet_seq"].tolist() == [k + 1, k + 1]
        assert out["arrival"].tolist() == [1, 1]
        d = np.linalg.norm(TARGET - TRUE_BEACONS[k])
        expected = d / 1500.0 if ranging == "owtt" else 2.0 * d / 1500.0 + turnaround
        np.testing.assert_allclose(out["travel_time"], expected, rtol=1e-12)
        np.testing.assert_allclose(out["range"], d, rtol=1e-12)


@pytest.mark.parametrize("propagation", PROPAGATION)
def test_a_ping_reaches_every_receiver_one_way_at_its_emission(propagation):
    """``ranging = "toa"`` (the inverted LBL): the diver at rest pings every P = 4 T (the round-robin cycle) on its
    own clock; the step that reaches the emission sends one packet per receiver, each arriving ``‖p − b_i‖ / c``
    after the emission (isovelocity water: the eigenray is the straight line), carrying the ping's nominal epoch
    as ``tx_time``, ``c (rx_time − tx_time)`` as its range and the slot counter ``4 (c − 1) + i``; all four are
    delivered together (lane 1 the earliest, then lanes 2 to 4 in the order of arrival). With 100 ppm of the
    pinger's drift the second ping leaves ``100e-6 P`` late and its ranges are ``c`` times that longer."""
    T = 0.25
    for ppm in (0.0, 100.0):
        core = make(dict(sigma_range=0.0, slot_period=T, ranging="toa", clock_drift_ppm=ppm,
                         propagation=propagation), replicates=(0, 1))
        pings, t = [], 0.0
        while len(pings) < 2:
            out = core.step(t, T)
            t += T
            if out["packet_seq"][0] and (not pings or out["packet_seq"][0] != pings[-1]["packet_seq"][0]):
                pings.append({name: v.copy() for name, v in out.items()})
        for c, out in enumerate(pings, start=1):
            emitted = c * 4 * T * (1.0 + ppm * 1e-6)
            lanes = [{name: out[lane_name(m, name)][0] for name in ("packet_seq", "beacon_id", "tx_time", "rx_time",
                                                                     "travel_time", "range")} for m in range(1, 5)]
            assert [lane["rx_time"] for lane in lanes] == sorted(lane["rx_time"] for lane in lanes)
            assert sorted(lane["packet_seq"] for lane in lanes) == [4 * (c - 1) + i for i in range(1, 5)]
            for lane in lanes:
                d = np.linalg.norm(TARGET - TRUE_BEACONS[int(lane["beacon_id"]) - 1])
                assert lane["packet_seq"] == 4 * (c - 1) + lane["beacon_id"]
                assert lane["travel_time"] == pytest.approx(d / 1500.0, rel=1e-12)
                assert lane["rx_time"] == pytest.approx(emitted + d / 1500.0, rel=1e-12)
                assert lane["tx_time"] == pytest.approx(c * 4 * T, rel=1e-15)
                assert lane["range"] == pytest.approx(1500.0 * (lane["rx_time"] - lane["tx_time"]), rel=1e-12)
                assert lane["range"] == pytest.approx(d + 1500.0 * (emitted - c * 4 * T), rel=1e-12)


def test_an_event_names_choices_of_a_choice_parameter():
    """``ProgramBuilder.event(when=...)`` refuses a parameter that is not a choice, a choice it does not have, a
    bare string and no choice at all."""
    b = ProgramBuilder(Acoustics, 4, states=[("k", 1)])
    due = lambda x, u, p, d, t, h: x["k"] < 0  # noqa: E731
    tick = lambda x, u, p, d, w, t, h: {"k": x["k"] + 1}  # noqa: E731
    assert b.event("e", due, tick, when={"ranging": ["twtt"]}).when == (("ranging", ("twtt",)),)
    assert b.event("e", due, tick, when={"ranging": ["twtt"], "propagation": ("ray",)}).when == (
        ("ranging", ("twtt",)), ("propagation", ("ray",)))
    for when in ({"sigma_range": ["twtt"]}, {"ranging": ["usbl"]}, {"ranging": "twtt"}, {"ranging": []},
                 {"ranging": ["twtt"], "propagation": ["curved"]}):
        with pytest.raises(ValueError, match="choice parameter"):
            b.event("e", due, tick, when=when)

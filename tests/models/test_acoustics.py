"""Tests of the acoustic channel: round robin, noise, loss, multipath, sound speed, travel time.

References are independent: numpy distances, chi-square / binomial confidence
intervals, scipy quadrature of the CTD cast read straight from its CSV, the
closed-form root of the moving-target travel-time quadratic, and the two
sound speeds quoted in ``models/acoustics/data/README.md``.
"""

from __future__ import annotations

import csv
import math
from importlib import resources

import numpy as np
import pytest
from scipy import integrate, stats

from models.acoustics import AcousticsCore, SoundSpeedProfile, load_profile
from models.platform import beacon_names

CONF = 0.999
Z = stats.norm.ppf(0.5 + CONF / 2)

TRUE_BEACONS = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [-1.0, 0.0, 1.0], [0.0, -1.0, 1.0]])
SENT_BEACONS = TRUE_BEACONS + np.array([[0.05, -0.02, 0.01], [0.03, 0.04, -0.02],
                                        [-0.01, 0.02, 0.03], [0.02, -0.03, 0.0]])
TARGET = np.array([12.0, -5.0, 8.0])


def channel_inputs(target=TARGET, velocity=(0.0, 0.0, 0.0)):
    inputs = {}
    for kind, pos in (("true", TRUE_BEACONS), ("broadcast", SENT_BEACONS)):
        for name, value in zip(beacon_names(4, kind), pos.ravel()):
            inputs[name] = value
    for name, value in zip(("target_x", "target_y", "target_z", "target_vx", "target_vy", "target_vz"),
                           list(target) + list(velocity)):
        inputs[name] = value
    return inputs


def make(params, replicates=(0,), target=TARGET, velocity=(0.0, 0.0, 0.0)):
    core = AcousticsCore(params, replicates=list(replicates))
    core.initialize(0.0)
    core.set_inputs(channel_inputs(target, velocity))
    return core


def std_ci_contains(x, sigma, conf=CONF):
    x = np.ravel(x)
    ss = float(np.sum(x * x))
    lo = math.sqrt(ss / stats.chi2.ppf(0.5 + conf / 2, x.size))
    hi = math.sqrt(ss / stats.chi2.ppf(0.5 - conf / 2, x.size))
    return lo <= sigma <= hi, math.sqrt(ss / x.size)


def binomial_ci_contains(k, n, p, conf=CONF):
    lo, hi = stats.binom.interval(conf, n, p)
    return lo <= k <= hi


# ----------------------------------------------------------------------------
# Round robin
# ----------------------------------------------------------------------------

def test_round_robin_order_sequence_and_tx_time():
    core = make(dict(sigma_range=0.0), replicates=(0, 1))
    assert core.outputs["packet_seq"].tolist() == [0, 0]
    assert core.outputs["beacon_id"].tolist() == [0, 0]
    T = 0.25
    for k in range(10):
        t = k * T
        core.step(t, T)
        out = core.outputs
        bid = k % 4 + 1
        assert out["beacon_id"].tolist() == [bid, bid]
        assert out["packet_seq"].tolist() == [k + 1, k + 1]
        np.testing.assert_allclose(out["tx_time"], t + T, rtol=0, atol=1e-12)
        assert out["packet_valid"].all()
        # the packet carries the broadcast position of the transmitting beacon ...
        np.testing.assert_array_equal(np.column_stack([out[f"beacon_{a}"] for a in "xyz"]),
                                      np.tile(SENT_BEACONS[bid - 1], (2, 1)))
        # ... and the range is measured from its true position
        np.testing.assert_allclose(out["range_true"], np.linalg.norm(TARGET - TRUE_BEACONS[bid - 1]), rtol=1e-13)
        np.testing.assert_allclose(out["range"], np.linalg.norm(TARGET - TRUE_BEACONS[bid - 1]), rtol=1e-12)


# ----------------------------------------------------------------------------
# Noise, loss, multipath
# ----------------------------------------------------------------------------

def test_range_noise_std():
    sigma = 0.2
    core = make(dict(sigma_range=sigma, seed=3), replicates=range(4000))
    errors = []
    for k in range(2):
        core.step(k * 1.0, 1.0)
        out = core.outputs
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


def test_packet_loss_rate_and_lost_packet_fields():
    loss = 20.0
    core = make(dict(loss_pct=loss, sigma_range=0.1, outlier_pct=50.0, seed=4), replicates=range(3000))
    valid = []
    for k in range(2):
        core.step(k * 1.0, 1.0)
        out = core.outputs
        v = out["packet_valid"]
        valid.append(v)
        assert np.all(np.isnan(out["range"][~v]))
        for a in "xyz":
            assert np.all(np.isnan(out[f"beacon_{a}"][~v]))
            assert np.all(np.isfinite(out[f"beacon_{a}"][v]))
        assert np.all(np.isfinite(out["range"][v]))
        assert not np.any(out["outlier"][~v])
        # slot bookkeeping continues for lost packets
        assert np.all(out["packet_seq"] == k + 1) and np.all(out["beacon_id"] == k + 1)
        assert np.all(np.isfinite(out["range_true"]))
    v = np.concatenate(valid)
    lost = int(np.sum(~v))
    assert binomial_ci_contains(lost, v.size, loss / 100.0), f"{lost} lost of {v.size}"


def test_loss_extremes():
    core = make(dict(loss_pct=100.0), replicates=range(50))
    core.step(0.0, 1.0)
    assert not core.outputs["packet_valid"].any()
    core = make(dict(loss_pct=0.0), replicates=range(50))
    core.step(0.0, 1.0)
    assert core.outputs["packet_valid"].all()


def test_outliers_only_lengthen_ranges_with_exponential_excess():
    p_out, mean_excess = 30.0, 2.0
    core = make(dict(outlier_pct=p_out, outlier_excess=mean_excess, sigma_range=0.0, clock_drift_ppm=0.0,
                     sound_speed_assumed=1500.0, sound_speed_true=1500.0, seed=8), replicates=range(4000))
    core.step(0.0, 1.0)
    out = core.outputs
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
    core = make(dict(sound_speed_assumed=c_a, sound_speed_true=c_t, sigma_range=0.0), replicates=(0,))
    for k in range(4):
        core.step(k * 0.5, 0.5)
        d = np.linalg.norm(TARGET - TRUE_BEACONS[k])
        assert core.outputs["range"][0] == pytest.approx(d * c_a / c_t, rel=1e-13)
        assert core.outputs["travel_time"][0] == pytest.approx(d / c_t, rel=1e-13)


def test_clock_drift_adds_drift_times_reception_epoch():
    drift_ppm, c = 200.0, 1500.0
    core = make(dict(clock_drift_ppm=drift_ppm, sigma_range=0.0, sound_speed_assumed=c, sound_speed_true=c))
    T = 2.0
    for k in range(3):
        core.step(k * T, T)
        d = np.linalg.norm(TARGET - TRUE_BEACONS[k])
        tau = d / c
        expected = c * (tau + drift_ppm * 1e-6 * ((k + 1) * T + tau))
        assert core.outputs["range"][0] == pytest.approx(expected, rel=1e-13)


def test_channel_replicate_alone_equals_replicate_in_batch():
    params = dict(sigma_range=0.3, loss_pct=10.0, outlier_pct=10.0, seed=17, cell=4)
    batch = make(params, replicates=range(5))
    alone = make(params, replicates=[2])
    for k in range(20):
        batch.step(k * 1.0, 1.0)
        alone.step(k * 1.0, 1.0)
        for name in batch.outputs:
            np.testing.assert_array_equal(alone.outputs[name], batch.outputs[name][2:3], err_msg=name)


# ----------------------------------------------------------------------------
# Sound-speed profile
# ----------------------------------------------------------------------------

CAST = "11E101663_20120821_122817"


def read_cast_raw():
    """Depth and sound-speed columns of the shipped cast, parsed with the csv module."""
    text = (resources.files("models.acoustics") / "data" / f"{CAST}.csv").read_text()
    rows = [r for r in csv.reader(line for line in text.splitlines() if not line.startswith("%"))]
    header, data = rows[0], rows[1:]
    i_depth = header.index("Depth (Meter)")
    i_speed = header.index("Sound velocity (Meters per Second)")
    depth = np.array([float(r[i_depth]) for r in data])
    speed = np.array([float(r[i_speed]) for r in data])
    return depth, speed


def slowness_quad(depth, speed, z1, z2):
    """∫_{z1}^{z2} dz / c(z) with c linearly interpolated (constant beyond the ends), by scipy quad."""
    lo, hi = min(z1, z2), max(z1, z2)
    knots = np.concatenate([[lo], depth[(depth > lo) & (depth < hi)], [hi]])
    total = 0.0
    for a, b in zip(knots[:-1], knots[1:]):
        val, _ = integrate.quad(lambda z: 1.0 / np.interp(z, depth, speed), a, b, epsabs=0, epsrel=1e-12)
        total += val
    return total if z2 >= z1 else -total


def test_cast_speeds_match_data_readme():
    prof = load_profile(f"ctd:{CAST}", 1500.0, 15.0, 35.0)
    # "Sound speed falls from about 1512.6 m/s at the surface to about 1491.5 m/s at 22 m"
    assert prof.speed_at(np.array(0.0)) == pytest.approx(1512.6, abs=0.1)
    assert prof.speed_at(np.array(22.0)) == pytest.approx(1491.5, abs=0.1)
    # the loaded table is the cast's depth and sound-speed columns
    depth, speed = read_cast_raw()
    assert np.all(np.diff(depth) > 0)
    np.testing.assert_allclose(prof.speed_at(depth), speed, rtol=1e-12)


@pytest.mark.parametrize("z1,z2", [(0.0, 22.0), (1.0, 8.0), (15.3, 3.7), (0.5, 0.9), (2.0, 30.0), (-1.0, 5.0)])
def test_harmonic_mean_matches_quadrature(z1, z2):
    prof = load_profile(f"ctd:{CAST}", 1500.0, 15.0, 35.0)
    depth, speed = read_cast_raw()
    ref = (z2 - z1) / slowness_quad(depth, speed, z1, z2)
    forward = float(prof.harmonic_mean(np.array(z1), np.array(z2)))
    assert forward == pytest.approx(ref, rel=1e-6)
    # symmetric in its ends
    assert float(prof.harmonic_mean(np.array(z2), np.array(z1))) == pytest.approx(forward, rel=1e-12)


def test_harmonic_mean_hand_worked_linear_profile():
    # c(z) = 1500 + z on [0, 100]: ∫ dz / c = ln(c2 / c1), harmonic mean (z2 - z1) / ln(c2 / c1)
    prof = SoundSpeedProfile(np.linspace(0.0, 100.0, 2001), 1500.0 + np.linspace(0.0, 100.0, 2001))
    z1, z2 = np.array([10.0, 0.0]), np.array([60.0, 100.0])
    ref = (z2 - z1) / np.log((1500.0 + z2) / (1500.0 + z1))
    np.testing.assert_allclose(prof.harmonic_mean(z1, z2), ref, rtol=1e-9)
    # a level path takes the local speed
    assert float(prof.harmonic_mean(np.array(25.0), np.array(25.0))) == pytest.approx(1525.0)


def test_constant_profile_harmonic_mean():
    prof = load_profile("constant", 1487.0, 15.0, 35.0)
    np.testing.assert_allclose(prof.harmonic_mean(np.array([0.0, 3.0, 7.0]), np.array([10.0, 3.0, -2.0])), 1487.0,
                               rtol=1e-13)


# ----------------------------------------------------------------------------
# Travel time with a moving target
# ----------------------------------------------------------------------------

def _positive_root(d, v, c):
    """Positive root τ of |d + v τ|² = c² τ²: (v·v − c²) τ² + 2 (d·v) τ + d·d = 0 (a < 0 < d·d)."""
    a = np.sum(v * v, axis=-1) - c * c
    b = 2 * np.sum(d * v, axis=-1)
    cc = np.sum(d * d, axis=-1)
    return (-b - np.sqrt(b * b - 4 * a * cc)) / (2 * a)


def test_travel_time_moving_target_solves_quadratic():
    rng = np.random.default_rng(2024)
    c = 1500.0
    core = AcousticsCore(dict(sound_speed_true=c))
    B = 50
    beacon = rng.uniform(-2, 2, (B, 3))
    position = rng.uniform(-40, 40, (B, 3))
    velocity = rng.uniform(-8, 8, (B, 3))
    tau, distance = core.travel_time(beacon, position, velocity)
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
    np.testing.assert_allclose(distance, c * tau, rtol=1e-11)
    # the moving target is not at the transmit-time distance: the test is not trivial
    assert np.min(np.abs(tau - np.linalg.norm(d, axis=1) / c) / bound) > 1e3


def test_travel_time_diver_speed_is_exact():
    """At diver speeds (≤ 2 m/s) the fixed point is converged to rounding."""
    rng = np.random.default_rng(7)
    c = 1490.0
    core = AcousticsCore(dict(sound_speed_true=c))
    beacon = rng.uniform(-2, 2, (30, 3))
    position = rng.uniform(-30, 30, (30, 3))
    velocity = rng.uniform(-1.15, 1.15, (30, 3))
    tau, _ = core.travel_time(beacon, position, velocity)
    np.testing.assert_allclose(tau, _positive_root(position - beacon, velocity, c), rtol=1e-11)


def test_step_with_moving_target_reports_reception_distance():
    c = 1500.0
    v = np.array([1.5, -1.0, 0.3])
    core = make(dict(sound_speed_true=c, sound_speed_assumed=c, sigma_range=0.0), velocity=v)
    core.step(0.0, 1.0)
    out = core.outputs
    d = TARGET - TRUE_BEACONS[0]
    tau = float(_positive_root(d, v, c))
    assert out["travel_time"][0] == pytest.approx(tau, rel=1e-11)
    assert out["range_true"][0] == pytest.approx(np.linalg.norm(d + v * tau), rel=1e-11)
    assert out["range"][0] == pytest.approx(c * tau, rel=1e-11)
    # and differs from the distance at transmit by about the radial motion v·u τ
    u = d / np.linalg.norm(d)
    assert out["range_true"][0] - np.linalg.norm(d) == pytest.approx(v @ u * tau, rel=1e-3)

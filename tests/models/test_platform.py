"""Tests of the platform: rotations, beacon geometry, wave motion, sampled GPS/IMU, reproducibility.

References are independent: scipy's Rotation, hand-worked rotations by 90°,
the WMO Beaufort table and the Pierson-Moskowitz closed form for the waves, a
numpy re-implementation of the sampled sensors fed by the Philox reference
streams of :mod:`sblsim.models.philox` (``uniforms``/``normals``), and chi-square /
Fisher-z confidence intervals for the noise statistics.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from sblsim.models.declarations import ModelError
from sblsim.models.philox import normals, uniforms
from sblsim.models.platform import Platform, beacon_names, beacon_positions, cross_offsets, parse_offsets, rotation_ned
from sblsim.models.platform.waves import WIND_SPEED, wave_motion
from tests.helpers import Core

CONF = 0.999  # confidence level of the statistical checks
G = 9.80665  # standard gravity [m/s^2]
COMPONENT = 0  # the platform's component index in the seed tree
PHASES, GPS, IMU = 0, 1, 2  # stream purposes (sblsim.models.philox docstring, "Randomness")
INSTALLATION, IMU_SCALE, IMU_MISALIGNMENT = 3, 4, 5  # the per-run errors' streams, drawn once at initialization
#: Outputs of a platform run by the code before the per-run errors existed (hexadecimal floats).
PINNED = Path(__file__).resolve().parents[1] / "data" / "platform_pinned.json"

# WMO-No. 558 Beaufort scale: 10 m wind-speed ranges [m/s] and probable wave heights [m], levels 0..8.
WMO_WIND_RANGES = [(0.0, 0.2), (0.3, 1.5), (1.6, 3.3), (3.4, 5.4), (5.5, 7.9), (8.0, 10.7), (10.8, 13.8),
                   (13.9, 17.1), (17.2, 20.7)]
WMO_WAVE_HEIGHT = [0.0, 0.1, 0.2, 0.6, 1.0, 2.0, 3.0, 4.0, 5.5]


# ----------------------------------------------------------------------------
# Helpers and the numpy reference model
# ----------------------------------------------------------------------------

def std_ci_contains(samples: np.ndarray, sigma: float, conf: float = CONF) -> tuple[bool, float]:
    """Whether ``sigma`` lies in the chi-square CI of the std of zero-mean samples."""
    x = np.asarray(samples, float).ravel()
    n = x.size
    ss = float(np.sum(x * x))
    lo = math.sqrt(ss / stats.chi2.ppf(0.5 + conf / 2, n))
    hi = math.sqrt(ss / stats.chi2.ppf(0.5 - conf / 2, n))
    return lo <= sigma <= hi, math.sqrt(ss / n)


def corr_ci_contains(a: np.ndarray, b: np.ndarray, rho: float, conf: float = CONF) -> tuple[bool, float]:
    """Whether ``rho`` lies in the Fisher-z CI of the sample correlation of a and b."""
    a, b = np.ravel(a), np.ravel(b)
    r = float(np.corrcoef(a, b)[0, 1])
    half = stats.norm.ppf(0.5 + conf / 2) / math.sqrt(a.size - 3)
    return abs(math.atanh(r) - math.atanh(rho)) <= half, r


def beacons_of(core: Core, kind: str, n: int = 4) -> np.ndarray:
    """Beacon positions of a core's outputs, shape (B, n, 3)."""
    return np.stack([core.outputs[name] for name in beacon_names(n, kind)], axis=-1).reshape(core.batch, n, 3)


def _rotation_function() -> ca.Function:
    r, p, y = ca.SX.sym("r"), ca.SX.sym("p"), ca.SX.sym("y")
    return ca.Function("R", [r, p, y], [rotation_ned(r, p, y)])


ROTATION = _rotation_function()


def rot(roll: float, pitch: float, yaw: float) -> np.ndarray:
    return np.array(ROTATION(roll, pitch, yaw))


def scipy_rot(roll: float, pitch: float, yaw: float) -> np.ndarray:
    return Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()


def cross_reference(L: float, h: float, n: int = 4) -> np.ndarray:
    th = 2 * np.pi * np.arange(n) / n
    return np.column_stack([L * np.cos(th), L * np.sin(th), np.full(n, h)])


def wave_reference(beaufort: int, hull: float) -> tuple[float, float, float, float]:
    """(tilt, yaw amplitude, heave amplitude, frequency) from the documented closed form.

    Pierson-Moskowitz peak period of the level's wind speed, deep-water
    wavelength, slope π H / λ capped by atan(H / hull).
    """
    H = WMO_WAVE_HEIGHT[beaufort]
    period = 2 * math.pi * WIND_SPEED[beaufort] / (0.877 * G)
    wavelength = G * period**2 / (2 * math.pi)
    tilt = min(math.pi * H / wavelength, math.atan(H / hull))
    return tilt, 0.5 * tilt, 0.5 * H, 1.0 / period


def platform_reference(q: dict, replicate: int, t0: float, times, n: int = 4):
    """Expected outputs at each host time (the first is t0), from the Philox reference streams.

    Yields a dict per time: true (n, 3), broadcast (n, 3), gps (3,), roll, pitch, yaw.
    """
    keys = (q["seed"], q["scenario_key"], q["cell"], replicate)
    offsets = cross_reference(q["baseline"], q["transducer_depth"], n)
    phases = 2 * np.pi * uniforms(*keys, COMPONENT, PHASES, 0, 4)
    tilt, yaw_amp, heave, freq = wave_reference(q["beaufort"], q["hull_length"])
    heading = math.radians(q["heading_deg"])
    Ts, sigma = q["sample_period"], q["gps_sigma"]
    phi = math.exp(-Ts / q["gps_tau"])

    def attitude(t):
        w = 2 * math.pi * freq * t
        return (tilt * math.sin(w + phases[0]), tilt * math.sin(w + phases[1]),
                heading + yaw_amp * math.sin(0.5 * w + phases[2]), -heave * math.sin(w + phases[3]))

    errors = [sigma * normals(*keys, COMPONENT, GPS, 0, 3)]
    for t in times:
        k = math.floor((t - t0) / Ts + 1e-9)
        while len(errors) <= k:
            j = len(errors)
            noise = normals(*keys, COMPONENT, GPS, j, 3)
            errors.append(sigma * noise if q["gps_model"] == "white"
                          else phi * errors[-1] + sigma * math.sqrt(1 - phi * phi) * noise)
        roll, pitch, yaw, depth = attitude(t)
        true = np.array([0.0, 0.0, depth]) + offsets @ scipy_rot(roll, pitch, yaw).T
        t_k = t0 + k * Ts
        r_k, p_k, y_k, d_k = attitude(t_k)
        bias = math.radians(q["imu_bias_deg"]) + q["imu_gyro_bias"] * t_k
        imu = np.array([r_k, p_k, y_k]) + bias + math.radians(q["imu_sigma_deg"]) * normals(*keys, COMPONENT,
                                                                                            IMU, k, 3)
        gps = np.array([0.0, 0.0, d_k]) + errors[k]
        yield dict(true=true, roll=roll, pitch=pitch, yaw=yaw, gps=gps, k=k, phases=phases,
                   broadcast=gps + offsets @ scipy_rot(*imu).T)


# ----------------------------------------------------------------------------
# Geometry
# ----------------------------------------------------------------------------

def test_rotation_ned_matches_scipy_zyx():
    rng = np.random.default_rng(3)
    for roll, pitch, yaw in zip(rng.uniform(-np.pi, np.pi, 20), rng.uniform(-np.pi / 2, np.pi / 2, 20),
                                rng.uniform(-np.pi, np.pi, 20)):
        np.testing.assert_allclose(rot(roll, pitch, yaw), scipy_rot(roll, pitch, yaw), atol=1e-14)


@pytest.mark.parametrize("roll,pitch,yaw,ref", [
    (0.0, 0.0, 0.0, np.eye(3)),
    # yaw 90°: North -> East, East -> South
    (0.0, 0.0, 90.0, np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]])),
    # pitch 90° (nose up in NED): forward -> up (-Down), down -> forward
    (0.0, 90.0, 0.0, np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]])),
    # roll 90° (right wing down): right -> down, down -> left
    (90.0, 0.0, 0.0, np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])),
])
def test_rotation_ned_hand_worked(roll, pitch, yaw, ref):
    R = rot(*np.radians([roll, pitch, yaw]))
    np.testing.assert_allclose(R, ref, atol=1e-15)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_cross_offsets_formula():
    L_, h_ = ca.SX.sym("L"), ca.SX.sym("h")
    L, h = 2.5, 0.8
    for n in (4, 6):
        f = ca.Function("off", [L_, h_], [ca.horzcat(*cross_offsets(L_, h_, n)).T])
        off = np.array(f(L, h))
        # a_i = L (cos θ_i, sin θ_i, 0) + (0, 0, h), θ_i = 2π i / n
        np.testing.assert_allclose(off, cross_reference(L, h, n), atol=1e-14)
    # the paper's four beacons: exact zeros on the axes (no 1e-16 residue of cos 90°)
    off4 = np.array(ca.Function("off", [L_, h_], [ca.horzcat(*cross_offsets(L_, h_, 4)).T])(L, h))
    np.testing.assert_array_equal(off4, [[L, 0, h], [0, L, h], [-L, 0, h], [0, -L, h]])


def test_beacon_positions_hand_worked():
    L, h = 2.0, 1.5
    p_, r_, q_, y_ = ca.SX.sym("p", 3), ca.SX.sym("r"), ca.SX.sym("q"), ca.SX.sym("y")
    f = ca.Function("b", [p_, r_, q_, y_],
                    [ca.horzcat(*beacon_positions(p_, rotation_ned(r_, q_, y_), cross_offsets(L, h, 4))).T])

    def b(p, roll, pitch, yaw):
        return np.array(f(p, *np.radians([roll, pitch, yaw])))

    p = np.array([1.0, 2.0, 0.3])
    # yaw 90° + translation: (L,0,h) -> (0,L,h), (0,L,h) -> (-L,0,h)
    np.testing.assert_allclose(b(p, 0, 0, 90), p + np.array([[0, L, h], [-L, 0, h], [0, -L, h], [L, 0, h]]),
                               atol=1e-14)
    # pitch 90°: (x, y, z) -> (z, y, -x)
    np.testing.assert_allclose(b(np.zeros(3), 0, 90, 0), [[h, 0, -L], [h, L, 0], [h, 0, L], [h, -L, 0]], atol=1e-14)
    # roll 90°: (x, y, z) -> (x, -z, y)
    np.testing.assert_allclose(b(np.zeros(3), 90, 0, 0), [[L, -h, 0], [0, -h, L], [-L, -h, 0], [0, -h, -L]],
                               atol=1e-14)
    # yaw 180° + translation: (x, y, z) -> (-x, -y, z) + p
    p = np.array([-1.0, 0.0, 0.0])
    np.testing.assert_allclose(b(p, 0, 0, 180), p + np.array([[-L, 0, h], [0, -L, h], [L, 0, h], [0, L, h]]),
                               atol=1e-14)


def test_parse_offsets_accepts_blanks_and_commas_and_refuses_malformed_text():
    np.testing.assert_array_equal(parse_offsets("1 2 3; -4,5.5, 6 ;"), [[1, 2, 3], [-4, 5.5, 6]])
    for bad in ("1 2; 3 4 5", "1 2 x", "", "1 2 nan", "1 2 3 4"):
        with pytest.raises(ModelError, match=r"^platform\.beacon_offsets: "):
            parse_offsets(bad)


def test_custom_layout_calm_sea_true_beacons_are_rotated_offsets():
    offsets = np.array([[1.0, 2.0, 0.5], [-3.0, 0.25, 1.0], [0.0, -2.0, 2.0], [4.5, 1.5, 0.0]])
    text = "; ".join(" ".join(str(x) for x in row) for row in offsets)
    heading = -40.0
    core = Core(Platform, dict(layout="custom", beacon_offsets=text, beaufort=0, heading_deg=heading,
                               gps_sigma=0.0, imu_sigma_deg=0.0), replicates=[0, 1]).initialize(0.0)
    ref = offsets @ scipy_rot(0.0, 0.0, math.radians(heading)).T
    for k in range(3):
        np.testing.assert_allclose(beacons_of(core, "true"), np.broadcast_to(ref, (2, 4, 3)), atol=1e-13)
        np.testing.assert_allclose(beacons_of(core, "broadcast"), np.broadcast_to(ref, (2, 4, 3)), atol=1e-13)
        core.step(0.3 * k, 0.3)
    # the FMU parameters turn back into the same configuration text (17 digits)
    config = Platform.config_values(core.values)
    assert config["layout"] == "custom"
    np.testing.assert_array_equal(parse_offsets(config["beacon_offsets"]), offsets)
    # a layout with another number of beacons than the interface is refused
    with pytest.raises(ModelError, match=r"platform\.beacon_offsets: 3 beacons"):
        Core(Platform, dict(layout="custom", beacon_offsets="1 0 0; 0 1 0; 0 0 1"))


# ----------------------------------------------------------------------------
# Wave motion
# ----------------------------------------------------------------------------

def test_wind_speed_table_is_the_wmo_mid_range():
    mids = np.array([0.5 * (lo + hi) for lo, hi in WMO_WIND_RANGES])
    # mid-range to within the 0.1 m/s rounding of the table
    np.testing.assert_allclose(WIND_SPEED, mids, atol=0.05 + 1e-12)
    assert np.all(np.diff(WIND_SPEED) > 0)


@pytest.mark.parametrize("hull", [0.5, 2.0, 50.0])
def test_wave_motion_closed_form(hull):
    b_, l_ = ca.SX.sym("b"), ca.SX.sym("l")
    f = ca.Function("w", [b_, l_], list(wave_motion(b_, l_)))
    for beaufort in range(9):
        got = np.array([float(v) for v in f(beaufort, hull)])
        np.testing.assert_allclose(got, wave_reference(beaufort, hull), rtol=1e-13, atol=0, err_msg=str(beaufort))
    # both branches of the tilt are exercised: a long hull is limited by atan(H / hull), a short one
    # follows the wave slope
    tilt_long = float(f(4, 50.0)[0])
    assert tilt_long == pytest.approx(math.atan(1.0 / 50.0), rel=1e-14)
    tilt_short = float(f(4, 0.5)[0])
    assert tilt_short < math.atan(1.0 / 0.5)


# ----------------------------------------------------------------------------
# The compiled platform against the reference model
# ----------------------------------------------------------------------------

REFERENCE_PARAMS = dict(baseline=1.7, transducer_depth=0.6, heading_deg=25.0, beaufort=5, hull_length=3.0,
                        gps_sigma=0.4, gps_tau=1.3, imu_sigma_deg=2.5, imu_bias_deg=-1.5, imu_gyro_bias=0.02,
                        sample_period=0.1, seed=1234, scenario_key=3, cell=7)


@pytest.mark.parametrize("gps_model", ["white", "gauss-markov"])
def test_platform_matches_reference_model(gps_model):
    """Every output at irregular host steps from t0 = 2.5: true pose at the step end, sensors at the last
    sample t0 + k T_s, noise from the Philox reference streams."""
    q = dict(REFERENCE_PARAMS, gps_model=gps_model)
    replicates = [0, 5, 17]
    t0 = 2.5
    rng = np.random.default_rng(0)
    steps = rng.uniform(0.03, 0.37, 60)
    steps = np.where(np.abs(steps / 0.1 - np.round(steps / 0.1)) < 1e-3, steps + 0.013, steps)
    times = t0 + np.concatenate([[0.0], np.cumsum(steps)])
    # avoid host times within rounding of a sample instant (the reference floors (t - t0) / T_s)
    near = np.abs((times - t0) / 0.1 - np.round((times - t0) / 0.1)) < 1e-6
    near[0] = False
    times = np.where(near, times + 0.004, times)
    core = Core(Platform, q, replicates=replicates).initialize(t0)
    refs = [list(platform_reference(q, r, t0, times)) for r in replicates]
    phases = np.array([ref[0]["phases"] for ref in refs])
    np.testing.assert_allclose(core.state["phase_sin"], np.sin(phases), rtol=1e-15, atol=1e-16)
    np.testing.assert_allclose(core.state["phase_cos"], np.cos(phases), rtol=1e-15, atol=1e-16)
    for i, t in enumerate(times):
        if i > 0:
            core.step(times[i - 1], t - times[i - 1])
        for b, ref in enumerate(r[i] for r in refs):
            assert core.state["k"][b, 0] == ref["k"]
            np.testing.assert_allclose(beacons_of(core, "true")[b], ref["true"], atol=1e-12, err_msg=f"t={t}")
            np.testing.assert_allclose(beacons_of(core, "broadcast")[b], ref["broadcast"], atol=1e-12,
                                       err_msg=f"t={t}")
            np.testing.assert_allclose([core.outputs[f"gps_{a}"][b] for a in "xyz"], ref["gps"], atol=1e-13)
            np.testing.assert_allclose([core.outputs[a][b] for a in ("roll", "pitch", "yaw")],
                                       [ref["roll"], ref["pitch"], ref["yaw"]], atol=1e-13)
    assert refs[0][-1]["k"] > 100  # the run did sample many times


def test_calm_sea_true_beacons_are_the_offsets_rotated_by_heading():
    L, h, heading = 1.7, 0.9, 30.0
    core = Core(Platform, dict(beaufort=0, baseline=L, transducer_depth=h, heading_deg=heading,
                               gps_sigma=0.0, imu_sigma_deg=0.0), replicates=[0, 1]).initialize(0.0)
    c, s = math.cos(math.radians(heading)), math.sin(math.radians(heading))
    ref = np.array([[L * c, L * s, h], [-L * s, L * c, h], [-L * c, -L * s, h], [L * s, -L * c, h]])
    for k in range(3):
        np.testing.assert_allclose(beacons_of(core, "true"), np.broadcast_to(ref, (2, 4, 3)), atol=1e-14)
        np.testing.assert_allclose(core.outputs["yaw"], math.radians(heading), rtol=1e-15)
        np.testing.assert_array_equal(core.outputs["roll"], 0.0)
        core.step(0.5 * k, 0.5)


@pytest.mark.parametrize("beaufort", [0, 4])
def test_zero_sensor_noise_broadcast_equals_true_at_sample_instants(beaufort):
    """Host steps on the sample grid: the held sample is the pose at the step end."""
    core = Core(Platform, dict(beaufort=beaufort, gps_sigma=0.0, imu_sigma_deg=0.0, imu_bias_deg=0.0,
                               imu_gyro_bias=0.0, baseline=2.0, sample_period=0.25),
                replicates=range(3)).initialize(0.0)
    history = []
    for k in range(6):
        true, sent = beacons_of(core, "true"), beacons_of(core, "broadcast")
        np.testing.assert_allclose(sent, true, atol=1e-13)
        # the GPS is the reference point: the centre of the cross minus the rotated transducer depth (h = 1)
        gps = np.column_stack([core.outputs[f"gps_{a}"] for a in "xyz"])
        down = np.array([scipy_rot(*(core.outputs[a][b] for a in ("roll", "pitch", "yaw")))[:, 2]
                         for b in range(3)])
        np.testing.assert_allclose(gps, true.mean(axis=1) - down, atol=1e-13)
        np.testing.assert_array_equal(gps[:, :2], 0.0)  # moored at the NED origin
        history.append(true)
        core.step(0.5 * k, 0.5)
    spread = np.ptp(np.stack(history), axis=0).max()
    if beaufort == 0:
        assert spread == 0.0           # calm: nothing moves
    else:
        assert spread > 1e-2           # the sea moves the beacons: the equality is not trivial


def test_sensors_hold_the_last_sample_between_host_steps():
    """Steps of 0.25 s with T_s = 0.1 s: the broadcast positions are the pose at the last sample
    (0.2 s, 0.5 s, ...), not at the step end, and differ from the true positions there."""
    q = dict(REFERENCE_PARAMS, gps_sigma=0.0, imu_sigma_deg=0.0, imu_bias_deg=0.0, imu_gyro_bias=0.0,
             gps_model="white", beaufort=6)
    core = Core(Platform, q, replicates=[2]).initialize(0.0)
    phases = 2 * np.pi * uniforms(q["seed"], q["scenario_key"], q["cell"], 2, COMPONENT, PHASES, 0, 4)
    tilt, yaw_amp, heave, freq = wave_reference(q["beaufort"], q["hull_length"])
    offsets = cross_reference(q["baseline"], q["transducer_depth"])

    def pose(t):
        w = 2 * math.pi * freq * t
        R = scipy_rot(tilt * math.sin(w + phases[0]), tilt * math.sin(w + phases[1]),
                      math.radians(q["heading_deg"]) + yaw_amp * math.sin(0.5 * w + phases[2]))
        return np.array([0, 0, -heave * math.sin(w + phases[3])]) + offsets @ R.T

    for k in range(1, 9):
        core.step(0.25 * (k - 1), 0.25)
        t = 0.25 * k
        last_sample = 0.1 * math.floor(t / 0.1 + 1e-9)
        np.testing.assert_allclose(beacons_of(core, "broadcast")[0], pose(last_sample), atol=1e-12)
        np.testing.assert_allclose(beacons_of(core, "true")[0], pose(t), atol=1e-12)
        if k % 2:  # 0.25, 0.75, ...: the step end is off the sample grid
            assert np.abs(beacons_of(core, "broadcast")[0] - pose(t)).max() > 1e-3


def test_host_step_does_not_change_the_sampled_outputs():
    q = dict(REFERENCE_PARAMS, gps_model="gauss-markov")
    runs = {}
    for h in (0.05, 0.3, 1.5):
        core = Core(Platform, q, replicates=[0, 1]).initialize(0.0)
        seen, t = {}, 0.0
        for k in range(int(round(3.0 / h))):
            core.step(k * h, h)
            t = (k + 1) * h
            if abs(t / 1.5 - round(t / 1.5)) < 1e-9:
                seen[round(t, 6)] = {n: v.copy() for n, v in core.outputs.items()}
        runs[h] = seen
    for t in (1.5, 3.0):
        for h in (0.05, 0.3):
            for name in beacon_names(4, "broadcast") + ["gps_x", "gps_y", "gps_z"]:
                np.testing.assert_array_equal(runs[h][t][name], runs[1.5][t][name], err_msg=f"{name} h={h}")
            for name in beacon_names(4, "true"):
                np.testing.assert_allclose(runs[h][t][name], runs[1.5][t][name], atol=1e-12)


# ----------------------------------------------------------------------------
# Noise: exact streams and statistics
# ----------------------------------------------------------------------------

def _gps_errors(core: Core) -> np.ndarray:
    """Broadcast minus true, checked to be the same vector for every beacon; shape (B, 3)."""
    diff = beacons_of(core, "broadcast") - beacons_of(core, "true")
    np.testing.assert_allclose(diff, np.broadcast_to(diff[:, :1, :], diff.shape), atol=1e-12)
    gps = np.column_stack([core.outputs[f"gps_{a}"] for a in "xyz"])
    np.testing.assert_allclose(diff[:, 0, :], gps, atol=1e-12)  # the calm platform sits at the origin
    return diff[:, 0, :]


def test_gps_white_noise_is_the_reference_stream_and_has_std_sigma():
    sigma, seed, B = 0.3, 11, 2000
    core = Core(Platform, dict(beaufort=0, gps_sigma=sigma, imu_sigma_deg=0.0, seed=seed, sample_period=1.0),
                replicates=range(B)).initialize(0.0)
    errors = [_gps_errors(core)]
    for k in range(3):
        core.step(float(k), 1.0)
        errors.append(_gps_errors(core))
    # exact: draw k of the GPS stream, for a few replicates
    for k, e in enumerate(errors):
        for r in (0, 1, 999):
            np.testing.assert_allclose(e[r], sigma * normals(seed, 0, 0, r, COMPONENT, GPS, k, 3), atol=1e-15)
    for e in errors:
        ok, est = std_ci_contains(e, sigma)
        assert ok, f"sample std {est} vs {sigma}"
        assert abs(e.mean()) <= stats.norm.ppf(0.5 + CONF / 2) * sigma / math.sqrt(e.size)
    ok, r = corr_ci_contains(errors[1], errors[2], 0.0)  # white: successive samples uncorrelated
    assert ok, f"lag-1 correlation {r} of white GPS noise"


def test_gps_gauss_markov_autocorrelation_and_stationary_std():
    sigma, tau, dt = 0.5, 2.0, 1.0
    core = Core(Platform, dict(beaufort=0, gps_sigma=sigma, gps_model="gauss-markov", gps_tau=tau,
                               imu_sigma_deg=0.0, seed=5, sample_period=dt), replicates=range(2000)).initialize(0.0)
    errors = [_gps_errors(core)]
    for k in range(4):
        core.step(k * dt, dt)
        errors.append(_gps_errors(core))
    phi = math.exp(-dt / tau)
    for a, b in ((0, 1), (3, 4)):
        ok, r = corr_ci_contains(errors[a], errors[b], phi)
        assert ok, f"lag-1 correlation {r} vs exp(-dt/tau) = {phi}"
    ok, r = corr_ci_contains(errors[0], errors[2], phi**2)
    assert ok, f"lag-2 correlation {r} vs {phi ** 2}"
    for e in errors:  # stationary start: the std is sigma at every sample
        ok, est = std_ci_contains(e, sigma)
        assert ok, f"sample std {est} vs {sigma}"
    np.testing.assert_allclose(core.state["gps_error"], errors[-1], atol=1e-12)


def test_imu_noise_rotates_broadcast_beacons():
    """With GPS exact and only IMU noise, |broadcast - gps| = |a_i| and the angle errors have std σ_IMU
    and are the reference IMU stream."""
    sig_deg, L, B = 2.0, 3.0, 2000
    core = Core(Platform, dict(beaufort=0, gps_sigma=0.0, imu_sigma_deg=sig_deg, baseline=L, transducer_depth=0.0,
                               seed=2), replicates=range(B)).initialize(0.0)
    sent = beacons_of(core, "broadcast")
    np.testing.assert_allclose(np.linalg.norm(sent, axis=-1), L, rtol=1e-12)
    # beacon 1 at (L, 0, 0): R e_x = (cos p cos y, cos p sin y, -sin p)
    pitch_err = np.arcsin(-sent[:, 0, 2] / L)
    yaw_err = np.arctan2(sent[:, 0, 1], sent[:, 0, 0])
    for name, err in (("pitch", pitch_err), ("yaw", yaw_err)):
        ok, est = std_ci_contains(err, math.radians(sig_deg))
        assert ok, f"{name} error std {math.degrees(est)} deg vs {sig_deg}"
    ref = np.array([math.radians(sig_deg) * normals(2, 0, 0, r, COMPONENT, IMU, 0, 3) for r in range(B)])
    np.testing.assert_allclose(pitch_err, ref[:, 1], atol=1e-12)
    np.testing.assert_allclose(yaw_err, ref[:, 2], atol=1e-12)


def test_imu_bias_and_gyro_drift_at_the_sample_time():
    """A constant bias b and drift ω t_k rotate the calm-sea broadcast cross by b + ω t_k about every axis,
    t_k the last sample (2.0 s while the host is at 2.3 s)."""
    bias_deg, drift, L, h = 3.0, 0.01, 2.0, 1.0
    core = Core(Platform, dict(beaufort=0, gps_sigma=0.0, imu_sigma_deg=0.0, imu_bias_deg=bias_deg,
                               imu_gyro_bias=drift, baseline=L, transducer_depth=h, sample_period=0.5),
                replicates=[0]).initialize(0.0)
    t = 0.0
    for h_step, t_sample in ((2.0, 2.0), (0.3, 2.0), (2.0, 4.0), (0.6, 4.5)):
        core.step(t, h_step)
        t += h_step
        ang = math.radians(bias_deg) + drift * t_sample
        ref = Rotation.from_euler("ZYX", [ang, ang, ang]).apply(cross_reference(L, h))
        np.testing.assert_allclose(beacons_of(core, "broadcast")[0], ref, atol=1e-12, err_msg=f"t={t}")
        np.testing.assert_allclose(beacons_of(core, "true")[0], cross_reference(L, h), atol=1e-15)


def test_replicate_alone_equals_replicate_in_batch_and_seed_keys_matter():
    params = dict(beaufort=4, gps_sigma=0.2, gps_model="gauss-markov", gps_tau=5.0, imu_sigma_deg=1.5,
                  seed=99, scenario_key=2, cell=3)
    batch = Core(Platform, params, replicates=range(5)).initialize(0.0)
    alone = Core(Platform, params, replicates=[3]).initialize(0.0)
    others = [Core(Platform, dict(params, **change), replicates=[3]).initialize(0.0)
              for change in (dict(seed=100), dict(scenario_key=1), dict(cell=4))]
    for k in range(40):
        for name in batch.outputs:
            np.testing.assert_array_equal(alone.outputs[name], batch.outputs[name][3:4], err_msg=name)
        for core in [batch, alone] + others:
            core.step(0.25 * k, 0.25)
    # replicates of a batch differ from each other; another seed, scenario or cell gives other numbers
    assert np.unique(batch.outputs["gps_x"]).size == 5
    for other in others:
        assert other.outputs["gps_x"][0] != alone.outputs["gps_x"][0]
        assert other.outputs["roll"][0] != alone.outputs["roll"][0]  # other wave phases


def test_many_samples_in_one_step_use_consecutive_draws():
    """One host step of 30 s takes 300 samples; the held GPS error is then draw 300 of the stream."""
    sigma = 0.7
    core = Core(Platform, dict(beaufort=0, gps_sigma=sigma, imu_sigma_deg=0.0, seed=8, scenario_key=1, cell=2),
                replicates=[4, 9]).initialize(0.0)
    core.step(0.0, 30.0)
    np.testing.assert_array_equal(core.state["k"][:, 0], [300, 300])
    for b, r in enumerate((4, 9)):
        np.testing.assert_allclose([core.outputs[f"gps_{a}"][b] for a in "xyz"],
                                   sigma * normals(8, 1, 2, r, COMPONENT, GPS, 300, 3), atol=1e-15)


# ----------------------------------------------------------------------------
# Errors fixed per run: transducer installation, IMU scale factor and misalignment
# ----------------------------------------------------------------------------

FIXED = dict(beaufort=0, gps_sigma=0.0, imu_sigma_deg=0.0, baseline=2.0, transducer_depth=0.0, seed=6,
             scenario_key=2, cell=1)


def test_zero_per_run_errors_give_the_numbers_from_before_them_bit_for_bit():
    """σ = 0 for the three per-run errors (their defaults): every output equals, bit for bit, what the
    platform gave before they existed (every other error on, Gauss-Markov GPS, waves); the outputs the systems
    added since (the USBL array's and the IMU's attitudes) are the only new ones."""
    pinned = json.loads(PINNED.read_text())
    core = Core(Platform, pinned["params"], replicates=pinned["replicates"]).initialize(0.0)
    added = {f"{prefix}_{a}" for prefix in ("array", "imu") for a in ("roll", "pitch", "yaw")}
    for k, want in enumerate(pinned["outputs"]):
        assert sorted(set(core.outputs) - added) == sorted(want)
        for name, values in want.items():
            assert [float(v).hex() for v in core.outputs[name]] == values, (k, name)
        core.step(pinned["step"] * k, pinned["step"])


def test_installation_error_is_fixed_per_run_different_per_replicate_and_the_reference_stream():
    """Calm sea, exact GPS and IMU: the broadcast beacons are the nominal cross, the true ones are the cross
    plus δ_i, constant over the run, other in each replicate, σ times the installation stream."""
    sigma, B = 0.05, 3
    core = Core(Platform, dict(FIXED, installation_sigma=sigma), replicates=range(B)).initialize(0.0)
    nominal = cross_reference(2.0, 0.0)
    ref = np.array([sigma * normals(6, 2, 1, r, COMPONENT, INSTALLATION, 0, 12).reshape(4, 3) for r in range(B)])
    first = beacons_of(core, "true") - beacons_of(core, "broadcast")
    for k in range(12):
        np.testing.assert_allclose(beacons_of(core, "broadcast"), np.broadcast_to(nominal, (B, 4, 3)), atol=1e-15)
        np.testing.assert_array_equal(beacons_of(core, "true") - beacons_of(core, "broadcast"), first)
        core.step(0.25 * k, 0.25)
    np.testing.assert_allclose(first, ref, atol=1e-15)
    assert np.abs(first).min() > 0.0
    assert np.unique(first[:, 0, 0]).size == B  # each replicate installs its own errors


def test_installation_error_rotates_with_the_platform():
    """In a sea, the true beacons are b_i = p + R (a_i + δ_i): the installation error moves with the attitude."""
    sigma = 0.2
    core = Core(Platform, dict(FIXED, beaufort=5, installation_sigma=sigma), replicates=[0, 1]).initialize(0.0)
    delta = np.array([sigma * normals(6, 2, 1, r, COMPONENT, INSTALLATION, 0, 12).reshape(4, 3) for r in (0, 1)])
    nominal = cross_reference(2.0, 0.0)
    for k in range(8):
        core.step(0.3 * k, 0.3)
        for b in range(2):
            R = scipy_rot(*(core.outputs[a][b] for a in ("roll", "pitch", "yaw")))
            heave = np.array([0.0, 0.0, core.outputs["gps_z"][b]])  # exact GPS, on the host step: same instant
            np.testing.assert_allclose(beacons_of(core, "true")[b], heave + (nominal + delta[b]) @ R.T, atol=1e-12)


def test_installation_error_spread_is_sigma():
    sigma, B = 0.3, 200
    core = Core(Platform, dict(FIXED, installation_sigma=sigma), replicates=range(B)).initialize(0.0)
    delta = beacons_of(core, "true") - beacons_of(core, "broadcast")
    ok, est = std_ci_contains(delta, sigma)
    assert ok, f"installation error std {est} m vs {sigma}"
    assert abs(float(delta.mean())) < 4 * sigma / math.sqrt(delta.size)


def _imu_errors(core: Core) -> tuple[np.ndarray, np.ndarray]:
    """Scale-factor errors [-] and misalignments [rad] of each replicate, (B, 3) each."""
    return core.state["imu_scale"], core.state["imu_misalignment"]


def test_imu_scale_factor_and_misalignment_enter_the_broadcast_attitude():
    """In a sea with exact GPS and no IMU noise, on the sample grid: the broadcast cross is
    R((1 + s) θ + m) a_i for each angle θ of the true attitude."""
    ppm, deg = 5000.0, 0.8
    core = Core(Platform, dict(FIXED, beaufort=5, heading_deg=30.0, imu_scale_factor_ppm=ppm,
                               imu_misalignment_deg=deg, sample_period=0.25), replicates=[0, 1]).initialize(0.0)
    scale = np.array([ppm * 1e-6 * normals(6, 2, 1, r, COMPONENT, IMU_SCALE, 0, 3) for r in (0, 1)])
    mis = np.array([math.radians(deg) * normals(6, 2, 1, r, COMPONENT, IMU_MISALIGNMENT, 0, 3) for r in (0, 1)])
    nominal = cross_reference(2.0, 0.0)
    for k in range(8):
        s, m = _imu_errors(core)
        np.testing.assert_allclose(s, scale, rtol=1e-15)
        np.testing.assert_allclose(m, mis, rtol=1e-15)
        for b in range(2):
            true = np.array([core.outputs[a][b] for a in ("roll", "pitch", "yaw")])
            gps = np.array([core.outputs[f"gps_{a}"][b] for a in "xyz"])
            want = gps + nominal @ scipy_rot(*((1.0 + scale[b]) * true + mis[b])).T
            np.testing.assert_allclose(beacons_of(core, "broadcast")[b], want, atol=1e-12, err_msg=f"k={k}")
            np.testing.assert_allclose(beacons_of(core, "true")[b], gps + nominal @ scipy_rot(*true).T, atol=1e-12)
        core.step(0.25 * k, 0.25)


def test_imu_scale_factor_is_fixed_per_run_and_scales_the_heading():
    """Calm sea at heading 40°: the broadcast heading is (1 + s_yaw) 40° at every sample, s_yaw its own per
    replicate."""
    ppm, heading = 20000.0, 40.0
    core = Core(Platform, dict(FIXED, heading_deg=heading, imu_scale_factor_ppm=ppm),
                replicates=range(3)).initialize(0.0)
    ref = np.array([ppm * 1e-6 * normals(6, 2, 1, r, COMPONENT, IMU_SCALE, 0, 3)[2] for r in range(3)])
    for k in range(10):
        sent = beacons_of(core, "broadcast")
        yaw = np.arctan2(sent[:, 0, 1], sent[:, 0, 0])  # beacon 1 at (L, 0, 0)
        np.testing.assert_allclose(yaw, (1.0 + ref) * math.radians(heading), rtol=1e-13)
        core.step(0.5 * k, 0.5)
    assert np.unique(ref).size == 3 and np.abs(ref).min() > 0.0


def test_imu_misalignment_is_fixed_per_run_and_rotates_the_broadcast_cross():
    """Calm sea at heading 0: the broadcast cross is the cross rotated by the misalignment angles, the same at
    every sample and other in each replicate."""
    deg = 1.5
    core = Core(Platform, dict(FIXED, imu_misalignment_deg=deg), replicates=range(3)).initialize(0.0)
    ref = np.array([math.radians(deg) * normals(6, 2, 1, r, COMPONENT, IMU_MISALIGNMENT, 0, 3) for r in range(3)])
    want = np.array([cross_reference(2.0, 0.0) @ scipy_rot(*ref[b]).T for b in range(3)])
    for k in range(10):
        np.testing.assert_allclose(beacons_of(core, "broadcast"), want, atol=1e-13)
        np.testing.assert_allclose(beacons_of(core, "true"), np.broadcast_to(cross_reference(2.0, 0.0), (3, 4, 3)),
                                   atol=1e-15)
        core.step(0.5 * k, 0.5)
    assert np.unique(ref[:, 2]).size == 3


@pytest.mark.parametrize("key,block,factor,sigma", [
    ("imu_scale_factor_ppm", "imu_scale", 1e-6, 3000.0),
    ("imu_misalignment_deg", "imu_misalignment", math.pi / 180.0, 0.5),
])
def test_imu_per_run_error_spread_is_sigma(key, block, factor, sigma):
    """200 replicates × 3 axes: the sample std of the per-run errors lies in the chi-square CI of σ."""
    core = Core(Platform, dict(FIXED, **{key: sigma}), replicates=range(200)).initialize(0.0)
    values = core.state[block]
    ok, est = std_ci_contains(values, sigma * factor)
    assert ok, f"{key}: std {est / factor} vs {sigma}"
    assert abs(float(values.mean())) < 4 * sigma * factor / math.sqrt(values.size)


def test_per_run_errors_do_not_shift_the_other_streams():
    """The per-run errors on: GPS, IMU noise and wave phases keep their numbers (their own streams)."""
    base = dict(REFERENCE_PARAMS, gps_model="white")
    off = Core(Platform, base, replicates=[0, 1]).initialize(0.0)
    on = Core(Platform, dict(base, installation_sigma=0.5, imu_scale_factor_ppm=1e4, imu_misalignment_deg=2.0),
              replicates=[0, 1]).initialize(0.0)
    for k in range(10):
        for name in ("gps_x", "gps_y", "gps_z", "roll", "pitch", "yaw"):
            np.testing.assert_array_equal(on.outputs[name], off.outputs[name], err_msg=name)
        assert not np.array_equal(on.outputs["beacon1_x"], off.outputs["beacon1_x"])
        assert not np.array_equal(on.outputs["beacon1_true_x"], off.outputs["beacon1_true_x"])
        for core in (on, off):
            core.step(0.25 * k, 0.25)


# ----------------------------------------------------------------------------
# Parameters
# ----------------------------------------------------------------------------

def test_per_replicate_parameters():
    """Per-replicate arrays of a batch: each row behaves as a batch of that value alone."""
    baselines = np.array([0.5, 1.25, 3.0])
    periods = np.array([0.1, 0.25, 0.5])
    core = Core(Platform, dict(beaufort=0, gps_sigma=0.2, imu_sigma_deg=0.0, transducer_depth=0.0, seed=4),
                replicates=[0, 1, 2])
    core.values.update(baseline=baselines, sample_period=periods)
    core.initialize(0.0)
    np.testing.assert_allclose(core.outputs["beacon1_true_x"], baselines, rtol=1e-15)
    np.testing.assert_allclose(core.outputs["beacon2_true_y"], baselines, rtol=1e-15)
    core.step(0.0, 1.0)
    np.testing.assert_array_equal(core.state["k"][:, 0], np.round(1.0 / periods))
    for b in range(3):
        k = int(round(1.0 / periods[b]))
        np.testing.assert_allclose(core.outputs["gps_x"][b], 0.2 * normals(4, 0, 0, b, COMPONENT, GPS, k, 3)[0],
                                   atol=1e-15)
    with pytest.raises(ModelError, match=r"platform\.sample_period: 2 per-replicate values for a batch of 3"):
        core.values.update(sample_period=np.array([0.1, 0.2]))
        core.initialize(0.0)


@pytest.mark.parametrize("params,field", [
    (dict(baseline=0.0), "platform.baseline"),
    (dict(beaufort=9), "platform.beaufort"),
    (dict(gps_model="pink"), "platform.gps_model"),
    (dict(sample_period=0.0), "platform.sample_period"),
    (dict(gps_tau=0.0), "platform.gps_tau"),
    (dict(installation_sigma=-0.1), "platform.installation_sigma"),
    (dict(installation_sigma=10.5), "platform.installation_sigma"),
    (dict(imu_scale_factor_ppm=-1.0), "platform.imu_scale_factor_ppm"),
    (dict(imu_misalignment_deg=-1.0), "platform.imu_misalignment_deg"),
])
def test_out_of_range_parameters_are_refused(params, field):
    with pytest.raises(ModelError, match=f"^{field}: "):
        Core(Platform, params).initialize(0.0)


@pytest.mark.parametrize("n", [3, 4, 6])
def test_layout_offsets_of_a_cross_are_the_casadi_offsets(n):
    from sblsim.models.platform.geometry import cross_offsets, layout_offsets

    expected = np.array([np.array(ca.DM(a)).ravel() for a in cross_offsets(2.5, 0.7, n)])
    np.testing.assert_array_equal(layout_offsets("cross", 2.5, 0.7, "", n), expected)
    np.testing.assert_array_equal(layout_offsets("custom", 0, 0, "1 2 3; 4 5 6"), [[1, 2, 3], [4, 5, 6]])

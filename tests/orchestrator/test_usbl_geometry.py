"""The USBL transceiver sits where the docs say, ``(0, 0, platform.transducer_depth)`` below the GPS antenna (plus
its installation error), whatever ``platform.baseline``; the simulation, the receivers' lever arm, the bound and the
map use that one geometry.

* The platform of a USBL configuration broadcasts ``(0, 0, h)`` (calm sea, no GPS or IMU error) and its true
  transceiver is there plus the installation error drawn for the run, for a baseline of 0.5, 3 and 200 m.
* A static diver's horizontal fix error over 200 replicates (the ``lsq`` receiver's fix of each packet and the
  depth) is within 10 % of the accuracy map's DRMS at the diver's point, with the default GPS error (0.1 m) and with
  1 m; and within 15 % 200 m off it at 1,000 m depth, 200 m and 1 km off at ``usbl-deep``, 1 km and 2 km off at
  the ``lbl-field`` site, and 3 km off there, where only bottom reflections are heard (the map holds the fix the
  reflection gives, and ``map.csv`` marks the point echo-only); straight
  below the transceiver and near the vertical at 1,000 m (where the range's second order constrains the fix and the
  Fisher information at the point does not see it), and below the transceiver at ``usbl-deep``, within 10 %.
* The consistency of ``ekf-seq`` (mean NEES) lies in [1.5, 4.5], and the numbers do not depend on the baseline; with
  a 1 m GPS error too (the transceiver's error shifts the angles, and R holds it), its 95 % coverage near 0.95.
* The map is finite everywhere, straight below the transceiver too, and never beats the GPS error (√2 σ_GPS
  horizontally, reached below the transceiver with a perfect array).
* A diver 4 m straight below the transceiver is seen at 90° elevation (within the angle noise), and every receiver's
  estimate and the bound stay finite there (the direction cosines are defined everywhere).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.models.platform.core import Platform, beacon_names
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import run, run_batch, with_replicates
from sblsim.orchestrator.maps import accuracy_map, echo_spread, grid, point_accuracy
from tests.helpers import Core

BASELINES = (0.5, 3.0, 200.0)
#: A static diver 15 m North of the platform, 5 s, calm sea.
STATIC = ("platform.beaufort=0", "target.speed=1e-9", "simulation.duration=5")
#: A diver held 4 m straight below the transceiver (1 m deep), 20 s.
BELOW = ("target.trajectory=file", "target.waypoints=0 0 0 5; 100 0 0 5", "simulation.duration=20")


def usbl(baseline: float, *more: str) -> list[str]:
    return ["platform.system=usbl", f"platform.baseline={baseline}", *more]


def transceiver(cfg: dict, kind: str) -> np.ndarray:
    """The platform's true or broadcast transceiver position at t = 0 for a configuration, (3,) [m]."""
    n = SYSTEMS["usbl"].interface_beacons
    core = Core(Platform, make_plan(cfg).component_parameters("platform"), n_beacons=n).initialize(0.0)
    return np.array([core.outputs[name][0] for name in beacon_names(n, kind)])


@pytest.mark.parametrize("baseline", BASELINES)
def test_the_broadcast_transceiver_is_below_the_antenna_whatever_the_baseline(baseline):
    calm = ("platform.beaufort=0", "platform.gps_sigma=0", "platform.imu_sigma_deg=0", "platform.transducer_depth=2.5")
    cfg = load_config("semicircle", usbl(baseline, *calm), seed=1)
    np.testing.assert_array_equal(transceiver(cfg, "broadcast"), [0.0, 0.0, 2.5])
    np.testing.assert_array_equal(transceiver(cfg, "true"), [0.0, 0.0, 2.5])
    # an installation error moves the true transceiver, not the broadcast one: by the run's draw, not the baseline
    installed = load_config("semicircle", usbl(baseline, *calm, "platform.installation_sigma=0.05"), seed=1)
    error = transceiver(installed, "true") - np.array([0.0, 0.0, 2.5])
    np.testing.assert_array_equal(transceiver(installed, "broadcast"), [0.0, 0.0, 2.5])
    assert 1e-4 < np.linalg.norm(error) < 0.5
    reference = load_config("semicircle", usbl(BASELINES[0], *calm, "platform.installation_sigma=0.05"), seed=1)
    np.testing.assert_array_equal(error, transceiver(reference, "true") - np.array([0.0, 0.0, 2.5]))
    # the receivers' lever arm and the map's are the same point
    np.testing.assert_array_equal(SYSTEMS["usbl"].lever_arms(cfg["platform"]), [[0.0, 0.0, 2.5]])
    seq = load_config("semicircle", usbl(baseline, *calm, "simulation.receiver=ekf-seq"), seed=1)
    assert seq["receiver"]["beacon_arm"] == 2.5  # the receivers' lever arm (ekf-seq declares it)


def static_fix_error(cfg: dict, ts) -> tuple[float, float, int]:
    """The horizontal RMS error of the ``lsq`` receiver's fix at every new received packet of a static vehicle's runs
    (the least-squares fix of the packet and the depth), the map's DRMS at the vehicle's point, and the fixes'
    count."""
    seq = ts["packet_seq"].to_numpy()
    new = (seq != np.r_[0, seq[:-1]]) & (seq > 0) & ts["packet_valid"].to_numpy(bool)
    rows = ts[new]
    fix = rows[["est_x", "est_y", "est_z"]].to_numpy()
    truth = rows[["true_x", "true_y", "true_z"]].to_numpy()
    assert np.ptp(truth, axis=0).max() < 1e-6  # static
    rms = float(np.sqrt(np.mean(np.sum((fix[:, :2] - truth[:, :2]) ** 2, axis=1))))
    point = truth[0]
    drms = float(accuracy_map(cfg, np.array([point[1]]), np.array([point[0]]), depth=float(point[2]))[0, 0])
    return rms, drms, len(rows)


def test_a_static_divers_fix_error_is_the_maps_value_whatever_the_baseline():
    """200 replicates of a diver held 15 m from the platform, 4 m below the transceiver (calm sea: the platform's
    motion is not in the map); the horizontal RMS of the fix of every received packet against the map's DRMS at that
    point, and the same packets whatever the baseline."""
    series = {}
    for baseline in BASELINES:
        cfg = load_config("semicircle", usbl(baseline, *STATIC, "simulation.receiver=lsq"), seed=3)
        series[baseline] = (cfg, run_batch(with_replicates(cfg, range(200)), "local", timeseries=True).timeseries)
    cfg, ts = series[3.0]
    for baseline in BASELINES:
        np.testing.assert_array_equal(series[baseline][1]["range"], ts["range"])
        np.testing.assert_array_equal(series[baseline][1]["beacon_x"], ts["beacon_x"])
    rms, drms, count = static_fix_error(cfg, ts)
    assert count > 2000
    assert rms == pytest.approx(drms, rel=0.10), (rms, drms)
    point = ts[["true_x", "true_y", "true_z"]].to_numpy()[0]
    # a transceiver at the 200 m baseline's arm (where the platform model put it before) maps far from the run
    far = load_config("semicircle", ["platform.system=usbl", "platform.layout=custom",
                                     "platform.beacon_offsets=200 0 1"], seed=3)
    moved = float(accuracy_map(far, np.array([point[1]]), np.array([point[0]]), depth=float(point[2]))[0, 0])
    assert moved > 2.0 * rms


@pytest.mark.parametrize("baseline", BASELINES)
def test_the_usbl_filter_is_consistent_whatever_the_baseline(baseline):
    cfg = load_config("semicircle", usbl(baseline, "simulation.receiver=ekf-seq"), seed=1)
    metrics = run_batch(with_replicates(cfg, range(20)), "local", timeseries=False).metrics
    nees = float(metrics["nees_mean"].mean())
    assert 1.5 <= nees <= 4.5, nees
    default = load_config("semicircle", usbl(3.0, "simulation.receiver=ekf-seq"), seed=1)
    reference = run_batch(with_replicates(default, range(20)), "local", timeseries=False).metrics
    np.testing.assert_array_equal(metrics["e_tot_rms"], reference["e_tot_rms"])
    np.testing.assert_array_equal(metrics["pcrb_rms"], reference["pcrb_rms"])


def test_with_a_1_m_gps_error_the_static_fix_error_is_the_maps_value_and_above_the_gps_floor():
    """The same static diver with a 1 m GPS error per axis: the transceiver's error dominates and moves the angles;
    the packets' fix error over 200 replicates is the map's value (which holds it across the angles, not only along
    the range: the map without it said 0.086 m where the GPS alone gives √2 m)."""
    cfg = load_config("semicircle", usbl(3.0, *STATIC, "platform.gps_sigma=1", "simulation.receiver=lsq"), seed=3)
    ts = run_batch(with_replicates(cfg, range(200)), "local", timeseries=True).timeseries
    rms, drms, count = static_fix_error(cfg, ts)
    assert count > 2000
    assert rms == pytest.approx(drms, rel=0.10), (rms, drms)
    assert drms >= np.sqrt(2.0)


#: Static vehicles far from the 15 m of the paper's scenarios: 200 m off the transceiver at 1,000 m (isovelocity,
#: 0.5 s cycle), 200 m and 1 km off at the ``usbl-deep`` site (800 m deep, 8 s cycle) and 1 km and 2 km off at the
#: ``lbl-field`` site (rays through its profile, detection by signal-to-noise, its 3 s cycle; the receiver turns
#: each direction by the eigenray's bending). At 3 km there the direct ray is shadowed and every packet is a bottom
#: reflection (:data:`ECHO_ONLY_POINT`).
FAR = {
    "200m-off-1000m": ("semicircle", ("simulation.sampling_time=0.5", "simulation.duration=10",
                                      "target.waypoints=0 200 0 1000; 100 200 0 1000")),
    "usbl-deep-200m": ("usbl-deep", ("simulation.duration=400", "target.waypoints=0 200 0 800; 100 200 0 800")),
    "usbl-deep-1km": ("usbl-deep", ("simulation.duration=400", "target.waypoints=0 1000 0 800; 100 1000 0 800")),
    "lbl-field-1km": ("lbl-field", ("simulation.duration=45", "target.waypoints=0 1000 0 150; 100 1000 0 150")),
    "lbl-field-2km": ("lbl-field", ("simulation.duration=45", "target.waypoints=0 2000 0 150; 100 2000 0 150")),
}
#: 3 km North of the transceiver at ``lbl-field``, 150 m deep: the thermocline shadows the direct ray and every
#: packet is a bottom reflection, its range about 47 m long and its elevation steeper.
ECHO_ONLY_POINT = ("lbl-field", ("simulation.duration=45", "target.waypoints=0 3000 0 150; 100 3000 0 150"))
#: Straight below the transceiver at 1,000 m.
NADIR = ("semicircle", ("simulation.sampling_time=0.5", "simulation.duration=10",
                        "target.waypoints=0 0.5 0 1000; 100 0.5 0 1000"))


def far_fix_error(scenario: str, sets, *more: str, replicates: int = 200) -> tuple[float, float, int]:
    cfg = load_config(scenario, ["platform.system=usbl", "simulation.receiver=lsq", "target.trajectory=file",
                                 *sets, *more], seed=5)
    ts = run_batch(with_replicates(cfg, range(replicates)), "local", timeseries=True).timeseries
    return static_fix_error(cfg, ts)


@pytest.mark.slow
@pytest.mark.parametrize("where", FAR)
def test_the_map_is_what_a_static_vehicle_gets_off_the_vertical_to_kilometres(where):
    """The USBL map at a point against a static-vehicle Monte Carlo there: the ``lsq`` receiver's fix of each
    received packet (its horizontal RMS error) within 15 % of the map's DRMS, from 200 m to 2 km off: 200
    replicates at 1,000 m, 40 at the site (its eigenrays cost; over 500 packets, the RMS's sampling std about 3 %)."""
    site = FAR[where][0] != "semicircle"
    rms, drms, count = far_fix_error(*FAR[where], replicates={"lbl-field": 40, "usbl-deep": 20}.get(FAR[where][0], 200))
    assert count > (500 if site else 1500), count
    assert rms == pytest.approx(drms, rel=0.15), (where, rms, drms)


@pytest.mark.slow
def test_where_only_echoes_are_heard_the_map_is_the_reflected_fix_and_says_so(tmp_path, capsys):
    """3 km off at ``lbl-field`` every packet is a bottom reflection. The map holds the fix that reflection gives:
    the static vehicle's fixes (40 replicates) scatter about a point off the diver along its azimuth, by the offset
    the map computes from the reflection's path (within 15 %), and their RMS error is the map's value (within 15 %:
    the direct ray's geometry alone, the map before, is 23 % low); ``map.csv`` marks the point echo-only, and the
    points 1 km off (the direct ray heard) not."""
    cfg = load_config(ECHO_ONLY_POINT[0], ["platform.system=usbl", "simulation.receiver=lsq",
                                           "target.trajectory=file", *ECHO_ONLY_POINT[1]], seed=5)
    ts = run_batch(with_replicates(cfg, range(40)), "local", timeseries=True).timeseries
    assert (ts["arrival"][ts["packet_valid"].to_numpy(bool)] == 3).all()  # bottom reflections only
    rms, drms, count = static_fix_error(cfg, ts)
    assert count > 400, count
    assert rms == pytest.approx(drms, rel=0.15), (rms, drms)
    seq = ts["packet_seq"].to_numpy()
    new = (seq != np.r_[0, seq[:-1]]) & (seq > 0) & ts["packet_valid"].to_numpy(bool)
    radial = float(np.mean(ts["est_x"][new] - ts["true_x"][new]))  # the diver is due North of the transceiver
    plan = make_plan(cfg)
    point = np.array([[3000.0, 0.0, 150.0]])
    values = point_accuracy(plan, point)
    assert values["echo"][0] > 0.99
    offset = np.sqrt(echo_spread(plan, point, dict(plan.bound), plan["acoustics"]["sigma_range"], values["echo"])[0][0])
    assert radial == pytest.approx(offset, rel=0.15), (radial, offset)
    assert 30.0 < offset < 60.0
    direct = float(np.sqrt(drms ** 2 - offset ** 2))  # what the map held before: the direct ray's geometry alone
    assert direct < 0.85 * rms
    out = tmp_path / "m"
    code = main(["map", "lbl-field", "--set", "platform.system=usbl", "--extent", "3000", "--step", "1000",
                 "--out", str(out)])
    assert code == 0
    frame = pd.read_csv(out / "map.csv")
    share = 100 * frame["echo_only"].mean()
    assert f"; {share:.0f} % echo-only (hatched)" in capsys.readouterr().out
    north = frame[frame["east"] == 0].set_index("north")
    assert bool(north.loc[3000.0, "echo_only"]) and not bool(north.loc[1000.0, "echo_only"])
    assert north.loc[3000.0, "drms"] == pytest.approx(drms, rel=1e-9)


#: Offsets [m] from the vertical below the transceiver at 1,000 m (the IMU's 1° and the array's 0.5°): below it, in
#: the rise, where the fix's error exceeds the Fisher information's, and where the two meet again.
NEAR_VERTICAL = (0.5, 10.0, 28.0, 60.0)


def near_vertical(offset: float) -> tuple[str, tuple[str, ...]]:
    return NADIR[0], (*NADIR[1][:2], f"target.waypoints=0 {offset!r} 0 1000; 100 {offset!r} 0 1000")


@pytest.mark.parametrize("offset", NEAR_VERTICAL)
def test_straight_below_and_near_the_vertical_the_map_is_what_a_static_vehicle_gets(offset):
    """At 1,000 m the range carries no horizontal information to first order straight below the transceiver, so
    the Fisher information at the point holds the direction noise alone (1000 m × √(σ_u² + σ_θ²) per axis); the fix
    of range, direction and depth uses the second order too (the slant range minus the depth is ρ² / 2z). Near the
    vertical the map is the fix's own RMS error (by quasi-Monte Carlo over the packet's noise): within 10 % of a
    static vehicle's fixes, below the first-order value straight below, above it in the rise (28 m off), and the
    first-order value again beyond."""
    rms, drms, count = far_fix_error(*near_vertical(offset))
    assert count > 1500, count
    assert rms == pytest.approx(drms, rel=0.10), (offset, rms, drms)
    cfg = load_config("semicircle", ["platform.system=usbl", "simulation.sampling_time=0.5"], seed=5)
    fisher = 1000.0 * np.sqrt(2.0) * np.hypot(np.radians(0.5), np.radians(cfg["platform"]["imu_sigma_deg"]))
    if offset < 1.0:
        assert drms < 0.6 * fisher, (drms, fisher)
    if offset == 28.0:  # the fix's error rises above the first-order value 150 m off before it meets it
        far = float(accuracy_map(cfg, np.array([150.0]), np.array([0.0]), depth=1000.0)[0, 0])
        assert drms > 1.05 * far, (drms, far)


@pytest.mark.slow
def test_straight_below_with_the_array_s_noise_alone_and_at_a_deep_site():
    """With the IMU's error removed (the direction noise alone, 0.5°), and straight below the transceiver at the
    ``usbl-deep`` site (800 m, its eigenrays and detection, 0.14° array), the map is the fix's error within 10 %."""
    quiet_rms, quiet_drms, _ = far_fix_error(*near_vertical(0.5), "platform.imu_sigma_deg=0")
    assert quiet_rms == pytest.approx(quiet_drms, rel=0.10), (quiet_rms, quiet_drms)
    assert quiet_drms < 0.9 * 1000.0 * np.sqrt(2.0) * np.radians(0.5)
    rms, drms, count = far_fix_error("usbl-deep", ("simulation.duration=400",
                                                   "target.waypoints=0 0.5 0 800; 100 0.5 0 800"), replicates=40)
    assert count > 1500, count
    assert rms == pytest.approx(drms, rel=0.10), (rms, drms)


@pytest.mark.parametrize("gps", [pytest.param(1.0, marks=pytest.mark.slow), 0.1])
def test_the_usbl_map_is_finite_everywhere_and_never_beats_the_gps_error(gps, tmp_path, capsys):
    """``sblsim map`` of a USBL configuration over a grid through the point straight below the transceiver: every
    value finite (``map.csv`` has no ``inf``), at least √2 σ_GPS (the GPS error alone, per axis, gives that
    horizontally), and with a perfect array (range noise, angle noise at their minimums, no attitude error) the
    floor itself below the transceiver (to 1e-4: there the map is the fix's RMS error over its errors' draws)."""
    sets = ["platform.system=usbl", f"platform.gps_sigma={gps}"]
    out = tmp_path / "m"
    code = main(["map", "semicircle", *(a for o in sets for a in ("--set", o)), "--extent", "4", "--step", "0.5",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    frame = pd.read_csv(out / "map.csv")
    assert len(frame) == 17 * 17 and np.isfinite(frame["drms"]).all()
    assert "inf" not in (out / "map.csv").read_text()
    assert (frame["drms"] >= np.sqrt(2.0) * gps).all()
    below = frame[(frame["east"] == 0) & (frame["north"] == 0)]["drms"].item()
    assert below <= (1 + 1e-4) * frame["drms"].min()  # the best point is straight below, not a hole
    perfect = load_config("semicircle", [*sets, "acoustics.sigma_range=1e-6", "platform.usbl_angle_sigma_deg=0",
                                         "platform.imu_sigma_deg=0", "target.depth_sigma=1e-3"])
    east, north = grid(30.0, 0.5)
    m = accuracy_map(perfect, east, north)
    # near the vertical the map is the fix's own error over the errors' draws (to 1e-4 of the floor there)
    assert np.isfinite(m).all() and m.min() >= np.sqrt(2.0) * gps * (1 - 1e-4)
    assert m[len(north) // 2, len(east) // 2] == pytest.approx(np.sqrt(2.0) * gps, rel=1e-3)


def test_with_a_1_m_gps_error_the_usbl_filter_is_consistent():
    """ekf-seq with a 1 m GPS error per axis: mean NEES in [1.5, 4.5] (3 if consistent; 9.6 and a coverage of 0.51
    when R held the GPS error along the range only) and the share of steps inside the 95 % ellipsoid near 0.95."""
    cfg = load_config("semicircle", usbl(3.0, "simulation.receiver=ekf-seq", "platform.gps_sigma=1"), seed=1)
    metrics = run_batch(with_replicates(cfg, range(20)), "local", timeseries=False).metrics
    nees, coverage = float(metrics["nees_mean"].mean()), float(metrics["coverage_95"].mean())
    assert 1.5 <= nees <= 4.5, nees
    assert 0.85 <= coverage <= 0.99, coverage


@pytest.mark.parametrize("calm", [True, False], ids=["no-gps-no-imu", "default"])
def test_a_diver_straight_below_the_transceiver_is_seen_at_90_degrees(calm):
    """A diver held at (0, 0, 5) under a transceiver 1 m deep: every received packet's elevation is within the angle
    noise of 90° (calm, no GPS or IMU error: the array's 0.5° only, folded at 90°: within 5σ, mean within 1°; with
    the default sea, GPS and IMU errors, within 5°), its range about 4 m; the receivers' estimates are finite from
    their first fix on (before it they have none, NaN), which is the step of the first received packet, and the bound
    and the reported spread are finite at every step (the direction cosines are defined straight below, where an
    azimuth is not)."""
    errors = ("platform.gps_sigma=0", "platform.imu_sigma_deg=0", "platform.beaufort=0") if calm else ()
    for receiver in ("ekf-seq", "ukf", "lsq"):
        cfg = load_config("semicircle", usbl(3.0, *BELOW, *errors, f"simulation.receiver={receiver}"), seed=2)
        result = run(cfg, replicates=[0, 1])
        ts = result.timeseries
        valid = ts["packet_valid"].to_numpy(bool)
        assert valid.sum() > 300
        elevation = np.degrees(ts["elevation"].to_numpy()[valid])
        assert np.all(elevation <= 90.0)
        if calm:
            assert np.all(elevation >= 90.0 - 5 * 0.5) and elevation.mean() >= 89.0
            np.testing.assert_allclose(ts["range"].to_numpy()[valid], 4.0, atol=5 * 0.1)
        else:
            assert np.all(elevation >= 85.0)
        assert np.isfinite(ts[["pcrb", "pos_std"]].to_numpy()).all(), receiver
        for _, one in ts.groupby("replicate"):
            estimates = one[["est_x", "est_y", "est_z"]].to_numpy()
            first = int(np.argmax(one["packet_valid"].to_numpy(bool)))  # the first received packet: the first fix
            assert np.isnan(estimates[:first]).all() and np.isfinite(estimates[first:]).all(), receiver
        assert np.isfinite(result.metrics[["nees_mean", "e_tot_rms", "pcrb_rms"]].to_numpy()).all(), receiver

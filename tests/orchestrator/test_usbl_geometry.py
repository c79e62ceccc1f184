"""The USBL transceiver sits where the docs say, ``(0, 0, platform.transducer_depth)`` below the GPS antenna (plus
its installation error), whatever ``platform.baseline``; the simulation, the receivers' lever arm, the bound and the
map use that one geometry.

* The platform of a USBL configuration broadcasts ``(0, 0, h)`` (calm sea, no GPS or IMU error) and its true
  transceiver is there plus the installation error drawn for the run, for a baseline of 0.5, 3 and 200 m.
* A static diver's horizontal fix error over 200 replicates (the efficient fix from each packet and the depth,
  computed here from the recorded packets) is within 10 % of the accuracy map's DRMS at the diver's point.
* The consistency of ``ekf-seq`` (mean NEES) lies in [1.5, 4.5], and the numbers do not depend on the baseline.
"""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.platform.core import Platform, beacon_names
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.config import component_params, load_config
from sblsim.orchestrator.maps import accuracy_map
from sblsim.orchestrator.run import run_batch, with_replicates
from tests.helpers import Core

BASELINES = (0.5, 3.0, 200.0)


def usbl(baseline: float, *more: str) -> list[str]:
    return ["platform.system=usbl", f"platform.baseline={baseline}", *more]


def transceiver(cfg: dict, kind: str) -> np.ndarray:
    """The platform's true or broadcast transceiver position at t = 0 for a configuration, (3,) [m]."""
    n = SYSTEMS["usbl"].interface_beacons
    core = Core(Platform, component_params(cfg, "platform"), n_beacons=n).initialize(0.0)
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


def packet_fix(z: np.ndarray, b: np.ndarray, depth: np.ndarray, cfg: dict, iterations: int = 8) -> np.ndarray:
    """The weighted least-squares fix (M, 3) of each packet ``z = [r, α, ε]`` (M, 3) from the transceiver ``b`` (M, 3)
    with the depth reading (M,): Gauss-Newton on ``Σ y_k² / R_k + (d − p_z)² / σ_d²`` with the receivers' R of a
    USBL packet (range ``σ_r² + σ_GPS²``, each angle ``(σ_θ / max(cos φ, 0.1))² + σ_att²``; the platform's GPS and
    IMU errors), written here in numpy,
    from the polar fix."""
    r, a, e = z.T
    p = b + r[:, None] * np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=1)
    rc, platform = cfg["receiver"], cfg["platform"]
    for _ in range(iterations):
        d = p - b
        rho2 = d[:, 0] ** 2 + d[:, 1] ** 2
        rho, rng = np.sqrt(rho2), np.linalg.norm(d, axis=1)
        h = np.stack([rng, np.arctan2(d[:, 1], d[:, 0]), np.arctan2(d[:, 2], rho)], axis=1)
        y = z - h
        y[:, 1:] = (y[:, 1:] + np.pi) % (2 * np.pi) - np.pi
        H = np.zeros((len(p), 4, 3))
        H[:, 0] = d / rng[:, None]
        H[:, 1] = np.stack([-d[:, 1], d[:, 0], np.zeros(len(p))], axis=1) / rho2[:, None]
        H[:, 2] = np.stack([-d[:, 0] * d[:, 2], -d[:, 1] * d[:, 2], rho2], axis=1) / (rng**2 * rho)[:, None]
        H[:, 3, 2] = 1.0
        angle = (np.radians(rc["sigma_angle_deg"]) / np.maximum(d[:, 2] / rng, 0.1)) ** 2 \
            + np.radians(platform["imu_sigma_deg"]) ** 2
        W = np.stack([np.full(len(p), 1.0 / (rc["sigma_range"] ** 2 + platform["gps_sigma"] ** 2)), 1.0 / angle,
                      1.0 / angle, np.full(len(p), 1.0 / rc["sigma_depth"] ** 2)], axis=1)
        residual = np.concatenate([y, (depth - p[:, 2])[:, None]], axis=1)
        A = np.einsum("mki,mk,mkj->mij", H, W, H)
        g = np.einsum("mki,mk,mk->mi", H, W, residual)
        p = p + np.linalg.solve(A, g[..., None])[..., 0]
    return p


def test_a_static_divers_fix_error_is_the_maps_value_whatever_the_baseline():
    """200 replicates of a diver held 15 m from the platform, 4 m below the transceiver (calm sea: the platform's
    motion is not in the map); the horizontal RMS of the fix of every received packet against the map's DRMS at that
    point, and the same packets whatever the baseline."""
    series = {}
    for baseline in BASELINES:
        cfg = load_config("semicircle", usbl(baseline, "platform.beaufort=0", "target.speed=1e-9",
                                             "simulation.duration=5"), seed=3)
        series[baseline] = (cfg, run_batch(with_replicates(cfg, range(200)), "local", timeseries=True).timeseries)
    cfg, ts = series[3.0]
    for baseline in BASELINES:
        np.testing.assert_array_equal(series[baseline][1]["range"], ts["range"])
        np.testing.assert_array_equal(series[baseline][1]["beacon_x"], ts["beacon_x"])
    seq = ts["packet_seq"].to_numpy()
    new = (seq != np.r_[0, seq[:-1]]) & (seq > 0) & ts["packet_valid"].to_numpy(bool)
    assert new.sum() > 2000
    rows = ts[new]
    fix = packet_fix(rows[["range", "azimuth", "elevation"]].to_numpy(), rows[["beacon_x", "beacon_y",
                                                                            "beacon_z"]].to_numpy(),
                     rows["depth"].to_numpy(), cfg)
    truth = rows[["true_x", "true_y", "true_z"]].to_numpy()
    rms = float(np.sqrt(np.mean(np.sum((fix[:, :2] - truth[:, :2]) ** 2, axis=1))))
    point = truth[0]
    drms = float(accuracy_map(cfg, np.array([point[1]]), np.array([point[0]]), depth=float(point[2]))[0, 0])
    assert rms == pytest.approx(drms, rel=0.10), (rms, drms)
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

"""Detection by signal-to-noise (``acoustics.detection = "snr"``): what the channel hears, checked against
closed forms (image sources, the Cramér–Rao scaling of the angle noise), against the site's own detection
probabilities, and the receivers' consistency at the two built-in sites."""

from __future__ import annotations

import math

import numpy as np
import pytest

import sblsim
from sblsim.models.acoustics import ambient_noise, volume_absorption
from sblsim.models.acoustics.channel.site_levels import site_levels
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.cosim.plan import load_plan
from sblsim.orchestrator.maps import availability_map, fix_probability, packet_probabilities

SNR = ("acoustics.propagation=ray", "acoustics.detection=snr")


def _static(point: str, duration: float = 60.0) -> tuple[str, ...]:
    """A diver held at ``point`` ('N E D' [m]) for ``duration`` [s]."""
    return ("target.trajectory=file", f"target.waypoints=0 {point}; 100000 {point}", f"simulation.duration={duration}")


def _packets(result) -> "sblsim.pd.DataFrame":
    """One row per slot sent (the step its packet was delivered)."""
    ts = result.timeseries
    first = ts["packet_seq"].diff().fillna(ts["packet_seq"]) != 0
    return ts[first & (ts["packet_seq"] > 0)]


def test_detection_by_snr_needs_eigenrays():
    with pytest.raises(ConfigError, match=r"^acoustics\.detection: snr needs acoustics\.propagation = ray"):
        sblsim.load("semicircle", set=["acoustics.detection=snr"])


def test_a_diver_straight_below_at_20_m_never_loses_a_packet():
    """SL 180 dB at 20 m: SNR far above any threshold, every packet heard on the direct path."""
    result = sblsim.run("semicircle", seed=3, set=[*SNR, "acoustics.source_level=180", "acoustics.water_depth=60",
                                                   *_static("0 0 20", 100.0)])
    packets = _packets(result)
    assert len(packets) > 900
    assert packets["packet_valid"].all() and (packets["arrival"] == 1).all()
    assert result.metrics["detected_pct"].item() == 100.0
    assert (packets["snr"] > 60.0).all() and (packets["detection_probability"] == 1.0).all()


def test_a_surface_reflected_range_carries_the_image_source_excess():
    """Constant 1500 m/s, a calm sea (no roughness loss), the threshold at the direct path's SNR with a wide
    fluctuation: some packets miss the direct arrival and range on the surface-reflected one; their excess over
    the true range is the image source's path difference, sqrt(x² + (zs + zr)²) − sqrt(x² + (zr − zs)²)."""
    baseline, depth_t, zr, north = 3.0, 1.0, 6.0, 40.0
    overrides = [*SNR, "platform.beaufort=0", "platform.gps_sigma=0", "platform.imu_sigma_deg=0",
                 f"platform.baseline={baseline}", f"platform.transducer_depth={depth_t}",
                 "acoustics.sigma_range=0", "acoustics.water_depth=100", "acoustics.bottom=mud",
                 "acoustics.sound_speed_assumed=1500", "acoustics.sound_speed_true=1500",
                 "acoustics.source_level=120", "acoustics.fluctuation=20", "simulation.sampling_time=0.25",
                 *_static(f"{north} 0 {zr}", 60.0)]
    result = sblsim.run("semicircle", seed=5, set=overrides)
    packets = _packets(result)
    surface = packets[(packets["arrival"] == 2) & packets["packet_valid"]]  # heard and decoded
    assert len(surface) > 20 and (packets["arrival"] == 1).sum() > 20
    assert surface["outlier"].all()
    beacon = surface[["beacon_x", "beacon_y"]].to_numpy()
    x = np.hypot(north - beacon[:, 0], 0.0 - beacon[:, 1])
    zs = surface["beacon_z"].to_numpy()
    excess = np.hypot(x, zs + zr) - np.hypot(x, zr - zs)
    np.testing.assert_allclose(surface["range"] - surface["range_true"], excess, atol=1e-6)
    assert excess.min() > 0.2  # a geometric excess, not round-off


def test_the_usbl_angle_noise_at_the_reference_snr_is_the_configured_one_and_doubles_6_db_below():
    """A static diver below a USBL; the source level puts the reply's SNR at the reference, then 6.02 dB below
    it: the elevation's spread is σ_θ / cos φ, then twice that (the Cramér–Rao scaling, docs/model.md)."""
    sigma_deg, point = 0.5, np.array([30.0, 0.0, 40.0])
    base = ["platform.system=usbl", "platform.layout=cross", f"platform.usbl_angle_sigma_deg={sigma_deg}",
            "platform.gps_sigma=0", "platform.imu_sigma_deg=0", "platform.beaufort=0", "simulation.sampling_time=1",
            "acoustics.sound_speed_true=1500", "acoustics.sound_speed_assumed=1500", "acoustics.fluctuation=0",
            "acoustics.detection_threshold=-30", "acoustics.decoding_margin=0",
            *SNR, *_static(" ".join(f"{v:g}" for v in point), 1500.0)]
    probe = sblsim.run("semicircle", seed=1, set=[*base, "acoustics.source_level=190"])
    above = _packets(probe)["snr"].iloc[5] - 20.0  # the source level that makes the reply's SNR 20 dB
    spreads = []
    for drop in (0.0, 20.0 * math.log10(2.0)):
        result = sblsim.run("semicircle", seed=2, set=[*base, f"acoustics.source_level={190 - above - drop}"])
        packets = _packets(result)
        assert packets["packet_valid"].all()
        np.testing.assert_allclose(packets["snr"], 20.0 - drop, atol=0.05)
        transceiver = np.array([0.0, 0.0, result.config["platform"]["transducer_depth"]])
        v = point - transceiver
        true_elevation = math.atan2(v[2], math.hypot(v[0], v[1]))
        cos_axis = v[2] / np.linalg.norm(v)  # the ray's angle off the array's axis (body down)
        errors = packets["elevation"].to_numpy() - true_elevation
        spreads.append(np.std(errors) * cos_axis / math.radians(sigma_deg))
    # 375 packets: the standard deviation's own relative error is about 1/sqrt(2 * 375) = 3.7 %
    assert spreads[0] == pytest.approx(1.0, rel=0.12)
    assert spreads[1] == pytest.approx(2.0, rel=0.12)


@pytest.mark.slow
def test_detection_probability_falls_with_range_and_is_zero_in_a_shadow():
    """A downward-refracting profile (1500 → 1480 m/s over 1000 m) without boundaries, a source at 50 m and a
    receiver at 300 m: P_d of the direct eigenray never rises with range, and beyond the shadow edge (no
    eigenray) it is 0; it is the detection model at the site's SNR."""
    plan = load_plan("semicircle", [*SNR, "acoustics.sound_speed_profile=table",
                                    "acoustics.sound_speed_table=0 1500; 1000 1480", "acoustics.source_level=175",
                                    "acoustics.frequency=12000", "acoustics.fluctuation=4"])
    x = np.linspace(10.0, 12000.0, 200)
    receivers = np.column_stack([x, np.zeros_like(x), np.full_like(x, 300.0)])
    levels = site_levels(plan.component_parameters("acoustics"), np.tile([0.0, 0.0, 50.0], (x.size, 1)), receivers)
    pd, valid, snr = levels["pd"][:, 0], levels["valid"][:, 0] > 0.5, levels["snr"][:, 0]
    assert valid[:100].all() and not valid[-10:].any()
    assert np.all(np.diff(pd[valid]) <= 1e-12) and np.all(np.diff(snr[valid]) < 0)
    assert np.all(pd[~valid] == 0.0)
    assert pd[0] > 0.999 and 0.0 < pd[valid].min() < 0.5
    from scipy.stats import norm  # Φ((SNR − DT)/σ_f), scipy's normal
    np.testing.assert_allclose(pd[valid], norm.cdf((snr[valid] - 12.0) / 4.0), atol=1e-12)


def test_fix_probability_is_the_poisson_binomial_tail():
    rng = np.random.default_rng(4)
    p = rng.uniform(size=(50, 5))
    want = np.zeros(50)
    for mask in range(32):  # every subset of received packets
        bits = np.array([(mask >> j) & 1 for j in range(5)], bool)
        if bits.sum() >= 3:
            want += np.prod(np.where(bits, p, 1.0 - p), axis=1)
    np.testing.assert_allclose(fix_probability(p, 3), want, rtol=1e-12)


@pytest.mark.slow
def test_the_availability_map_is_the_channel_heard():
    """A one-beacon-at-a-time USBL site: the map's probability of a packet equals the fraction of packets a
    long run of a static diver receives there (no fluctuation of geometry: the same path every slot)."""
    point = "0 2600 800"
    overrides = ["acoustics.fluctuation=6", "acoustics.source_level=170", *_static(point, 8000.0)]
    result = sblsim.run("usbl-deep", seed=7, set=overrides)
    heard = _packets(result)["packet_valid"].mean()
    plan = load_plan("usbl-deep", overrides)
    predicted = packet_probabilities(plan, np.array([[0.0, 2600.0, 800.0]]))[0].item()
    assert 0.05 < predicted < 0.95  # a point where the question is open
    n = len(_packets(result))
    assert abs(heard - predicted) < 4.0 * math.sqrt(predicted * (1 - predicted) / n)
    grid = availability_map(plan, np.array([2600.0]), np.array([0.0]), depth=800.0)
    assert grid[0, 0] == pytest.approx(predicted, rel=1e-12)  # USBL: one packet is a fix


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["usbl-deep", "lbl-field"])
def test_ekf_seq_is_consistent_at_the_sites(scenario):
    result = sblsim.run(scenario, seed=11, replicates=3)
    nees = result.metrics["nees_mean"].mean()
    assert 1.5 <= nees <= 4.5, nees
    assert (result.metrics["detected_pct"] > 90.0).all()


def test_an_exchange_heard_into_the_next_slot_is_flagged():
    """The longest time from a slot's epoch to its exchange's last heard arrival: 0 when every exchange ends
    within the slot; otherwise beyond the slot, at least the longest reflected arrival of the run's packets."""
    long = sblsim.run("lbl-field", seed=1, set=["simulation.duration=60"])
    assert long.metrics["slot_overrun"].item() == 0.0
    short = sblsim.run("lbl-field", seed=1, set=["simulation.sampling_time=0.5", "simulation.duration=30"])
    overrun = short.metrics["slot_overrun"].item()
    packets = _packets(short)
    assert overrun > 0.5 and overrun >= (packets["rx_time"] - packets["tx_time"]).max() - 1e-9


def test_sonar_terms_reach_the_channel():
    """The site's SNR of a direct path in isovelocity water equals SL − (20 log r + α r) − (NL − DI) from the
    sonar module's terms (spherical spreading, the configuration's absorption and Wenz noise)."""
    plan = load_plan("semicircle", [*SNR, "platform.beaufort=4", "acoustics.shipping=0.3",
                                    "acoustics.frequency=30000", "acoustics.bandwidth=6000",
                                    "acoustics.directivity_index=3", "acoustics.source_level=185"])
    params = plan.component_parameters("acoustics")
    src, rec = np.array([[0.0, 0.0, 2.0]]), np.array([[300.0, 400.0, 50.0]])
    snr = site_levels(params, src, rec)["snr"][0, 0]
    r = float(np.linalg.norm(rec - src))
    alpha = volume_absorption.absorption(30000.0, 15.0, 35.0, 0.0)
    noise = ambient_noise.noise_level(30000.0, 6000.0, ambient_noise.wind_speed(4), 0.3)
    assert snr == pytest.approx(185.0 - 20 * math.log10(r) - alpha * r - (noise - 3.0), abs=1e-6)

"""The telemetry design's confirmation through real clocks (issue 70, part 3): a tag's pings read on receiver clocks
drawn at a VR2W-class grade (±2 s, ±20 ppm), the array synchronised from a sync tag at each receiver by the sync
model of ``sblsim sync``, the arrivals corrected and tracked. Checked against the truth the simulation drew: the
track within 10 % (RMS) of the same pings tracked with the true clocks (issue 68's target), the fitted offsets
within 3 of their sigmas of the drawn clocks' for at least 95 % of the receiver-bins, and the design's outputs."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import sblsim
from sblsim.models.errors import ModelError
from sblsim.models.sync.simulate import sync_tag_arrivals
from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.simulate import simulate_pings
from sblsim.orchestrator.design.telemetry_tracking import (
    CLOCK_GRADE,
    synchronised_toa,
    track_path,
    track_synchronised,
)

#: A small lake's array: 8 receivers round a 300 m × 250 m pond, a logistic detection curve (50 % at 350 m).
RECEIVERS = np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 250.0], [0.0, 250.0], [150.0, 120.0], [90.0, 230.0],
                      [220.0, 40.0], [150.0, -20.0]])
SOUND_SPEED, SIGMA_TOA = 1480.0, 1.5e-4


def _curve(d: np.ndarray) -> np.ndarray:
    return 1.0 / (1.0 + np.exp(0.02 * (np.asarray(d) - 350.0)))


def _hears(receivers: np.ndarray) -> np.ndarray:
    """[i, j] the probability that receiver i hears the sync tag at receiver j (its own: 0), computed here."""
    q = _curve(np.linalg.norm(receivers[:, None] - receivers[None], axis=-1))
    np.fill_diagonal(q, 0.0)
    return q


@pytest.fixture(scope="module")
def walk():
    """600 pings of a random burst interval U(20, 40) s (about 5 h), the tag circling inside the array, each
    receiver hearing each ping with the curve's probability at its distance."""
    settings = TrackerSettings(sound_speed=SOUND_SPEED, sigma_toa=SIGMA_TOA, acceleration_psd=1e-4)

    def circle(t):  # 80 m round the array's middle in an hour (0.14 m/s)
        a = 2.0 * np.pi * np.asarray(t) / 3600.0
        return np.column_stack([150.0 + 80.0 * np.cos(a), 125.0 + 80.0 * np.sin(a)])

    rng = np.random.default_rng(5)
    toa, positions, emissions = simulate_pings(RECEIVERS, 600, settings, rng, detection=1.0, ping_type="rbi",
                                               burst_interval=(20.0, 40.0), path=circle)
    d = np.linalg.norm(positions[:, None] - RECEIVERS[None], axis=-1)
    toa[rng.random(toa.shape) >= _curve(d)] = np.nan
    return toa, positions, emissions


def test_the_fitted_clocks_are_the_drawn_ones_within_three_sigmas(walk):
    """Each synchronised receiver's fitted offset at every bin edge against the drawn clock's true offset against
    the reference's (computed here from the drawn offsets and drifts): within 3 sigmas for >= 95 % of the
    receiver-bins, the sigmas the errors' own (their z-scores' spread neither tiny nor large); every receiver
    synchronised, and each corrected arrival within 5 timing sigmas (plus the fit's) of its true time."""
    toa, _, _ = walk
    synced = synchronised_toa(RECEIVERS, toa, _hears(RECEIVERS), SIGMA_TOA, SOUND_SPEED, np.random.default_rng(11))
    assert synced.synchronised.all() and synced.reference == 0
    a, b, ref = synced.offset0, synced.drift, synced.reference
    assert np.all(np.abs(a) <= CLOCK_GRADE["receiver_clock_offset"]) and np.ptp(a) > 0.5  # drawn, of the grade
    assert np.all(np.abs(b) <= CLOCK_GRADE["receiver_clock_drift_ppm"] * 1e-6) and np.ptp(b) > 5e-6
    edges = synced.fit.edges
    z = []
    for j in range(len(RECEIVERS)):
        if j == ref:
            continue
        tau = (edges - a[j]) / (1.0 + b[j])  # the true time at which clock j reads each edge
        truth = edges - (tau + a[ref] + b[ref] * tau)
        z.append((synced.fit.knots[j] - truth) / synced.fit.knot_sigma[j])
    z = np.concatenate(z)
    assert len(z) >= 7 * 5  # at least five bin edges (about 5 h in 1 h bins) for each of the 7 receivers
    assert np.mean(np.abs(z) <= 3.0) >= 0.95, z
    assert 0.4 < np.std(z) < 1.6, np.std(z)
    assert synced.within_3_sigma == pytest.approx(np.mean(np.abs(z) <= 3.0))
    heard = np.isfinite(toa)
    assert np.array_equal(np.isfinite(synced.toa), heard)  # the same detections, only the clocks' errors added
    error = synced.toa[heard] - toa[heard]  # the reference (receiver 0) keeps the true time
    assert np.abs(error).max() < 5.0 * np.hypot(SIGMA_TOA, np.nanmax(synced.fit.knot_sigma)), np.abs(error).max()
    np.testing.assert_allclose(np.sort(np.abs(error)), np.sort(np.abs(synced.error)), rtol=0, atol=1e-12)


@pytest.mark.slow
def test_the_track_through_synchronised_clocks_is_within_ten_percent_of_the_true_clocks(walk):
    """Issue 68's target: the same pings tracked through the synchronised clocks within 10 % (RMS) of their track
    with the true clocks; and without the synchronisation (the raw clocks' readings) the track is far worse, so
    the clocks matter and the fit removed them."""
    toa, positions, emissions = walk
    truth = track_path(RECEIVERS, toa, positions, emissions, SOUND_SPEED, SIGMA_TOA, (20.0, 40.0))
    row = track_synchronised(RECEIVERS, toa, positions, emissions, _hears(RECEIVERS), SOUND_SPEED, SIGMA_TOA,
                             (20.0, 40.0), np.random.default_rng(11))
    assert truth["tracked_pings"] == row["synced_pings"] == 600
    assert abs(row["synced_rms_m"] / truth["tracked_rms_m"] - 1.0) <= 0.10, (row, truth["tracked_rms_m"])
    assert row["synced_ratio"] == pytest.approx(row["synced_rms_m"] / truth["tracked_rms_m"], rel=1e-12)
    assert row["sync_within_3_sigma"] >= 0.95 and row["sync_receivers"] == len(RECEIVERS)
    synced = synchronised_toa(RECEIVERS, toa, _hears(RECEIVERS), SIGMA_TOA, SOUND_SPEED, np.random.default_rng(11))
    heard = np.isfinite(toa)
    assert row["sync_residual_m"] == pytest.approx(SOUND_SPEED * np.sqrt(np.mean((synced.toa - toa)[heard] ** 2)))
    raw = toa + synced.offset0 + synced.drift * toa  # read on the drawn clocks, not corrected
    try:  # seconds of clock error: no track, or a far worse one
        unsynced = track_path(RECEIVERS, raw, positions, emissions, SOUND_SPEED, SIGMA_TOA, (20.0, 40.0))
    except ModelError:
        unsynced = {"tracked_rms_m": np.inf}
    assert not unsynced["tracked_rms_m"] < 10.0 * truth["tracked_rms_m"], unsynced


def test_the_sync_tags_are_heard_with_a_probability_per_pair():
    """``sync_tag_arrivals`` with a (R, R) probability: a scalar and the same value for every pair draw alike (bit
    for bit); a pair of probability 0 is never heard; each pair's share of the emissions heard is its probability
    within 4 binomial sigmas."""
    positions = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 200.0]])
    args = (positions, 200_000.0, (100.0, 140.0), 1480.0)
    same = sync_tag_arrivals(*args, 0.4, 1e-4, np.random.default_rng(2))
    pairs = sync_tag_arrivals(*args, np.full((3, 3), 0.4), 1e-4, np.random.default_rng(2))
    for x, y in zip(same, pairs):
        np.testing.assert_array_equal(x, y)
    p = np.array([[0.0, 0.9, 0.2], [0.5, 0.0, 0.7], [0.1, 0.3, 0.0]])  # [tag, receiver]
    rec, tag, _ = sync_tag_arrivals(*args, p, 1e-4, np.random.default_rng(3))
    emitted = 200_000.0 / 120.0
    for i in range(3):
        for j in range(3):
            n = np.sum((tag == i) & (rec == j))
            if p[i, j] == 0.0:
                assert n == 0
            else:
                assert abs(n / emitted - p[i, j]) <= 4.0 * np.sqrt(p[i, j] * (1 - p[i, j]) / emitted) + 0.02, (i, j)


SMALL = {
    "design": {"name": "pond"},
    "site.area": {"polygon": "0 0; 0 300; 150 300; 150 150; 300 150; 300 0"},
    "detection": {"range_50_m": 350.0, "slope": 0.02, "sync_p": 0.5, "sigma_toa_s": 1e-4, "sound_speed": 1480.0},
    "work_area": {"shape": "site", "points": 8},
    "prescription": {"drms_m": 2.0, "coverage_pct": 90.0, "positioning_yield_pct": 80.0},
    "candidates": {"systems": ["ilbl"], "receivers": [4, 7]},
    "search": {"generations": 6, "seed": 3},
    "monte_carlo": {"replicates": 10, "path": True},
}


@pytest.mark.slow
def test_the_design_reports_the_synchronised_track_beside_the_true_clocks(tmp_path):
    """design.json's path row holds the synchronised track's keys and the summary line says it; with
    ``monte_carlo.sync_clocks = false`` every other figure of the design is the same, bit for bit (added, not
    replaced); the row's synchronised RMS is the one ``track_synchronised`` gives on the walk's own pings."""
    on = sblsim.design(None, **SMALL, out=tmp_path / "on")
    off = sblsim.design(None, **{**SMALL, "monte_carlo": {**SMALL["monte_carlo"], "sync_clocks": False}},
                        out=tmp_path / "off")
    with_sync = json.loads((tmp_path / "on" / "design.json").read_text())
    without = json.loads((tmp_path / "off" / "design.json").read_text())
    (row,) = with_sync["designs"][0]["path"]
    (plain,) = without["designs"][0]["path"]
    added = {k for k in row if k.startswith(("synced_", "sync_", "clock_"))}
    assert {"synced_rms_m", "synced_ratio", "sync_residual_m", "sync_within_3_sigma"} <= added
    assert {k: v for k, v in row.items() if k not in added} == plain and not set(plain) & added
    assert with_sync["designs"][0]["monte_carlo"] == without["designs"][0]["monte_carlo"]
    assert with_sync["designs"][0]["predicted"] == without["designs"][0]["predicted"]
    clause = re.search(r"; through clocks synchronised from the sync tags: RMS [\d.]+ m \([\d.]+ times the true "
                       r"clocks', their error [\d.e-]+ m RMS\)", on.summary)
    assert clause and on.summary.replace(clause.group(0), "") == off.summary, (on.summary, off.summary)
    assert row["sync_receivers"] == len(with_sync["designs"][0]["receivers_m"])
    assert abs(row["synced_ratio"] - 1.0) <= 0.10 and row["sync_within_3_sigma"] >= 0.9, row
    assert row["synced_ratio"] == pytest.approx(row["synced_rms_m"] / row["tracked_rms_m"], rel=1e-12)


def test_an_array_that_cannot_be_synchronised_gives_no_synchronised_track(walk):
    """No receiver hears another's sync tag: the fit has nothing to synchronise, the row says so (no pings, NaN
    figures, no receiver synchronised) instead of failing the design; three receivers hearing one another (a
    receiver deaf to its own tag, as the design's sync coverage counts: an emission ties clocks where two others
    hear it) and the rest none: those three synchronised, the rest's arrivals left out."""
    toa, positions, emissions = walk
    row = track_synchronised(RECEIVERS, toa, positions, emissions, np.zeros((8, 8)), SOUND_SPEED, SIGMA_TOA,
                             (20.0, 40.0), np.random.default_rng(1))
    assert row["synced_pings"] == 0 and row["sync_receivers"] == 0 and np.isnan(row["synced_rms_m"]), row
    three = np.zeros((8, 8))
    three[:3, :3] = 0.9
    np.fill_diagonal(three, 0.0)
    synced = synchronised_toa(RECEIVERS, toa, three, SIGMA_TOA, SOUND_SPEED, np.random.default_rng(1))
    assert synced.synchronised.tolist() == [True] * 3 + [False] * 5
    assert np.isnan(synced.toa[:, 3:]).all() and np.array_equal(np.isfinite(synced.toa[:, :3]),
                                                                np.isfinite(toa[:, :3]))


@pytest.mark.slow
def test_the_lake_hald_array_tracked_through_synchronised_clocks():
    """The worked case: every receiver synchronised, the offsets within 3 sigmas at >= 95 % of the receiver-bins
    and the walk's track through the synchronised clocks within 10 % (RMS) of the true clocks'."""
    (row,) = sblsim.design("lake-hald-array").designs[0]["path"]
    assert row["sync_receivers"] == 22 and row["sync_within_3_sigma"] >= 0.95, row
    assert abs(row["synced_ratio"] - 1.0) <= 0.10 and row["synced_pings"] == row["tracked_pings"], row

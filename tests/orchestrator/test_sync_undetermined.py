"""A receiver whose clock the sync-tag arrivals do not determine: one emission shared with the others leaves its
drift free (sblsim.models.sync.emissions ``connected``: two at least; the clocks' normal equations were singular, a
traceback), and a clock whose offset's sigma at its arrivals exceeds what ``clock_sigma_s`` may say
(sblsim.models.sync.noise ``undetermined``, orchestrator/sync/segments.py ``without_undetermined``) is not
synchronised either. Each is said and its detections set aside, rather than written with a ``clock_sigma_s`` of hours
that a study's own ``receivers.csv`` then refuses (16 simulated receivers with 3 sync tags: every tag of the study
was refused so). And the sound speed the other sync tags cannot tell once one is left out
(orchestrator/sync/sync_tags.py ``_fit_without``): held at the full fit's, where it went to 0.035 m/s and the left-out
tag's fixes 269 m off with a σ of 17 µm (a NEES of 10¹⁵ that the study's report then refused)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.sync.emissions import components, connected
from sblsim.models.sync.noise import undetermined
from sblsim.models.sync.simulate import simulate_sync
from sblsim.models.tracking.timing import CLOCK_SIGMA_RANGE
from sblsim.orchestrator.readers.detections import Detections
from sblsim.orchestrator.sync.run import synchronise
from sblsim.orchestrator.telemetry.simulate import simulate_study

EPOCH = 1_700_000_000


def test_a_clock_is_undetermined_where_its_offsets_sigma_at_its_arrivals_is_beyond_the_limit():
    """Against the RMS computed here: each row's variance interpolated linearly in time between its bin's edges,
    averaged over its arrivals; a row without arrivals, or without sigmas (NaN), is never undetermined."""
    edges = np.array([0.0, 10.0, 20.0])
    sigma = np.array([[0.1, 0.1, 0.1], [0.5, 2.0, 4.0], [np.nan, np.nan, np.nan], [0.0, 0.0, 0.0]])
    rows = np.array([0, 1, 1, 2, -1, 0])
    time = np.array([5.0, 2.0, 15.0, 4.0, 3.0, 19.0])
    at_2 = 0.8 * 0.5**2 + 0.2 * 2.0**2
    at_15 = 0.5 * 2.0**2 + 0.5 * 4.0**2
    rms = np.sqrt((at_2 + at_15) / 2)  # 2.5
    assert undetermined(rows, time, sigma, edges, rms - 1e-9).tolist() == [False, True, False, False]
    assert undetermined(rows, time, sigma, edges, rms + 1e-9).tolist() == [False, False, False, False]


def test_a_receiver_sharing_one_emission_is_not_connected_and_the_count_is_taken_again_without_it():
    """Receivers 0-1-2 share emissions 1 to 3; receiver 3 shares emission 4 with 0 and emission 5 with 4, receiver 4
    emission 5 alone: 4 shares one and is left out, then, counted again without it, 3 shares one (with 0) and goes
    too; receiver 5 hears alone. With a second emission for each of 3 and 4 all five are tied."""
    receiver = np.array([0, 1, 2, 0, 1, 0, 2, 3, 0, 4, 3, 5])
    emission = np.array([1, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6])
    assert connected(receiver, emission, 6, 0).tolist() == [True, True, True, False, False, False]
    twice = np.r_[receiver, 3, 0, 4, 3], np.r_[emission, 7, 7, 8, 8]
    assert connected(*twice, 6, 0).tolist() == [True, True, True, True, True, False]
    roots, able = components(receiver, emission, 6)  # the graph itself: who shares enough, from any receiver
    assert able.tolist() == [True, True, True, False, False, False] and len(set(roots[:3])) == 1
    alone = components(np.array([0, 1, 2, 0]), np.array([1, 2, 3, 4]), 3)[1]  # each emission heard once
    assert not alone.any()


def test_a_clock_segment_undetermined_is_named_and_its_receiver_kept_where_another_segment_holds():
    """A receiver whose clock broke (two rows, an arrival set aside between them): its second segment's sigma beyond a
    second is not synchronised (its knots NaN) and named with its arrivals' count, the receiver still synchronised by
    its first; a receiver whose only row is undetermined is not."""
    from sblsim.models.sync.clock_fit import ClockFit
    from sblsim.orchestrator.sync.segments import without_undetermined

    sigma = np.array([[1e-4, 1e-4], [5.0, 5.0], [1e-4, 1e-4], [3.0, 3.0]])  # rows: A, A after its break, B, C
    n = np.zeros(6)
    fit = ClockFit(np.array([0.0, 10.0]), np.zeros((4, 2)), sigma, np.zeros((4, 1)), np.zeros((4, 1)),
                   np.ones((4, 1), int), np.zeros(6), n, n, np.ones(6, bool), np.full(4, 1e-4), None, None, 1,
                   site=np.array([0, 0, 1, 2]), clock=np.array([0, -1, 1, 1, 2, 3]))
    receiver = np.array([0, 0, 0, 0, 1, 2])
    time = np.array([1.0, 5.0, 6.0, 7.0, 2.0, 3.0])
    got, gone, note = without_undetermined(fit, receiver, time, np.ones(6, bool), ["A", "B", "C"])
    assert gone.tolist() == [False, False, True]
    assert note.endswith("set aside: A (2 arrivals), C (1 arrival)"), note
    assert np.isnan(got.knots[[1, 3]]).all() and np.isfinite(got.knots[[0, 2]]).all()


def _frame(sim, keep: np.ndarray) -> Detections:
    t = sim.time[keep] + EPOCH
    frame = pd.DataFrame({"receiver": [f"R{j}" for j in sim.receiver[keep]], "tag": [f"S{i}" for i in sim.tag[keep]],
                          "time": t, "sensor_value": np.nan, "sensor_unit": "", "line": np.arange(len(t)) + 2})
    return Detections(frame, "simulated", "yaps")


def test_a_receiver_tied_by_one_arrival_is_not_synchronised_and_the_others_are_as_without_it():
    """6 simulated receivers, 3 h; R5 has no sync tag of its own and hears one emission of the others: the sync says
    so in a note, R5 is not synchronised (its arrival's reason, the receivers' table), every ``clock_sigma_s``
    written is within what a receivers file may say, and the other clocks are those of the sync without R5's
    arrival at all."""
    sim = simulate_sync(n_receivers=6, hours=3.0, seed=5, noise=0.15e-3, echo_share=0.0)
    at_r5 = np.flatnonzero((sim.receiver == 5) & (sim.tag != 5))
    keep = (sim.tag != 5) & ((sim.receiver != 5) | (np.arange(len(sim.time)) == at_r5[len(at_r5) // 2]))
    hydrophones = pd.DataFrame({"receiver": [f"R{j}" for j in range(6)],
                                "sync_tag": [f"S{j}" if j != 5 else "" for j in range(6)],
                                "x": sim.positions[:, 0], "y": sim.positions[:, 1], "z": np.nan})
    got = synchronise(_frame(sim, keep), hydrophones, sound_speed=sim.sound_speed, reference="R0",
                      leave_one_out=False)
    said = [n for n in got.summary.get("notes", []) if "cannot be synchronised" in n]
    assert len(said) == 1 and said[0].endswith("left out: R5") and "fewer than 2 sync-tag emissions" in said[0]
    assert not got.receivers.set_index("receiver").loc["R5", "synchronised"]
    assert (got.residuals.loc[got.residuals["receiver"] == "R5", "reason"] == "not synchronised").all()
    clock = got.offsets["clock_sigma_s"].to_numpy(float)
    assert ((clock >= CLOCK_SIGMA_RANGE[0]) & (clock <= CLOCK_SIGMA_RANGE[1])).all(), got.offsets
    assert "R5" not in set(got.offsets["receiver"]) or got.offsets.loc[got.offsets["receiver"] == "R5",
                                                                       "offset_start_s"].isna().all()
    alone = synchronise(_frame(sim, keep & (sim.receiver != 5)), hydrophones.iloc[:5], sound_speed=sim.sound_speed,
                        reference="R0", leave_one_out=False)
    mine = got.offsets[got.offsets["receiver"] != "R5"].reset_index(drop=True)
    np.testing.assert_allclose(mine["offset_start_s"], alone.offsets["offset_start_s"], rtol=0, atol=1e-9)


@pytest.mark.slow
def test_a_study_of_few_sync_tags_tracks_every_tag_without_the_receiver_it_cannot_synchronise(tmp_path):
    """The simulated study that found it (16 receivers, 3 of them with a sync tag, 2 animals, 6 hours, seed 6):
    receiver 461012 shares one sync-tag emission with the others and is not synchronised (``study.json``'s
    ``clocks.not_synchronised``, and the synchronisation's note saying why among the study's), and both tags are
    tracked (before: both refused, their ``receivers.csv``'s ``clock_sigma_s`` 22,957 s out of range), each within
    0.5 m RMS of its simulated path."""
    sim = simulate_study(n_receivers=16, n_tags=2, days=0.25, redeployed=0, seed=6)
    files = sim.write(tmp_path / "in", "vue")
    sheet = pd.read_csv(files["deployments"], dtype=str, keep_default_na=False)
    sheet.loc[~sheet.index.isin([0, 5, 10]), "transmitter"] = ""
    sheet.to_csv(tmp_path / "deployments.csv", index=False)
    result = sblsim.track(files["detections"], receivers=tmp_path / "deployments.csv", tags=files["tags"],
                          workers=2, out=tmp_path / "study")
    assert result.summary["clocks"]["not_synchronised"] == ["461012"], result.summary["clocks"]
    said = [n for n in result.summary["notes"] if "cannot be synchronised" in n]
    assert len(said) == 1 and said[0].endswith("left out: 461012"), result.summary["notes"]
    assert (result.tags["status"] == "tracked").all(), result.tags["reason"].tolist()
    reference = result.summary["clocks"]["reference_receiver"]
    k = int(np.flatnonzero(result.receivers["receiver"].to_numpy() == reference)[0])
    for tag, rows in result.tracks.groupby("tag"):
        ok = (rows["quality"] == "ok").to_numpy()
        error = np.linalg.norm(rows[["x", "y"]].to_numpy()[ok] - sim.truth_at(tag, rows["epoch_s"].to_numpy()[ok], k),
                               axis=1)
        assert ok.mean() > 0.9 and np.sqrt(np.mean(error**2)) < 0.5, (tag, ok.mean(), np.sqrt(np.mean(error**2)))


def test_a_sync_tag_left_out_keeps_the_sound_speed_the_others_cannot_tell():
    """6 simulated receivers, 2 of them with a sync tag, the sound speed estimated: without either tag the other
    alone cannot tell the sound speed from the clocks (each receiver one distance to it), and the fit without it
    holds the full fit's. Both tags are positioned (before: neither), their fixes' medians within 5 cm of those of
    the same synchronisation with that sound speed given (whose fits without a tag never estimate it), each within
    its σ as a consistent estimator's (NEES mean at most 4.5)."""
    sim = simulate_sync(n_receivers=6, hours=3.0, seed=2, noise=0.15e-3, echo_share=0.0)
    keep = sim.tag < 2
    hydrophones = pd.DataFrame({"receiver": [f"R{j}" for j in range(6)], "sync_tag": ["S0", "S1", "", "", "", ""],
                                "x": sim.positions[:, 0], "y": sim.positions[:, 1], "z": np.nan})
    estimated = synchronise(_frame(sim, keep), hydrophones, reference="R0")
    given = synchronise(_frame(sim, keep), hydrophones, reference="R0", sound_speed=1.0 / estimated.fit.slowness)
    assert abs(1.0 / estimated.fit.slowness - sim.sound_speed) < 1.0
    assert estimated.sync_tags["tag"].tolist() == ["S0", "S1"] == given.sync_tags["tag"].tolist()
    median = ["median_x_m", "median_y_m"]
    np.testing.assert_allclose(estimated.sync_tags[median], given.sync_tags[median], rtol=0, atol=0.05)
    truth = sim.positions[[0, 1], :2]
    assert (np.hypot(*(estimated.sync_tags[median].to_numpy() - truth).T) < 2.0).all()
    assert (estimated.sync_tags["nees_mean"] <= 4.5).all(), estimated.sync_tags["nees_mean"]

"""Clocks aligned coarsely from the tags the receivers hear together (models/sync/coarse_lags.py), against simulated
clocks: each pair's lag where its detections' differences pile up, the receivers' offsets from the pairs'."""

from __future__ import annotations

import numpy as np

from sblsim.models.sync.coarse_lags import MIN_PAIRS, coarse_offsets, pair_lag


def test_a_pairs_lag_is_where_its_differences_pile_up():
    """30 pings' differences within ±0.1 s of 12.3 s among 200 spread over ±120 s: the lag within 0.1 s; too few, or
    two stretches as dense (a fixed interval's multiples), no lag."""
    rng = np.random.default_rng(0)
    true = 12.3 + rng.uniform(-0.1, 0.1, 30)
    lag, count = pair_lag(np.r_[true, rng.uniform(-120.0, 120.0, 200)], 0.3)
    assert abs(lag - 12.3) < 0.1 and count >= 30
    assert np.isnan(pair_lag(true[:MIN_PAIRS - 1], 0.3)[0])
    assert np.isnan(pair_lag(np.r_[true, true + 60.0], 0.3)[0])


def _pings(rng, receivers: int, offsets: np.ndarray, tags: int = 3, span: float = 6 * 3600.0, drift=None):
    """Each tag's pings at random intervals of 60-120 s, each heard by each receiver with probability 0.7 after a
    travel time of up to 0.15 s, logged on its clock (offset, and drift [s/s] where given)."""
    receiver, tag, time = [], [], []
    for t in range(tags):
        emitted = np.cumsum(rng.uniform(60.0, 120.0, int(span / 60.0)))
        emitted = emitted[emitted < span]
        for r in range(receivers):
            heard = emitted[rng.random(len(emitted)) < 0.7]
            logged = heard + rng.uniform(0.0, 0.15, len(heard)) + offsets[r]
            if drift is not None:
                logged += drift[r] * heard
            receiver.append(np.full(len(heard), r))
            tag.append(np.full(len(heard), t))
            time.append(logged)
    return np.concatenate(receiver), np.concatenate(tag), np.concatenate(time)


def test_the_receivers_offsets_come_back_to_within_a_crossing_time():
    """Six receivers' clocks off by up to ±40 s (a VR2W's after a month) and drifting by up to 20 ppm, three tags at
    random intervals: each receiver's offset from the time base's in each of two 3 h windows within 0.15 s of the
    simulated clocks' at the window's middle (the crossing time); a receiver that hears no tag another hears is
    not tied to the time base (NaN)."""
    rng = np.random.default_rng(4)
    offsets = rng.uniform(-40.0, 40.0, 6)
    drift = rng.uniform(-20e-6, 20e-6, 6)
    receiver, tag, time = _pings(rng, 6, offsets, drift=drift)
    alone = np.cumsum(rng.uniform(60.0, 120.0, 200))
    receiver, tag, time = np.r_[receiver, np.full(200, 6)], np.r_[tag, np.full(200, 9)], np.r_[time, alone]
    edges = np.array([0.0, 3 * 3600.0, 6 * 3600.0]) - 50.0
    found = coarse_offsets(receiver, tag, time, 7, edges, 120.0, 0.3, base=2)
    centres = 0.5 * (edges[:-1] + edges[1:])
    truth = offsets[:, None] + drift[:, None] * centres[None]
    assert np.abs(found.offsets[:6] - (truth - truth[2])).max() < 0.15, found.offsets[:6] - (truth - truth[2])
    assert np.isnan(found.offsets[6]).all() and (found.offsets[2] == 0.0).all()
    assert found.largest_lag > 10.0 and found.pairs == 2 * 15


def test_a_fast_tags_differences_are_bounded(monkeypatch):
    """A tag's differences beyond :data:`MAX_DIFFERENCES` are those of every k-th detection alone: the offsets the
    same to within the crossing time with the bound set low (a fast tag's 10⁸ differences never made)."""
    import sblsim.models.sync.coarse_lags as coarse

    rng = np.random.default_rng(8)
    offsets = rng.uniform(-20.0, 20.0, 5)
    receiver, tag, time = _pings(rng, 5, offsets, tags=2, span=3 * 3600.0)
    edges = np.array([-50.0, 3 * 3600.0 + 50.0])
    whole = coarse_offsets(receiver, tag, time, 5, edges, 120.0, 0.3, base=0)
    monkeypatch.setattr(coarse, "MAX_DIFFERENCES", 500)
    bounded = coarse_offsets(receiver, tag, time, 5, edges, 120.0, 0.3, base=0)
    truth = (offsets - offsets[0])[:, None]
    assert np.abs(whole.offsets - truth).max() < 0.15 and np.abs(bounded.offsets - truth).max() < 0.15


def test_a_window_the_time_base_is_not_deployed_in_takes_another_receiver_as_its_base():
    """Receiver 0 (the time base) recovered after the first 3 h window: in the second, where before no receiver was
    tied (every offset NaN), each offset comes back from the receiver of the most pairs there, the differences
    between any two receivers within the crossing time of the simulated clocks' (a common offset moves no position);
    the first window's still from receiver 0."""
    rng = np.random.default_rng(11)
    offsets = rng.uniform(-20.0, 20.0, 5)
    receiver, tag, time = _pings(rng, 5, offsets)
    gone = (receiver == 0) & (time - offsets[0] > 3 * 3600.0)
    receiver, tag, time = receiver[~gone], tag[~gone], time[~gone]
    edges = np.array([-50.0, 3 * 3600.0, 6 * 3600.0 + 50.0])
    found = coarse_offsets(receiver, tag, time, 5, edges, 120.0, 0.3, base=0)
    first, second = found.offsets[:, 0], found.offsets[1:, 1]
    assert np.abs(first - (offsets - offsets[0])).max() < 0.15 and first[0] == 0.0
    assert np.isfinite(second).all() and (second == 0.0).sum() == 1
    differences = second[:, None] - second[None]
    truth = offsets[1:, None] - offsets[None, 1:]
    assert np.abs(differences - truth).max() < 0.3

"""The receivers that heard each ping at once (:func:`sblsim.models.sync.at_once.heard_at_once`) against the
emissions that made the detections: transmissions from known places heard by the receivers within range, each
ping's count the receivers that heard that transmission; a false detection a window's width from a ping, at a
receiver whose travel time cannot put it there, is no receiver of that ping."""

from __future__ import annotations

import numpy as np

from sblsim.models.sync.at_once import heard_at_once

SPEED = 1480.0


def _heard(seed: int, n: int = 400):
    """Transmissions at random places over a 2 km square of 8 receivers, every 60 to 120 s, each heard by the
    receivers within 700 m: the detections (receiver, time) and each transmission's receivers."""
    rng = np.random.default_rng(seed)
    receivers = rng.uniform(0, 2000, (8, 2))
    where = rng.uniform(0, 2000, (n, 2))
    emitted = np.cumsum(rng.uniform(60, 120, n))
    d = np.linalg.norm(where[:, None] - receivers[None], axis=2)
    ping, receiver = np.nonzero(d < 700)
    time = emitted[ping] + d[ping, receiver] / SPEED + rng.normal(0, 1e-4, len(ping))
    return receivers, receiver, time, ping, (d < 700).sum(axis=1)


def test_each_ping_s_receivers_are_its_transmission_s():
    for seed in range(3):
        receivers, receiver, time, ping, count = _heard(seed)
        found = heard_at_once(receiver, time, receivers, 1300.0, 0.02)
        heard = count[count > 0]
        assert len(found.receivers) == len(heard)
        assert np.array_equal(found.receivers, heard)
        for k in (1, 3, 4):
            assert found.heard_by(k) == int((heard >= k).sum())
        # each detection's ping holds the detections of its own transmission
        assert np.array_equal(found.receivers[found.ping], count[ping])
        assert np.array_equal(found.detections_heard_by(3), count[ping] >= 3)


def test_a_false_detection_the_travel_times_cannot_place_is_left_out():
    """Receivers 0 and 1 are 100 m apart, 2 is 3 km from both: a window of more than 2 s. A transmission heard at
    receiver 0 and, 0.5 s later, at receiver 2, and a false detection at receiver 1 0.9 s after receiver 0's: within
    the window, but 100 m allow 0.1 s at most between receivers 0 and 1; that ping is heard by 2 at once, not 3."""
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [3000.0, 0.0]])
    receiver = np.array([0, 2, 1])
    time = np.array([1000.0, 1000.5, 1000.9])
    found = heard_at_once(receiver, time, receivers, 1300.0, 0.02)
    assert found.window > 2.0 and len(found.receivers) == 1  # one group within the window
    assert found.receivers.tolist() == [2] and found.heard_by(3) == 0
    # receiver 1's detection 0.05 s after receiver 0's: the three are one ping of 3
    near = heard_at_once(receiver, np.array([1000.0, 1000.5, 1000.05]), receivers, 1300.0, 0.02)
    assert near.receivers.tolist() == [3]


def test_whole_second_times_agree_within_their_rounding():
    """Times rounded to whole seconds: a ping's arrivals 0.1 s apart may read 1 s apart; with the rounding in the
    tolerance they are one ping again."""
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]])
    receiver = np.array([0, 1, 2])
    time = np.array([999.0, 1000.0, 1000.0])  # 999.95, 1000.02 and 1000.04 as logged to the second
    assert heard_at_once(receiver, time, receivers, 1300.0, 0.02).receivers.max() < 3
    assert heard_at_once(receiver, time, receivers, 1300.0, 1.02).receivers.tolist() == [3]

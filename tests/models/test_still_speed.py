"""A still tag's sound speed from its pings as one place (models/tracking/still_speed.py), against the speed the
record was simulated with: four receivers in 2-D (no ping can calibrate it alone), the water's speed constant and
changing, and the refusals."""

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.tracking import still_speed
from sblsim.models.tracking.calibration import BATCHES
from sblsim.models.tracking.still_speed import calibrate_still_sound_speed

RECEIVERS = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 800.0], [0.0, 800.0]])
SIGMA = 1e-4


def _record(seed: int, speed, pings: int = 720, receivers: np.ndarray = RECEIVERS, place=(780.0, 560.0)):
    """Times of arrival (pings, R) [s] of a tag at ``place`` heard 80 % of the time, ``speed(t)`` [m/s] at each
    ping's time t, and those times."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(96.0, 144.0, pings))
    c = speed(t)
    toa = t[:, None] + np.linalg.norm(np.asarray(place)[None] - receivers, axis=1)[None] / c[:, None]
    toa += SIGMA * rng.normal(size=toa.shape)
    toa[rng.random(toa.shape) > 0.8] = np.nan
    return toa, t


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_four_receivers_tell_a_still_tags_speed(seed):
    """Constant water at 1,480 m/s: the median of the stretches within 0.5 m/s (from 0.1 ms of timing noise on
    ranges of about 500 m) and within 4 of its own standard errors; every stretch fitted."""
    toa, _ = _record(seed, lambda t: np.full(len(t), 1480.0))
    cal = calibrate_still_sound_speed(toa, RECEIVERS, SIGMA)
    assert abs(cal.c - 1480.0) < 0.5 and abs(cal.c - 1480.0) <= 4 * cal.sigma + 0.05, cal
    assert len(cal.batches) == BATCHES and np.isfinite(cal.batches).all()
    assert cal.pings == int((np.isfinite(toa).sum(axis=1) >= 2).sum())


def test_each_stretch_follows_the_water_and_the_error_holds_its_spread():
    """1,480 ± 5 m/s over a day (a sine): each stretch's speed within 1.5 m/s of the simulated speed's mean over it
    (each stretch fits its own place, which trades a little with the speed); the median's standard error is that of
    the stretches' spread (1.2533 s / √K)."""
    def speed(t):
        return 1480.0 + 5.0 * np.sin(2 * np.pi * t / 86400.0 + 0.3)

    toa, t = _record(4, speed)
    cal = calibrate_still_sound_speed(toa, RECEIVERS, SIGMA)
    means = [speed(t[rows]).mean() for rows in np.array_split(np.arange(len(t)), BATCHES)]
    assert np.allclose(cal.batches, means, atol=1.5), (cal.batches, means)
    assert cal.sigma == pytest.approx(1.2533 * np.std(cal.batches, ddof=1) / np.sqrt(BATCHES))
    assert cal.c == pytest.approx(np.median(cal.batches))


def test_a_reflection_at_one_receiver_does_not_move_it(monkeypatch):
    """A tenth of one receiver's arrivals 10 m of path late (a reflection): the soft-L1 fit keeps the speed within
    1 m/s, where the same fit of the squares (its scale made huge) is more than 5 m/s off."""
    toa, _ = _record(5, lambda t: np.full(len(t), 1480.0))
    late = np.random.default_rng(6).random(len(toa)) < 0.1
    toa[late, 1] += 10.0 / 1480.0
    robust = calibrate_still_sound_speed(toa, RECEIVERS, SIGMA).c
    monkeypatch.setattr(still_speed, "ROBUST_SCALE", 1e9)
    squares = calibrate_still_sound_speed(toa, RECEIVERS, SIGMA).c
    assert abs(robust - 1480.0) < 1.0 and abs(squares - 1480.0) > 5.0, (robust, squares)


def test_three_receivers_cannot_tell_the_place_from_the_speed():
    toa, _ = _record(0, lambda t: np.full(len(t), 1480.0), receivers=RECEIVERS[:3])
    with pytest.raises(ModelError, match="3 receivers hear the tag; at least 4 are needed"):
        calibrate_still_sound_speed(toa, RECEIVERS[:3], SIGMA)


def test_a_record_too_short_for_its_stretches_is_refused():
    toa, _ = _record(0, lambda t: np.full(len(t), 1480.0), pings=40)
    with pytest.raises(ModelError, match="stretches of the record fitted; at least 3 are needed"):
        calibrate_still_sound_speed(toa, RECEIVERS, SIGMA)


def test_receivers_in_3d_are_refused_in_one_line():
    """In 3-D the tag's depth trades with the speed (the per-ping calibration's depth term): refused, not guessed."""
    toa, _ = _record(0, lambda t: np.full(len(t), 1480.0))
    with pytest.raises(ModelError, match="receivers in 3-D; allowed: 2-D"):
        calibrate_still_sound_speed(toa, np.c_[RECEIVERS, [-5.0, -6.0, -5.0, -6.0]], SIGMA)

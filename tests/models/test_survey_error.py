"""The survey error a synchronisation's residuals show (models/sync/survey_error.py), against Monte Carlo draws of the
model it states: the receivers' positions off by N(0, σ²) per axis, each pair's median residual the range error
``u · (δ_k − δ_h)`` plus its own noise plus whatever the clocks, the emissions and the sound speed absorb."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.sync.survey_error import Z_SEEN, survey_error

R = 16


def _array(seed: int = 0):
    """16 receivers in 600 m × 600 m, a sync tag at every third, each heard by the receivers within 450 m."""
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0.0, 600.0, (R, 2))
    listener, home, tag = [], [], []
    for t, h in enumerate(range(0, R, 3)):
        for k in range(R):
            if k != h and np.linalg.norm(positions[k] - positions[h]) < 450.0:
                listener.append(k)
                home.append(h)
                tag.append(t)
    listener, home, tag = map(np.array, (listener, home, tag))
    count = rng.integers(20, 400, len(listener)).astype(float)
    scale = rng.uniform(0.1, 1.0, len(listener))
    return positions, listener, home, tag, count, scale


def _medians(rng, sigma, positions, listener, home, tag, count, scale):
    """One draw of the pairs' medians [m]: the positions' errors seen along each pair, the median's noise, and a
    clock per receiver, an emission time per tag and a sound-speed error (what the fit absorbs)."""
    delta = sigma * rng.normal(size=positions.shape)
    d = positions[listener] - positions[home]
    u = d / np.linalg.norm(d, axis=1)[:, None]
    m = np.einsum("pi,pi->p", u, delta[listener] - delta[home])
    m += rng.normal(size=len(m)) * np.sqrt(np.pi / 2 * scale**2 / count)
    return m + 3.0 * rng.normal(size=R)[listener] + 3.0 * rng.normal(size=tag.max() + 1)[tag] \
        + 0.01 * rng.normal() * np.linalg.norm(d, axis=1)


@pytest.mark.parametrize("sigma", [0.5, 2.0])
def test_the_variance_is_unbiased_and_its_standard_error_the_spread(sigma):
    """Over 300 draws the mean of σ̂² is σ² (within 3 of its standard errors) and the reported standard error of σ̂ is
    the draws' spread within 20 %; every draw says it is seen."""
    array = _array()
    rng = np.random.default_rng(1)
    found = [survey_error(_medians(rng, sigma, *array), array[4], array[5], array[1], array[2], array[3], array[0])
             for _ in range(300)]
    est = np.array([f.sigma for f in found])
    assert all(f.seen for f in found)
    assert abs(np.mean(est**2) - sigma**2) < 3 * np.std(est**2) / np.sqrt(len(est))
    assert np.mean([f.sigma_se for f in found]) == pytest.approx(np.std(est), rel=0.2)
    # the pairs kept less the clocks, the tags and the speed (one in common)
    assert all(f.degrees == f.pairs - f.set_aside - (R + 6 + 1 - 1) for f in found)


def test_without_a_survey_error_it_is_seldom_seen():
    """σ = 0: the excess's z is about standard normal, and is said seen (z ≥ 3) in few draws; σ̂ is then 0."""
    array = _array(2)
    rng = np.random.default_rng(3)
    found = [survey_error(_medians(rng, 0.0, *array), array[4], array[5], array[1], array[2], array[3], array[0])
             for _ in range(400)]
    z = np.array([f.z for f in found])
    assert abs(z.mean()) < 0.2 and 0.8 < z.std() < 1.25
    assert np.mean(z >= Z_SEEN) < 0.03
    assert all(f.sigma == 0.0 for f in found if not f.seen)


def test_pairs_a_reflection_lengthens_are_set_aside():
    """σ = 1 m, and one pair in twenty 10 to 30 m long (a reflection for the whole season): over 100 draws σ̂ stays
    within 15 % of σ in root mean square, those pairs set aside in nine draws of ten."""
    array = _array(6)
    rng = np.random.default_rng(7)
    P = len(array[1])
    est, aside = [], []
    for _ in range(100):
        m = _medians(rng, 1.0, *array)
        bent = rng.permutation(P)[: P // 20]
        m[bent] += rng.uniform(10.0, 30.0, len(bent))
        found = survey_error(m, array[4], array[5], array[1], array[2], array[3], array[0])
        est.append(found.sigma)
        aside.append(found.set_aside >= len(bent))
    assert abs(np.sqrt(np.mean(np.square(est))) - 1.0) < 0.15, np.sqrt(np.mean(np.square(est)))
    assert np.mean(aside) > 0.9


def test_what_the_fit_absorbs_changes_nothing():
    """Adding any clock per receiver, emission time per tag or sound-speed error to the medians leaves σ̂ and z."""
    positions, listener, home, tag, count, scale = _array(4)
    rng = np.random.default_rng(5)
    m = _medians(rng, 1.0, positions, listener, home, tag, count, scale)
    one = survey_error(m, count, scale, listener, home, tag, positions)
    shifted = m + 50.0 * rng.normal(size=R)[listener] - 7.0 * rng.normal(size=tag.max() + 1)[tag] \
        + 0.3 * np.linalg.norm(positions[listener] - positions[home], axis=1)
    two = survey_error(shifted, count, scale, listener, home, tag, positions)
    assert two.sigma == pytest.approx(one.sigma, rel=1e-9) and two.z == pytest.approx(one.z, rel=1e-9)


def test_bad_pairs_are_refused():
    positions, listener, home, tag, count, scale = _array()
    with pytest.raises(ValueError, match="differ in length"):
        survey_error(np.zeros(3), count, scale, listener, home, tag, positions)
    with pytest.raises(ValueError, match="no distance"):
        survey_error(np.zeros(len(home)), count, scale, home, home, tag, positions)
    few = survey_error(np.zeros(2), np.full(2, 20.0), np.ones(2), listener[:2], home[:2], tag[:2], positions)
    assert not few.seen and np.isnan(few.sigma) and few.degrees == 0


def test_pairs_without_noise_are_weighed_without_a_division_by_zero():
    """A pair whose noise is 0 (its arrivals' variance nothing at v = 0): its ratio is infinite where its residual
    is not 0 and 0 where it is, with no warning; the variance found is the one the other pairs give."""
    import warnings

    from sblsim.models.sync.survey_error import _robust_variance

    square, parts = np.array([4.0, 4.0, 4.0, 0.0]), np.ones(4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        found = _robust_variance(square, parts, np.zeros(4))
        with_noise = _robust_variance(square, parts, np.full(4, 1e-30))
    assert found == pytest.approx(with_noise, rel=1e-6) and found > 0


@pytest.mark.parametrize("seed", [0, 3])
def test_the_speed_s_share_of_the_survey_error_is_the_draws_spread(seed):
    """``scale_sigma``: the positions moved by N(0, σ²) per axis (400 draws), each pair's range taken from them as a
    distance, not along the pair's line, the least squares of the pairs' range errors on a clock per receiver, an
    emission time per tag and the distance (numpy's ``lstsq``): the distance's coefficient, the relative error the
    sound speed takes, spreads as σ ``scale_sigma`` within 12 %; NaN where the pairs do not determine it."""
    positions, listener, home, tag, count, scale = _array(seed)
    found = survey_error(np.zeros(len(home)), count, scale, listener, home, tag, positions)
    rng = np.random.default_rng(seed + 10)
    sigma, distance = 2.0, np.linalg.norm(positions[listener] - positions[home], axis=1)
    X = np.column_stack([np.eye(R)[listener], np.eye(tag.max() + 1)[tag], distance])
    coefficient = []
    for _ in range(400):
        moved = positions + sigma * rng.normal(size=positions.shape)
        error = np.linalg.norm(moved[listener] - moved[home], axis=1) - distance
        coefficient.append(np.linalg.lstsq(X, error, rcond=None)[0][-1])
    assert np.std(coefficient) == pytest.approx(sigma * found.scale_sigma, rel=0.12), (np.std(coefficient), found)
    assert found.summary()["speed_scale_sigma_per_m"] == found.scale_sigma
    one = survey_error(np.zeros(2), np.full(2, 20.0), np.ones(2), listener[:2], home[:2], tag[:2], positions)
    assert np.isnan(one.scale_sigma) and one.summary()["speed_scale_sigma_per_m"] is None

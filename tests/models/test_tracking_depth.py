"""Whether an array's arrivals determine a tag's depth, and the prior where not (models/tracking/depth.py), against
the fix's covariance written again from its Jacobian with numpy, and covariances built by hand."""

from __future__ import annotations

import numpy as np

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking.depth import MIN_FIXES, UNDETERMINED_RATIO, at_least, depth_prior, fixes_depth

#: 8 receivers over 200 x 150 m moored 1-5 m deep (a lake's array), and the same array 2-20 m deep.
HORIZONTAL = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0],
                       [140.0, 20.0], [30.0, 80.0]])
SHALLOW = np.column_stack([HORIZONTAL, -np.array([1.0, 4.5, 2.0, 5.0, 3.0, 1.5, 4.0, 2.5])])
DEEP = np.column_stack([HORIZONTAL, -np.array([2.0, 15.0, 4.0, 20.0, 8.0, 3.0, 12.0, 6.0])])
C, SIGMA = 1480.0, 1e-4


def _pings(receivers: np.ndarray, depth: float, count: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free times of arrival of ``count`` pings at tags spread over the array at ``depth`` [m], and the tags."""
    rng = np.random.default_rng(3)
    tags = np.column_stack([rng.uniform(20.0, 180.0, count), rng.uniform(15.0, 135.0, count), np.full(count, -depth)])
    emission = 2.0 * np.arange(count)
    toa = emission[:, None] + np.linalg.norm(tags[:, None, :] - receivers[None], axis=2) / C
    return toa, tags


def _by_hand(receivers: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Each position's depth σ [m] from the TOA model's Jacobian, the rows ``[(p − r_i)ᵀ / (c ‖p − r_i‖), 1]`` and
    the covariance σ² (JᵀJ)⁻¹ (Kay 1993, § 8.9)."""
    sigmas = []
    for p in positions:
        d = p - receivers
        J = np.column_stack([d / (C * np.linalg.norm(d, axis=1)[:, None]), np.ones(len(d))])
        sigmas.append(np.sqrt((SIGMA ** 2 * np.linalg.inv(J.T @ J))[2, 2]))
    return np.array(sigmas)


def test_the_fixes_depth_sigma_is_the_jacobian_s():
    for receivers, depth in ((SHALLOW, 2.0), (DEEP, 10.0)):
        toa, tags = _pings(receivers, depth)
        fx, _, cov, used, _ = tt.fix_pings(toa, receivers, C, SIGMA)
        sigma, height, count = fixes_depth(fx, cov, used.sum(axis=1))
        assert count == len(tags)
        # at each fix (a fix may lie in the depth's mirror image: its covariance is the one there)
        assert np.isclose(sigma, np.median(_by_hand(receivers, fx)), rtol=1e-6), (sigma, receivers[:, 2])
        assert height == np.median(fx[:, 2])
    # fixes of three receivers do not count
    assert fixes_depth(fx, cov, np.full(len(cov), 3))[2] == 0


def test_a_shallow_array_near_its_tag_does_not_determine_the_depth_and_a_deep_one_does():
    heights = SHALLOW[:, 2]
    toa, tags = _pings(SHALLOW, 2.0)
    fx, _, cov, used, _ = tt.fix_pings(toa, SHALLOW, C, SIGMA)
    prior = depth_prior(fx, cov, used.sum(axis=1), SHALLOW)
    sigma = np.median(_by_hand(SHALLOW, fx))
    assert prior is not None and np.isclose(prior.ratio, sigma / (heights.max() - heights.min()))
    assert prior.ratio > UNDETERMINED_RATIO
    assert np.isclose(prior.depth, -heights.mean()) and np.isclose(prior.sigma, max(sigma, 4.0))
    # the same array with the tags 10 m below its mean, and an array 2-20 m deep: the depth determined
    for receivers, depth in ((SHALLOW, 13.0), (DEEP, 10.0), (DEEP, 2.0)):
        toa, _ = _pings(receivers, depth)
        fx, _, cov, used, _ = tt.fix_pings(toa, receivers, C, SIGMA)
        assert depth_prior(fx, cov, used.sum(axis=1), receivers) is None, (receivers[:, 2], depth)
        sigma = fixes_depth(fx, cov, used.sum(axis=1))[0]
        assert sigma / np.ptp(receivers[:, 2]) < UNDETERMINED_RATIO or depth == 13.0, (depth, sigma)
    # an array on one plane (its extent 0) with the tags 40 m above it: they lie outside its heights, no prior
    flat = np.column_stack([HORIZONTAL, np.full(len(HORIZONTAL), -50.0)])
    toa, tags = _pings(flat, 10.0)
    guesses = tags + np.array([3.0, -2.0, 5.0])
    fx, _, cov, used, _ = tt.fix_pings(toa, flat, C, SIGMA, guesses=guesses)
    assert np.median(fx[:, 2]) > -45.0
    assert depth_prior(fx, cov, used.sum(axis=1), flat) is None
    # too few fixes decide nothing
    toa, _ = _pings(SHALLOW, 2.0, count=MIN_FIXES - 1)
    fx, _, cov, used, _ = tt.fix_pings(toa, SHALLOW, C, SIGMA)
    assert depth_prior(fx, cov, used.sum(axis=1), SHALLOW) is None


def test_at_least_raises_only_the_depth_variance():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(5, 3, 3))
    P = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(3)
    P[0, 2, 2] = 9.0  # already above the prior's 2² there
    term = at_least(P, 2.0)
    raised = P + term
    assert np.allclose(np.delete(raised.reshape(5, 9), 8, axis=1), np.delete(P.reshape(5, 9), 8, axis=1))
    assert np.allclose(raised[:, 2, 2], np.maximum(P[:, 2, 2], 4.0))
    # a positive semi-definite addition: no eigenvalue falls
    assert (np.linalg.eigvalsh(raised) >= np.linalg.eigvalsh(P) - 1e-12).all()

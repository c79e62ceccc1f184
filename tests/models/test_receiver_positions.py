"""The receivers' positions from a moving tag's pings (models/tracking/receiver_positions.py): an array whose shape is
off by 1-5 m comes back to within centimetres and its fixes to within 1.1 x those of the true array; an array right
is left right and the held-out pings say the refinement does not help; a translation and a rotation of the whole
array (no time of arrival changes) stay the survey's; the reduced system's covariance against a dense least squares
of the same problem built here by finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.fix import fix_pings
from sblsim.models.tracking.receiver_positions import held_out, refine_receivers

C, SIGMA, SURVEY = 1480.0, 2e-4, 3.0


def _rotation(angle: float) -> np.ndarray:
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def _shape_errors(rng: np.random.Generator, at: np.ndarray, low: float = 1.0, high: float = 5.0) -> np.ndarray:
    """Each receiver at ``at`` off by ``low``-``high`` m in a random direction, less the errors' translation and
    rotation of the whole array (what no time of arrival sees: the survey's datum)."""
    direction = rng.normal(size=at.shape)
    errors = rng.uniform(low, high, len(at))[:, None] * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    return _without_gauge(errors, at)


def _without_gauge(errors: np.ndarray, at: np.ndarray) -> np.ndarray:
    """``errors`` less their best translation and rotation about ``at``'s centroid (a least-squares fit)."""
    centred = at - at.mean(axis=0)
    H = np.zeros((2 * len(at), 3))
    H[0::2, 0] = H[1::2, 1] = 1.0
    H[0::2, 2], H[1::2, 2] = -centred[:, 1], centred[:, 0]
    v = errors.ravel()
    return (v - H @ np.linalg.lstsq(H, v, rcond=None)[0]).reshape(-1, 2)


def _towed(rng: np.random.Generator, receivers: np.ndarray, pings: int = 1200, late: float = 0.02):
    """A tag towed on a Lissajous path over the array, heard by each receiver with probability 0.6, with late
    (multipath) arrivals: times of arrival (P, R) [s] and the true places (P, 2) [m]."""
    t = np.cumsum(rng.uniform(20.0, 40.0, pings))
    centre, half = receivers.mean(axis=0), 0.4 * np.ptp(receivers, axis=0)
    path = np.c_[centre[0] + half[0] * np.sin(t / 3000.0), centre[1] + half[1] * np.cos(t / 4100.0)]
    ranges = np.linalg.norm(path[:, None] - receivers[None], axis=2)
    toa = t[:, None] + ranges / C + SIGMA * rng.normal(size=ranges.shape)
    toa[rng.random(toa.shape) > 0.6] = np.nan
    echoes = rng.random(toa.shape) < late
    toa[echoes] += rng.uniform(0.002, 0.02, echoes.sum())
    return toa, path


def _fix_error(toa, receivers, path):
    """The single-ping fixes' median 2-D error [m] over the pings heard by four receivers or more (a few fix in their
    mirror place whatever the array: an RMS would be theirs)."""
    p = fix_pings(toa, receivers, C, SIGMA)[0]
    rows = (np.isfinite(toa).sum(axis=1) >= 4) & np.isfinite(p).all(axis=1)
    return float(np.median(np.linalg.norm(p[rows] - path[rows], axis=1)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_an_array_whose_shape_is_off_comes_back(seed):
    """Ten receivers over 400 m each off by 1-5 m (its shape: the survey's datum right): the refined shape within
    0.1 m RMS, every receiver determined, the fixes' median error within 1.1 x the true array's (and far below the
    table's),
    and the held-out pings say it helps."""
    rng = np.random.default_rng(seed)
    true = rng.uniform(0.0, 400.0, (10, 2))
    table = true + _shape_errors(rng, true)
    toa, path = _towed(rng, true)
    starts = fix_pings(toa, table, C, SIGMA)[0]
    refined = refine_receivers(toa, table, starts, C, SIGMA, SURVEY)
    assert refined.converged and refined.determined.all(), refined
    moved = table + refined.shift
    shape = np.sqrt(np.mean(np.sum(_without_gauge(moved - true, true) ** 2, axis=1)))
    assert shape < 0.1, shape
    at_true, at_table, at_refined = (_fix_error(toa, a, path) for a in (true, table, moved))
    assert at_refined <= 1.1 * at_true and at_table > 2 * at_true, (at_true, at_table, at_refined)
    check = held_out(toa, table, starts, C, SIGMA, SURVEY)
    assert check.helps and check.refined < 0.2 * check.surveyed, check


def test_an_array_right_is_left_right():
    """The true positions as the table: every shift within its posterior σ's reach (and 10 cm), the fixes no worse,
    the held-out pings fit no better than by chance (the refinement would not be taken)."""
    rng = np.random.default_rng(7)
    true = rng.uniform(0.0, 400.0, (10, 2))
    toa, path = _towed(rng, true)
    starts = fix_pings(toa, true, C, SIGMA)[0]
    refined = refine_receivers(toa, true, starts, C, SIGMA, SURVEY)
    # each shift what the arrivals' noise makes of a right position: within its own posterior (χ²(2) at 0.999)
    blocks = [refined.covariance[2 * i:2 * i + 2, 2 * i:2 * i + 2] for i in range(len(true))]
    nees = [float(d @ np.linalg.solve(b, d)) for d, b in zip(refined.fitted, blocks, strict=True)]
    assert max(nees) < 13.8 and np.abs(refined.shift).max() < 0.1, (nees, refined.shift)
    assert _fix_error(toa, true + refined.shift, path) <= 1.02 * _fix_error(toa, true, path)
    check = held_out(toa, true, starts, C, SIGMA, SURVEY)
    assert not check.helps, check


def test_a_translation_and_a_rotation_of_the_whole_array_stay_the_surveys():
    """The table the true array moved 3 m and turned 1 degree (with its track: no time of arrival changes): the
    shifts undo neither (their mean translation and rotation are the prior's, 0), the shape stays right."""
    rng = np.random.default_rng(3)
    true = rng.uniform(0.0, 400.0, (8, 2))
    centre = true.mean(axis=0)
    table = (true - centre) @ _rotation(np.radians(1.0)).T + centre + np.array([3.0, -2.0])
    toa, _ = _towed(rng, true)
    refined = refine_receivers(toa, table, fix_pings(toa, table, C, SIGMA)[0], C, SIGMA, SURVEY)
    assert np.abs(refined.fitted).max() < 0.1, refined.fitted


def _dense(toa, receivers, places, emissions, shifts, c, sigma, survey):
    """The whole problem's normal matrix by central finite differences of the model (pings' x, y, t, then the
    shifts), unit weights over σ²; the shifts' covariance its inverse's block."""
    heard = np.argwhere(np.isfinite(toa))
    p, n = len(toa), len(receivers)

    def model(theta):
        xy = theta[:2 * p].reshape(p, 2)
        t = theta[2 * p:3 * p]
        d = theta[3 * p:].reshape(n, 2)
        return np.array([t[j] + np.linalg.norm(xy[j] - receivers[i] - d[i]) / c for j, i in heard])

    theta = np.concatenate([places.ravel(), emissions, shifts.ravel()])
    J = np.empty((len(heard), len(theta)))
    for k in range(len(theta)):
        step = np.zeros_like(theta)
        step[k] = 1e-4 if k < 2 * p or k >= 3 * p else 1e-7
        J[:, k] = (model(theta + step) - model(theta - step)) / (2 * step[k])
    normal = J.T @ J / sigma**2
    normal[3 * p:, 3 * p:] += np.eye(2 * n) / survey**2
    return np.linalg.inv(normal)[3 * p:, 3 * p:]


def test_the_shifts_covariance_is_the_whole_problems():
    """Without noise or echoes every residual is 0, where an arrival's Student-t observed information is (ν + 1) / ν
    times the Gaussian's: the reduced system's covariance equals the inverse's block of the dense problem built by
    finite differences with σ / √((ν + 1) / ν), and not the one with σ."""
    rng = np.random.default_rng(5)
    receivers = rng.uniform(0.0, 300.0, (5, 2))
    t = np.arange(30) * 30.0
    path = np.c_[150 + 100 * np.sin(t / 200), 150 + 100 * np.cos(t / 300)]
    toa = t[:, None] + np.linalg.norm(path[:, None] - receivers[None], axis=2) / C
    toa[rng.random(toa.shape) < 0.1] = np.nan
    toa[np.isfinite(toa).sum(axis=1) < 4] = np.nan
    refined = refine_receivers(toa, receivers, path, C, SIGMA, SURVEY)
    assert np.abs(refined.fitted).max() < 1e-6
    rows = np.isfinite(toa).sum(axis=1) >= 4
    dense = _dense(toa[rows], receivers, path[rows], t[rows], refined.fitted, C, SIGMA, SURVEY)
    dof = 3.0
    scaled = _dense(toa[rows], receivers, path[rows], t[rows], refined.fitted, C, SIGMA / np.sqrt((dof + 1) / dof),
                    SURVEY)
    assert np.allclose(refined.covariance, scaled, rtol=1e-5, atol=1e-12), (refined.covariance[:2, :2], scaled[:2, :2])
    assert not np.allclose(refined.covariance, dense, rtol=1e-3)


def test_bad_shapes_and_too_few_arrivals_are_refused():
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    toa = np.full((5, 4), 1.0)
    toa[:, 3] = np.nan  # three arrivals a ping: nothing to fit
    with pytest.raises(ModelError, match="four receivers"):
        refine_receivers(toa, receivers, np.zeros((5, 2)), C, SIGMA, SURVEY)
    with pytest.raises(ModelError, match="places"):
        refine_receivers(np.ones((5, 4)), receivers, np.zeros((4, 2)), C, SIGMA, SURVEY)
    with pytest.raises(ModelError, match="survey sigma"):
        refine_receivers(np.ones((5, 4)), receivers, np.zeros((5, 2)), C, SIGMA, 0.0)

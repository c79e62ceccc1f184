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
from sblsim.models.tracking.held_out import held_out
from sblsim.models.tracking.receiver_positions import refine_receivers
from tests.helpers import gauge_free, shape_rms

C, SIGMA, SURVEY = 1480.0, 2e-4, 3.0


def _rotation(angle: float) -> np.ndarray:
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def _shape_errors(rng: np.random.Generator, at: np.ndarray, low: float = 1.0, high: float = 5.0) -> np.ndarray:
    """Each receiver at ``at`` off by ``low``-``high`` m in a random direction, less the errors' translation and
    rotation of the whole array (what no time of arrival sees: the survey's datum)."""
    direction = rng.normal(size=at.shape)
    errors = rng.uniform(low, high, len(at))[:, None] * direction / np.linalg.norm(direction, axis=1, keepdims=True)
    return gauge_free(errors, at)


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


@pytest.mark.parametrize("seed", [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)])
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
    shape = shape_rms(moved - true, true)
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


def _with_sync_tags(rng: np.random.Generator, true: np.ndarray, clock: np.ndarray, per_tag: int = 40):
    """Each receiver's sync tag (at the receiver) emitting ``per_tag`` times, heard by each other receiver with
    probability 0.7, on clocks ``clock`` [s] off: times of arrival (Q, R) [s] and each emission's receiver (Q,)."""
    source = np.repeat(np.arange(len(true)), per_tag)
    emitted = rng.uniform(0.0, 1e4, len(source))
    ranges = np.linalg.norm(true[source][:, None] - true[None], axis=2)
    toa = emitted[:, None] + ranges / C + SIGMA * rng.normal(size=ranges.shape) + clock[None]
    toa[rng.random(toa.shape) > 0.7] = np.nan
    return toa, source


def test_clock_offsets_are_told_from_positions_by_the_sync_tags():
    """Every clock off by a constant (2 ms σ: a synchronisation made on the wrong positions) and the shape off by
    1-5 m: shifts alone are thrown far off; with each receiver's clock offset fitted and the sync tags' emissions
    (both directions of each pair) the shape comes back within 0.25 m and each offset within 4 σ of its truth."""
    rng = np.random.default_rng(0)
    true = rng.uniform(0.0, 400.0, (9, 2))
    table = true + _shape_errors(rng, true)
    toa, _ = _towed(rng, true, pings=400)
    clock = rng.normal(0.0, 0.002, 9)
    toa = toa + clock[None]
    anchored = _with_sync_tags(rng, true, clock)
    starts = fix_pings(toa, table, C, SIGMA)[0]

    def shape(fit):
        return shape_rms(table + fit.fitted - true, true)

    alone = refine_receivers(toa, table, starts, C, SIGMA, SURVEY)
    joint = refine_receivers(toa, table, starts, C, SIGMA, SURVEY, biases=True, anchored=anchored)
    assert shape(alone) > 1.0 and shape(joint) < 0.25, (shape(alone), shape(joint))
    # the offsets less their mean (a common offset is every emission time's: the gauge), in metres
    offset = (clock - clock.mean()) * C
    fitted = joint.bias[:, 0] - joint.bias[:, 0].mean()
    sigma = joint.bias_sigma[:, 0]
    assert joint.bias.shape == (9, 1) and np.all(np.abs(fitted - offset) < 4 * sigma + 0.05), (fitted, offset, sigma)
    assert joint.anchored == len(anchored[0])


def test_a_sound_speed_calibrated_on_a_wrong_array_is_fitted_with_it():
    """The pings at 1480 m/s given as 1472 m/s (a calibration on wrong positions): with the sound speed's scale free
    the shape comes back (within 0.1 m, the scale a gauge: the survey's) and the speed to within 3 σ of the truth
    times the survey's scale; held at 1472 m/s the array is shrunk to fit it (0.3 m more off than free)."""
    rng = np.random.default_rng(2)
    true = rng.uniform(0.0, 400.0, (10, 2))
    table = true + _shape_errors(rng, true)
    toa, _ = _towed(rng, true)
    wrong = 1472.0
    starts = fix_pings(toa, table, wrong, SIGMA)[0]
    held = refine_receivers(toa, table, starts, wrong, SIGMA, SURVEY)
    free = refine_receivers(toa, table, starts, wrong, SIGMA, SURVEY, speed_sigma=0.01)

    def shape(fit, scale: bool):
        return shape_rms(table + fit.fitted - true, true, scale)

    # held, the wrong speed is a wrong scale the shifts take up against the survey; free, the survey's scale stays
    assert shape(free, True) < 0.1 and shape(held, False) > shape(free, False) + 0.3, (
        shape(free, True), shape(free, False), shape(held, False))
    # the array's scale is the survey's: the speed is the truth's over that scale (the table's size over the truth's)
    size = np.linalg.norm(table + free.fitted - (table + free.fitted).mean(axis=0), axis=1).sum() \
        / np.linalg.norm(true - true.mean(axis=0), axis=1).sum()
    assert abs(wrong * free.speed_scale - 1480.0 * size) < 3 * wrong * free.speed_scale_sigma + 0.5, (
        wrong * free.speed_scale, 1480.0 * size)


def test_the_arrays_scale_is_in_the_gauge_only_where_asked():
    """A posterior that knows everything but the array's dilation (its variance the survey's): each receiver's ratio
    in the shape is near 0 with the scale in the gauge and near 1 (away from the centroid) without it."""
    from sblsim.models.sync.identifiability import shape_sigma_ratio

    rng = np.random.default_rng(9)
    xy = rng.uniform(0.0, 300.0, (6, 2))
    centred = (xy - xy.mean(axis=0)).ravel()
    dilation = centred / np.linalg.norm(centred)
    covariance = 1e-6 * np.eye(12) + SURVEY**2 * np.outer(dilation, dilation) * len(xy)
    with_scale = shape_sigma_ratio(xy, covariance, SURVEY, np.ones(6, bool), scale=True)
    without = shape_sigma_ratio(xy, covariance, SURVEY, np.ones(6, bool))
    assert with_scale.max() < 0.01 and without.max() > 0.5, (with_scale, without)


def test_clock_errors_changing_from_bin_to_bin_are_fitted_at_the_edges():
    """Three sync tags among nine receivers and each clock off by an error that changes from one bin to the next
    (linear between knots 2000 s apart, 1.5 ms σ at each: a synchronisation made on wrong positions with few sync
    tags leaves it): one constant offset per receiver leaves the shape far off; offsets at the bins' edges bring it
    back within 0.25 m, each knot within 4 σ of its truth (less the common offset at each edge: every emission
    time's, the gauge)."""
    rng = np.random.default_rng(3)
    true = rng.uniform(0.0, 400.0, (9, 2))
    table = true + _shape_errors(rng, true)
    toa, _ = _towed(rng, true, pings=320)  # 10,000 s as the sync tags'
    edges = np.arange(0.0, 10001.0, 2000.0)
    clock = rng.normal(0.0, 1.5e-3, (9, len(edges)))
    times = np.nanmin(np.where(np.isfinite(toa), toa, np.inf), axis=1)  # inf: a ping nobody heard
    toa = toa + np.stack([np.interp(times, edges, knots) for knots in clock], axis=1)
    sync, source = _with_sync_tags(rng, true, np.zeros(9), per_tag=300)
    sync, source = sync[source < 3], source[source < 3]
    emitted = np.nanmin(sync, axis=1)
    sync = sync + np.stack([np.interp(emitted, edges, knots) for knots in clock], axis=1)
    starts = fix_pings(toa, table, C, SIGMA)[0]

    def shape(fit):
        return shape_rms(table + fit.fitted - true, true)

    constant = refine_receivers(toa, table, starts, C, SIGMA, SURVEY, biases=True, anchored=(sync, source))
    knots = refine_receivers(toa, table, starts, C, SIGMA, SURVEY, biases=True, anchored=(sync, source, emitted),
                             times=times, edges=edges)
    assert shape(constant) > 0.5 and shape(knots) < 0.25, (shape(constant), shape(knots))
    assert knots.bias.shape == (9, len(edges)) and np.array_equal(knots.edges, edges)
    offset = (clock - clock.mean(axis=0)) * C
    fitted = knots.bias - knots.bias.mean(axis=0)
    assert np.all(np.abs(fitted - offset) < 4 * knots.bias_sigma + 0.05), np.abs(fitted - offset) / knots.bias_sigma
    at = knots.bias_at(np.array([1000.0, 5000.0]), 2)
    assert np.allclose(at, 0.5 * (knots.bias[:, [0, 2]] + knots.bias[:, [1, 3]]).T)


def test_each_receivers_timing_noise_is_its_own_residuals_with_rescale():
    """Every receiver given 1 ms of timing noise where it has 0.2 ms (a synchronisation's on wrong positions): with
    ``rescale`` each one's is found within 20 % of the simulation's (0.81-1.03 of it here: the median's spread over
    some 360 arrivals, and what the shifts take), one heard too rarely keeps the given, and the shifts' σ in the
    array's shape shrink with it; without, the given is kept."""
    rng = np.random.default_rng(6)
    true = rng.uniform(0.0, 400.0, (9, 2))
    table = true + _shape_errors(rng, true)
    toa, path = _towed(rng, true, pings=600, late=0.0)
    toa[20:, 8] = np.nan  # the last receiver heard by 20 pings at most: fewer than MIN_RESCALE arrivals fitted
    starts = fix_pings(toa, table, C, SIGMA)[0]
    given = np.full(9, 1e-3)
    plain = refine_receivers(toa, table, starts, C, given, SURVEY)
    rescaled = refine_receivers(toa, table, starts, C, given, SURVEY, rescale=True)
    assert np.array_equal(plain.sigma, given) and rescaled.sigma[8] == given[8]
    assert np.all(np.abs(rescaled.sigma[:8] / SIGMA - 1.0) < 0.2), rescaled.sigma / SIGMA
    # in the array's shape (its worst direction: the path's geometry's more than the noise's)
    assert np.all(rescaled.sigma_ratio[:8] < plain.sigma_ratio[:8]), (rescaled.sigma_ratio, plain.sigma_ratio)


def test_clocks_off_by_tens_of_milliseconds_are_fitted_with_their_own_prior():
    """Clocks taken as logged (no sync tag), each off by up to ±30 ms (45 m of range) and drifting, the positions
    right: each receiver's range bias fitted with a broad prior of its own (``bias_sigma``: 1 s of range), one
    receiver's tiny (the time base), the shifts held at 1 cm. Each clock's offset at both knots comes back within
    4 σ of its truth less the time base's (the simulated clocks), a few tenths of a millisecond; with the survey's
    σ as the biases' prior (the default) the biases cannot reach it."""
    rng = np.random.default_rng(11)
    receivers = rng.uniform(0.0, 400.0, (8, 2))
    toa, path = _towed(rng, receivers, pings=400, late=0.0)
    times = np.nanmin(np.where(np.isfinite(toa), toa, np.inf), axis=1)
    edges = np.array([0.0, times[np.isfinite(times)].max() + 1.0])
    clock = np.c_[rng.uniform(-0.03, 0.03, 8), np.zeros(8)]
    clock[:, 1] = clock[:, 0] + rng.uniform(-5e-6, 5e-6, 8) * edges[1]  # a drift of up to 5 ppm
    toa = toa + np.stack([np.interp(times, edges, knots) for knots in clock], axis=1)
    starts = fix_pings(toa, receivers, C, SIGMA)[0]
    prior = np.full(8, 1.0 * C)
    prior[0] = 1e-7 * C
    fit = refine_receivers(toa, receivers, starts, C, SIGMA, 0.01, biases=True, bias_sigma=prior,
                           times=times, edges=edges)
    truth = (clock - clock[0]) * C  # [m] of range, against receiver 0's clock
    assert np.all(np.abs(fit.bias - truth) < 4 * fit.bias_sigma + 1e-3), \
        np.abs(fit.bias - truth) / fit.bias_sigma
    assert np.abs(fit.bias - truth).max() < 0.5 * C * 1e-3  # within half a millisecond
    assert np.abs(fit.fitted).max() < 0.05  # the positions held
    survey = refine_receivers(toa, receivers, starts, C, SIGMA, 0.01, biases=True, times=times, edges=edges)
    assert np.abs(survey.bias - survey.bias[0] - truth).max() > 10.0
    with pytest.raises(ModelError, match="range biases' prior sigma"):
        refine_receivers(toa, receivers, starts, C, SIGMA, 0.01, biases=True, bias_sigma=np.zeros(8))
    with pytest.raises(ModelError, match="range biases' prior sigma"):
        refine_receivers(toa, receivers, starts, C, SIGMA, 0.01, biases=True, bias_sigma=np.ones(3))


def test_each_knot_may_take_its_own_time_base():
    """The clocks of the test above at three knots, receiver 0 the time base at the first two and receiver 5 at the
    last (``bias_sigma`` per receiver and knot: a redeployed array's, no deployment spanning the season): each
    knot's offsets come back within 4 σ of the simulated clocks' less that knot's base's; a prior of another shape is
    refused in one line."""
    rng = np.random.default_rng(11)
    receivers = rng.uniform(0.0, 400.0, (8, 2))
    toa, _ = _towed(rng, receivers, pings=400, late=0.0)
    times = np.nanmin(np.where(np.isfinite(toa), toa, np.inf), axis=1)
    last = times[np.isfinite(times)].max() + 1.0
    edges = np.array([0.0, 0.5 * last, last])
    clock = rng.uniform(-0.03, 0.03, 8)[:, None] + rng.uniform(-5e-6, 5e-6, 8)[:, None] * edges[None]
    toa = toa + np.stack([np.interp(times, edges, knots) for knots in clock], axis=1)
    starts = fix_pings(toa, receivers, C, SIGMA)[0]
    bases = np.array([0, 0, 5])
    prior = np.full((8, 3), 1.0 * C)
    prior[bases, np.arange(3)] = 1e-7 * C
    fit = refine_receivers(toa, receivers, starts, C, SIGMA, 0.01, biases=True, bias_sigma=prior,
                           times=times, edges=edges)
    truth = (clock - clock[bases, np.arange(3)]) * C
    assert np.all(np.abs(fit.bias - truth) < 4 * fit.bias_sigma + 1e-3), np.abs(fit.bias - truth) / fit.bias_sigma
    assert fit.bias_sigma[0, 2] > 10 * fit.bias_sigma[5, 2] and fit.bias_sigma[5, 0] > 10 * fit.bias_sigma[0, 0]
    with pytest.raises(ModelError, match=r"allowed: positive numbers \[m\], one, 8 or \(8, 3\)"):
        refine_receivers(toa, receivers, starts, C, SIGMA, 0.01, biases=True, bias_sigma=np.ones((8, 2)),
                         times=times, edges=edges)

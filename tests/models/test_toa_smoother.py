"""The robust fixed-interval smoother of an inverted LBL (a pinger's track from its times of arrival at a fixed array,
the emission times unknown): its answer is the minimum of its stated cost, found here by scipy's own least squares
on that cost written again with numpy (no casadi, no Gauss-Newton of ours); its covariance is the inverse of that
cost's information, inverted densely; on simulated pings with late (multipath) arrivals it is consistent over 20
seeds and beats the RTS smoother it starts from."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import least_squares

from sblsim.models.errors import ModelError
from sblsim.models.receiver import toa_tracking as tt

DATA = Path(__file__).resolve().parents[2] / "data" / "lake-hald"


def lake_hald_receivers() -> np.ndarray:
    receivers = np.genfromtxt(DATA / "hydrophones.csv", delimiter=",", skip_header=1, usecols=(1, 2))
    return receivers[np.isfinite(receivers).all(axis=1)]


def late_arrivals(toa: np.ndarray, rng: np.random.Generator, share: float) -> np.ndarray:
    """A share of the arrivals made 1 to 3 ms late (a reflected path)."""
    late = np.isfinite(toa) & (rng.random(toa.shape) < share)
    return np.where(late, toa + rng.uniform(1e-3, 3e-3, toa.shape), toa)


def cost_residuals(theta: np.ndarray, toa: np.ndarray, receivers: np.ndarray, s: tt.TrackerSettings, dof: float,
                   schedule=None):
    """The smoother's cost as a vector r with Σ r² the cost, written from its docstring with numpy alone: per heard
    arrival ``sign(z) sqrt((ν + 1) ln(1 + z² / ν))`` (z / ... as ν → ∞), per ping after the first the process noise's
    whitened innovation (Q over the step's duration at the nominal interval, as the EKF's model: one interval per
    row, or a schedule's ``n_k Δ + o_k``), and the first interval's prior."""
    m, n = toa.shape
    X = theta.reshape(m, 6)
    p, v, te, interval = X[:, :2], X[:, 2:4], X[:, 4], X[:, 5]
    k, i = np.nonzero(np.isfinite(toa))
    z = (toa[k, i] - te[k] - np.sqrt(((p[k] - receivers[i]) ** 2).sum(axis=1)) / s.sound_speed) / s.sigma_toa
    arrival = z if dof == np.inf else np.sign(z) * np.sqrt((dof + 1) * np.log1p(z**2 / dof))
    if schedule is None:
        count, offset = np.ones(m - 1), np.zeros(m - 1)
        te_sigma, drift = np.full(m - 1, s.jitter), np.full(m - 1, s.interval_drift)
    else:
        count, offset, te_sigma, drift = schedule.count, schedule.offset, schedule.te_sigma, schedule.drift_sigma
    q = s.acceleration_psd
    process = []
    for j in range(m - 1):
        T = count[j] * s.interval + offset[j]
        Q = np.zeros((6, 6))
        for a in range(2):
            Q[np.ix_([a, 2 + a], [a, 2 + a])] = q * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
        Q[4, 4], Q[5, 5] = te_sigma[j] ** 2, drift[j] ** 2
        W = np.linalg.inv(np.linalg.cholesky(Q))  # Q = L Lᵀ: the innovation whitened by L⁻¹
        step = count[j] * interval[j] + offset[j]
        predicted = np.r_[p[j] + step * v[j], v[j], te[j] + step, interval[j]]
        process.append(W @ (X[j + 1] - predicted))
    prior = [(interval[0] - s.interval) / s.sigma_interval]
    return np.concatenate([arrival, np.ravel(process), prior])


def small_problem(seed: int = 2, pings: int = 30, late: float = 0.1):
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=2.0, jitter=1e-3, acceleration_psd=1e-4)
    receivers = lake_hald_receivers()
    rng = np.random.default_rng(seed)
    toa, truth, emissions = tt.simulate_pings(receivers, pings, s, rng, speed=0.3, detection=0.25)
    return late_arrivals(toa, rng, late), receivers, s, truth, emissions


def start_of(toa, receivers, s):
    tracker = tt.ToaTracker(receivers, s)
    record = tracker.run(toa)
    xs, _ = tracker.smooth(record)
    return record.start, xs


@pytest.mark.slow
@pytest.mark.parametrize("dof", [tt.ROBUST_DOF, np.inf], ids=["student-t", "gaussian"])
def test_the_smoother_is_the_minimum_of_its_cost(dof):
    """scipy's trust-region least squares (finite-difference Jacobian) on the cost written again with numpy, started
    from the smoother's answer moved 0.5 m and 0.1 ms, lands on it: positions within 1 mm, emission times within
    1 µs, the same cost to 1e-6; with ν → ∞ (a Gaussian error) the same. 10 % of the arrivals are 1 to 3 ms late."""
    toa, receivers, s, truth, _ = small_problem()
    k0, xs = start_of(toa, receivers, s)
    toa = toa[k0:]
    robust = tt.robust_smooth(toa, receivers, s, [xs[k0:]], dof=1e12 if dof == np.inf else dof)
    moved = robust.x.copy()
    moved[:, :2] += 0.5
    moved[:, 4] += 1e-4
    reference = least_squares(cost_residuals, moved.ravel(), args=(toa, receivers, s, dof), method="trf",
                              x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
    X = reference.x.reshape(robust.x.shape)
    assert np.abs(X[:, :2] - robust.x[:, :2]).max() < 1e-3
    assert np.abs(X[:, 4] - robust.x[:, 4]).max() < 1e-6
    ours = float((cost_residuals(robust.x.ravel(), toa, receivers, s, dof) ** 2).sum())
    assert abs(ours - 2 * reference.cost) <= 1e-6 * ours
    assert abs(ours - robust.cost) <= 1e-9 * ours  # the cost it reports is the cost it states


def late_cost(theta, toa, receivers, s):
    """The smoother's cost with late arrivals modelled (``delay_share``, ``delay_mean``, ``delay_dof``): per heard
    arrival the mixture's ``−2 ln p(z)`` of scipy's Student-t and exponentially modified Gaussian densities, plus
    the squares of the process and prior residuals of :func:`cost_residuals`."""
    from scipy import stats

    m = len(toa)
    X = theta.reshape(m, 6)
    k, i = np.nonzero(np.isfinite(toa))
    z = (toa[k, i] - X[k, 4] - np.sqrt(((X[k, :2] - receivers[i]) ** 2).sum(axis=1)) / s.sound_speed) / s.sigma_toa
    lam = s.delay_mean / s.sigma_toa
    p = (1 - s.delay_share) * stats.t.pdf(z, s.delay_dof) + s.delay_share * stats.exponnorm.pdf(z, lam)
    rest = cost_residuals(theta, toa, receivers, s, np.inf)[len(z):]
    return float(-2.0 * np.log(p).sum() + (rest**2).sum())


@pytest.mark.slow
def test_with_late_arrivals_modelled_the_smoother_is_a_minimum_of_its_cost():
    """The one-sided delay term (``delay_share`` 0.1, ``delay_mean`` 2 ms, 10 % of the arrivals 1 to 3 ms late):
    the smoother's answer is a minimum of the mixture's cost written again with scipy's Student-t and exponentially
    modified Gaussian densities (:func:`late_cost`): moving any one state, or all of them along a random
    direction, by 1 cm (1 cm/s, 10 µs) either way raises that cost, and the cost the smoother reports is that cost
    up to its constant."""
    from dataclasses import replace

    from scipy import stats

    toa, receivers, s, _, _ = small_problem(pings=20)
    k0, xs = start_of(toa, receivers, s)
    toa = toa[k0:]
    s = replace(s, delay_share=0.1, delay_mean=2e-3)
    robust = tt.robust_smooth(toa, receivers, s, [xs[k0:]])

    def cost(theta):
        return late_cost(theta, toa, receivers, s)

    x = robust.x.ravel()
    at = cost(x)
    step = np.tile([1e-2, 1e-2, 1e-2, 1e-2, 1e-5, 1e-5], len(toa))
    rng = np.random.default_rng(0)
    directions = [np.eye(len(x))[j] * step[j] for j in range(len(x))]
    directions += [rng.choice([-1.0, 1.0], len(x)) * step for _ in range(20)]
    for d in directions:
        assert min(cost(x + d), cost(x - d)) > at - 1e-9 * abs(at)
    h = int(np.isfinite(toa).sum())
    # the reported cost's terms are −2 ln p + 2 ln((1 − π) t_ν(0)) (ArrivalModel.terms)
    constant = 2 * h * np.log((1 - s.delay_share) * stats.t.pdf(0.0, s.delay_dof))
    assert abs(at + constant - robust.cost) <= 1e-9 * abs(at)


def test_the_covariance_is_the_inverse_of_the_information():
    """Gaussian errors (ν → ∞): the smoother's covariance per ping is the diagonal block of (JᵀJ)⁻¹, J the
    Jacobian of the cost's residuals at its answer by scipy's finite differences, inverted densely here."""
    from scipy.optimize._numdiff import approx_derivative

    toa, receivers, s, _, _ = small_problem(seed=3, late=0.0)
    k0, xs = start_of(toa, receivers, s)
    toa = toa[k0:]
    robust = tt.robust_smooth(toa, receivers, s, [xs[k0:]], dof=1e12)
    J = approx_derivative(cost_residuals, robust.x.ravel(), method="cs", args=(toa, receivers, s, np.inf))
    cov = np.linalg.inv(J.T @ J)
    for k in range(len(toa)):
        block = cov[6 * k:6 * k + 6, 6 * k:6 * k + 6]
        assert np.allclose(robust.P[k], block, rtol=1e-6, atol=1e-12 * np.abs(block).max())


@pytest.mark.slow
def test_consistent_on_simulated_pings_with_late_arrivals_and_better_than_rts():
    """20 seeds of simulated pings (Lake Hald's array, a quarter of the arrivals heard, 5 % of them 1 to 3 ms late):
    the robust smoother's 2-D NEES against the exact truth within 20 % of 2 (consistent: its covariance from the
    arrivals' observed information; from their Gauss-Newton weights it was 2.48) and its RMS error below the RTS
    smoother's on the same pings."""
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=2.0, jitter=1e-3, acceleration_psd=1e-4)
    receivers = lake_hald_receivers()
    nees, robust_sq, rts_sq = [], [], []
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        toa, truth, _ = tt.simulate_pings(receivers, 80, s, rng, speed=0.3, detection=0.25)
        toa = late_arrivals(toa, rng, 0.05)
        k0, xs = start_of(toa, receivers, s)
        robust = tt.robust_smooth(toa[k0:], receivers, s, [xs[k0:]])
        e = robust.x[:, :2] - truth[k0:]
        nees.append(np.mean(np.einsum("ki,kij,kj->k", e, np.linalg.inv(robust.P[:, :2, :2]), e)))
        robust_sq.append(np.mean((e**2).sum(axis=1)))
        rts_sq.append(np.mean(((xs[k0:, :2] - truth[k0:]) ** 2).sum(axis=1)))
    assert 1.6 <= np.mean(nees) <= 2.4, np.mean(nees)
    assert np.sqrt(np.mean(robust_sq)) < np.sqrt(np.mean(rts_sq)), (np.mean(robust_sq), np.mean(rts_sq))


def test_observed_information_is_the_student_t_log_density_s_curvature():
    """Each arrival's information is minus the second derivative of scipy's Student-t log-density (central
    differences), where that is positive, and 0 beyond √ν."""
    from scipy.stats import t as student

    dof, h = tt.ROBUST_DOF, 1e-4
    z = np.linspace(-6.0, 6.0, 241)
    curvature = -(student.logpdf(z + h, dof) - 2 * student.logpdf(z, dof) + student.logpdf(z - h, dof)) / h**2
    np.testing.assert_allclose(tt.observed_information(z, dof), np.maximum(curvature, 0.0), rtol=1e-6, atol=1e-6)
    assert np.all(tt.observed_information(z[np.abs(z) > np.sqrt(dof) + 1e-9], dof) == 0.0)


def test_the_lowest_cost_start_is_kept_and_bad_starts_refused():
    """Two starts, one of them 30 m off: the answer is the other's (the lower cost), whichever order; a start of
    the wrong shape or not finite, or none, is refused."""
    toa, receivers, s, truth, _ = small_problem(seed=4, late=0.0)
    k0, xs = start_of(toa, receivers, s)
    toa, good = toa[k0:], xs[k0:]
    far = good.copy()
    far[:, :2] += 30.0
    a = tt.robust_smooth(toa, receivers, s, [far, good])
    b = tt.robust_smooth(toa, receivers, s, [good, far])
    assert (a.start, b.start) == (1, 0) and np.array_equal(a.x, b.x) and a.cost == b.cost
    assert np.median(np.hypot(*(a.x[:, :2] - truth[k0:]).T)) < 0.5
    for starts in ([], [good[:-1]], [np.where(good == good[3, 0], np.nan, good)]):
        with pytest.raises(ModelError, match="robust smoother"):
            tt.robust_smooth(toa, receivers, s, starts)


def test_the_anchored_start_follows_the_agreeing_fixes():
    """The start made of the single-ping fixes that kept every arrival: a fix moved 200 m (a gross fix) is left out
    by its neighbours, and the start passes within 1 m of the truth at the fixes it keeps."""
    toa, receivers, s, truth, emissions = small_problem(seed=5, pings=60, late=0.0)
    fx, fe, _, fused, _ = tt.fix_pings(toa, receivers, s.sound_speed, s.sigma_toa)
    heard = np.isfinite(toa).sum(axis=1)
    good = np.flatnonzero(np.isfinite(fe) & (fused.sum(axis=1) >= 4) & (fused.sum(axis=1) == heard))
    assert len(good) > 10
    gross = good[len(good) // 2]
    fx = fx.copy()
    fx[gross] += 200.0
    X = tt.anchored_start((fx, fe, fused), heard, s, 2)
    assert X.shape == (60, 6) and np.isfinite(X).all()
    assert np.hypot(*(X[gross, :2] - truth[gross])) < 5.0
    kept = np.setdiff1d(good, [gross])
    assert np.abs(X[kept, :2] - truth[kept]).max() < 1.0 and np.abs(X[kept, 4] - emissions[kept]).max() < 1e-3
    assert tt.anchored_start((fx[:1], fe[:1], fused[:1]), heard[:1], s, 2) is None


def test_a_splice_puts_the_track_on_the_fixes_it_disagrees_with_and_tapers_to_its_neighbours():
    """Six pings of a simulated random-interval tag moved 60 m off the truth: :func:`splice_pings` names exactly the
    moved pings that a fix of dim + 1 arrivals or more explains better; :func:`spliced` puts each on its fix
    (position and emission time), moves the pings beside by the share 1 − |j − k| / (W + 1) of the fix's offset
    (the nearer fix's where two windows meet) and leaves the rest; the smoother from the track and the splice lands
    on the truth's own minimum."""
    from sblsim.models.tracking import schedule as ps
    from sblsim.models.tracking.starts import SPLICE_WINDOW, splice_pings, spliced, with_fixes_spliced

    receivers = lake_hald_receivers()
    s = tt.TrackerSettings(sound_speed=1420.0, sigma_toa=1.5e-4, interval=30.0, acceleration_psd=1e-5)
    toa, truth, emissions = tt.simulate_pings(receivers, 40, s, np.random.default_rng(3), speed=0.3, detection=0.4,
                                              ping_type="rbi", burst_interval=(20.0, 40.0))
    schedule = ps.build_schedule(toa, "rbi", s.interval, s.jitter, s.interval_drift,
                                 ps.crossing_time(receivers, s.sound_speed), (20.0, 40.0))
    fixes = tt.fix_pings(toa, receivers, s.sound_speed, s.sigma_toa)
    fx, fe, fused = fixes[0], fixes[1], fixes[3]
    X = np.zeros((40, 6))
    X[:, :2], X[:, 2:4] = truth, np.gradient(truth, emissions, axis=0)
    X[:, 4], X[:, 5] = emissions, s.interval
    right = tt.robust_smooth(toa, receivers, s, [X], schedule=schedule)
    off = right.x.copy()
    stretch = np.arange(15, 21)
    off[stretch, 0] += 60.0
    # by hand: a fix of 3 arrivals or more, that many of them within 6.1 σ of its ping's median emission time at the
    # fix (more than at the moved track), 5 m or more from the track
    def agree(p):
        e = toa - np.linalg.norm(p[:, None, :] - receivers[None], axis=2) / s.sound_speed
        return (np.abs(e - np.nanmedian(e, axis=1)[:, None]) <= 6.1 * s.sigma_toa).sum(axis=1)
    with np.errstate(invalid="ignore"):
        theirs = np.where(np.isfinite(fe), agree(np.nan_to_num(fx, nan=1e9)), 0)
        expected = np.flatnonzero((theirs >= 3) & (theirs > agree(off[:, :2]))
                                  & (np.hypot(*(off[:, :2] - fx).T) > 5.0))
    pings = splice_pings(off, toa, receivers, s, (fx, fe, fused))
    assert np.array_equal(pings, expected) and set(pings) <= set(stretch) and len(pings) >= 3, (pings, expected)
    start = spliced(off, (fx, fe, fused), pings)
    assert np.array_equal(start[pings, :2], fx[pings]) and np.array_equal(start[pings, 4], fe[pings])
    share, nearest = np.zeros(40), np.full(40, -1)
    for k in pings:
        for j in range(max(k - SPLICE_WINDOW, 0), min(k + SPLICE_WINDOW, 39) + 1):
            if 1 - abs(j - k) / (SPLICE_WINDOW + 1) > share[j]:
                share[j], nearest[j] = 1 - abs(j - k) / (SPLICE_WINDOW + 1), k
    for j in np.flatnonzero(share > 0):
        assert np.allclose(start[j, :2], off[j, :2] + share[j] * (fx[nearest[j]] - off[nearest[j], :2]))
    untouched = share == 0
    assert untouched.any() and np.array_equal(start[untouched], off[untouched])
    track = tt.robust_smooth(toa, receivers, s, [off], iterations=0, schedule=schedule)  # held where it was put
    mended = with_fixes_spliced(track, toa, receivers, s, (fx, fe, fused), schedule)
    assert np.hypot(*(mended.x[:, :2] - right.x[:, :2]).T).max() < 0.01
    assert mended.cost == pytest.approx(right.cost, rel=1e-6) and mended.P is not None
    assert with_fixes_spliced(right, toa, receivers, s, (fx, fe, fused), schedule) is right

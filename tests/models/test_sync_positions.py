"""The sync tags' fixes (:mod:`sblsim.models.sync.positions`): the robust fix against scipy's least squares with
the same loss, late arrivals rejected (not a tight wrong fix), a fix without redundancy reported and not trusted,
and the fixes' NEES consistent on simulated arrivals without multipath."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.stats import chi2, norm

from sblsim.models.sync import positions
from sblsim.models.sync.positions import position_emissions

SIGMA = 0.15e-3  # [s] the timing noise
C = 1480.0  # [m/s]


def _array(rng: np.random.Generator, n: int = 8, radius: float = 300.0) -> np.ndarray:
    angle = np.sort(rng.uniform(0, 2 * np.pi, n))
    return np.c_[radius * np.cos(angle), radius * np.sin(angle)] + rng.normal(0, 30, (n, 2))


def _ring(rng: np.random.Generator, n: int = 8, radius: float = 300.0) -> np.ndarray:
    """(n, 2) [m] receivers evenly on a circle, 20 m of scatter: a tag inside is surrounded."""
    angle = 2 * np.pi * np.arange(n) / n
    return np.c_[radius * np.cos(angle), radius * np.sin(angle)] + rng.normal(0, 20, (n, 2))


def _arrivals(rng, receivers, tags, late=None):
    """(E, R) [s] arrivals of emissions at ``tags`` (E, 2), emission times 100 s apart, with Gaussian noise and
    ``late`` (E, R) [s] added."""
    T = 100.0 * np.arange(len(tags))
    a = T[:, None] + np.linalg.norm(tags[:, None] - receivers[None], axis=2) / C
    a = a + rng.normal(0, SIGMA, a.shape)
    return a + (0.0 if late is None else late), T


def test_the_robust_step_is_scipys_least_squares_with_the_student_t_loss():
    """The IRLS Gauss–Newton with Student-t weights is a minimum of Σ (ν+1)/2 log(1 + u²/ν): scipy's
    least_squares with that loss (ρ(z) = (ν+1) log(1 + z/ν), its cost ½ Σ ρ) from the same start reaches the same
    point (to the Gauss–Newton's stopping step, 0.1 mm), and from our point does not move."""
    rng = np.random.default_rng(3)
    receivers = _array(rng)
    tag = np.array([[20.0, -40.0]])
    late = np.zeros((1, 8))
    late[0, [2, 5]] = [8e-3, 1e-3]  # two late arrivals (12 m and 1.5 m of extra path)
    a, _ = _arrivals(rng, receivers, tag, late)
    sigma = np.full(8, SIGMA)
    nu = positions.NU
    p, T, residual, *_ = positions._gauss_newton(a, np.ones_like(a, bool), receivers, sigma, np.full(1, 1 / C),
                                                 np.array([[0.0, 0.0]]), np.array([a.min()]), robust=True)

    def loss(z):
        return np.vstack([(nu + 1) * np.log1p(z / nu), (nu + 1) / (nu + z), -(nu + 1) / (nu + z) ** 2])

    def f(x):
        return (a[0] - x[2] - np.linalg.norm(x[:2] - receivers, axis=1) / C) / SIGMA

    def solve(x0):
        return least_squares(f, x0, loss=loss, x_scale="jac", xtol=1e-15, ftol=1e-15, gtol=1e-15).x

    ref = solve(np.r_[0.0, 0.0, a.min()])
    assert np.linalg.norm(p[0] - ref[:2]) < 1e-3 and abs(T[0] - ref[2]) < 1e-9
    np.testing.assert_allclose(residual[0] / SIGMA, f(ref), atol=1e-2)
    assert f(ref)[2] > 40 and np.linalg.norm(p[0] - tag[0]) < 0.5  # the 12 m late arrival left aside
    again = solve(np.r_[p[0], T[0]])
    assert np.linalg.norm(again[:2] - p[0]) < 1e-3


def test_one_late_arrival_is_rejected_and_the_fix_is_the_least_squares_of_the_others():
    """8 receivers, one arrival 20 ms late (30 m): the fix drops it (the brute force: of the 8 least squares leaving
    one arrival out, the lowest χ² leaves out the late one) and is scipy's least squares of the other 7, its
    covariance (Jᵀ Σ⁻¹ J)⁻¹ of scipy's Jacobian there."""
    rng = np.random.default_rng(2)
    receivers = _array(rng)
    tag = np.array([[-50.0, 30.0]])
    late = np.zeros((1, 8))
    late[0, 3] = 20e-3
    a, _ = _arrivals(rng, receivers, tag, late)
    fixes = position_emissions(a, receivers, np.full(8, SIGMA), np.full(1, 1 / C))

    def fit(keep):
        def f(x):
            return (a[0, keep] - x[2] - np.linalg.norm(x[:2] - receivers[keep], axis=1) / C) / SIGMA
        return least_squares(f, np.r_[0.0, 0.0, a.min()], x_scale=np.r_[1.0, 1.0, 1e-3], xtol=1e-15, ftol=1e-15,
                             gtol=1e-15)

    fits = [fit(np.flatnonzero(np.arange(8) != k)) for k in range(8)]
    cost = [2 * r.cost for r in fits]
    assert int(np.argmin(cost)) == 3
    ref = fits[3]
    assert fixes.ok[0] and fixes.status[0] == positions.CHECKED
    assert fixes.used[0].tolist() == [k != 3 for k in range(8)] and fixes.rejected[0] == 1
    assert fixes.redundancy[0] == 7 - 3
    assert np.linalg.norm(fixes.position[0] - ref.x[:2]) < 1e-5
    assert fixes.chi2[0] == pytest.approx(2 * ref.cost, rel=1e-5)
    covariance = np.linalg.inv(ref.jac.T @ ref.jac)[:2, :2]
    np.testing.assert_allclose(fixes.covariance[0], covariance, rtol=1e-4)


@pytest.mark.parametrize("n_late", [1, 2])
def test_late_arrivals_give_no_tight_wrong_fix(n_late):
    """300 emissions inside 8 receivers on a ring, each with one or two arrivals late by 2 to 30 m of path (up to
    130 sigmas): over 90 % of the fixes trusted, a trusted fix's error within its own sigma (NEES over the 99.9 %
    point of χ²₂ in at most 2 % of them, the mean NEES at most 3), where the least squares of all the arrivals (the
    same emissions) is far off."""
    rng = np.random.default_rng(10 + n_late)
    receivers = _ring(rng)
    E = 300
    tags = rng.uniform(-150, 150, (E, 2))
    late = np.zeros((E, 8))
    for e in range(E):
        late[e, rng.choice(8, n_late, replace=False)] = rng.uniform(2, 30, n_late) / C
    a, _ = _arrivals(rng, receivers, tags, late)
    fixes = position_emissions(a, receivers, np.full(8, SIGMA), np.full(E, 1 / C))
    ok = fixes.ok
    error = fixes.position[ok] - tags[ok]
    nees = np.einsum("ek,ekl,el->e", error, np.linalg.inv(fixes.covariance[ok]), error)
    assert ok.mean() > 0.9
    assert (nees > chi2.isf(1e-3, 2)).mean() <= 0.02 and nees.mean() <= 3.0, (nees.mean(), np.sort(nees)[-5:])
    # the plain least squares of every arrival (numpy's Gauss-Newton from the truth) is a tight wrong fix
    x = np.c_[tags, a.min(axis=1)]
    for _ in range(10):
        rng_ = np.linalg.norm(x[:, None, :2] - receivers[None], axis=2)
        r = (a - x[:, 2:3] - rng_ / C) / SIGMA
        J = np.concatenate([(x[:, None, :2] - receivers[None]) / rng_[..., None] / C, np.ones((E, 8, 1))],
                           axis=2) / SIGMA
        x = x + np.linalg.solve(J.transpose(0, 2, 1) @ J, (J.transpose(0, 2, 1) @ r[..., None]))[..., 0]
    cov = np.linalg.inv(J.transpose(0, 2, 1) @ J)[:, :2, :2]
    plain = np.einsum("ek,ekl,el->e", x[:, :2] - tags, np.linalg.inv(cov), x[:, :2] - tags)
    assert plain.mean() > 30 * nees.mean()


def test_a_fix_without_redundancy_is_reported_unchecked_and_one_with_an_unidentifiable_outlier_failed():
    """3 arrivals in 2-D (x, y and the emission time: fitted exactly whatever they are) are ``unchecked``, not
    trusted, χ² 0; 4 arrivals with one 20 ms late fail the overall test (redundancy 1: every w statistic is the
    same, so the late one cannot be found), not trusted; 4 clean arrivals pass; 2 are too few."""
    rng = np.random.default_rng(4)
    receivers = _array(rng, n=4)
    tags = np.zeros((4, 2))
    late = np.zeros((4, 4))
    late[1, 2] = 20e-3
    a, _ = _arrivals(rng, receivers, tags, late)
    a[0, 3] = np.nan  # 3 arrivals
    a[3, 2:] = np.nan  # 2 arrivals
    fixes = position_emissions(a, receivers, np.full(4, SIGMA), np.full(4, 1 / C))
    assert fixes.status.tolist() == [positions.UNCHECKED, positions.FAILED, positions.CHECKED, positions.TOO_FEW]
    assert fixes.ok.tolist() == [False, False, True, False]
    assert fixes.redundancy.tolist() == [0, 1, 1, -1]
    assert fixes.chi2[0] < 1e-6 and fixes.chi2[1] > chi2.isf(positions.TEST_SIZE, 1)
    assert np.isnan(fixes.position[[0, 1, 3]]).all() and np.isfinite(fixes.position[2]).all()
    assert positions.W_CRITICAL == pytest.approx(norm.isf(positions.TEST_SIZE / 2))


def test_the_fixes_are_consistent_over_20_seeds_without_multipath():
    """20 seeds of 60 emissions inside 8 receivers with Gaussian timing noise only: the mean NEES (2-D) is 2 within
    its Monte Carlo spread (1,200 fixes: the standard error 2/√1200 = 0.06; allowed ±0.25), and the robust fix takes
    (almost) nothing from consistent data: under 1 % of the arrivals rejected, 99 % of the fixes trusted."""
    nees, rejected, n, trusted = [], 0, 0, 0
    for seed in range(20):
        rng = np.random.default_rng(100 + seed)
        receivers = _array(rng)
        tags = rng.uniform(-150, 150, (60, 2))
        a, _ = _arrivals(rng, receivers, tags)
        fixes = position_emissions(a, receivers, np.full(8, SIGMA), np.full(60, 1 / C))
        error = fixes.position[fixes.ok] - tags[fixes.ok]
        nees.append(np.einsum("ek,ekl,el->e", error, np.linalg.inv(fixes.covariance[fixes.ok]), error))
        rejected += int(fixes.rejected.sum())
        n += a.size
        trusted += int(fixes.ok.sum())
    nees = np.concatenate(nees)
    assert abs(nees.mean() - 2.0) < 0.25 and rejected / n < 0.01, (nees.mean(), rejected / n)
    assert trusted >= 0.99 * 20 * 60


@pytest.mark.slow
def test_a_start_away_from_the_centroid_finds_the_global_minimum():
    """The fix is the lowest χ² over the starts: no start of a dense grid over the array (numpy's Gauss–Newton of the
    same arrivals from each) reaches a lower χ² than the fix's."""
    rng = np.random.default_rng(7)
    receivers = _array(rng, n=5, radius=200.0)
    tags = rng.uniform(-250, 250, (20, 2))
    a, _ = _arrivals(rng, receivers, tags)
    fixes = position_emissions(a, receivers, np.full(5, SIGMA), np.full(20, 1 / C))
    grid = np.stack(np.meshgrid(np.linspace(-400, 400, 7), np.linspace(-400, 400, 7)), -1).reshape(-1, 2)
    for e in np.flatnonzero(fixes.ok):
        mask = fixes.used[e]
        best = np.inf
        for g in grid:
            x = np.r_[g, a[e, mask].min()]
            for _ in range(40):
                d = x[:2] - receivers[mask]
                rr = np.maximum(np.linalg.norm(d, axis=1), 1e-6)
                r = (a[e, mask] - x[2] - rr / C) / SIGMA
                J = np.c_[d / rr[:, None] / C, np.ones(mask.sum())] / SIGMA
                step = np.linalg.lstsq(J, r, rcond=None)[0]
                step[:2] *= min(1.0, 200.0 / max(np.linalg.norm(step[:2]), 1e-12))
                x = x + step
            best = min(best, float(np.sum(r ** 2)))
        assert fixes.chi2[e] <= best + 1e-6, (e, fixes.chi2[e], best)


def test_no_emission_and_emissions_heard_by_none_give_no_fix():
    """No emission: empty fixes; emissions heard by no receiver (all NaN): ``too few``, not trusted, NaN."""
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    empty = position_emissions(np.zeros((0, 4)), receivers, np.full(4, SIGMA), np.zeros(0))
    assert empty.position.shape == (0, 2) and empty.ok.shape == (0,)
    none = position_emissions(np.full((2, 4), np.nan), receivers, np.full(4, SIGMA), np.full(2, 1 / C))
    assert none.status.tolist() == [positions.TOO_FEW] * 2 and not none.ok.any() and np.isnan(none.position).all()


def test_emissions_positioned_a_block_at_a_time_are_each_positioned_alone(monkeypatch):
    """A season's emissions are positioned a block at a time (:data:`~positions.EMISSIONS_BLOCK`): every fix is its
    emission's own, so blocks of 7 give what one call over all 60 gives and what each emission positioned alone
    gives (late arrivals, receivers that miss some emissions and one that hears none among them)."""
    rng = np.random.default_rng(5)
    receivers = _ring(rng, n=9)
    E = 60
    tags = rng.uniform(-150, 150, (E, 2))
    late = np.where(rng.random((E, 9)) < 0.1, rng.uniform(2, 30, (E, 9)) / C, 0.0)
    a, _ = _arrivals(rng, receivers, tags, late)
    a[rng.random((E, 9)) < 0.2] = np.nan
    a[:, 4] = np.nan
    args = (receivers, np.full(9, SIGMA), np.full(E, 1 / C))
    whole = position_emissions(a, *args)
    monkeypatch.setattr(positions, "EMISSIONS_BLOCK", 7)
    blocks = position_emissions(a, *args)
    alone = [position_emissions(a[e:e + 1], receivers, np.full(9, SIGMA), np.full(1, 1 / C)) for e in range(E)]
    assert whole.ok.sum() > 40
    for name in ("position", "covariance", "emission_time", "used", "ok", "redundancy", "chi2", "status", "rejected"):
        for got in (getattr(blocks, name), np.concatenate([getattr(f, name) for f in alone])):
            want = getattr(whole, name)
            if want.dtype.kind == "f":
                np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12, equal_nan=True, err_msg=name)
            else:
                np.testing.assert_array_equal(got, want, err_msg=name)

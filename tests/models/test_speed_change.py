"""A still tag's place fitted with the sound speed's change over its record (sblsim.models.tracking.speed_change),
against the simulated water's truth and against scipy's least squares on the same model written out."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

from sblsim.models.tracking.speed_change import _basis, speed_change_fix
from sblsim.models.tracking.stationary import stationary_fix

RECEIVERS = np.array([[0.0, 0.0], [1000.0, 0.0], [1000.0, 800.0], [0.0, 800.0], [500.0, 400.0]])
TAG = np.array([700.0, 500.0])
SIGMA = 1e-4


def water(seed: int, pings: int = 720, amplitude: float = 5.0, interval: float = 120.0):
    """A still tag's times of arrival (pings, 5) [s] in water of 1,480 ± ``amplitude`` m/s over a day, each receiver
    hearing 80 %, the pings' times and the true speed at each."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.8 * interval, 1.2 * interval, pings))
    c = 1480.0 + amplitude * np.sin(2 * np.pi * t / 86400.0 + rng.uniform(0, 2 * np.pi))
    rho = np.linalg.norm(TAG[None] - RECEIVERS, axis=1)
    toa = t[:, None] + rho[None] / c[:, None] + SIGMA * rng.normal(size=(pings, len(RECEIVERS)))
    toa[rng.random(toa.shape) > 0.8] = np.nan
    return toa, t, c


def test_the_speeds_change_is_found_and_the_place_is_where_the_pooled_fit_at_one_speed_is_not():
    toa, t, c = water(3)
    fitted = speed_change_fix(toa, RECEIVERS, 1480.0, SIGMA, TAG + 2.0)
    found = 1480.0 / (1.0 + fitted.change)
    assert np.sqrt(np.mean((found - c) ** 2)) < 0.3  # m/s, of a ±5 m/s swing
    assert fitted.knots == int(np.ceil(np.ptp(t) / 3600.0)) + 1
    error = np.linalg.norm(fitted.fix.position - TAG)
    assert error < 0.02
    pooled = stationary_fix(toa, RECEIVERS, 1480.0, SIGMA, TAG + 2.0)  # the speed's change left out
    assert np.linalg.norm(pooled.position - TAG) > 3 * error
    # what the covariance says the error is, over the seeds: the mean NEES of a place of 2 dimensions near 2
    nees = []
    for seed in range(8):
        toa, _, _ = water(seed)
        fix = speed_change_fix(toa, RECEIVERS, 1480.0, SIGMA, TAG + 2.0).fix
        e = fix.position - TAG
        nees.append(e @ np.linalg.solve(fix.covariance, e))
    assert 0.5 < np.mean(nees) < 4.5


def test_the_fit_is_least_squares_on_the_model_written_out():
    """Many degrees of freedom (the Student-t as least squares): the same place and knots as scipy's least squares
    of every arrival's residual, each ping's emission time an unknown, the knots' prior as residuals of its own."""
    toa, t, _ = water(5, pings=200, interval=300.0)
    c, dof = 1480.0, 1e9
    fitted = speed_change_fix(toa, RECEIVERS, c, SIGMA, TAG + 2.0, dof=dof)
    heard = np.isfinite(toa)
    times = np.nanmin(toa, axis=1)
    B = _basis(times, 3600.0).toarray()
    K = B.shape[1]

    def residuals(x: np.ndarray) -> np.ndarray:
        p, a, te = x[:2], x[2:2 + K], x[2 + K:]
        rho = np.linalg.norm(p[None] - RECEIVERS, axis=1)
        predicted = te[:, None] + rho[None] * (1.0 + B @ a)[:, None] / c
        return np.concatenate([((toa - predicted) / SIGMA)[heard], a * c / 5.0])

    x0 = np.concatenate([TAG + 2.0, np.zeros(K), times - 0.4])
    ref = least_squares(residuals, x0, x_scale=np.concatenate([np.ones(2), np.full(K, 1e-3), np.full(len(t), 1e-3)]),
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert np.allclose(fitted.fix.position, ref.x[:2], atol=1e-4)
    assert np.allclose(fitted.change, B @ ref.x[2:2 + K], atol=1e-6)  # 0.0015 m/s
    assert np.allclose(fitted.fix.emissions, ref.x[2 + K:], atol=1e-8)
    ours = np.concatenate([fitted.fix.position, np.linalg.lstsq(B, fitted.change, rcond=None)[0],
                           fitted.fix.emissions])
    assert 0.5 * np.sum(residuals(ours) ** 2) <= ref.cost + 1e-6  # at scipy's minimum or below it
    # its covariance: the place's block of the inverse of the Gauss-Newton information
    J = ref.jac
    full = np.linalg.inv(J.T @ J)
    assert np.allclose(fitted.fix.covariance, full[:2, :2], rtol=1e-3)


def test_still_water_leaves_the_place_where_one_speed_puts_it():
    toa, _, _ = water(1, amplitude=0.0)
    fitted = speed_change_fix(toa, RECEIVERS, 1480.0, SIGMA, TAG + 2.0)
    pooled = stationary_fix(toa, RECEIVERS, 1480.0, SIGMA, TAG + 2.0)
    assert np.abs(1480.0 / (1.0 + fitted.change) - 1480.0).max() < 0.5
    d = fitted.fix.position - pooled.position
    assert d @ np.linalg.solve(fitted.fix.covariance, d) < 1.0
    # the corrected times less the speed's change: a pooled fit at one speed on them finds the same place
    again = stationary_fix(fitted.corrected, RECEIVERS, 1480.0, SIGMA, TAG + 2.0)
    assert np.linalg.norm(again.position - fitted.fix.position) < 1e-3


@pytest.mark.parametrize("pings, interval", [(20, 600.0), (100, 60.0)])
def test_a_record_too_short_or_too_few_pings_is_fitted_at_one_speed(pings, interval):
    toa, _, _ = water(2, pings=pings, interval=interval)
    fitted = speed_change_fix(toa, RECEIVERS, 1480.0, SIGMA, TAG + 2.0)
    pooled = stationary_fix(toa, RECEIVERS, 1480.0, SIGMA, TAG + 2.0)
    assert fitted.knots == 0 and not fitted.change.any()
    assert np.array_equal(fitted.fix.position, pooled.position)
    assert fitted.speed_range(1480.0) == [0.0, 0.0]

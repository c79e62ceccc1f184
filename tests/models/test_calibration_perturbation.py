"""The calibration solver with a sound-speed perturbation: its Jacobian against finite differences, a simulated
survey whose perturbation is known (recovered within its sigma; without the model, the array biased as the docs
predict), the Earth-flattened and hung eigenrays against closed forms, GARPOS's statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sblsim.fmus.compiled_functions import compiled_exact_points
from sblsim.models.calibration import EigenRay, Perturbation, Replies, StraightRay, ocean, select, solve
from sblsim.models.calibration.perturbation import basis, uniform_knots
from sblsim.models.declarations import ModelError

C = 1500.0
DEPTH = 2000.0
ARRAY = np.array([[700.0, 0.0, -DEPTH], [0.0, 700.0, -DEPTH - 20.0], [-700.0, 0.0, -DEPTH + 15.0],
                  [0.0, -700.0, -DEPTH - 5.0]])


def _delay(t: np.ndarray) -> np.ndarray:
    """The true two-way nadir delay [s]: 1 ms plus a 0.2 ms wave of a 3-hour period."""
    return 1e-3 + 2e-4 * np.sin(2 * np.pi * t / 10800.0)


def _gamma(t: np.ndarray) -> np.ndarray:
    """A true GARPOS correction: the relative speed change of the delay over the array's two-way nadir time."""
    return -_delay(t) * C / (2 * DEPTH)


def _survey(rng, shift=(0.05, -0.03, 0.02), hours=4.0, noise=2e-5, form="ntd"):
    """A vessel circling 800 m out every 30 minutes about a centre that wanders 400 m about the array's over 2
    hours (a track symmetric about the array cannot tell a uniform speed change from the array's dilation), a ping
    every 20 s, replies of all four transponders; straight rays at C plus the delay mapped by the mean nadir
    cosine of the two legs (``form="ntd"``) or times exp(-gamma), gamma the mean at transmit and receive
    (``"garpos"``); the true array = ARRAY + shift."""
    t_tx = np.arange(0.0, hours * 3600.0, 20.0)
    n = len(t_tx)
    phase = 2 * np.pi * t_tx / 1800.0
    drift = 2 * np.pi * t_tx / 7200.0
    truth = ARRAY + np.asarray(shift)
    rows = []
    for j, x in enumerate(truth):
        tx = np.column_stack((800 * np.sin(phase) + 400 * np.sin(drift), 800 * np.cos(phase) + 400 * np.cos(drift),
                              np.zeros(n)))
        rx = tx + np.array([1.0, 0.5, 0.1])
        legs = np.linalg.norm(tx - x, axis=1) + np.linalg.norm(rx - x, axis=1)
        mapping = 0.5 * ((tx[:, 2] - x[2]) / np.linalg.norm(tx - x, axis=1)
                         + (rx[:, 2] - x[2]) / np.linalg.norm(rx - x, axis=1))
        t_rx = t_tx + legs / C
        if form == "ntd":
            twtt = legs / C + _delay(0.5 * (t_tx + t_rx)) / mapping
        else:
            twtt = legs / C * np.exp(-0.5 * (_gamma(t_tx) + _gamma(t_rx)))
        twtt = twtt + noise * rng.normal(size=n)
        rows.append((tx, rx, twtt, np.full(n, j), t_tx, t_rx))
    tx, rx, twtt, k, a, b = (np.concatenate(v) for v in zip(*rows))
    sigma = np.full_like(tx, 0.01)
    return Replies(tx, sigma, rx, sigma, twtt, k.astype(int), a, b), truth


def _prediction(design, legs, rows, mapping, p, theta):
    """The model's prediction with the mapping and the perturbation's columns held (as the solver's Jacobian)."""
    tau = ocean._perturbed_model(design, ARRAY, theta, C, True, legs, rows)[2]
    if design.pert.kind == "ntd":  # SeaGap holds the mapping and the gradients' directions at the current estimate
        return mapping * tau + p @ theta[3:]
    return np.log(tau) / design.unit - p @ theta[3:]


@pytest.mark.slow
def test_the_jacobian_is_the_prediction_s_finite_differences():
    rng = np.random.default_rng(0)
    replies, _ = _survey(rng, hours=1.0)
    legs = EigenRay(np.array([[0.0, 1520.0], [300.0, 1490.0], [2500.0, 1500.0]]), C, 0.0, compiled_exact_points())
    for kind, gradient in (("ntd", "shallow+deep"), ("garpos", "shallow+deep")):
        pert = Perturbation(kind, n_bases=8, gradient=gradient)
        knots = uniform_knots(replies.t_tx.min(), replies.t_rx.max(), 8)
        design = ocean._Design(pert, replies, ARRAY, knots, C)
        rows = np.arange(0, len(replies), 23)
        theta = np.concatenate(([0.3, -0.2, 0.1], rng.normal(0.0, 1e-4 if kind == "ntd" else 1.0, design.width())))
        _, a, tau, _, mapping, _, _, p = ocean._perturbed_model(design, ARRAY, theta, C, True, legs, rows)
        for j in [0, 1, 2, *rng.choice(np.arange(3, len(theta)), 6, replace=False)]:
            step = 1e-4 if j < 3 else 1.0
            up, down = theta.copy(), theta.copy()
            up[j] += step
            down[j] -= step
            fd = (_prediction(design, legs, rows, mapping, p, up)
                  - _prediction(design, legs, rows, mapping, p, down)) / (2 * step)
            np.testing.assert_allclose(a[:, j], fd, rtol=2e-6, atol=1e-6 * np.max(np.abs(a[:, j])) + 1e-15,
                                       err_msg=f"{kind} column {j}")


def test_a_known_ntd_is_recovered_and_ignoring_it_biases_the_array_as_predicted():
    rng = np.random.default_rng(11)
    nees, errors = [], []
    for seed in range(20):
        replies, truth = _survey(np.random.default_rng(seed))
        sol = solve(replies, ARRAY, C, rigid=True, outlier_factor=None,
                    perturbation=Perturbation("ntd", n_bases=30))
        e = sol.offset[0] - (truth[0] - ARRAY[0])
        errors.append(e)
        nees.append(float(e @ np.linalg.solve(sol.covariance, e)))
        fit = sol.perturbation
        assert fit.n_bases == 30 and fit.parameters == 33
        if seed == 0:
            # the delay itself (but the half hours at the ends, where fewer replies hold the splines): its changes
            # within 4 of its coefficients' sigma; its mean trades against Up (2 e_u <cos> / c)
            t = np.linspace(replies.t_tx.min() + 1800.0, replies.t_rx.max() - 1800.0, 500)
            got, want = basis(t, fit.knots) @ fit.coefficients, _delay(t)
            sigma = np.median(fit.coefficient_sigma[fit.used_bases])
            assert 1e-7 < sigma < 5e-6
            assert np.max(np.abs((got - got.mean()) - (want - want.mean()))) < 4 * sigma
            assert abs(got.mean() - want.mean()) < 2 * abs(e[2]) / C + 2e-6
    assert 1.5 <= np.mean(nees) <= 4.5, np.mean(nees)
    # without the model: the array sinks by c <delay> / (2 <cos^2>), the horizontal stays within centimetres
    replies, truth = _survey(rng)
    plain = solve(replies, ARRAY, C, rigid=True, outlier_factor=None)
    x = ARRAY[replies.transponder] + (truth[0] - ARRAY[0])
    mapping = 0.5 * ((replies.tx[:, 2] - x[:, 2]) / np.linalg.norm(replies.tx - x, axis=1)
                     + (replies.rx[:, 2] - x[:, 2]) / np.linalg.norm(replies.rx - x, axis=1))
    predicted = -C * np.mean(_delay(0.5 * (replies.t_tx + replies.t_rx))) / (2 * np.mean(mapping**2))
    bias = plain.offset[0] - (truth[0] - ARRAY[0])
    assert bias[2] == pytest.approx(predicted, rel=0.03)
    assert abs(predicted) > 0.8  # metres: far beyond the modelled solution's millimetres
    # the track's centre wanders while the delay changes: the horizontal takes a few centimetres of it too
    assert 0.01 < np.hypot(bias[0], bias[1]) < 0.1 * abs(bias[2])


def test_the_search_picks_the_criterion_minimum_and_the_linearised_candidates_equal_full_solutions():
    replies, _ = _survey(np.random.default_rng(3), hours=3.0)
    candidates = [Perturbation("ntd", n_bases=n) for n in (6, 12, 20, 40)]
    chosen, table = select(replies, ARRAY, C, candidates, rigid=True, criterion="bic")
    best = min(table, key=lambda row: row["bic"])
    assert best["chosen"] and chosen.perturbation.n_bases == best["n_bases"]
    for row, candidate in zip(table, candidates):
        full = solve(replies, ARRAY, C, rigid=True, outlier_factor=None, perturbation=candidate)
        assert row["bic"] == pytest.approx(full.perturbation.bic, abs=1e-6)
        assert row["aic"] == pytest.approx(full.perturbation.aic, abs=1e-6)
        assert row["e_m"] == pytest.approx(full.offset[0, 0], abs=1e-8)


def test_garpos_recovers_a_known_perturbation_and_its_abic_prefers_the_right_smoothness():
    replies, truth = _survey(np.random.default_rng(4), hours=3.0, form="garpos")
    solutions = {}
    for log_lambda0 in (-6.0, 0.0, 6.0):
        pert = Perturbation("garpos", knot_interval=600.0, log_lambda0=log_lambda0)
        solutions[log_lambda0] = solve(replies, ARRAY, C, outlier_factor=None, perturbation=pert)
    best = min(solutions, key=lambda k: solutions[k].perturbation.abic)
    sol = solutions[best]
    error = sol.offset - (truth - ARRAY)
    assert np.all(np.abs(error) < 4 * sol.sigma + 1e-4), (error, sol.sigma)
    # the background: the true gamma within 4 of its coefficients' sigma (but the half hours at the ends)
    fit = sol.perturbation
    t = np.linspace(replies.t_tx.min() + 1800.0, replies.t_rx.max() - 1800.0, 300)
    got = basis(t, fit.knots) @ fit.coefficients
    assert np.max(np.abs(got - _gamma(t))) < 4 * np.median(fit.coefficient_sigma)
    assert fit.abic is not None and fit.aic is None
    assert best == 0.0  # the smooth truth: neither the stiffest nor the loosest


def test_the_rejection_drops_the_outliers():
    replies, _ = _survey(np.random.default_rng(8), hours=2.0, form="garpos")
    twtt = replies.twtt.copy()
    twtt[[10, 500, 900]] += 1e-3  # three outliers of 1 ms
    bad = Replies(replies.tx, replies.tx_sigma, replies.rx, replies.rx_sigma, twtt, replies.transponder,
                  replies.t_tx, replies.t_rx)
    pert = Perturbation("garpos", knot_interval=600.0, reject_sigma=5.0)
    sol = solve(bad, ARRAY, C, outlier_factor=None, perturbation=pert)
    assert sorted(np.flatnonzero(~sol.used)) == [10, 500, 900]
    with pytest.raises(ModelError, match="mu_t"):
        solve(replies, ARRAY, C, perturbation=Perturbation("ntd", n_bases=10, mu_t=60.0))
    with pytest.raises(ModelError, match="solve_sound_speed"):
        solve(replies, ARRAY, C, solve_sound_speed=True, perturbation=Perturbation("ntd", n_bases=10))


def test_abic_tells_correlated_noise_from_white_and_the_correlated_sigma_holds():
    """Noise drawn from GARPOS's own covariance (60 s, 0.5 between transponders): the ABIC search over the
    smoothness and the correlation length picks that covariance, whose sigma holds the error while independent
    replies' is overconfident; for white noise it picks independent replies."""
    white, truth = _survey(np.random.default_rng(9), hours=2.0, noise=0.0, form="garpos")
    order = np.argsort(white.t_tx, kind="stable")
    n = len(white)
    t, k = white.t_tx[order], white.transponder[order]
    dense = np.exp(-np.abs(t[:, None] - t[None, :]) / 60.0) * np.where(k[:, None] == k[None, :], 1.0, 0.5)
    dense[np.abs(t[:, None] - t[None, :]) >= 240.0] = 0.0
    noise = np.empty(n)
    noise[order] = np.linalg.cholesky(dense) @ np.random.default_rng(10).normal(0.0, 2e-5, n)
    candidates = [Perturbation("garpos", knot_interval=600.0, mu_t=mu_t, mu_mt=0.5, log_lambda0=lam)
                  for mu_t in (0.0, 60.0) for lam in (-2.0, 0.0, 2.0)]
    chosen = {}
    for name, draw in (("white", np.random.default_rng(10).normal(0.0, 2e-5, n)), ("correlated", noise)):
        replies = Replies(white.tx, white.tx_sigma, white.rx, white.rx_sigma, white.twtt + draw, white.transponder,
                          white.t_tx, white.t_rx)
        chosen[name], table = select(replies, ARRAY, C, candidates, rigid=True)
        assert [row["chosen"] for row in table].count(True) == 1
        assert min(table, key=lambda row: row["abic"])["mu_t"] == chosen[name].perturbation.settings.mu_t
    assert chosen["white"].perturbation.settings.mu_t == 0.0
    assert chosen["correlated"].perturbation.settings.mu_t == 60.0
    right = chosen["correlated"]
    error = right.offset[0] - (truth[0] - ARRAY[0])
    assert np.all(np.abs(error) < 3 * right.sigma[0]), (error, right.sigma[0])
    assert np.all(chosen["white"].sigma[0] < right.sigma[0])


@pytest.mark.slow
def test_eigenrays_in_spherical_layers_are_the_chord_in_still_water():
    """Isovelocity water in spherical shells: the ray is the straight chord between the radii R + U, whatever the
    flattening does to the flat profile; and its gradient is the chord's."""
    c, radius = 1500.0, 6.371e6
    # rows 12 m apart: the flattened speed, c R / r, is linear between them to 1e-12 of itself
    legs = EigenRay(np.column_stack((np.linspace(0.0, 3000.0, 256), np.full(256, c))), c, 0.0, earth_radius=radius)
    points = np.array([[0.0, 0.0, 0.0], [1500.0, -800.0, 3.0], [2500.0, 2500.0, -1.0]])
    x = np.array([[10.0, 20.0, -2500.0]] * 3)
    length, gradient = legs.legs(points, x, np.zeros(3, int))
    b, cc = radius + points[:, 2], radius + x[:, 2]
    arc = np.hypot(points[:, 0] - x[:, 0], points[:, 1] - x[:, 1]) / radius
    chord = np.sqrt((b - cc) ** 2 + 2 * b * cc * (1 - np.cos(arc)))
    np.testing.assert_allclose(length, chord, rtol=1e-9)
    flat = np.linalg.norm(points - x, axis=1)
    assert np.all(np.abs(length - flat)[1:] > 0.1)  # the sphere matters kilometres away
    for j in range(3):
        for axis in range(3):
            d = np.zeros(3)
            d[axis] = 1e-3
            fd = (legs.legs(points[j:j + 1], x[j:j + 1] + d, np.zeros(1, int))[0]
                  - legs.legs(points[j:j + 1], x[j:j + 1] - d, np.zeros(1, int))[0]) / 2e-3
            assert gradient[j, axis] == pytest.approx(fd[0], abs=1e-6)


def test_a_profile_hung_from_the_transducer_is_the_profile_at_its_own_surface():
    table = np.array([[0.0, 1530.0], [100.0, 1500.0], [1000.0, 1485.0], [3000.0, 1510.0]])
    depth = 5.0
    hung = EigenRay(table, 1500.0, 0.0, transducer_depth=depth)
    points = np.array([[0.0, 0.0, 1.2], [900.0, 300.0, -0.7]])
    x = np.array([[100.0, -50.0, -2400.0], [0.0, 0.0, -2410.0]])
    got, gradient = hung.legs(points, x, np.zeros(2, int))
    for j in range(2):  # each leg through the profile whose surface is this transducer's Up plus the depth
        own = EigenRay(table, 1500.0, points[j, 2] + depth)
        want, want_gradient = own.legs(points[j:j + 1], x[j:j + 1], np.zeros(1, int))
        assert got[j] == pytest.approx(want[0], abs=1e-9)
        np.testing.assert_allclose(gradient[j], want_gradient[0], atol=1e-12)
    with pytest.raises(ModelError, match="earth_radius_m"):
        EigenRay(table, 1500.0, 0.0, earth_radius=1000.0)


def test_straight_legs_take_a_perturbation_too():
    replies, truth = _survey(np.random.default_rng(6), hours=2.0)
    sol = solve(replies, ARRAY, C, rigid=True, legs=StraightRay(), outlier_factor=3.0,
                perturbation=Perturbation("ntd", knot_interval=900.0, gradient="deep"))
    assert sol.perturbation.n_bases == int((replies.t_rx.max() - replies.t_tx.min()) / 900.0) + 3
    e = sol.offset[0] - (truth[0] - ARRAY[0])
    assert np.all(np.abs(e) < 5 * sol.sigma[0])
    assert set(sol.perturbation.gradient) == {"deep"}
    assert np.all(np.abs(sol.perturbation.gradient["deep"]) < 5 * sol.perturbation.gradient_sigma["deep"] + 1e-7)
    assert math.isfinite(sol.perturbation.aic)

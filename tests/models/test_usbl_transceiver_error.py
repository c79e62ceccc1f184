"""What the USBL transceiver's position error (GPS, the lever arm turned by the attitude error) does to a packet,
against independent computations.

* R's transceiver term ``H_b Σ_b H_bᵀ`` (:meth:`RangeBearingModel.transceiver_covariance`, and its diagonal for an
  isotropic Σ_b, ``σ_b² [1, 1 / ρ², 1 / r²]``) against a Monte Carlo of the transceiver position error pushed through
  h written in numpy: the covariance of the simulated (r, α, ε) perturbations, at a few geometries, for an
  isotropic and an anisotropic, correlated Σ_b.
* The receivers' R (:func:`sblsim.models.systems.usbl.variances`) is the channel's angle noise plus that term, with
  ``σ_b² = σ_GPS² + (σ_att a)²``; finite and floored (ρ ≥ 1 mm) straight below the transceiver, where the derivatives
  are finite too.
* The map's covariance of one packet plus the depth (:func:`sblsim.models.systems.usbl.fix_information`, the
  Cartesian form) is the inverse of the bound's information of the same packet (the bound's step from a wide
  prior, whose information is taken off; H and R of the receivers): the map and the bound use one R; below the
  transceiver the map is finite and keeps the GPS error (DRMS ≥ √2 σ_GPS).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from sblsim.models.receiver.range_bearing import RangeBearingModel
from sblsim.models.systems import usbl

#: Geometries (diver − transceiver, NED [m]): near and far, shallow and steep, due South (α near ±π).
GEOMETRIES = ([15.0, 0.0, 4.0], [-3.0, 2.0, 20.0], [40.0, -30.0, 2.0], [-8.0, 1e-3, 6.0], [1.0, 1.0, 4.0])


def np_h(d):
    """[r, α, ε] of the diver at ``d = p − b`` (N, 3) from the transceiver, numpy."""
    d = np.atleast_2d(d)
    return np.stack([np.linalg.norm(d, axis=1), np.arctan2(d[:, 1], d[:, 0]),
                     np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1]))], axis=1)


def monte_carlo(d, covariance, n=400_000, seed=0):
    """Sample covariance (3, 3) of ``h(p − b_true) − h(p − b_broadcast)``: the broadcast transceiver is the true one
    plus an error drawn from N(0, covariance); the angle differences wrapped to (−π, π]."""
    rng = np.random.default_rng(seed)
    error = rng.multivariate_normal(np.zeros(3), covariance, size=n)
    dz = np_h(np.asarray(d)[None, :]) - np_h(np.asarray(d)[None, :] - error)
    dz[:, 1:] = (dz[:, 1:] + np.pi) % (2 * np.pi) - np.pi
    return np.cov(dz.T), n


def evaluate(expression_of, d):
    p, b = ca.SX.sym("p", 3), ca.SX.sym("b", 3)
    f = ca.Function("f", [p, b], [expression_of(p, b)])
    return np.array(f(np.asarray(d, float), np.zeros(3)))


def within_sampling_error(sample, expected, n, k=5.0):
    """Each entry of a sample covariance within k standard errors, ``sqrt((Σ_ii Σ_jj + Σ_ij²) / n)``, of the
    expected (Gaussian sampling), plus the second-order terms of h the first-order Σ leaves out (relative 1e-3)."""
    diagonal = np.diag(expected)
    se = np.sqrt((np.outer(diagonal, diagonal) + expected ** 2) / n)
    assert np.all(np.abs(sample - expected) <= k * se + 1e-3 * np.sqrt(np.outer(diagonal, diagonal))), \
        (sample, expected)


@pytest.mark.parametrize("d", GEOMETRIES)
def test_the_transceiver_term_is_the_monte_carlo_covariance_of_the_transceiver_error_through_h(d):
    model = usbl._POSITION_MODEL
    sigma = 0.01  # small against every distance: first order holds
    isotropic = sigma ** 2 * np.eye(3)
    expected = evaluate(lambda p, b: model.transceiver_covariance(p, b, isotropic), d)
    sample, n = monte_carlo(d, isotropic)
    within_sampling_error(sample, expected, n)
    # isotropic: diagonal, σ_b² [1, 1 / ρ², 1 / r²], and the variances the receivers add are its diagonal
    rho, r = math.hypot(d[0], d[1]), float(np.linalg.norm(d))
    np.testing.assert_allclose(np.diag(expected), sigma ** 2 * np.array([1.0, 1.0 / rho ** 2, 1.0 / r ** 2]),
                               rtol=1e-12)
    np.testing.assert_allclose(evaluate(lambda p, b: model.transceiver_variances(p, b, sigma ** 2), d).ravel(),
                               np.diag(expected), rtol=1e-12)
    assert np.all(np.abs(expected - np.diag(np.diag(expected))) <= 1e-12 * np.max(expected))
    # anisotropic and correlated (a GPS worse vertically, a tilted error ellipsoid): the full H_b Σ_b H_bᵀ
    a = np.array([[1.0, 0.4, 0.0], [0.0, 0.7, 0.2], [0.3, 0.0, 2.0]]) * sigma
    anisotropic = a @ a.T
    expected = evaluate(lambda p, b: model.transceiver_covariance(p, b, anisotropic), d)
    sample, n = monte_carlo(d, anisotropic, seed=1)
    within_sampling_error(sample, expected, n)
    correlation = expected / np.sqrt(np.outer(np.diag(expected), np.diag(expected)))
    assert np.max(np.abs(correlation - np.eye(3))) > 0.05  # the rows are correlated


def np_receiver_variances(d, rc):
    """The receivers' R written out: the channel's angle noise ``(σ_θ / max(cos φ, 0.1))² + σ_att²`` on each angle,
    ``σ_r²`` on the range, plus ``σ_b² [1, 1 / max(ρ, 1 mm)², 1 / r²]``, ``σ_b² = σ_GPS² + (σ_att a)²``."""
    rho, r = math.hypot(d[0], d[1]), float(np.linalg.norm(d))
    floored = math.hypot(max(rho, 1e-3), d[2])  # the slant range of the point 1 mm off the vertical
    attitude = math.radians(rc["beacon_attitude_sigma_deg"])
    b2 = rc["beacon_gps_sigma"] ** 2 + (attitude * rc["beacon_arm"]) ** 2
    angle = (math.radians(rc["sigma_angle_deg"]) / max(d[2] / r, 0.1)) ** 2 + attitude ** 2
    return np.array([rc["sigma_range"] ** 2 + b2, angle + b2 / max(rho, 1e-3) ** 2, angle + b2 / floored ** 2])


def test_the_receivers_r_carries_the_transceiver_error_on_the_angles_and_stays_finite_below_it():
    rc = {"sigma_range": 0.1, "sigma_angle_deg": 0.5, "beacon_gps_sigma": 1.0, "beacon_attitude_sigma_deg": 1.0,
          "beacon_arm": 2.0}
    for d in [*GEOMETRIES, [0.3, -0.4, 4.0], [1e-4, 0.0, 4.0], [0.0, 0.0, 4.0]]:
        value = evaluate(lambda p, b: usbl.variances(p, b, rc), d).ravel()
        np.testing.assert_allclose(value, np_receiver_variances(d, rc), rtol=1e-12)
    # straight below: the azimuth's term is σ_b² / (1 mm)², the derivatives finite (the azimuth's row ∝ ρ_min)
    x, b = ca.SX.sym("x", 6), ca.SX.sym("b", 3)
    h, H = usbl.MODEL_RB.linearize(x, b)
    f = ca.Function("f", [x, b], [h, H, usbl.MODEL_RB.transceiver_jacobian(x, b)])
    for state in ([0.0, 0.0, 0.0, 0.0, 4.0, 0.0], [1e-5, 0.0, -2e-5, 0.0, 4.0, 0.0]):
        outputs = [np.array(v) for v in f(state, [0.0, 0.0, 0.0])]
        assert all(np.isfinite(v).all() for v in outputs)
        H = outputs[1]
        assert np.linalg.norm(H[1]) == pytest.approx(1e3, rel=1e-9)  # |∂α/∂p| = 1 / ρ_min
        np.testing.assert_allclose(outputs[2], -H[:, [0, 2, 4]], rtol=0, atol=0)
        np.testing.assert_allclose(outputs[0][2], np.arctan2(4.0, np.hypot(state[0], state[2])), rtol=1e-15)
    # the exact model (no floor) is not finite there: what the floor is for
    exact = RangeBearingModel()
    g = ca.Function("g", [x, b], [exact.linearize(x, b)[1]])
    assert not np.isfinite(np.array(g([0.0, 0.0, 0.0, 0.0, 4.0, 0.0], [0.0, 0.0, 0.0]))).all()
    with pytest.raises(ValueError, match="floor"):
        RangeBearingModel(floor=-1.0)


#: The prior's variance of the one-packet bound [m², m²/s²]: wide, and its information (1 / PRIOR) taken off.
PRIOR = 1e4


def one_packet_bound(position, transceiver, fixed):
    """The bound's step (the receivers' H and R of one USBL packet plus the depth) from a wide prior with no process
    noise: the information about the position it adds, ``B_pos⁻¹ − I / PRIOR`` (3, 3) [1/m²]."""
    step = usbl.bound_step()
    n = 6
    prior = np.eye(n).reshape(-1) * PRIOR
    B = np.array(step(prior, 1e-12, 0.0, 0.0, position, transceiver, fixed["range_variance"],
                      fixed["position_variance"], fixed["angle_sigma_deg"], fixed["attitude_variance"],
                      fixed["depth_variance"], 1.0, 1.0)).reshape(n, n, order="F")
    return np.linalg.inv(B[np.ix_([0, 2, 4], [0, 2, 4])]) - np.eye(3) / PRIOR


@pytest.mark.parametrize("gps", [0.1, 1.0])
def test_the_map_is_the_bounds_information_of_one_packet_and_finite_below_the_transceiver(gps):
    fixed = {"range_variance": 0.01, "position_variance": gps ** 2 + (math.radians(1.0) * 1.0) ** 2,
             "angle_sigma_deg": 0.5, "attitude_variance": math.radians(1.0) ** 2, "depth_variance": 1e-4}
    f = usbl.fix_information()
    transceiver = np.array([0.0, 0.0, 1.0])
    for d in GEOMETRIES:
        position = transceiver + np.asarray(d)
        C, drms = (np.array(v) for v in f(position, transceiver, *fixed.values()))
        information = one_packet_bound(position, transceiver, fixed)
        np.testing.assert_allclose(np.linalg.inv(C), information, rtol=1e-6, atol=1e-9 * np.abs(information).max())
        bound = np.linalg.inv(information)
        assert drms.item() == pytest.approx(math.sqrt(bound[0, 0] + bound[1, 1]), rel=1e-6)
    # below the transceiver and near it: finite, the transceiver's error kept, the same as the bound off the floor
    below = [usbl.horizontal_std(transceiver + [[dn, 0.0, 4.0]], transceiver, *fixed.values())[0]
             for dn in (0.0, 1e-6, 0.5)]
    assert np.isfinite(below).all() and min(below) >= math.sqrt(2 * fixed["position_variance"]) * (1 - 1e-12)
    off = np.linalg.inv(one_packet_bound(transceiver + [0.5, 0.0, 4.0], transceiver, fixed))
    assert below[2] == pytest.approx(math.sqrt(off[0, 0] + off[1, 1]), rel=1e-6)
    # and a perfect array (σ_r, σ_θ at their minimums, no attitude error): the GPS floor √2 σ everywhere, reached
    perfect = {**fixed, "range_variance": 1e-12, "position_variance": gps ** 2, "angle_sigma_deg": 1e-3,
               "attitude_variance": 0.0}
    points = np.array([[n, e, 5.0] for n in (-30.0, -0.5, 0.0, 1e-7, 3.0, 30.0) for e in (-20.0, 0.0, 0.5, 25.0)])
    drms = usbl.horizontal_std(points, transceiver, *perfect.values())
    assert np.isfinite(drms).all() and np.all(drms >= math.sqrt(2.0) * gps * (1 - 1e-12))
    assert drms.min() == pytest.approx(math.sqrt(2.0) * gps, rel=1e-3)

"""The receivers' correlated position errors in the consider terms (sblsim.models.tracking.survey_root): the
survey's frame against its closed form, the square root against the covariance it is made from, each consider
term's correlated path against its own independent path (a root rotated by an orthogonal matrix is the same
covariance, and mixes every receiver into every column), and the fixes' NEES where the receivers' errors share a
translation."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking.filter_consider import consider_terms_along, filter_sensitivity
from sblsim.models.tracking.fix import fix_pings
from sblsim.models.tracking.smoother_covariance import consider_covariance
from sblsim.models.tracking.survey_root import (
    frame_conditioned,
    gauge_modes,
    survey_root,
    taken_for,
)

R2 = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0], [140.0, 20.0]])
SETTINGS = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-3)
SIGMA = np.array([0.5, 1.0, 0.2, 0.8, 0.3, 0.6, 0.4])


def _rotated(root: np.ndarray, seed: int = 3) -> np.ndarray:
    """The root times a random orthogonal matrix: the same covariance, every column a mix of receivers."""
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(root.shape[1], root.shape[1])))
    return root @ q


def test_the_frame_of_an_isotropic_prior_is_its_shape_projector():
    """For P = σ² I the survey's frame is σ² (I − H (HᵀH)⁻¹ Hᵀ) (the shape's projector, written out here), with and
    without the scale; for any covariance the conditioned one gives the gauge no variance and is symmetric."""
    for scale in (False, True):
        H = gauge_modes(R2, scale)
        expected = 4.0 * (np.eye(len(H)) - H @ np.linalg.inv(H.T @ H) @ H.T)
        assert np.allclose(frame_conditioned(R2, 4.0 * np.eye(len(H)), scale), expected, atol=1e-12)
        a = np.random.default_rng(1).normal(size=(len(H), len(H)))
        conditioned = frame_conditioned(R2, a @ a.T + np.eye(len(H)), scale)
        assert np.abs(H.T @ conditioned @ H).max() < 1e-8 * np.abs(conditioned).max()
        assert np.allclose(conditioned, conditioned.T)
    with pytest.raises(ModelError, match="allowed"):
        frame_conditioned(R2, np.eye(4))
    with pytest.raises(ModelError, match="gauge"):
        frame_conditioned(np.zeros((3, 2)), np.eye(6))


def test_the_root_squares_to_the_covariance_it_was_made_of():
    """The root of independent σ squares to their diagonal (each axis, z too); with a horizontal covariance for some
    receivers, to it on their x and y, the σ elsewhere; ``taken_for`` picks a track's receivers by name, in its
    order, one the covariance does not name keeping its σ."""
    root = survey_root(SIGMA, 3)
    assert np.allclose(root @ root.T, np.diag(np.repeat(SIGMA**2, 3)))
    a = np.random.default_rng(2).normal(size=(4, 4))
    horizontal = np.full((2 * len(SIGMA), 2 * len(SIGMA)), np.nan)
    horizontal[2:6, 2:6] = a @ a.T  # receivers 1 and 2
    for dim in (2, 3):
        cov = survey_root(SIGMA, dim, horizontal) @ survey_root(SIGMA, dim, horizontal).T
        xy = [dim + 0, dim + 1, 2 * dim + 0, 2 * dim + 1]
        assert np.allclose(cov[np.ix_(xy, xy)], a @ a.T)
        rest = [k for k in range(len(cov)) if k not in xy]
        assert np.allclose(cov[np.ix_(rest, rest)], np.diag(np.repeat(SIGMA**2, dim))[np.ix_(rest, rest)])
        assert np.allclose(cov[np.ix_(xy, rest)], 0.0)
    names = ["r0", "r1", "r2"]
    full = np.arange(36.0).reshape(6, 6)
    full = full @ full.T + np.eye(6)
    picked = taken_for(["r2", "x", "r0"], np.array([0.1, 0.7, 0.2]), 2, (names, full))
    cov = picked @ picked.T
    assert np.allclose(cov[np.ix_([0, 1, 4, 5], [0, 1, 4, 5])], full[np.ix_([4, 5, 0, 1], [4, 5, 0, 1])])
    assert np.allclose(cov[2:4, 2:4], 0.49 * np.eye(2)) and np.allclose(cov[2:4, [0, 1, 4, 5]], 0.0)
    assert taken_for(["x"], np.array([1.0]), 2, (names, full)) is None and taken_for(names, SIGMA[:3], 2, None) is None


def test_every_consider_term_takes_a_root_as_the_sigmas_it_squares_to():
    """A root of the σ rotated (the same covariance, each column mixing every receiver): the fixes', the filter's
    (the EKF's and its RTS smoother's) and the robust track's consider terms equal those of the σ themselves; the
    filter's sensitivity to the root's columns is its sensitivity to each receiver's axes times the root."""
    toa, _, _ = tt.simulate_pings(R2, 60, SETTINGS, np.random.default_rng(8), speed=0.2, detection=0.9)
    root = _rotated(survey_root(SIGMA, 2))
    fixed = fix_pings(toa, R2, 1480.0, 1e-4, survey_sigma=SIGMA)[2]
    ok = np.isfinite(fixed).all(axis=(1, 2))
    assert ok.sum() > 40
    assert np.allclose(fix_pings(toa, R2, 1480.0, 1e-4, survey_sigma=root)[2][ok], fixed[ok], rtol=1e-9, atol=1e-14)
    record = tt.ToaTracker(R2, SETTINGS).run(toa)
    unit = filter_sensitivity(record, R2, 1480.0, 1e-4, np.ones(len(R2)), 1.0)
    ours = filter_sensitivity(record, R2, 1480.0, 1e-4, root, 1.0)
    assert np.allclose(ours[..., :-1], unit[..., :-1] @ root, equal_nan=True, atol=1e-12)
    assert np.allclose(ours[..., -1], unit[..., -1], equal_nan=True)
    rows = np.flatnonzero(record.used.any(axis=1) & np.isfinite(record.x_filtered[:, 0]))
    for a, b in zip(consider_terms_along(record, R2, 1480.0, 1e-4, rows, root, 1.0, True),
                    consider_terms_along(record, R2, 1480.0, 1e-4, rows, SIGMA, 1.0, True)):
        assert np.allclose(a, b, rtol=1e-9, atol=1e-14)
    xs = tt.ToaTracker(R2, SETTINGS).smooth(record)[0]
    k0 = record.start
    track = tt.robust_smooth(toa[k0:], R2, SETTINGS, [xs[k0:]])
    theirs = consider_covariance(toa[k0:], R2, replace(SETTINGS, survey_sigma=SIGMA), track.x)
    ours = consider_covariance(toa[k0:], R2, replace(SETTINGS, survey_sigma=root), track.x)
    assert np.abs(theirs).max() > 0 and np.allclose(ours, theirs, rtol=1e-8, atol=1e-14)


def test_the_fixes_hold_errors_the_receivers_share():
    """30 arrays whose surveyed positions share one translation (0.8 m per axis) besides their own error (0.3 m):
    the fixes' 2-D NEES near 2 with the root of that covariance, above 4.5 with each receiver's σ alone (the same
    variances, their errors taken as independent: a shared error does not average out across a fix's receivers)."""
    n = len(R2)
    cov = np.kron(np.ones((n, n)), 0.64 * np.eye(2)) + 0.09 * np.eye(2 * n)
    root = survey_root(np.zeros(n), 2, cov)
    means = {}
    for name, survey in (("shared", root), ("alone", np.sqrt(np.diag(cov))[0::2])):
        nees = []
        for seed in range(30):
            rng = np.random.default_rng(seed)
            toa, truth, _ = tt.simulate_pings(R2, 50, SETTINGS, rng, speed=0.2, detection=0.9)
            surveyed = R2 + (root @ rng.normal(size=root.shape[1])).reshape(n, 2)
            fx, fe, fc, _, _ = fix_pings(toa, surveyed, 1480.0, 1e-4, survey_sigma=survey)
            ok = np.isfinite(fe)
            e = fx[ok] - truth[ok]
            nees.extend(np.einsum("ka,kab,kb->k", e, np.linalg.inv(fc[ok][:, :2, :2]), e))
        means[name] = float(np.mean(nees))
    assert 1.5 <= means["shared"] <= 4.5 and means["alone"] > 4.5, means

"""Pings of a simulated tag moving as the tracker's model says (or along a path given), of any ping type, heard by an
array: the tracker's reference of truth in the tests and the benchmarks.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.ekf import TrackerSettings


def simulate_pings(receivers: np.ndarray, n_pings: int, settings: TrackerSettings, rng: np.random.Generator,
                   start: np.ndarray | None = None, speed: float = 1.0, detection: float = 0.8,
                   first_emission: float = 0.0, ping_type: str = "sbi",
                   burst_interval: tuple[float, float] | None = None, burst_sequence: np.ndarray | None = None,
                   path: Callable[[np.ndarray], np.ndarray] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pings of a target moving as the tracker's model says, heard by an array.

    The target starts at ``start`` (default the array's centroid) at ``speed`` [m/s] in a random direction and
    moves by the discrete white-noise-acceleration model of ``settings.acceleration_psd`` over each step's
    duration; the ping types (:mod:`sblsim.models.tracking.schedule`): ``sbi``, ping k emitted at
    ``t_e,k = t_e,k−1 + Δ_k−1 + jitter`` and the interval walking by ``interval_drift``; ``rbi``, each step a draw
    of ``U(min, max)`` (``burst_interval``); ``pbi``, the steps of ``burst_sequence`` in turn (from its start) plus
    the jitter. Each receiver hears each ping with probability ``detection`` with Gaussian timing noise
    ``sigma_toa``. With ``path`` (the target's positions (k, dim) [m] at emission times (k,) [s]), the target is
    where the path says at each emission instead: the motion is still drawn (the clock, the timing noise and the
    detections are the same numbers as without it), its positions left aside. A walk of the motion model drifts
    without bound over many pings (its velocity's variance grows as ``q t``); a path keeps a long record's
    target in the array.

    Returns
    -------
    toa : ndarray, (n_pings, n)
        Times of arrival [s], NaN where not heard.
    positions : ndarray, (n_pings, dim)
        The target's position at each emission [m].
    emissions : ndarray, (n_pings,)
        Emission times [s].
    """
    receivers = np.asarray(receivers, float)
    n, dim = receivers.shape
    s = settings
    p = receivers.mean(axis=0) if start is None else np.asarray(start, float)
    heading = rng.normal(size=dim)
    v = speed * heading / np.linalg.norm(heading)
    if ping_type == "rbi" and burst_interval is None:
        raise ModelError("simulate_pings: a random burst interval needs burst_interval (min, max) [s]")
    if ping_type == "pbi" and (burst_sequence is None or not len(burst_sequence)):
        raise ModelError("simulate_pings: a pseudo-random burst interval needs burst_sequence [s]")
    if ping_type == "rbi":
        positions, emissions = _walk_random_interval(p, v, n_pings, settings, rng, burst_interval, first_emission)
    else:
        positions, emissions = _walk(p, v, n_pings, settings, rng, ping_type, burst_sequence, first_emission)
    if path is not None:
        positions = np.asarray(path(emissions), float).reshape(n_pings, dim)
    ranges = np.linalg.norm(positions[:, None, :] - receivers[None, :, :], axis=2)
    toa = emissions[:, None] + ranges / s.sound_speed + s.sigma_toa * rng.normal(size=(n_pings, n))
    toa[rng.random((n_pings, n)) > detection] = np.nan
    return toa, positions, emissions


def _step_noise(steps: np.ndarray, q: float, normals: np.ndarray) -> np.ndarray:
    """The white-noise acceleration's position and velocity errors (k, dim, 2) over steps (k,) [s] from standard
    normals (k, dim, 2), as :meth:`numpy.random.Generator.multivariate_normal` (its ``svd`` method) makes them from
    the same draws: ``x Fᵀ`` with ``F = U √S`` of the covariance ``q [T³/3, T²/2; T²/2, T]`` (the same numbers)."""
    T = steps.tolist()  # Python floats: the powers as a scalar step computes them
    cov = np.array([[[q * (t**3 / 3), q * (t**2 / 2)], [q * (t**2 / 2), q * t]] for t in T]).reshape(-1, 2, 2)
    u, sv, _ = np.linalg.svd(cov)
    return normals @ (u * np.sqrt(sv)[:, None, :]).transpose(0, 2, 1)


def _accumulate(first: np.ndarray, *increments: np.ndarray) -> np.ndarray:
    """The recursion ``y_k+1 = ((y_k + a_k) + b_k) + …`` over the increments (k, ...) each, added in that order
    step by step (:func:`numpy.cumsum` adds sequentially): y (k, ...), y_0 = ``first``, the last sum left out."""
    k = len(increments[0])
    flat = np.empty((k * len(increments) + 1,) + np.shape(first))
    flat[0] = first
    for j, a in enumerate(increments):
        flat[1 + j::len(increments)] = a
    return np.cumsum(flat, axis=0)[:-1:len(increments)]


def _walk(p, v, n_pings, s, rng, ping_type, burst_sequence, first_emission):
    """The positions (n_pings, dim) and emission times (n_pings,) of the stable and pseudo-random burst intervals,
    all pings at once: each step's draws (the jitter and the drift for ``sbi`` after the motion's, the jitter before
    it for ``pbi``) taken from one block of standard normals in the order a step-by-step loop draws them."""
    dim = len(p)
    if ping_type == "sbi":
        z = rng.standard_normal((n_pings, 2 * dim + 2))
        motion, jitter, drift = z[:, :2 * dim], z[:, -2], z[:, -1]
        intervals = np.cumsum(np.r_[s.interval, s.interval_drift * drift[:-1]])[:n_pings]
        steps = intervals
        emissions = _accumulate(first_emission, intervals, s.jitter * jitter)
    else:
        z = rng.standard_normal((n_pings, 2 * dim + 1))
        jitter, motion = z[:, 0], z[:, 1:]
        sequence = np.asarray(burst_sequence, float)
        steps = sequence[np.arange(n_pings) % len(sequence)] + s.jitter * jitter
        emissions = _accumulate(first_emission, steps)
    w = _step_noise(steps, s.acceleration_psd, motion.reshape(n_pings, dim, 2))
    velocities = _accumulate(v, w[:, :, 1])
    positions = _accumulate(p, steps[:, None] * velocities, w[:, :, 0])
    return positions, emissions


def _walk_random_interval(p, v, n_pings, s, rng, burst_interval, first_emission):
    """The positions (n_pings, dim) and emission times (n_pings,) of the random burst interval, step by step (its
    uniform and normal draws interleave)."""
    dim = len(p)
    te = first_emission
    positions, emissions = np.empty((n_pings, dim)), np.empty(n_pings)
    for k in range(n_pings):
        positions[k], emissions[k] = p, te
        T = rng.uniform(*burst_interval)
        cov = s.acceleration_psd * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
        w = rng.multivariate_normal(np.zeros(2), cov, size=dim)  # (dim, 2): position and velocity noise per axis
        p, v = p + T * v + w[:, 0], v + w[:, 1]
        te = te + T
    return positions, emissions


__all__ = ["simulate_pings"]

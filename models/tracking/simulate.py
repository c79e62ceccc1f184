"""Pings of a simulated tag moving as the tracker's model says, of any ping type, heard by an array: the tracker's
reference of truth in the tests.
"""

from __future__ import annotations

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.ekf import TrackerSettings


def simulate_pings(receivers: np.ndarray, n_pings: int, settings: TrackerSettings, rng: np.random.Generator,
                   start: np.ndarray | None = None, speed: float = 1.0, detection: float = 0.8,
                   first_emission: float = 0.0, ping_type: str = "sbi",
                   burst_interval: tuple[float, float] | None = None, burst_sequence: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pings of a target moving as the tracker's model says, heard by an array.

    The target starts at ``start`` (default the array's centroid) at ``speed`` [m/s] in a random direction and
    moves by the discrete white-noise-acceleration model of ``settings.acceleration_psd`` over each step's
    duration; the ping types (:mod:`sblsim.models.tracking.schedule`): ``sbi``, ping k emitted at
    ``t_e,k = t_e,k−1 + Δ_k−1 + jitter`` and the interval walking by ``interval_drift``; ``rbi``, each step a draw
    of ``U(min, max)`` (``burst_interval``); ``pbi``, the steps of ``burst_sequence`` in turn (from its start) plus
    the jitter. Each receiver hears each ping with probability ``detection`` with Gaussian timing noise
    ``sigma_toa``.

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
    te, interval = first_emission, s.interval
    positions, emissions = np.empty((n_pings, dim)), np.empty(n_pings)
    for k in range(n_pings):
        positions[k], emissions[k] = p, te
        if ping_type == "rbi":
            T = rng.uniform(*burst_interval)
        elif ping_type == "pbi":
            T = float(burst_sequence[k % len(burst_sequence)]) + s.jitter * rng.normal()
        else:
            T = interval
        cov = s.acceleration_psd * np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]])
        w = rng.multivariate_normal(np.zeros(2), cov, size=dim)  # (dim, 2): position and velocity noise per axis
        p, v = p + T * v + w[:, 0], v + w[:, 1]
        if ping_type == "sbi":
            te = te + interval + s.jitter * rng.normal()
            interval = interval + s.interval_drift * rng.normal()
        else:
            te = te + T
    ranges = np.linalg.norm(positions[:, None, :] - receivers[None, :, :], axis=2)
    toa = emissions[:, None] + ranges / s.sound_speed + s.sigma_toa * rng.normal(size=(n_pings, n))
    toa[rng.random((n_pings, n)) > detection] = np.nan
    return toa, positions, emissions


__all__ = ["simulate_pings"]

"""Each emission of a tag positioned from its synchronised times of arrival: the check of a synchronisation
against the sync tags' known positions (``sync_tags.csv``).

One emission's unknowns are the tag's position ``p`` (2-D or 3-D) and its emission time ``T``; an arrival at
receiver ``j`` is ``a_j = T + |p − p_j| s + ε_j`` with ``s`` the slowness and ``ε_j`` of sigma ``σ_j`` (the
receiver's timing noise). All emissions are solved at once by Gauss–Newton on padded arrays (emissions × receivers),
from the centroid of the receivers that heard it, each step at most :data:`MAX_STEP`; an arrival whose residual is
beyond :data:`OUTLIER` sigmas is dropped and the fix solved again (twice at most) while more than ``dim + 2``
remain. A fix's covariance is ``(Jᵀ Σ⁻¹ J)⁻¹`` at its solution (its own sigma, from the receivers' noise and the
geometry).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The largest Gauss–Newton step of a position [m], the iterations and the outlier threshold [sigmas].
MAX_STEP = 200.0
ITERATIONS = 20
OUTLIER = 5.0


@dataclass
class Fixes:
    """Positioned emissions: ``position`` (E, dim) [m] and ``covariance`` (E, dim, dim) [m²] (NaN where not
    positioned), ``emission_time`` (E,) [s], ``used`` (E, R) bool (the arrivals kept), ``ok`` (E,) bool (at least
    ``dim + 2`` arrivals kept and converged)."""

    position: np.ndarray
    covariance: np.ndarray
    emission_time: np.ndarray
    used: np.ndarray
    ok: np.ndarray


def _solve(arrival: np.ndarray, mask: np.ndarray, receivers: np.ndarray, sigma: np.ndarray, slowness: np.ndarray,
           start: np.ndarray):
    E, dim = len(arrival), receivers.shape[1]
    p = start.copy()
    a = np.where(mask, arrival, 0.0)
    weight = np.where(mask, 1.0 / sigma[None, :] ** 2, 0.0)
    T = np.array([np.min(a[e][mask[e]]) if mask[e].any() else 0.0 for e in range(E)])
    info = np.zeros((E, dim + 1, dim + 1))
    for _ in range(ITERATIONS):
        delta = p[:, None, :] - receivers[None, :, :]
        rng = np.maximum(np.linalg.norm(delta, axis=2), 1e-6)
        residual = a - T[:, None] - rng * slowness[:, None]
        J = np.concatenate([delta / rng[..., None] * slowness[:, None, None], np.ones((E, len(sigma), 1))], axis=2)
        info = np.einsum("erk,er,erl->ekl", J, weight, J)
        grad = np.einsum("erk,er,er->ek", J, weight, residual)
        info_reg = info + 1e-12 * np.eye(dim + 1)
        step = np.linalg.solve(info_reg, grad[..., None])[..., 0]
        move = np.linalg.norm(step[:, :dim], axis=1)
        shrink = np.minimum(1.0, MAX_STEP / np.maximum(move, 1e-12))
        p = p + step[:, :dim] * shrink[:, None]
        T = T + step[:, dim] * shrink
        if np.max(move, initial=0.0) < 1e-4:
            break
    delta = p[:, None, :] - receivers[None, :, :]
    rng = np.linalg.norm(delta, axis=2)
    residual = np.where(mask, a - T[:, None] - rng * slowness[:, None], 0.0)
    return p, T, info, residual, move


def position_emissions(arrival: np.ndarray, receivers: np.ndarray, sigma: np.ndarray, slowness: np.ndarray
                       ) -> Fixes:
    """Position each emission (the module docstring).

    Parameters
    ----------
    arrival : numpy.ndarray
        (E, R) [s] the synchronised times of arrival, NaN where not heard.
    receivers : numpy.ndarray
        (R, dim) [m] the receivers' positions.
    sigma : numpy.ndarray
        (R,) [s] each receiver's timing sigma.
    slowness : numpy.ndarray
        (E,) [s/m] 1 / the sound speed of each emission.

    Returns
    -------
    Fixes
    """
    E, dim = len(arrival), receivers.shape[1]
    mask = np.isfinite(arrival)
    enough = mask.sum(axis=1) >= dim + 2
    start = np.array([receivers[m].mean(axis=0) if m.any() else np.zeros(dim) for m in mask])
    for _ in range(3):
        p, T, info, residual, move = _solve(arrival, mask, receivers, sigma, slowness, start)
        u = np.abs(residual) / sigma[None, :]
        worst = np.argmax(np.where(mask, u, -1.0), axis=1)
        bad = (u[np.arange(E), worst] > OUTLIER) & (mask.sum(axis=1) > dim + 2)
        if not bad.any():
            break
        mask[np.flatnonzero(bad), worst[bad]] = False
        start = p
    enough &= mask.sum(axis=1) >= dim + 2
    ok = enough & np.isfinite(p).all(axis=1) & (move < 1e-2)
    covariance = np.full((E, dim, dim), np.nan)
    if ok.any():
        full = np.linalg.inv(info[ok] + 1e-12 * np.eye(dim + 1))
        covariance[ok] = full[:, :dim, :dim]
    p[~ok] = np.nan
    T[~ok] = np.nan
    return Fixes(p, covariance, T, mask, ok)


__all__ = ["Fixes", "ITERATIONS", "MAX_STEP", "OUTLIER", "position_emissions"]

"""The robust smoother's covariances: the diagonal and lag-one blocks of the inverse of its block tridiagonal Hessian by
block cyclic reduction, and the receivers' survey error's and the sound speed's error's shares as consider
covariances.

References
----------
Heller, "Some aspects of the cyclic reduction algorithm for block tridiagonal linear systems", SIAM J. Numer. Anal.
13(4), 1976; Tapley, Schutz & Born, *Statistical Orbit Determination*, Elsevier 2004, § 6.3.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.smoother_cost import (
    ROBUST_DOF,
    _arrival_jacobians,
    _arrival_sums,
    _information,
    _Problem,
)
from sblsim.models.tracking.smoother_system import _banded_solve, _given_system, _normal_blocks


def _inverse(a: np.ndarray) -> np.ndarray:
    """The inverses of blocks (k, s, s), their pseudo-inverses where one is singular."""
    try:
        return np.linalg.inv(a)
    except np.linalg.LinAlgError:
        return np.linalg.pinv(a)


#: Blocks per chunk of the covariance's cyclic reduction (each level's operations a chunk at a time: the
#: temporaries stay small).
REDUCTION_CHUNK = 4096


def _block_covariance(D: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The diagonal blocks (m, s, s) of N⁻¹ for the symmetric positive definite block-tridiagonal N of diagonal blocks D
    (m, s, s) and upper blocks B (m − 1, s, s), and its blocks (k + 1, k) (m − 1, s, s): in place, D and B
    overwritten with them and returned.

    By block cyclic reduction (all blocks of a level at once, log₂ m levels; Heller, "Some aspects of the cyclic
    reduction algorithm for block tridiagonal linear systems", SIAM J. Numer. Anal. 13(4), 1976): the odd rows are
    eliminated (the Schur complement on the even ones is again block tridiagonal, half the size), the even rows'
    blocks of the inverse found, then the odd rows' from them, ``Σ_oo = D_o⁻¹ − Y₁ Σ_(o−1),o − Y₂ Σ_(o+1),o`` and
    ``Σ_o,e = −(Y₁ Σ_(o−1),e + Y₂ Σ_(o+1),e)`` with ``Y₁ = D_o⁻¹ N_o,(o−1)``, ``Y₂ = D_o⁻¹ N_o,(o+1)``. The same
    blocks as the Rauch-Tung-Striebel recursion in information form, without a Python step per ping. Each level
    keeps ``D_o⁻¹``, ``Y₁`` and ``Y₂`` where ``D_o``, ``N_(o−1),o`` and ``N_o,(o+1)`` were, and its even rows' Schur
    complement where theirs were; beside the output, one array of half the blocks per level (the even rows'
    couplings, m blocks over all levels), its operations a chunk of :data:`REDUCTION_CHUNK` blocks at a time."""
    _reduce(D, B)
    for lo in range(0, len(D), REDUCTION_CHUNK):
        block = D[lo:lo + REDUCTION_CHUNK]
        block[...] = 0.5 * (block + block.transpose(0, 2, 1))
    return D, B


def _reduce(D: np.ndarray, B: np.ndarray):
    """:func:`_block_covariance`'s recursion, in place: D (m, s, s) becomes the diagonal blocks of N⁻¹, B (m − 1, s, s)
    its blocks (k + 1, k)."""
    m, s = len(D), D.shape[1]
    if m == 1:
        D[:] = _inverse(D)
        return
    even, odd, before, after = D[0::2], D[1::2], B[0::2], B[1::2]  # before[j]: N_(o−1),o; after[j]: N_o,(o+1)
    no, nx = m // 2, (m - 1) // 2  # odd rows, odd rows with a next one (o = 2 j + 1)
    coupling = np.empty((nx, s, s))  # N'_(o−1),(o+1), then Σ_(o+1),(o−1)
    for c0 in range(0, no, REDUCTION_CHUNK):
        c1 = min(c0 + REDUCTION_CHUNK, no)
        x1 = min(c1, nx)
        Di = _inverse(odd[c0:c1])
        Y1 = Di @ before[c0:c1].transpose(0, 2, 1)  # D_o⁻¹ N_o,(o−1)
        Y2 = Di[:x1 - c0] @ after[c0:x1]  # D_o⁻¹ N_o,(o+1)
        even[c0:c1] -= before[c0:c1] @ Y1
        even[c0 + 1:x1 + 1] -= after[c0:x1].transpose(0, 2, 1) @ Y2
        coupling[c0:x1] = -(before[c0:x1] @ Y2)
        odd[c0:c1], before[c0:c1], after[c0:x1] = Di, Y1, Y2
    _reduce(even, coupling)  # the even rows: Σ_ee, and Σ_(e+2),e in coupling
    for c0 in range(0, no, REDUCTION_CHUNK):
        c1 = min(c0 + REDUCTION_CHUNK, no)
        x1 = min(c1, nx)
        Di, Y1, Y2 = odd[c0:c1], before[c0:c1], after[c0:x1]
        between = coupling[c0:x1]  # Σ_(o+1),(o−1)
        to_before = -(Y1 @ even[c0:c1])  # Σ_o,(o−1)
        to_before[:x1 - c0] -= Y2 @ between
        to_after = -(Y1[:x1 - c0] @ between.transpose(0, 2, 1) + Y2 @ even[c0 + 1:x1 + 1])  # Σ_o,(o+1)
        cov = Di - Y1 @ to_before.transpose(0, 2, 1)
        cov[:x1 - c0] -= Y2 @ to_after.transpose(0, 2, 1)
        odd[c0:c1], before[c0:c1], after[c0:x1] = cov, to_before, to_after.transpose(0, 2, 1)


def _survey_covariance(problem: _Problem, D: dict, B: dict, information: np.ndarray, Jz: np.ndarray,
                       survey: np.ndarray) -> np.ndarray:
    """The receivers' survey error's share of the track's covariance (m, s, s), a consider covariance (Tapley,
    Schutz & Born, *Statistical Orbit Determination*, Elsevier 2004, § 6.3): receiver i's position error δr_i, the
    same at every ping, moves the whole track by ``δx = −N⁻¹ (∂g/∂r_i) δr_i`` (N the cost's Hessian of the
    covariance, ``D``, ``B``; g its gradient, whose arrivals from receiver i change with r_i as their normalised
    residuals do, ``∂z/∂r_i = −∂z/∂p``), so each axis a adds ``σ_i² S S_kᵀ`` per ping with ``S = N⁻¹ u_(i,a)``:
    one banded solve per receiver and axis. Given the errors' square root L (n dim, p) instead of their σ (n,)
    (:mod:`~sblsim.models.tracking.survey_root`: correlated errors), ``δr = L θ``: one solve per column of L, of
    ``u_j = Σ_(i,a) L_(i a, j) u_(i,a)``, adding ``S_j S_jᵀ``."""
    P, dim = problem, problem.dim
    cols = list(range(dim)) + [P.s - 2]
    out = np.zeros((P.m, P.s, P.s))
    if survey.ndim == 2:
        for j in range(survey.shape[1]):
            along = sum(Jz[:, a] * survey[P.i * dim + a, j] for a in range(dim))  # each arrival's receiver's δr
            u = np.zeros((P.m, P.s))
            for x, col in enumerate(cols):
                u[:, col] = np.bincount(P.k, weights=-information * Jz[:, x] * along, minlength=P.m)
            S = _banded_solve(problem, _given_system(D, B, u), 1e-12)
            out += S[:, :, None] * S[:, None, :]
        return out
    for i in np.flatnonzero(survey > 0):
        mine = P.i == i
        for a in range(dim):
            u = np.zeros((P.m, P.s))
            for x, col in enumerate(cols):
                u[:, col] = np.bincount(P.k[mine], weights=-information[mine] * Jz[mine, x] * Jz[mine, a],
                                        minlength=P.m)
            S = _banded_solve(problem, _given_system(D, B, u), 1e-12)
            out += survey[i] ** 2 * S[:, :, None] * S[:, None, :]
    return out


def survey_covariance(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, X: np.ndarray,
                      schedule: PingSchedule | None = None, depth: np.ndarray | None = None,
                      dof: float = ROBUST_DOF) -> np.ndarray:
    """The receivers' survey error's share of a robust track's covariance at its states (the term
    :func:`~sblsim.models.tracking.smoother.robust_smooth` adds to ``P`` where ``settings.survey_sigma`` is given;
    :func:`_survey_covariance`), for a track solved without it.

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        [m].
    settings : TrackerSettings
        With ``survey_sigma`` (n,) [m], or the square root (n dim, p) [m] of correlated errors
        (:func:`~sblsim.models.tracking.survey_root.survey_root`) (None: a zero term).
    X : ndarray, (m, 2 dim + 2)
        The track's states (:class:`~sblsim.models.tracking.smoother.RobustTrack` ``x``).
    schedule, depth, dof
        As :func:`~sblsim.models.tracking.smoother.robust_smooth`.

    Returns
    -------
    ndarray, (m, 2 dim + 2, 2 dim + 2)
    """
    return consider_covariance(toa, receivers, settings, X, None, schedule, depth, dof)


def _speed_covariance(problem: _Problem, D: dict, B: dict, information: np.ndarray, Jz: np.ndarray, X: np.ndarray,
                      sigma_c: float) -> np.ndarray:
    """The sound speed's error's share of the track's covariance (m, s, s), a consider covariance as
    :func:`_survey_covariance`'s: an error δc, the same at every arrival, moves the whole track by
    ``δx = −N⁻¹ (∂g/∂c) δc``, each arrival's normalised residual changing by ``∂z/∂c = ρ / (c² σ_toa)`` (ρ its
    range at the states), so the term is ``σ_c² S S_kᵀ`` per ping with ``S = N⁻¹ u``: one banded solve."""
    P, dim = problem, problem.dim
    c = P.settings.sound_speed
    rho = np.sqrt(sum((X[P.k, a] - P.r[a]) ** 2 for a in range(dim)))
    dz = information * rho / (c * c * P.sigma)  # P.sigma: one, or each arrival's
    u = np.zeros((P.m, P.s))
    for x, col in enumerate(list(range(dim)) + [P.s - 2]):
        u[:, col] = np.bincount(P.k, weights=dz * Jz[:, x], minlength=P.m)
    S = _banded_solve(problem, _given_system(D, B, u), 1e-12)
    return sigma_c**2 * S[:, :, None] * S[:, None, :]


def speed_covariance(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, X: np.ndarray,
                     sigma_c: float, schedule: PingSchedule | None = None, depth: np.ndarray | None = None,
                     dof: float = ROBUST_DOF) -> np.ndarray:
    """The sound speed's error's share of a robust track's covariance at its states (:func:`_speed_covariance`; a
    consider covariance, Tapley, Schutz & Born 2004, § 6.3): what a speed calibrated from the pings, or a fallback,
    leaves uncertain in every range. ``toa``, ``receivers``, ``X``, ``schedule``, ``depth``, ``dof`` as
    :func:`survey_covariance`'s; ``settings`` with the speed the track was solved at (``sound_speed`` [m/s]);
    ``sigma_c`` the speed's standard error [m/s]. Returns (m, 2 dim + 2, 2 dim + 2) [m², ...]."""
    return consider_covariance(toa, receivers, replace(settings, survey_sigma=None), X, sigma_c, schedule, depth,
                               dof)


def consider_covariance(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, X: np.ndarray,
                        sigma_c: float | None = None, schedule: PingSchedule | None = None,
                        depth: np.ndarray | None = None, dof: float = ROBUST_DOF) -> np.ndarray:
    """The consider terms of a robust track's covariance at its states, from one Hessian: the receivers' survey
    error's (``settings.survey_sigma``, :func:`survey_covariance`) and the sound speed's (``sigma_c`` [m/s],
    :func:`speed_covariance`), each where given; arguments as theirs. Returns (m, 2 dim + 2, 2 dim + 2) [m², ...],
    zero where neither is given."""
    toa, X = np.asarray(toa, float), np.asarray(X, float)
    out = np.zeros((len(toa), X.shape[1], X.shape[1]))
    if settings.survey_sigma is None and not sigma_c:
        return out
    if schedule is None:
        schedule = PingSchedule.stable(len(toa), settings.interval, settings.jitter, settings.interval_drift)
    problem = _Problem(toa, np.asarray(receivers, float), settings, schedule, depth)
    states = _at_states(problem, X, dof)
    if settings.survey_sigma is not None:
        out += _survey_covariance(problem, *states, np.asarray(settings.survey_sigma, float))
    if sigma_c:
        out += _speed_covariance(problem, *states, X, float(sigma_c))
    return out


def _at_states(problem: _Problem, X: np.ndarray, dof: float) -> tuple:
    """What a consider term takes at the states X: the Hessian's blocks D, B (from the arrivals' observed
    information), each arrival's information and its Jacobian Jz."""
    z, Jz = _arrival_jacobians(problem, X)
    sums = _arrival_sums(problem, X, dof, information=True)
    D, B = _normal_blocks(problem, X, sums, problem.durations(X))
    return D, B, _information(problem, z, dof), Jz



__all__ = ["REDUCTION_CHUNK", "consider_covariance", "speed_covariance", "survey_covariance"]

"""The robust smoother re-solved over windows of a track, the rest of the track held: each window's states from a
start of its own, conditioned on the states about it, and what putting them in changes of the whole cost.

The robust smoother's cost is a sum of local terms (each ping's arrivals and depth reading, each step between two
pings, the first interval's prior): with the states outside a window held, the window's share of the cost is its own
arrivals and the steps from the row before it to the row after it, and putting its states into the track changes the
whole cost by the change of that share alone. Windows apart from one another (no window's rows among another's or
its held rows) are laid out as one problem, one after another across steps so long that they do not couple
(:data:`~sblsim.models.tracking.modes.SEPARATION`), and their changes add up. Each window is solved on its own: the
Gauss-Newton step of the problem is each window's own (the held rows decouple the normal equations), and each takes
its step, halves it and stops by its own cost (the robust smoother's line search and stopping rule,
:func:`~sblsim.models.tracking.smoother.robust_smooth`), so a window's answer does not depend on the others solved
beside it.

References
----------
Bell, "The iterated Kalman smoother as a Gauss-Newton method", SIAM J. Optim. 4(3), 1994 (the smoother's cost as a
chain of local terms).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.modes import _windows
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.smoother import ROBUST_ITERATIONS, ROBUST_SCREEN, ROBUST_TOLERANCE
from sblsim.models.tracking.smoother_cost import (
    ROBUST_DOF,
    _arrival_sums,
    _depth_residual,
    _interval_prior,
    _Problem,
    _robust_terms,
    _trial_cost,
)
from sblsim.models.tracking.smoother_system import _damped_solve, _held_system, _step_system


@dataclass
class Resolved:
    """What :func:`resolved_windows` found over B windows (their free rows ``lo:hi``) of a track of m pings.

    Attributes
    ----------
    lo, hi : ndarray of int, (B,)
        Each window's rows ``lo:hi``, re-solved.
    x : list of ndarray
        Each window's states (hi − lo, s) from its start, the rows before and after it held.
    weights : list of ndarray
        Each window's arrivals' Gauss-Newton weights at them (hi − lo, n), as :class:`RobustTrack`'s.
    gain : ndarray, (B,)
        The whole cost's fall where the window's states are put into the track (its share at the track's states minus
        its share at the window's) [1].
    screened : ndarray, (B,)
        The same after the solve's first ``screen`` steps (:func:`resolved_windows`).
    edge : ndarray, (B,)
        How far the window's states from its start lie from the same window solved from the track's own states, at
        its first and last rows beside a held row [m] (the position, or the emission time times the sound speed
        where larger): the start's reach there, the track's own convergence in the window the same in both; 0 where
        the window reaches the record's ends.
    """

    lo: np.ndarray
    hi: np.ndarray
    x: list
    weights: list
    gain: np.ndarray
    screened: np.ndarray
    edge: np.ndarray


def resolved_windows(X: np.ndarray, start: np.ndarray, lo: np.ndarray, hi: np.ndarray, toa: np.ndarray,
                     receivers: np.ndarray, settings: TrackerSettings, schedule: PingSchedule,
                     depth: np.ndarray | None = None, dof: float = ROBUST_DOF, screen: int = ROBUST_SCREEN,
                     lost=None, keep=None) -> Resolved:
    """The robust smoother of the windows ``lo:hi`` of a track X from the states ``start``, to convergence, the
    track's rows before and after each window held, each window on its own (the module's method: the smoother's
    Gauss-Newton steps, line search and stop, at most
    :data:`~sblsim.models.tracking.smoother.ROBUST_ITERATIONS` steps); each window's gain after the first
    ``screen`` steps too (as a start of the whole record is screened), and the windows solved from the track's own
    states beside, for :attr:`Resolved.edge`.

    Parameters
    ----------
    X : ndarray, (m, 2 dim + 2)
        The track's states.
    start : ndarray, (m, 2 dim + 2)
        The start of the windows' rows (its other rows not read).
    lo, hi : ndarray of int, (B,)
        The windows, increasing and apart: ``hi[b] < lo[b + 1]`` (each window's held rows ``lo − 1`` and ``hi`` none
        of another's rows).
    toa, receivers, settings, schedule, depth, dof
        As the track was solved with (:func:`~sblsim.models.tracking.smoother.robust_smooth`): times of arrival
        (m, n) [s], receivers (n, dim) [m], the settings, the steps between the rows, the depth readings (m,) [m].
    screen : int
        The steps after which :attr:`Resolved.screened` is taken (default the smoother's screening of its starts).
    lost : callable, optional
        Given the screened gains (B,): whether the start has lost its screening; where it has, the windows are
        not solved on (the answer's states, weights and gains the screening's, its edges NaN).
    keep : callable, optional
        Given the gains (B,) at the end: whether the windows' states would be put in; where not, their edges are
        not measured (NaN: the windows solved from the track's own states not made).

    Returns
    -------
    Resolved

    Raises
    ------
    numpy.linalg.LinAlgError
        Where a step's process noise is not positive definite (as the smoother's problem).
    """
    m, count = len(X), len(lo)
    outer_lo, outer_hi = np.maximum(lo - 1, 0), np.minimum(hi + 1, m)
    rows, block, inside, steps = _windows(outer_lo, outer_hi, schedule)
    held = (rows < np.repeat(lo, outer_hi - outer_lo)) | (rows >= np.repeat(hi, outer_hi - outer_lo))
    problem = _Problem(toa[rows], receivers, settings, steps, None if depth is None else depth[rows])
    windows = _Windows(problem, block, inside, held, count, dof, len(receivers))
    before = X[rows]
    costs = windows.costs(before)
    solved, cost, active = windows.descend(np.where(held[:, None], before, start[rows]), screen)
    screened = costs - cost
    free = np.flatnonzero(~held)
    cuts = np.cumsum(hi - lo)[:-1]

    def answer(gain, edge):
        weights = windows.weights(solved)
        return Resolved(lo, hi, np.split(solved[free], cuts), np.split(weights[free], cuts), gain, screened, edge)

    if lost is not None and lost(screened):
        return answer(screened, np.full(count, np.nan))
    solved, cost, _ = windows.descend(solved, ROBUST_ITERATIONS - screen, active, cost)
    gain = costs - cost
    if keep is not None and not keep(gain):
        return answer(gain, np.full(count, np.nan))
    own = windows.descend(before, ROBUST_ITERATIONS)[0]  # the track's own minimum in the windows (near it)
    dim = receivers.shape[1]
    moved = np.maximum(np.linalg.norm(solved[:, :dim] - own[:, :dim], axis=1),
                       settings.sound_speed * np.abs(solved[:, -2] - own[:, -2]))
    beside = ~held & (np.r_[held[1:], False] | np.r_[False, held[:-1]])  # a window's rows next to a held one
    edge = np.zeros(count)
    np.maximum.at(edge, block[beside], moved[beside])
    return answer(gain, edge)


class _Windows:
    """The windows of :func:`resolved_windows` as one problem (``problem``, N rows): each row's window ``block``
    (N,), the steps ``inside`` (N − 1,) a window's own (not those between two), the ``held`` rows (N,), ``count``
    windows, ν ``dof``, ``n`` receivers."""

    def __init__(self, problem: _Problem, block: np.ndarray, inside: np.ndarray, held: np.ndarray, count: int,
                 dof: float, n: int):
        self.problem, self.block, self.inside, self.held = problem, block, inside, held
        self.count, self.dof, self.n = count, dof, n
        self.scratch = (None, np.empty((problem.m - 1, problem.s)), np.empty(problem.m - 1))

    def costs(self, Y: np.ndarray) -> np.ndarray:
        """Each window's share of the robust cost at the states Y (N, s): (count,)."""
        _trial_cost(self.problem, Y, self.dof, self.scratch)
        return self._shares(Y)

    def _shares(self, Y: np.ndarray) -> np.ndarray:
        """Each window's share of the cost from the problem's terms at Y of the last pass (its arrivals', depth
        readings' and steps' terms; the first interval's prior on the first window: the record's, where that window
        starts the record, else the same on both sides of a difference)."""
        P, block, count = self.problem, self.block, self.count
        costs = np.bincount(block[P.k], (self.dof + 1.0) * P.logs, minlength=count)
        costs += np.bincount(block[:-1][self.inside], P.squares[self.inside].sum(axis=1), minlength=count)
        if len(P.depth_at):
            costs += np.bincount(block[P.depth_at], _depth_residual(P, Y) ** 2, minlength=count)
        costs[0] += _interval_prior(P.settings, Y) ** 2
        return costs

    def descend(self, Y: np.ndarray, iterations: int, active: np.ndarray | None = None,
                cost: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Up to ``iterations`` Gauss-Newton steps of each window still ``active`` (default all) from the states Y
        (N, s), the held rows and the other windows' rows fixed in each step's system; each window's step halved
        until its own cost falls (down to 10⁻⁶ of it: else it has stopped at a minimum), and stopped where a step
        gains less than :data:`~sblsim.models.tracking.smoother.ROBUST_TOLERANCE` of its cost. Returns the states,
        each window's cost (count,) (``cost``: at Y, where known) and which windows are still stepping."""
        P, block = self.problem, self.block
        X = np.array(Y, float)
        active = np.ones(self.count, bool) if active is None else active.copy()
        sums, e, T, _ = _robust_terms(P, X, self.dof)
        cost = self._shares(X) if cost is None else cost
        for _ in range(iterations):
            if not active.any():
                break
            system = partial(_step_system, P, X, sums, e, T)
            step = _damped_solve(P, partial(_held_system, self.held | ~active[block], system))
            if step is None:  # no damping makes the system positive definite: stopped where they are
                active[:] = False
                break
            scale, trying, taken, lower = np.ones(self.count), active.copy(), X.copy(), cost.copy()
            while trying.any():
                trial = X + scale[block, None] * step
                trial_cost = self.costs(trial)
                better = trying & (trial_cost < cost)
                rows = better[block]
                taken[rows], lower[better] = trial[rows], trial_cost[better]
                trying &= ~better
                scale[trying] *= 0.5
                flat = trying & (scale <= 1e-6)  # no step lowers its cost: a minimum
                active &= ~flat
                trying &= ~flat
            active &= ~(cost - lower <= ROBUST_TOLERANCE * lower)
            X, cost = taken, lower
            _robust_terms(P, X, self.dof, (sums, e, T))
        return X, cost, active

    def weights(self, Y: np.ndarray) -> np.ndarray:
        """Each arrival's Gauss-Newton weight at the states Y (N, s), as :class:`RobustTrack`'s (N, n)."""
        P = self.problem
        w = np.empty(len(P.k))
        _arrival_sums(P, Y, self.dof, information=True, weights=w)
        out = np.zeros((P.m, self.n))
        out[P.k, P.i] = w
        return out


__all__ = ["Resolved", "resolved_windows"]

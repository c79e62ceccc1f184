"""The robust smoother's other local modes where late arrivals are modelled, and the covariance of their mixture.

With late (multipath) arrivals in the model (:mod:`~sblsim.models.tracking.arrival_model`) the posterior of a ping
heard by few receivers can have two modes: the position that explains every arrival as direct, and one where an
arrival is late and the position lies elsewhere. A Gaussian about the better one (the Laplace approximation of
:func:`~sblsim.models.tracking.smoother.robust_smooth`) is then too tight. Here each hypothesis "arrival j of ping
k is late" (and "arrivals j and j' of ping k are late", :data:`MODE_LATE`) is solved locally — the pings
k − W … k + W re-solved with those arrivals left out, from the track and from ping k's neighbours' mean, then with
them back — and scored by the whole cost's change Δ (the window's own arrivals and steps and the steps joining it
to the track). A mode of lower cost is a better start (the track re-solved from it, screened against the track);
the others are weighed against the track by their evidence in Laplace's approximation, each mode's integral of
``exp(−cost/2)`` over the window's states with the rest of the track held, ``exp(−c/2) (2π)^(d/2) det(N)^(−1/2)``
(N the window's Gauss-Newton Hessian at the mode; MacKay, *Information Theory, Inference, and Learning
Algorithms*, Cambridge 2003, § 27.1): ``w_h = exp(−Δ/2) √(det N / det N_h)`` against the track's 1 (a mode that
leaves an arrival out of its position is wider, so it weighs more than its cost alone says). Their spread about the
track is added to its covariance: the second moment of the mixture about the reported estimate,
``P + Σ_h w_h (x_h − x)(x_h − x)ᵀ / (1 + w_h)`` (moment matching of a Gaussian mixture, as the IMM estimator
combines its modes: Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and Navigation*, Wiley
2001, § 11.6; each mode's own covariance taken as the track's).

The windows are solved together, as one problem whose windows follow one another across steps so long that they do
not couple (:data:`SEPARATION`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.smoother import RobustTrack, robust_smooth
from sblsim.models.tracking.smoother_cost import ROBUST_DOF, _arrival_sums, _depth_residual, _Problem, _robust_terms
from sblsim.models.tracking.smoother_system import _dense_blocks, _normal_blocks

#: Pings each side of a hypothesis's ping that its window re-solves.
MODE_WINDOW = 2

#: Gauss-Newton iterations of a window's solve without the arrival, and then with it back.
MODE_ITERATIONS = (30, 10)

#: The duration [s] (and the emission time's and interval's spread) of the step between two windows solved
#: together: its process noise so large that neither window weighs on the other.
SEPARATION = 1e7

#: Hypotheses solved together at most (their windows' rows about five times as many).
MODE_BATCH = 5000

#: A mode counts as another one where it lies outside the track's 1-σ ellipse at the hypothesis's ping (squared
#: Mahalanobis distance above this) and differs from the modes kept for that ping by more than that too.
MODE_DISTINCT = 1.0

#: A mode lower in cost than the track by more than this is a better start (not a spread about the track).
MODE_BETTER = 1.0

#: After the track is re-solved from its better modes, a ping's state counts as moved where a component changed by
#: more than this many of its own standard deviations; only the hypotheses whose windows (with the rows joining them
#: to the track) hold a moved row are searched again, the others' spread kept.
MODE_MOVED = 0.1

#: The late arrivals of one ping a hypothesis takes, at most (1 or 2): each arrival of a ping heard by dim + 1
#: receivers or more, and with 2 each pair of arrivals of a ping heard by dim + 2 or more (one arrival of the ping's
#: own still redundant without the pair). Where reflections are common a ping of four or more receivers often has
#: two late: at 10 % of 5 m, three of the eight worst pings of lake-hald-array's walk (seed 1) had
#: (docs/tracking.md).
MODE_LATE = 2


@dataclass
class Modes:
    """What :func:`local_modes` found about a track (m pings).

    Attributes
    ----------
    spread : ndarray, (m, dim, dim)
        ``Σ_h w_h (p_h − p)(p_h − p)ᵀ / (1 + w_h)`` of each ping's position over the modes found [m²] (0 where none).
    by_ping : ndarray, (m, 2 W + 1, dim, dim)
        The same sum split by the hypotheses' ping k: its share at rows k − W … k + W (W :data:`MODE_WINDOW`) [m²].
    better : ndarray, (m, s), or None
        The track with the windows of the modes lower in cost than it (by :data:`MODE_BETTER`) put in, each
        window's lowest; None where none is.
    hypotheses : int
        The hypotheses solved (:func:`hypotheses`).
    """

    spread: np.ndarray
    by_ping: np.ndarray
    better: np.ndarray | None
    hypotheses: int


def _spread(by_ping: np.ndarray) -> np.ndarray:
    """:attr:`Modes.spread` from :attr:`Modes.by_ping`: each ping's share summed onto the rows it reaches."""
    m, width = by_ping.shape[:2]
    spread = np.zeros((m,) + by_ping.shape[2:])
    for a in range(width):  # offset a − W from the hypothesis's ping
        shift = a - MODE_WINDOW
        lo, hi = max(0, -shift), min(m, m - shift)
        spread[lo + shift:hi + shift] += by_ping[lo:hi, a]
    return spread


def moved_pings(before: np.ndarray, after: np.ndarray, P: np.ndarray) -> np.ndarray:
    """The pings (m,) bool whose hypotheses' windows hold a state moved from ``before`` to ``after`` (m, s) by more
    than :data:`MODE_MOVED` of its standard deviation (the diagonal of ``P`` (m, s, s)), or within
    :data:`MODE_WINDOW` + 1 rows of one (the rows joining a window to the track)."""
    sigma = np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2), 1e-300, None))
    moved = (np.abs(after - before) > MODE_MOVED * sigma).any(axis=1)
    reach = MODE_WINDOW + 1
    return np.convolve(moved.astype(float), np.ones(2 * reach + 1), mode="same") > 0


def _windows(lo: np.ndarray, hi: np.ndarray, schedule: PingSchedule) -> tuple:
    """The rows (N,) of the windows ``lo:hi`` (B each) one after another, the block of each row (N,), and their
    schedule (N − 1 steps: each window's own, a :data:`SEPARATION` between two)."""
    lengths = hi - lo
    block = np.repeat(np.arange(len(lo)), lengths)
    first = np.r_[0, np.cumsum(lengths)[:-1]]
    rows = np.repeat(lo, lengths) + np.arange(lengths.sum()) - np.repeat(first, lengths)
    inside = block[:-1] == block[1:]
    step = np.where(inside, np.minimum(rows[:-1], len(schedule.count) - 1), 0)
    count = np.where(inside, schedule.count[step], 0.0)
    offset = np.where(inside, schedule.offset[step], SEPARATION)
    te = np.where(inside, schedule.te_sigma[step], SEPARATION)
    drift = np.where(inside, schedule.drift_sigma[step], SEPARATION)
    return rows, block, inside, replace(schedule, count=count, offset=offset, te_sigma=te, drift_sigma=drift,
                                        gaps=())


def hypotheses(heard: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The hypotheses of late arrivals the search solves (:data:`MODE_LATE`): each arrival of a ping heard by
    dim + 1 receivers or more, then each pair of arrivals of a ping heard by dim + 2 or more.

    Parameters
    ----------
    heard : ndarray of bool, (m, n)
        Which receivers heard each ping.
    dim : int
        The positions' dimension.

    Returns
    -------
    k : ndarray of int, (H,)
        Each hypothesis's ping.
    j : ndarray of int, (H, 2)
        Its late arrivals' receivers, −1 in the second column for one arrival alone.
    """
    count = heard.sum(axis=1)
    k, j = np.nonzero(heard & (count >= dim + 1)[:, None])
    ks, js = [k], [np.column_stack([j, np.full(len(j), -1)])]
    if MODE_LATE >= 2:
        for n in np.unique(count[count >= dim + 2]):  # the pings heard by n receivers: their C(n, 2) pairs
            pings = np.flatnonzero(count == n)
            who = np.nonzero(heard[pings])[1].reshape(len(pings), n)
            a, b = np.triu_indices(n, 1)
            ks.append(np.repeat(pings, len(a)))
            js.append(np.column_stack([who[:, a].ravel(), who[:, b].ravel()]))
    return np.concatenate(ks), np.concatenate(js)


def _window_costs(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, schedule: PingSchedule,
                  depth: np.ndarray | None, X: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  candidates: list[np.ndarray] = ()) -> tuple[np.ndarray, np.ndarray]:
    """Each window's share of the robust cost: the arrivals of the pings ``lo − 1 : hi + 1`` and the steps between
    them, at the track's states X (m, s), then with each candidate's states (N, s: the rows of :func:`_windows` of
    ``lo:hi``) put in (1 + candidates, B), all on one problem; and beside it (1 + candidates, B) the ln det of each
    window's Gauss-Newton Hessian over its own rows, the rows about it held (:func:`_window_logdets`)."""
    m = len(X)
    ext_lo, ext_hi = np.maximum(lo - 1, 0), np.minimum(hi + 1, m)
    rows, block, inside, sched = _windows(ext_lo, ext_hi, schedule)
    own = (rows >= np.repeat(lo, ext_hi - ext_lo)) & (rows < np.repeat(hi, ext_hi - ext_lo))  # the windows' rows
    problem = _Problem(toa[rows], receivers, settings, sched, None if depth is None else depth[rows])
    costs = np.empty((1 + len(candidates), len(lo)))
    logdets = np.empty_like(costs)
    for c, states in enumerate([None, *candidates]):
        Y = X[rows].copy()
        if states is not None:
            Y[own] = states
        _, _, T, _ = _robust_terms(problem, Y, ROBUST_DOF)
        costs[c] = np.bincount(block[problem.k], (ROBUST_DOF + 1.0) * problem.logs, minlength=len(lo))
        costs[c] += np.bincount(block[:-1][inside], problem.squares[inside].sum(axis=1), minlength=len(lo))
        if len(problem.depth_at):
            costs[c] += np.bincount(block[problem.depth_at], _depth_residual(problem, Y) ** 2, minlength=len(lo))
        logdets[c] = _window_logdets(problem, Y, T, own, hi - lo)
    return costs, logdets


def _window_logdets(problem: _Problem, Y: np.ndarray, T: np.ndarray, own: np.ndarray,
                    lengths: np.ndarray) -> np.ndarray:
    """ln det of each window's Gauss-Newton Hessian (the arrivals' observed information, as the smoother's
    covariance) over its own rows ``own`` (N,) of the windows' problem at the states Y (N, s) (T (N − 1,): the
    steps' durations there, :func:`~sblsim.models.tracking.smoother_cost._robust_terms`'), the rows about it held:
    the Hessian's submatrix on those rows, block tridiagonal, its determinant the product of its block Cholesky
    pivots' ``S_i = D_i − B_(i−1)ᵀ S_(i−1)⁻¹ B_(i−1)`` (all windows at once; ``lengths`` (B,) their rows)."""
    sums = _arrival_sums(problem, Y, ROBUST_DOF, information=True)
    D, B = _dense_blocks(problem, partial(_normal_blocks, problem, Y, sums, T))
    rows, first = np.flatnonzero(own), np.r_[0, np.cumsum(lengths)[:-1]]
    total = np.zeros(len(lengths))
    pivot = np.broadcast_to(np.eye(problem.s), (len(lengths), problem.s, problem.s)).copy()
    for i in range(int(lengths.max(initial=0))):
        have = lengths > i
        row = rows[first[have] + i]
        if i == 0:
            pivot[have] = D[row]
        else:
            coupling = B[row - 1]  # the block (row − 1, row)
            pivot[have] = D[row] - coupling.transpose(0, 2, 1) @ np.linalg.solve(pivot[have], coupling)
        total[have] += np.linalg.slogdet(pivot[have])[1]
    return total


def _solve(toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings, schedule: PingSchedule,
           depth: np.ndarray | None, X: np.ndarray, k: np.ndarray, j: np.ndarray, start_mean: bool) -> tuple:
    """The hypotheses (k (H,), j (H, 2): :func:`hypotheses`) solved in their windows, all at once: the window's
    states with ping k's arrivals j left out, then with them back (:data:`MODE_ITERATIONS`), from the track's states
    or (``start_mean``) with ping k's replaced by its neighbours' mean. Returns the states (N, s), the windows'
    bounds ``lo``, ``hi`` (H,), the track's row of each state (N,) and ping k's index among the states (H,)."""
    m = len(X)
    lo, hi = np.maximum(k - MODE_WINDOW, 0), np.minimum(k + MODE_WINDOW + 1, m)
    rows, _, _, sched = _windows(lo, hi, schedule)
    start = X[rows].copy()
    at = np.r_[0, np.cumsum(hi - lo)[:-1]] + (k - lo)  # ping k's row in each window
    if start_mean:
        inner = (k > 0) & (k < m - 1)
        start[at[inner]] = 0.5 * (X[k[inner] - 1] + X[k[inner] + 1])
    sub, sub_depth = toa[rows], None if depth is None else depth[rows]
    left = sub.copy()
    for late in np.reshape(j, (len(k), -1)).T:
        some = late >= 0
        left[at[some], late[some]] = np.nan
    out = robust_smooth(left, receivers, settings, [start], iterations=MODE_ITERATIONS[0], covariance=False,
                        schedule=sched, depth=sub_depth, student_start=False).x
    out = robust_smooth(sub, receivers, settings, [out], iterations=MODE_ITERATIONS[1], covariance=False,
                        schedule=sched, depth=sub_depth, student_start=False).x
    return out, lo, hi, rows, at


def local_modes(track: RobustTrack, toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings,
                schedule: PingSchedule, depth: np.ndarray | None = None, pings: np.ndarray | None = None,
                base: Modes | None = None) -> Modes:
    """The other local modes of the robust smoother's cost near a track, one hypothesis per arrival of each ping
    heard by dim + 1 receivers or more and per pair of arrivals of each ping heard by dim + 2 or more
    (:func:`hypotheses`; the module's method).

    Parameters
    ----------
    track : RobustTrack
        :func:`~sblsim.models.tracking.smoother.robust_smooth`'s answer, with its covariance.
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
        As the track was solved with (its late arrivals' share and mean among them).
    schedule : PingSchedule
        The steps between the rows.
    depth : ndarray, (m,), optional
        The tag's depth readings [m].
    pings : ndarray of bool, (m,), optional
        Only the hypotheses of these pings solved (default all), the others' share of the spread taken from ``base``
        (:func:`moved_pings`: after the track moved there).
    base : Modes, optional
        An earlier search of the same record, whose :attr:`Modes.by_ping` the pings not in ``pings`` keep.

    Returns
    -------
    Modes
    """
    X, P = track.x, track.P
    m, dim = X.shape[0], receivers.shape[1]
    k_all, j_all = hypotheses(np.isfinite(toa), dim)
    by_ping = np.zeros((m, 2 * MODE_WINDOW + 1, dim, dim))
    if pings is not None:
        if base is not None:
            by_ping[~pings] = base.by_ping[~pings]
        chosen = pings[k_all]
        k_all, j_all = k_all[chosen], j_all[chosen]
    better_cost = np.zeros(m)
    better = X.copy()
    solved = 0
    kept: dict[int, list[np.ndarray]] = {}  # each ping's modes kept, by their positions
    information = np.linalg.inv(P[:, :dim, :dim])
    for b0 in range(0, len(k_all), MODE_BATCH):
        k, j = k_all[b0:b0 + MODE_BATCH], j_all[b0:b0 + MODE_BATCH]
        solved += len(k)
        runs = [_solve(toa, receivers, settings, schedule, depth, X, k, j, mean) for mean in (False, True)]
        lo, hi = runs[0][1], runs[0][2]
        costs, logdets = _window_costs(toa, receivers, settings, schedule, depth, X, lo, hi, [run[0] for run in runs])
        deltas = costs[1:] - costs[0]
        widths = logdets[1:] - logdets[0]  # ln det N_h − ln det N: the modes' Laplace evidence beside their cost
        edges = np.r_[0, np.cumsum(hi - lo)]  # each window's states: edges[h]:edges[h + 1]
        for run, delta, width in zip(runs, deltas, widths):
            states, _, _, rows, at = run
            shift = states[:, :dim] - X[rows, :dim]
            d2 = np.einsum("hi,hij,hj->h", shift[at], information[k], shift[at])
            for h in np.flatnonzero(d2 > MODE_DISTINCT):  # a mode other than the track's, at ping k
                window = slice(edges[h], edges[h + 1])
                kk = k[h]
                if delta[h] < -MODE_BETTER:  # a better start: the window's lowest such mode kept
                    if delta[h] < better_cost[kk]:
                        better_cost[kk] = delta[h]
                        better[rows[window]] = states[window]
                    continue
                # the mode's weight against the track's 1, its evidence's (a mode within the ellipse of one kept
                # for the same ping: the same mode, counted once)
                here = states[at[h], :dim]
                if any((here - p) @ information[kk] @ (here - p) <= MODE_DISTINCT for p in kept.get(kk, ())):
                    continue
                kept.setdefault(kk, []).append(here)
                w = np.exp(-0.5 * (delta[h] + width[h]))
                s = shift[window]
                by_ping[kk, rows[window] - kk + MODE_WINDOW] += (w / (1.0 + w)) * np.einsum("ki,kj->kij", s, s)
    return Modes(_spread(by_ping), by_ping, better if (better_cost < 0).any() else None, solved)


def with_modes(track: RobustTrack, toa: np.ndarray, receivers: np.ndarray, settings: TrackerSettings,
               schedule: PingSchedule, depth: np.ndarray | None = None) -> RobustTrack:
    """The track re-solved from its better local modes where it has any (kept where its cost is lower; once), and
    its position covariance widened by the spread of its other modes (:func:`local_modes`; after a re-solve searched
    again only where the track moved, :func:`moved_pings`).

    Parameters
    ----------
    track : RobustTrack
        :func:`~sblsim.models.tracking.smoother.robust_smooth`'s answer (m pings).
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        Receiver positions [m].
    settings : TrackerSettings
        As the track was solved with.
    schedule : PingSchedule
        The steps between the rows.
    depth : ndarray, (m,), optional
        The tag's depth readings [m].

    Returns
    -------
    RobustTrack
        The track itself where late arrivals are not modelled (``delay_share`` 0) or it has no covariance; else its
        states (re-solved or not) with ``P[:, :dim, :dim]`` [m²] the mixture's second moment about them.
    """
    if settings.delay_share <= 0.0 or track.P is None:
        return track
    modes = local_modes(track, toa, receivers, settings, schedule, depth)
    if modes.better is not None:
        again = robust_smooth(toa, receivers, settings, [track.x, modes.better], schedule=schedule, depth=depth,
                              student_start=False)
        if again.cost < track.cost:
            moved = moved_pings(track.x, again.x, again.P)
            track = replace(again, start=track.start, start_names=track.start_names)
            modes = local_modes(track, toa, receivers, settings, schedule, depth, pings=moved, base=modes)
    P = track.P.copy()
    dim = receivers.shape[1]
    P[:, :dim, :dim] += modes.spread
    return replace(track, P=P)


__all__ = ["MODE_BATCH", "MODE_BETTER", "MODE_DISTINCT", "MODE_ITERATIONS", "MODE_LATE", "MODE_MOVED", "MODE_WINDOW",
           "Modes", "SEPARATION", "hypotheses", "local_modes", "moved_pings", "with_modes"]

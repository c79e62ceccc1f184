"""One transmitter id heard from two places at once: a second tag on the same code (a code collision, a code space
reused, another study's tag) whose single-ping fixes interleave with the tag's own, far from them in the same time.

Two tags sharing an id make one times-of-arrival matrix of two animals' pings; whatever the ping type (stated or
inferred), every tracker draws one track through both, each jump a step no animal swims. Where both places are compact
and each holds a fifth of the fixes, :mod:`~sblsim.models.tracking.twins` finds them; a tag that moves, or a second
tag heard a few dozen times, escapes it. Here the trusted single-ping fixes, in time order, are first linked into
**chains** (nearest-neighbour association, Bar-Shalom, Willett & Tian, *Tracking and Data Fusion*, 2011): a fix joins
the chain whose place (the median of its last :data:`MEMORY` fixes) is nearest among those it could have come from in
the time between at the chain's own speed (:data:`SPEED_FACTOR` times the median of its last :data:`SPEED_STEPS`
steps', at most :data:`~sblsim.models.tracking.twins.MAX_SPEED`; a new chain's the top speed), within :data:`SIGMAS`
of their combined sigmas; else it starts a chain. Each chain but the largest, of :data:`MIN_FIXES` fixes or more, is
the seed of a **second place**: every trusted fix is given to the place whose **path** (the median of its two fixes
before and two after) is nearer, again until none moves (at most :data:`ITERATIONS` times); the rest is the **first
place**. The two are two places at once where

* the second holds :data:`MIN_FIXES` trusted fixes or more, and no more than the first;
* they are heard *at once*: at least :data:`~sblsim.models.tracking.twins.MIN_JUMPS` of the second place's fixes are
  farther from the first place's fix just before or just after them than the top speed covers in the time between,
  with :data:`SIGMAS` of the two fixes' sigmas and both fixes' protection levels added (the farthest one reflection
  moves a fix unseen by its own test: :mod:`~sblsim.models.tracking.integrity`): neither motion nor one faulty
  arrival joins them;
* they interleave: the second place's fixes fall into at least :data:`RUN_SHARE` of their count of runs among the
  first place's (one tag's stretches in turn make a few long runs);
* each is one place at a time: the median step between consecutive fixes of each (the first's over the second's
  time span) is at most :data:`~sblsim.models.tracking.twins.COMPACT` of the **separation** (the median distance of
  the second place's fixes from the first place's path); scattered reflections make no such place;
* two paths explain the fixes far better than one: their lengths together are at most :data:`TRAVEL_SHARE` of the
  length of the one path through every fix in time order.

Of several seeds' splits, the one of the shortest paths is taken. The rows at the second place are its trusted fixes
and every other fix (untrusted) in its time span nearer its path than the first place's, within half the separation.
What to do with them (a track of the first place, or a refusal where no place holds a clear majority) is the
caller's: :mod:`sblsim.orchestrator.tracks.two_tags`. Two places nearer than the top speed covers between pings are
not told apart. In 20 simulations each (25 receivers 150 m apart, pings every 100-200 s): a second tag 400 m or
200 m away heard for 30 % of six hours found in all 20 (the first on a 30 m or a 120 m circle), heard for 10 % in 18
(the two missed had 14 trusted fixes), 100 m away in 13; one tag moving, shuttling between two places 400 m apart,
moving at 4 m/s, or with 15 % of its arrivals late by a reflection never split.

A duplicated code is a known telemetry problem: the code maps 1105 and 1303 repeat their ping codes across tags
(the AATAMS database's rule that an id is one tag's excepts them, github.com/aodn/aatams issue 374), a network's
database may hold two tags under one id (the European Tracking Network, github.com/inbo/etn issue 239), the Motus
radio-telemetry network keeps the detections of identical codes deployed at once as *ambiguous* rather than give them
to either tag (motusClient, "ambiguous detection handling"), and a code decoded from colliding pings is a false
detection (Pincock, "False detections: what they are and how to remove them from detection data", Vemco
DOC-004691, 2012; glatos' ``false_detections``).

Units: metres [m], seconds [s].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sblsim.models.tracking.twins import COMPACT, MAX_SPEED, MIN_JUMPS

#: The sigmas of two fixes' combined error a step may take beyond the top speed's reach.
SIGMAS = 3.0
#: The fixes a chain's place is the median of.
MEMORY = 3
#: A chain's speed: the median of its last steps' (this many), times this factor, at most the top speed.
SPEED_STEPS = 5
SPEED_FACTOR = 3.0
#: The largest share of one place's travel through all the fixes that two places' travel through theirs may take.
TRAVEL_SHARE = 0.5
#: The most times the fixes are shared out between the two places.
ITERATIONS = 10
#: The fewest trusted fixes of a second place.
MIN_FIXES = 10
#: The least share of the second place's fixes that start a run of its own among the first place's.
RUN_SHARE = 0.25


@dataclass(frozen=True)
class TwoPlaces:
    """Fixes at two places at once (:func:`places_at_once`).

    Attributes
    ----------
    places : ndarray, (2, 2)
        The median of the first place's trusted fixes over the second place's time span, and of the second place's
        [m].
    separation : float
        The median distance of the second place's fixes from the first place's path [m].
    fixes : tuple of int
        The trusted fixes at each place.
    out_of_reach : int
        The second place's fixes no motion at the top speed nor one faulty arrival joins to a neighbouring fix of the
        first place.
    span : tuple of float
        The second place's first and last emission times [s].
    second : ndarray of bool, (m,)
        The rows at the second place (its trusted fixes and the other fixes nearer it).
    """

    places: np.ndarray
    separation: float
    fixes: tuple[int, int]
    out_of_reach: int
    span: tuple[float, float]
    second: np.ndarray

    @property
    def shares(self) -> tuple[float, float]:
        """Each place's share of the trusted fixes at either."""
        total = sum(self.fixes)
        return self.fixes[0] / total, self.fixes[1] / total


def chains(positions: np.ndarray, times: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """Each fix's chain (module docstring), the fixes in time order.

    Parameters
    ----------
    positions : ndarray, (m, 2)
        Fixes [m], in time order.
    times : ndarray, (m,)
        Their emission times [s], increasing.
    variances : ndarray, (m,)
        Their horizontal variances (the trace of the horizontal covariance) [m²].

    Returns
    -------
    ndarray of int, (m,)
        The chain of each fix, numbered from 0 as they start.
    """
    p = np.asarray(positions, float)
    xs, ys = p[:, 0].tolist(), p[:, 1].tolist()
    ts, vs = np.asarray(times, float).tolist(), np.asarray(variances, float).tolist()
    label = np.empty(len(p), np.int64)
    # each chain's place (x, y), last time, largest variance of its last fixes and speed, grown as chains start; its
    # last MEMORY fixes and the speeds of its last SPEED_STEPS steps (a few operations a fix: 10^5 fixes in seconds)
    state = np.empty((5, 64))
    recent: list[list[int]] = []
    speeds: list[list[float]] = []
    for i in range(len(p)):
        n = len(recent)
        x, y, last, spread, speed = state[:, :n]
        d2 = (x - xs[i]) ** 2 + (y - ys[i]) ** 2
        reach = speed * (ts[i] - last) + SIGMAS * np.sqrt(vs[i] + spread)
        d2 = np.where(d2 <= reach * reach, d2, np.inf)
        c = int(np.argmin(d2)) if n else -1
        if c < 0 or d2[c] == np.inf:  # out of every chain's reach: a chain of its own
            c = n
            if n == state.shape[1]:
                state = np.concatenate([state, np.empty_like(state)], axis=1)
            state[:, n] = xs[i], ys[i], ts[i], vs[i], MAX_SPEED
            recent.append([i])
            speeds.append([])
        else:
            j = recent[c][-1]
            dt = ts[i] - ts[j]
            speeds[c] = (speeds[c] + [math.hypot(xs[i] - xs[j], ys[i] - ys[j]) / dt if dt > 0 else MAX_SPEED])[
                -SPEED_STEPS:]
            recent[c] = (recent[c] + [i])[-MEMORY:]
            last_fixes = recent[c]
            state[:, c] = (_median([xs[k] for k in last_fixes]), _median([ys[k] for k in last_fixes]), ts[i],
                           max(vs[k] for k in last_fixes),
                           # the chain's own speed: the median of its recent steps', a few times over
                           min(MAX_SPEED, SPEED_FACTOR * _median(speeds[c])) if len(speeds[c]) >= MEMORY
                           else MAX_SPEED)
        label[i] = c
    return label


def _median(values: list[float]) -> float:
    """The median of a few numbers (``numpy.median``'s: the mean of the middle two of an even count)."""
    ordered = sorted(values)
    half = len(ordered) // 2
    return ordered[half] if len(ordered) % 2 else (ordered[half - 1] + ordered[half]) / 2


def _path(p: np.ndarray, t: np.ndarray, group: np.ndarray, at: np.ndarray, own: np.ndarray) -> np.ndarray:
    """A place's path at the times ``t[at]``: the median of its two fixes before and two after each (``group``: its
    fixes' indices in time order; ``own``: whether each of ``at`` is one of them, then left out) [m] (k, 2)."""
    k = np.searchsorted(t[group], t[at])
    own = np.asarray(own, bool)
    out = np.empty((len(k), 2))
    for axis in (0, 1):
        a, b, c, d = (p[group, axis][np.clip(k + np.where(own, step, step - (step > 0)), 0, len(group) - 1)]
                      for step in (-2, -1, 1, 2))
        low, high = np.minimum(a, b), np.maximum(a, b)
        least, most = np.minimum(c, d), np.maximum(c, d)
        # the median of four: the mean of the middle two, all four less the largest and the least, halved
        out[:, axis] = (a + b + c + d - np.maximum(high, most) - np.minimum(low, least)) / 2
    return out


def _split(p: np.ndarray, t: np.ndarray, seed: np.ndarray) -> np.ndarray | None:
    """The fixes of a second place grown from a chain (``seed``): each fix taken by the place whose path
    (:func:`_path`) is nearer, until no fix changes place (at most :data:`ITERATIONS` times); None where either
    place is left with fewer than :data:`MEMORY` fixes."""
    second = np.zeros(len(p), bool)
    second[seed] = True
    every = np.arange(len(p))
    for _ in range(ITERATIONS):
        if min(second.sum(), (~second).sum()) < MEMORY:
            return None
        near = [np.linalg.norm(p - _path(p, t, np.flatnonzero(g), every, g), axis=1) for g in (~second, second)]
        moved = near[1] < near[0]
        if (moved == second).all():
            break
        second = moved
    return second if min(second.sum(), (~second).sum()) >= MEMORY else None


@dataclass(frozen=True)
class _Against:
    """A second place's fixes (``second``, indices in time order) against the first place's (``first``): those out of
    reach of the first place's fix just before or after (``out``), their median distance from the first place's path
    (``separation`` [m]), the median steps [m] of the second place and of the first over its span (``steps``), the
    runs the second falls into among the first's (``runs``) and the first place's fixes over its span (``during``)."""

    out: int
    separation: float
    steps: tuple[float, float]
    runs: int
    during: np.ndarray

    def holds(self, fixes: int) -> bool:
        """Whether the two are two places at once (module docstring), the second of ``fixes`` fixes."""
        return self.out >= MIN_JUMPS and self.runs >= RUN_SHARE * fixes and max(self.steps) <= \
            COMPACT * self.separation


def _against(first: np.ndarray, second: np.ndarray, p: np.ndarray, t: np.ndarray, var: np.ndarray,
             level: np.ndarray) -> _Against | None:
    """A second place against the first (:class:`_Against`); None where the first has fewer than two fixes over the
    second's span."""
    during = first[(t[first] >= t[second[0]]) & (t[first] <= t[second[-1]])]
    if len(during) < 2:
        return None
    k = np.searchsorted(t[first], t[second])
    out = np.zeros(len(second), bool)
    for b in (first[np.clip(k - 1, 0, len(first) - 1)], first[np.clip(k, 0, len(first) - 1)]):
        out |= np.linalg.norm(p[second] - p[b], axis=1) > (MAX_SPEED * np.abs(t[second] - t[b]) + level[second] +
                                                           level[b] + SIGMAS * np.sqrt(var[second] + var[b]))
    separation = float(np.median(np.linalg.norm(p[second] - _path(p, t, first, second, np.zeros(len(second), bool)),
                                                axis=1)))
    steps = tuple(float(np.median(np.linalg.norm(np.diff(p[g], axis=0), axis=1))) for g in (second, during))
    merged = np.isin(np.arange(len(p)), second)
    return _Against(int(out.sum()), separation, steps, int(merged[0]) + int((merged[1:] & ~merged[:-1]).sum()),
                    during)


def _travel(p: np.ndarray) -> float:
    """The length of the path through fixes in time order [m]."""
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


def places_at_once(positions: np.ndarray, times: np.ndarray, covariances: np.ndarray, trusted: np.ndarray,
                   protection: np.ndarray | None = None) -> TwoPlaces | None:
    """The two places one id is heard from at once, where its fixes show them (module docstring), else None.

    Parameters
    ----------
    positions : ndarray, (m, dim)
        Each row's single-ping fix [m], NaN where none.
    times : ndarray, (m,)
        Their emission times [s], NaN where none.
    covariances : ndarray, (m, p, p)
        Their covariances (the horizontal block is used) [m², ...].
    trusted : ndarray of bool, (m,)
        The fixes the checks trust (:func:`~sblsim.models.tracking.quality.trusted_fixes`): the places are made of
        these.
    protection : ndarray, (m,), optional
        Each fix's horizontal protection level [m] (:func:`~sblsim.models.tracking.integrity.protection_levels`; NaN
        or inf: unbounded); None: 0.

    Returns
    -------
    TwoPlaces or None
    """
    x = np.asarray(positions, float)[:, :2]
    t_all = np.asarray(times, float)
    C = np.asarray(covariances, float)
    var_all = C[:, 0, 0] + C[:, 1, 1]
    level = np.zeros(len(x)) if protection is None else np.asarray(protection, float)
    level = np.where(np.isnan(level), np.inf, level)
    fixed = np.isfinite(x).all(axis=1) & np.isfinite(t_all) & np.isfinite(var_all)
    rows = np.flatnonzero(fixed & np.asarray(trusted, bool))
    if len(rows) < 2 * MIN_FIXES:
        return None
    rows = rows[np.argsort(t_all[rows], kind="stable")]
    p, t, var, hpl = x[rows], t_all[rows], var_all[rows], level[rows]
    label = chains(p, t, var)
    sizes = np.bincount(label)
    best = None
    for c in np.flatnonzero(sizes >= MIN_FIXES):
        seed = label == c
        if c == np.argmax(sizes):
            continue
        alone = _against(np.flatnonzero(~seed), np.flatnonzero(seed), p, t, var, hpl)
        if alone is None or alone.out < MIN_JUMPS:  # a chain no motion separates from the other fixes seeds nothing
            continue
        split = _split(p, t, np.flatnonzero(seed))
        if split is None or not MIN_FIXES <= split.sum() <= (~split).sum():
            continue
        second = np.flatnonzero(split)
        found = _against(np.flatnonzero(~split), second, p, t, var, hpl)
        travel = _travel(p[~split]) + _travel(p[split])
        if found is not None and found.holds(len(second)) and travel <= TRAVEL_SHARE * _travel(p) and \
                (best is None or travel < best[2]):
            best = (split, found, travel)
    if best is None:
        return None
    split, found, _ = best
    first, second = np.flatnonzero(~split), np.flatnonzero(split)
    at_second = np.zeros(len(x), bool)
    at_second[rows[second]] = True
    # every other fix in the second place's time span nearer its path than the first's, within half the separation
    others = np.flatnonzero(fixed & ~at_second & (t_all >= t[second[0]]) & (t_all <= t[second[-1]]))
    if len(others):
        q = np.vstack([p, x[others]])
        u = np.r_[t, t_all[others]]
        at = np.arange(len(p), len(q))
        near = [np.linalg.norm(x[others] - _path(q, u, g, at, np.zeros(len(at), bool)), axis=1)
                for g in (first, second)]
        at_second[others[(near[1] < near[0]) & (near[1] <= found.separation / 2)]] = True
    return TwoPlaces(np.array([np.median(p[found.during], axis=0), np.median(p[second], axis=0)]), found.separation,
                     (len(first), len(second)), found.out, (float(t[second[0]]), float(t[second[-1]])), at_second)


__all__ = ["ITERATIONS", "MEMORY", "MIN_FIXES", "RUN_SHARE", "SIGMAS", "SPEED_FACTOR", "SPEED_STEPS", "TRAVEL_SHARE",
           "TwoPlaces", "chains", "places_at_once"]

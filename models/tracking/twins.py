"""Two tags under one transmitter id: a tag's single-ping fixes that keep jumping between two places.

Two tags that share a code (a code space reused, two studies' tags in one array) make one times-of-arrival matrix of
two animals' pings interleaved; every tracker then draws one track between them, and each jump is a step no animal
swims. The single-ping fixes show it before any tracking: consecutive trusted fixes farther apart than
:data:`MAX_SPEED` allows in the time between them (beyond three of their combined sigmas), in a large share of the
steps, and the fixes falling into two compact groups far apart (two-means, each group within :data:`COMPACT` of their
separation and holding :data:`MIN_GROUP_SHARE` of the fixes), the impossible steps mostly between the groups. One
tag's occasional outlying fixes (multipath) make a few impossible steps but no second compact group; one tag moving
between two places makes groups but no impossible steps.

Units: metres [m], seconds [s].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The fastest a tagged animal is taken to move between two pings [m/s] (sustained swimming of tagged fish is
#: 0.5-2 m/s; bursts last seconds).
MAX_SPEED = 5.0
#: The fewest impossible steps, and their least share of the steps between consecutive trusted fixes.
MIN_JUMPS = 10
MIN_JUMP_SHARE = 0.2
#: The least share of the fixes each group holds, the largest radius of a group (90 % of its fixes within it) as a
#: share of the groups' separation, and the least share of the impossible steps that go between the groups.
MIN_GROUP_SHARE = 0.2
COMPACT = 0.25
MIN_BETWEEN_SHARE = 0.8


@dataclass(frozen=True)
class TwoPlaces:
    """Fixes at two places (:func:`two_places`): the groups' ``centres`` (2, 2) [m], their ``shares`` of the
    ``fixes``, their ``separation`` [m] and the impossible steps (``jumps``) of ``steps``."""

    centres: np.ndarray
    shares: tuple[float, float]
    separation: float
    jumps: int
    steps: int
    fixes: int


def two_places(positions: np.ndarray, times: np.ndarray, covariances: np.ndarray) -> TwoPlaces | None:
    """The two places a tag's fixes jump between where they look like two tags (module docstring), else None.

    Parameters
    ----------
    positions : ndarray, (m, dim)
        The trusted single-ping fixes [m].
    times : ndarray, (m,)
        Their emission times [s].
    covariances : ndarray, (m, dim, dim) or (m, dim + 1, dim + 1)
        Their covariances [m², ...] (the horizontal block is used).

    Returns
    -------
    TwoPlaces or None
    """
    p = np.asarray(positions, float)[:, :2]
    t = np.asarray(times, float)
    C = np.asarray(covariances, float)
    ok = np.isfinite(p).all(axis=1) & np.isfinite(t) & np.isfinite(C[:, 0, 0]) & np.isfinite(C[:, 1, 1])
    p, t, C = p[ok], t[ok], C[ok]
    if len(p) < 2 * MIN_JUMPS:
        return None
    order = np.argsort(t, kind="stable")
    p, t = p[order], t[order]
    var = C[order, 0, 0] + C[order, 1, 1]
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    reach = MAX_SPEED * np.diff(t) + 3.0 * np.sqrt(np.maximum(var[1:] + var[:-1], 0.0))
    jump = step > reach
    if jump.sum() < MIN_JUMPS or jump.mean() < MIN_JUMP_SHARE:
        return None
    # two-means from the fix farthest from the median and the fix farthest from that one
    a = p[np.argmax(np.linalg.norm(p - np.median(p, axis=0), axis=1))]
    centres = np.array([a, p[np.argmax(np.linalg.norm(p - a, axis=1))]])
    label = np.zeros(len(p), np.int64)
    for _ in range(50):
        label = np.argmin(np.linalg.norm(p[:, None] - centres[None], axis=2), axis=1)
        if label.min() == label.max():
            return None
        moved = np.array([np.median(p[label == g], axis=0) for g in (0, 1)])
        if np.allclose(moved, centres):
            break
        centres = moved
    shares = tuple(float(np.mean(label == g)) for g in (0, 1))
    separation = float(np.linalg.norm(centres[0] - centres[1]))
    radius = max(float(np.percentile(np.linalg.norm(p[label == g] - centres[g], axis=1), 90)) for g in (0, 1))
    between = (label[1:] != label[:-1])[jump]
    if min(shares) < MIN_GROUP_SHARE or radius > COMPACT * separation or between.mean() < MIN_BETWEEN_SHARE:
        return None
    return TwoPlaces(centres, shares, separation, int(jump.sum()), int(len(step)), int(len(p)))


__all__ = ["COMPACT", "MAX_SPEED", "MIN_BETWEEN_SHARE", "MIN_GROUP_SHARE", "MIN_JUMPS", "MIN_JUMP_SHARE",
           "TwoPlaces", "two_places"]

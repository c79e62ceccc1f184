"""The sync coverage of a telemetry array: whether its receivers' clocks can be synchronised from sync tags.

A sync tag is moored at each receiver; receiver i hears the sync tag of receiver j with probability ``q_ij``
(:func:`sync_probabilities`, the detection range curve at their distance). The array can be synchronised when every
receiver hears at least two other receivers' sync tags each with probability ≥ p and the **sync graph** (the
receivers as nodes, an edge where one hears the other's sync tag with probability ≥ p) is connected
(:func:`sync_coverage`, :mod:`scipy.sparse.csgraph`). The criteria of a ping's fix are
:mod:`~sblsim.models.design.telemetry`'s.

Units: metres [m], probabilities [0–1].
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import connected_components

from sblsim.models.errors import ModelError

#: The sync tags a receiver must hear (:func:`sync_coverage`).
SYNC_NEEDED = 2


@dataclass(frozen=True)
class SyncCoverage:
    """Whether layouts can be synchronised from sync tags (:func:`sync_coverage`).

    Attributes
    ----------
    heard : ndarray of int, shape (..., n)
        The other receivers' sync tags each receiver hears with probability ≥ p.
    share : ndarray, shape (...)
        The share of receivers that hear at least :data:`SYNC_NEEDED` of them [0–1].
    components : ndarray of int, shape (...)
        The sync graph's connected components.
    labels : ndarray of int, shape (..., n)
        Each receiver's component.
    connected : ndarray of bool, shape (...)
        One component.
    met : ndarray of bool, shape (...)
        Connected and every receiver hears enough sync tags.
    """

    heard: np.ndarray
    share: np.ndarray
    components: np.ndarray
    labels: np.ndarray
    connected: np.ndarray
    met: np.ndarray


def sync_probabilities(receivers: np.ndarray, probability: Callable[[np.ndarray], np.ndarray],
                       tags: np.ndarray | None = None) -> np.ndarray:
    """The probability that receiver i hears the sync tag moored at receiver j, ``probability(‖r_i − t_j‖)``, with
    the receiver's own tag left out (zero on the diagonal).

    Parameters
    ----------
    receivers : ndarray, shape (..., n, dim)
        [m].
    probability : callable
        Distance [m] -> probability [0–1] (a :meth:`DetectionCurve.probability
        <sblsim.models.design.detection_curve.DetectionCurve.probability>`).
    tags : ndarray, shape (..., n, dim), optional
        The sync tags' positions [m] (default at the receivers).

    Returns
    -------
    ndarray, shape (..., n, n)
        ``q[i, j]`` [0–1].
    """
    receivers = np.asarray(receivers, float)
    tags = receivers if tags is None else np.asarray(tags, float)
    d = np.linalg.norm(receivers[..., :, None, :] - tags[..., None, :, :], axis=-1)
    q = np.asarray(probability(d), float).copy()
    n = receivers.shape[-2]
    q[..., np.arange(n), np.arange(n)] = 0.0
    return q


def sync_coverage(q: np.ndarray, p: float, needed: int = SYNC_NEEDED) -> SyncCoverage:
    """The sync coverage of layouts (module docstring).

    Receiver i counts sync tag j as heard when ``q[i, j] ≥ p``; the sync graph has an edge between i and j where
    either hears the other's (one way links the two clocks: the tag's emission is timed by its own receiver),
    and its components are :func:`scipy.sparse.csgraph.connected_components`' (weak connection).

    Parameters
    ----------
    q : ndarray, shape (..., n, n)
        ``q[i, j]``: the probability that receiver i hears the sync tag of receiver j [0–1] (the diagonal ignored).
    p : float
        The probability a link needs, in (0, 1].
    needed : int, optional
        The other sync tags each receiver must hear.

    Returns
    -------
    SyncCoverage

    Raises
    ------
    ModelError
        For p outside (0, 1].
    """
    if not 0.0 < p <= 1.0:
        raise ModelError(f"sync probability: {p!r}; allowed (0, 1]")
    q = np.asarray(q, float)
    n = q.shape[-1]
    links = (q >= p) & ~np.eye(n, dtype=bool)
    heard = links.sum(axis=-1)
    flat = links.reshape(-1, n, n)
    components, labels = np.empty(len(flat), int), np.empty((len(flat), n), int)
    for k, graph in enumerate(flat):
        components[k], labels[k] = connected_components(csr_matrix(graph), directed=True, connection="weak")
    shape = q.shape[:-2]
    components, labels = components.reshape(shape), labels.reshape(shape + (n,))
    share = (heard >= needed).mean(axis=-1)
    connected = components == 1
    return SyncCoverage(heard, share, components, labels, connected, connected & (share == 1.0))


__all__ = ["SYNC_NEEDED", "SyncCoverage", "sync_coverage", "sync_probabilities"]

"""The sync-tag arrivals grouped into emissions, their duplicates marked, and the receivers they tie together.

A sync tag's arrivals at every receiver, in time order, are one emission while they follow each other closely (the
receivers' clocks differ by less than a third of the tag's burst interval); a receiver's later arrival of an
emission it already logged is a multipath echo or a false detection; an emission heard by one receiver alone ties
no clock to another. The receivers the clocks' fit (:func:`sblsim.models.sync.clocks.fit_clocks`) can synchronise
are those connected to the reference through emissions heard by two receivers or more, each sharing two such
emissions at least (:data:`MIN_SHARED`: an offset and a drift). Times in seconds [s].
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph

from sblsim.models.declarations import ModelError


def group_emissions(tag: np.ndarray, time: np.ndarray, gap: np.ndarray) -> np.ndarray:
    """The emission each arrival belongs to: a tag's arrivals (at every receiver) sorted by time, a new emission
    where the next arrival is more than the tag's ``gap`` later.

    Parameters
    ----------
    tag : numpy.ndarray
        (n,) int, the tag's index.
    time : numpy.ndarray
        (n,) [s] the arrival on its receiver's clock.
    gap : numpy.ndarray
        (tags,) [s] the largest spread of one emission's arrivals (a third of the tag's burst interval: the
        receivers' clocks may differ by up to that).

    Returns
    -------
    numpy.ndarray
        (n,) int, the emission's index, numbered by tag, then time.
    """
    order = np.lexsort((time, tag))
    t, g = time[order], tag[order]
    new = np.ones(len(t), bool)
    new[1:] = (g[1:] != g[:-1]) | (np.diff(t) > gap[g[1:]])
    emission = np.empty(len(t), np.int64)
    emission[order] = np.cumsum(new) - 1
    return emission


def later_duplicates(emission: np.ndarray, receiver: np.ndarray, time: np.ndarray) -> np.ndarray:
    """(n,) bool: an arrival of an emission at a receiver that logged the same emission earlier (a multipath echo
    or a false detection): only the first is kept."""
    order = np.lexsort((time, receiver, emission))
    e, r = emission[order], receiver[order]
    dup = np.zeros(len(e), bool)
    dup[1:] = (e[1:] == e[:-1]) & (r[1:] == r[:-1])
    out = np.zeros(len(e), bool)
    out[order] = dup
    return out


def sync_emissions(tag: np.ndarray, receiver: np.ndarray, time: np.ndarray, gap: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sync-tag arrivals' emissions and which of them the clocks' fit takes: ``emission``
    (:func:`group_emissions`), ``duplicate`` (:func:`later_duplicates`: a receiver's later arrival of one emission,
    a multipath echo) and ``single`` (an emission heard by one receiver alone, its duplicates not counted: it ties
    no clock to another), each (n,); the fit takes ``~duplicate & ~single``.

    Parameters
    ----------
    tag, receiver : numpy.ndarray
        (n,) int, each arrival's tag and receiver.
    time : numpy.ndarray
        (n,) [s] the arrival on its receiver's clock.
    gap : numpy.ndarray
        (tags,) [s] as :func:`group_emissions`'.
    """
    emission = group_emissions(tag, time, gap)
    duplicate = later_duplicates(emission, receiver, time)
    heard_by = np.bincount(emission[~duplicate], minlength=int(emission.max(initial=-1)) + 1)
    return emission, duplicate, heard_by[emission] < 2


#: The emissions a receiver must share with another receiver for its clock to be determined: an offset and a drift
#: (a line) need two points; one leaves the drift free (the clocks' normal equations singular).
MIN_SHARED = 2


class SyncTagsUnheard(ModelError):
    """The sync tags not heard by two receivers (fewer than two detections of the receivers table's sync tags: an
    extract of a tag project holds its own tags alone; or each heard by its own receiver alone): a refusal of the
    synchronisation that a study takes as clocks not synchronised, said with its ``reason``."""

    def __init__(self, reason: str) -> None:
        self.reason = reason
        super().__init__(f"sync: {reason}; allowed: raw detections in which receivers hear the sync tags named in the "
                         "table's sync_tag column, each heard by two receivers or more")


def connected(receiver: np.ndarray, emission: np.ndarray, n_receivers: int, start: int) -> np.ndarray:
    """(n_receivers,) bool: the receivers tied to ``start`` through emissions heard by two receivers or more (the
    connected components of the graph linking the receivers that hear one emission), each sharing
    :data:`MIN_SHARED` emissions or more with the others so tied (a receiver that shares fewer is left out, and the
    count of the others is taken again without it)."""
    roots, able = components(receiver, emission, n_receivers)
    return (roots == roots[start]) & able


def components(receiver: np.ndarray, emission: np.ndarray, n_receivers: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`connected`'s graph: (n_receivers,) each receiver's component (a label) and (n_receivers,) bool whether
    it shares :data:`MIN_SHARED` emissions or more with the others of its component."""
    order = np.lexsort((receiver, emission))
    e, r = emission[order], receiver[order]
    while True:
        same = np.flatnonzero(e[1:] == e[:-1])
        pair = np.zeros(len(e), bool)  # each row heard with another receiver (one row per receiver and emission)
        pair[same] = pair[same + 1] = True
        shared = np.bincount(r[pair], minlength=n_receivers)
        few = (shared > 0) & (shared < MIN_SHARED)
        if not few.any():
            break
        e, r = e[~few[r]], r[~few[r]]
    graph = sp.csr_matrix((np.ones(len(same)), (r[same], r[same + 1])), shape=(n_receivers, n_receivers))
    _, roots = scipy.sparse.csgraph.connected_components(graph, directed=False)
    return roots, shared >= MIN_SHARED


__all__ = ["MIN_SHARED", "SyncTagsUnheard", "components", "connected", "group_emissions", "later_duplicates",
           "sync_emissions"]

"""Each receiver's timing noise from a synchronisation: what a time of arrival at that receiver is uncertain by once
its clock is corrected, for the tracker's measurement covariance.

Two parts, added in quadrature (independent errors):

* the **noise of an arrival**: the robust scale of the receiver's sync-tag residuals, ``1.4826 × median |r / √(1 −
  h)|`` (the median absolute residual, the Gaussian's standard deviation where the residuals are Gaussian; Huber &
  Ronchetti, *Robust Statistics*, Wiley 2009, § 5.1), each residual ``r`` over the square root of one less its
  leverage ``h`` (the emission time, which the emission's other arrivals share, and the clock's knots took part of
  it: Cook & Weisberg, *Residuals and Influence in Regression*, Chapman & Hall 1982, § 2.2), every arrival the fit
  positioned counted, those it rejected too (the median is robust to them; leaving them out would shrink the scale
  of a receiver whose arrivals are often late). The residuals are about the sync tags' known positions: a receiver
  whose position is metres off has residuals of metres, which its arrivals of a tag will have too. An arrival whose
  leverage is one (its residual 0 whatever its error: the fit cannot check it) is left out;
* the **clock's own uncertainty**: the root mean square of the receiver's offset sigma where its arrivals are (at
  each arrival's time, the variance interpolated linearly between the bin's two edges; the reference receiver's is
  0): a bin the record barely enters, whose far edge the fit extrapolates to (its sigma large), weighs by the
  arrivals in it, not as a bin (without the arrivals' times: the RMS over the edges). An offset's error is common to
  the arrivals of a bin; taken here as each arrival's own, it counts fully in a single ping's fix and over-counts in
  a smoother that averages the pings of a bin; it is small wherever the receiver hears the sync tags well.

A receiver with fewer than :data:`MIN_ARRIVALS` residuals takes the others' median noise (``measured`` False).

Units: seconds [s].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The fewest residuals a receiver's own noise is measured from.
MIN_ARRIVALS = 10
#: The timing noise written [s]: at least a microsecond (a clock's resolution), at most a second.
NOISE_RANGE = (1e-6, 1.0)
#: The median absolute deviation's factor to a Gaussian's standard deviation.
MAD_FACTOR = 1.4826


@dataclass(frozen=True)
class ReceiverNoise:
    """Per receiver (R,): ``sigma`` [s] the timing noise (``noise`` and ``clock`` in quadrature, NaN where not
    synchronised), ``noise`` [s] its residuals' robust scale, ``clock`` [s] its offsets' RMS sigma, ``arrivals``
    the residuals counted and ``measured`` whether ``noise`` is its own (else the others' median)."""

    sigma: np.ndarray
    noise: np.ndarray
    clock: np.ndarray
    arrivals: np.ndarray
    measured: np.ndarray


def receiver_noise(receiver: np.ndarray, corrected: np.ndarray, knot_sigma: np.ndarray,
                   synchronised: np.ndarray, time: np.ndarray | None = None,
                   edges: np.ndarray | None = None) -> ReceiverNoise:
    """Each receiver's timing noise (the module docstring).

    Parameters
    ----------
    receiver : ndarray of int, (n,)
        Each sync-tag arrival's receiver (0 ≤ j < R).
    corrected : ndarray, (n,)
        Its residual over √(1 − leverage) [s] (the clock fit's standardised residual times its receiver's scale);
        NaN where the fit did not position it (a multipath echo, a receiver alone, not synchronised), 0 where its
        leverage is one.
    knot_sigma : ndarray, (R, K + 1)
        Each receiver's offset sigma at each bin edge [s] (0 for the reference receiver; NaN where not computed).
    synchronised : ndarray of bool, (R,)
    time : ndarray, (n,), optional
        Each arrival's time on the fit's base [s]; with ``edges``, the clock's part is taken where the arrivals are.
    edges : ndarray, (K + 1,), optional
        The bins' edges on the same base [s].

    Returns
    -------
    ReceiverNoise
    """
    receiver = np.asarray(receiver, np.int64)
    corrected = np.asarray(corrected, float)
    synchronised = np.asarray(synchronised, bool)
    count = len(synchronised)
    usable = np.isfinite(corrected) & (corrected != 0.0)
    arrivals = np.bincount(receiver[usable], minlength=count)
    noise = np.full(count, np.nan)
    for j in np.flatnonzero(synchronised & (arrivals >= MIN_ARRIVALS)):
        noise[j] = MAD_FACTOR * float(np.median(np.abs(corrected[usable & (receiver == j)])))
    measured = np.isfinite(noise)
    if measured.any():
        noise = np.where(measured | ~synchronised, noise, np.median(noise[measured]))
    knots = np.asarray(knot_sigma, float)
    finite = np.isfinite(knots)
    clock = np.sqrt((np.where(finite, knots, 0.0) ** 2).sum(axis=1) / np.maximum(finite.sum(axis=1), 1))
    if time is not None and edges is not None:
        where = _at_arrivals(receiver, np.asarray(time, float), knots, np.asarray(edges, float), count)
        clock = np.where(np.isfinite(where), where, clock)
    clock = np.where(synchronised, clock, np.nan)
    sigma = np.clip(np.hypot(noise, clock), *NOISE_RANGE)
    return ReceiverNoise(np.where(synchronised & np.isfinite(noise), sigma, np.nan), noise, clock, arrivals,
                         measured)


def _at_arrivals(receiver: np.ndarray, time: np.ndarray, knots: np.ndarray, edges: np.ndarray, count: int
                 ) -> np.ndarray:
    """(R,) [s] each receiver's RMS offset sigma at its arrivals' times (the variance interpolated between the two
    edges of each arrival's bin; an edge without a sigma takes the other's); NaN for a receiver with none."""
    width = len(edges) - 1
    k = np.clip(np.searchsorted(edges, time, side="right") - 1, 0, max(width - 1, 0))
    f = np.clip((time - edges[k]) / np.maximum(edges[np.minimum(k + 1, width)] - edges[k], 1e-300), 0.0, 1.0)
    left, right = knots[receiver, k] ** 2, knots[receiver, np.minimum(k + 1, width)] ** 2
    left, right = np.where(np.isfinite(left), left, right), np.where(np.isfinite(right), right, left)
    variance = (1 - f) * left + f * right
    ok = np.isfinite(variance) & np.isfinite(time)
    total = np.bincount(receiver[ok], weights=variance[ok], minlength=count)
    n = np.bincount(receiver[ok], minlength=count)
    return np.where(n > 0, np.sqrt(total / np.maximum(n, 1)), np.nan)


def undetermined(rows: np.ndarray, time: np.ndarray, knot_sigma: np.ndarray, edges: np.ndarray,
                 limit: float) -> np.ndarray:
    """(R,) bool, the clock rows whose offset is not determined where their arrivals are: the RMS of its sigma at
    their times (as :class:`ReceiverNoise`'s ``clock``) above ``limit`` [s] (e.g. a clock tied to the others by one
    sync-tag arrival, its drift then free: its offset's sigma grows without bound away from it). ``rows`` (n,) int
    each arrival's clock row (−1: none), ``time`` (n,) its time on the fit's base [s], ``knot_sigma`` (R, K + 1) [s]
    (NaN where not computed: never counted undetermined), ``edges`` (K + 1,) [s]."""
    rows = np.asarray(rows, np.int64)
    on = rows >= 0
    where = _at_arrivals(rows[on], np.asarray(time, float)[on], np.asarray(knot_sigma, float),
                         np.asarray(edges, float), len(knot_sigma))
    return np.isfinite(where) & (where > limit)


__all__ = ["MAD_FACTOR", "MIN_ARRIVALS", "NOISE_RANGE", "ReceiverNoise", "receiver_noise", "undetermined"]

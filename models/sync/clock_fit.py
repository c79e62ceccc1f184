"""The synchronised clocks a fit gives (:func:`sblsim.models.sync.clocks.fit_clocks`): each receiver's offsets at
the bins' edges, its drifts and their sigmas, each arrival's residual, and a receiver's offset read at a time of its
own clock (the knots interpolated; a broken clock's segment found by its span). Times in seconds [s].
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np


@dataclass
class ClockFit:
    """The synchronised clocks.

    Attributes
    ----------
    edges : numpy.ndarray
        (K+1,) [s] the bins' edges on the receivers' own clocks (relative to the caller's origin).
    knots, knot_sigma : numpy.ndarray
        (R, K+1) [s] each receiver's offset at each edge and its sigma (the reference receiver's 0 and 0; a
        receiver not synchronised NaN).
    drift, drift_sigma : numpy.ndarray
        (R, K) [s/s] the drift in each bin and its sigma.
    counts : numpy.ndarray
        (R, K) int, the kept arrivals in each bin.
    emission_time : numpy.ndarray
        (E,) [s] each emission's time on the reference clock (NaN for an emission not used).
    residual : numpy.ndarray
        (n,) [s] each arrival's residual (NaN where not used).
    standardised : numpy.ndarray
        (n,) the residual over its receiver's scale and leverage.
    kept : numpy.ndarray
        (n,) bool, used and not rejected.
    scale : numpy.ndarray
        (R,) [s] each receiver's noise scale (its kept residuals' RMS, corrected for the leverage).
    slowness, slowness_sigma : float or None
        [s/m] the estimated slowness (1 / sound speed) and its sigma, None where it was given.
    iterations : int
    shift, shift_covariance : numpy.ndarray or None
        (R, 2) [m] and (R, 2, 2) [m²] each receiver's horizontal shift from the table and its covariance (refined
        positions: :class:`~sblsim.models.sync.clocks.Geometry`), else None.
    distance : numpy.ndarray or None
        (n,) [m] with refined positions, each arrival's distance at the refined positions (NaN where not used).
    site, span, clock, breaks : numpy.ndarray, numpy.ndarray, numpy.ndarray, list or None
        Where a receiver's clock broke (:func:`sblsim.models.sync.breaks.fit_with_breaks`) the rows above are its
        **clock segments**: ``site`` (R,) the receiver of each row, ``span`` (R, 2) [s] the times of the receiver's
        own clock each row's offsets hold for (±inf open; between two segments a stretch neither holds: set aside),
        ``clock`` (n,) each arrival's row (-1: in such a stretch, not fitted), ``breaks`` the
        :class:`~sblsim.models.sync.breaks.ClockBreak` s; else None (one row per receiver).
    part : numpy.ndarray or None
        (R,) int, each row's **clock part** where a receiver's time went back in the file's order (a reset kept in
        its logging order: the part of its rows from there, 1 first): a row holds for its part's times within its
        ``span`` only (two parts may read the same times); None: every row part 1.
    shift_covariance_all : numpy.ndarray or None
        (2R, 2R) [m²] with refined positions, all the shifts' joint covariance (x then y per receiver; the
        blocks of ``shift_covariance`` on its diagonal), else None.
    window_slowness : numpy.ndarray or None
        (W, 2) [s/m] a season fitted in windows (:mod:`sblsim.models.sync.windows`) with its slowness estimated:
        each window's slowness and sigma (NaN: none); else None.
    """

    edges: np.ndarray
    knots: np.ndarray
    knot_sigma: np.ndarray
    drift: np.ndarray
    drift_sigma: np.ndarray
    counts: np.ndarray
    emission_time: np.ndarray
    residual: np.ndarray
    standardised: np.ndarray
    kept: np.ndarray
    scale: np.ndarray
    slowness: float | None
    slowness_sigma: float | None
    iterations: int
    shift: np.ndarray | None = None
    shift_covariance: np.ndarray | None = None
    distance: np.ndarray | None = None
    site: np.ndarray | None = None
    span: np.ndarray | None = None
    clock: np.ndarray | None = None
    breaks: list | None = None
    part: np.ndarray | None = None
    shift_covariance_all: np.ndarray | None = None
    window_slowness: np.ndarray | None = None

    def rows_at(self, receiver: np.ndarray, time: np.ndarray, part: np.ndarray | None = None) -> np.ndarray:
        """(n,) int, the row of :attr:`knots` that holds ``receiver`` (n,) int's clock at its own ``time`` (n,)
        [s] in its clock ``part`` (n,) int (default 1): the receiver itself where its clock never broke, else the
        segment of that part whose :attr:`span` holds the time; -1 where none does (a stretch set aside at a
        break)."""
        receiver = np.asarray(receiver, np.int64)
        if self.site is None:
            return receiver.copy()
        time = np.asarray(time, float)
        part = np.ones(receiver.shape, np.int64) if part is None else np.asarray(part, np.int64)
        own = np.ones(len(self.site), np.int64) if self.part is None else self.part
        out = np.full(receiver.shape, -1, np.int64)
        for row in range(len(self.site)):
            hit = (receiver == self.site[row]) & (time >= self.span[row, 0]) & (time <= self.span[row, 1])
            out[hit & (part == own[row])] = row
        return out

    def offset(self, receiver: np.ndarray, time: np.ndarray) -> np.ndarray:
        """(n,) [s] the offset of ``receiver`` (n,) int at its own clock's ``time`` (n,) [s]: the knots
        interpolated, extended beyond the edges with the end bin's drift."""
        width = self.edges[1] - self.edges[0]
        k = np.clip(np.floor((time - self.edges[0]) / width).astype(np.int64), 0, len(self.edges) - 2)
        f = (time - self.edges[k]) / width
        return self.knots[receiver, k] * (1 - f) + self.knots[receiver, k + 1] * f

    def without(self, rows: np.ndarray) -> "ClockFit":
        """The fit with the clock ``rows`` (R,) bool not synchronised: their knots, drifts and sigmas NaN (their
        arrivals then on no synchronised clock)."""
        knots, knot_sigma, drift, drift_sigma = (np.array(a, float) for a in (self.knots, self.knot_sigma,
                                                                               self.drift, self.drift_sigma))
        for values in (knots, knot_sigma, drift, drift_sigma):
            values[np.asarray(rows, bool)] = np.nan
        return replace(self, knots=knots, knot_sigma=knot_sigma, drift=drift, drift_sigma=drift_sigma)


__all__ = ["ClockFit"]

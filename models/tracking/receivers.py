"""Each receiver judged by its own arrivals over a whole track: one whose arrivals are consistently late is out of
line of sight (behind a corner, heard by a reflection).

A direct arrival's residual against a good track, ``z = (toa − t_e − ‖p − r‖ / c) / σ_toa``, is centred on zero; a
multipath arrival is late (positive), now and then. A receiver that hears the tag only by a reflection, or through a
bend, has most of its arrivals late by about the same extra path: the median of its residuals is then positive and
large, where a line-of-sight receiver's median stays within a few tenths (the median is blind to up to half of
the arrivals being late). A receiver whose median residual over at least :data:`MIN_ARRIVALS` arrivals exceeds
:data:`LATE_SIGMAS` is named; the robust smoother has weighed its late arrivals down already (their Student-t
weights), and the report gives the share it kept.

References
----------
Chen, "Non-line-of-sight identification and mitigation in wireless location", IEEE WCNC 1999 (a receiver's residuals
over many measurements separate its line-of-sight and non-line-of-sight behaviour); Baktoft et al. 2017 (the
multipath arrivals of Lake Hald).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: A receiver's median normalised residual above which it is out of line of sight [σ_toa].
LATE_SIGMAS = 3.0
#: The fewest arrivals a receiver needs to be judged.
MIN_ARRIVALS = 20
#: An arrival counts as kept within this many σ_toa of the track (the robust smoother's weight 0.1 at ν = 3).
KEPT_SIGMAS = 6.1


@dataclass(frozen=True)
class ReceiverResiduals:
    """Per receiver (n,): ``arrivals`` heard at the track's pings, ``median_z`` (the median normalised residual,
    NaN without arrivals), ``kept`` (the share within :data:`KEPT_SIGMAS`), ``late`` (out of line of sight: the
    median beyond :data:`LATE_SIGMAS` over :data:`MIN_ARRIVALS` arrivals or more)."""

    arrivals: np.ndarray
    median_z: np.ndarray
    kept: np.ndarray
    late: np.ndarray


def receiver_residuals(toa: np.ndarray, receivers: np.ndarray, positions: np.ndarray, emissions: np.ndarray,
                       c: float, sigma_toa: float | np.ndarray) -> ReceiverResiduals:
    """Every receiver's residuals against a track (module docstring).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    receivers : ndarray, (n, dim)
        [m].
    positions : ndarray, (m, dim)
        The track's positions at each ping [m] (NaN: not positioned).
    emissions : ndarray, (m,)
        Its emission times [s].
    c : float
        Sound speed [m/s].
    sigma_toa : float or ndarray, (n,)
        [s]: one, or each receiver's (the residuals normalised by their receiver's).

    Returns
    -------
    ReceiverResiduals
    """
    d = np.linalg.norm(np.asarray(positions, float)[:, None, :] - np.asarray(receivers, float)[None], axis=2)
    z = (np.asarray(toa, float) - np.asarray(emissions, float)[:, None] - d / c) / sigma_toa
    heard = np.isfinite(z)
    arrivals = heard.sum(axis=0)
    median = np.full(z.shape[1], np.nan)
    kept = np.full(z.shape[1], np.nan)
    some = arrivals > 0
    median[some] = np.nanmedian(z[:, some], axis=0)
    kept[some] = (np.abs(np.where(heard, z, np.inf)) <= KEPT_SIGMAS).sum(axis=0)[some] / arrivals[some]
    late = (arrivals >= MIN_ARRIVALS) & (np.nan_to_num(median) > LATE_SIGMAS)
    return ReceiverResiduals(arrivals, median, kept, late)


__all__ = ["KEPT_SIGMAS", "LATE_SIGMAS", "MIN_ARRIVALS", "ReceiverResiduals", "receiver_residuals"]

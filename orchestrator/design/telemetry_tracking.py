"""The telemetry design's confirmation by the tracker: a simulated tag's pings along its path tracked as
``sblsim replay --format toa`` tracks a recorded tag (the single-ping fixes, the ping type's schedule, the motion
noise by EM, the robust smoother; :mod:`sblsim.orchestrator.tracks.track`), its 2-D error against the path beside
the tracker's smoothing bound at the path's true positions and velocities (the PCRB of the same motion model and
schedule, :func:`~sblsim.models.receiver.toa_bound.pcrb`; Tichavský, Muravchik & Nehorai, IEEE Trans. Signal
Process. 46(5), 1998, and its smoothing form, Šimandl, Královec & Tichavský, Automatica 37, 2001), and the track's
NEES against its own covariance.

With the receivers' clocks (:func:`track_synchronised`): each receiver's clock drawn with an offset and a drift of a
VR2W-class grade (:data:`CLOCK_GRADE`), a sync tag at each receiver pinging at random intervals and heard by the
others with the design's detection curve at their distance, the array synchronised from those arrivals by the sync
model of ``sblsim sync`` (:func:`~sblsim.models.sync.clocks.fit_clocks`; Baktoft, Gjelland, Økland & Thygesen 2017,
Sci. Rep. 7:14294), the walk's arrivals read on the receivers' clocks and corrected with the fitted clocks, then
tracked as above: the same pings, the same detections, only the clocks' errors added.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from sblsim.models.acoustics.channel.pinger import RECEIVER_CLOCK_VARIABLES
from sblsim.models.errors import ModelError
from sblsim.models.receiver import toa_bound as tb
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.sync.clock_fit import ClockFit
from sblsim.models.sync.clocks import fit_clocks
from sblsim.models.sync.emissions import connected, sync_emissions
from sblsim.models.sync.simulate import draw_clocks, on_clocks, sync_tag_arrivals
from sblsim.orchestrator.tracks.tracker import motion_model, ping_schedule, tracker_settings

#: The receivers' clocks and sync tags of :func:`track_synchronised`: the declared defaults of the simulated inverted
#: LBL's raw detections (``acoustics.receiver_clock_offset`` ±2 s, ``receiver_clock_drift_ppm`` ±20 ppm, a
#: VR2W-class crystal's grade; sync tags every ``sync_interval_min`` to ``sync_interval_max``, 540–660 s).
CLOCK_GRADE = {v.name: float(v.start) for v in RECEIVER_CLOCK_VARIABLES}
#: The sync model's time bins [s] (``sblsim sync``'s default ``--bin-hours 1``).
SYNC_BIN = 3600.0
#: The stream of the clocks' and sync tags' draws (beside the design's seed and the receiver count), so that no
#: draw of the confirmation without them moves.
SYNC_STREAM = 0x5C10C


def track_path(receivers: np.ndarray, toa: np.ndarray, positions: np.ndarray, emissions: np.ndarray,
               sound_speed: float, sigma_toa: float, burst_interval: tuple[float, float],
               depth: np.ndarray | None = None, depth_sigma: float = 0.3, ping_type: str = "rbi",
               burst_sequence: np.ndarray | None = None, multipath: tuple[float, float] | None = None) -> dict:
    """Track a simulated tag's pings and score the track against its path (in 3-D: tracked in 3-D, scored
    horizontally).

    Parameters
    ----------
    receivers : ndarray, shape (n, 2) or (n, 3)
        [m] (North, East[, depth]; depth positive down, given to the tracker as its height z = −depth).
    toa : ndarray, shape (K, n)
        Times of arrival [s], NaN where not heard.
    positions : ndarray, shape (K, dim)
        The tag's true position at each emission [m], as the receivers'.
    emissions : ndarray, shape (K,)
        The true emission times [s], increasing.
    sound_speed : float
        [m/s], given to the tracker (the design's).
    sigma_toa : float
        The timing σ [s].
    burst_interval : tuple of float
        The tag's random burst interval (min, max) [s] (``--ping-type rbi --burst-interval MIN:MAX``); a stable
        burst interval's (Δ, Δ) (the tracker's nominal interval); not read for ``pbi``.
    depth : ndarray, shape (K,), optional
        3-D: the tag's depth sensor's reading per ping [m] (positive down; None: no sensor), taken by the fixes and
        the robust smoother as the replay takes a ``depth_m`` column.
    depth_sigma : float, optional
        The readings' σ [m].
    ping_type : str, optional
        ``rbi`` (default), ``sbi`` or ``pbi``, as ``--ping-type`` takes it.
    burst_sequence : ndarray, shape (k,), optional
        ``pbi``: the tag's intervals in order [s] (``--burst-sequence``).
    multipath : tuple of float, optional
        The simulated multipath, ``(share, mean delay)`` [1, s]: a share of the arrivals late by an exponential
        delay of that mean, which the robust smoother then models (the tracker's ``delay_share``, ``delay_mean``:
        :mod:`sblsim.models.tracking.arrival_model`); None or a share of 0: not modelled.

    Returns
    -------
    dict
        ``tracked_pings`` (the pings from the first heard by three receivers to the last heard by one: the rows
        the tracker positions and the bound starts from), ``tracked_rms_m`` (the robust smoother's 2-D RMS error
        over them), ``tracked_bound_m`` (the smoothing bound's RMS DRMS over the same pings, its horizontal part in
        3-D, without the depth readings), ``tracked_ratio``
        (their ratio), ``tracked_nees`` (the mean 2-D NEES against the track's covariance; 2 when consistent),
        ``tracked_p95_m`` and ``acceleration_psd_m2_s3`` (the EM's motion noise). NaN figures where fewer than
        ten pings can be tracked.
    """
    nothing = {"tracked_pings": 0, "tracked_rms_m": math.nan, "tracked_bound_m": math.nan,
               "tracked_ratio": math.nan, "tracked_nees": math.nan, "tracked_p95_m": math.nan,
               "acceleration_psd_m2_s3": math.nan}
    heard = np.isfinite(toa).sum(axis=1)
    starts, ends = np.flatnonzero(heard >= 3), np.flatnonzero(heard >= 1)
    if not len(starts) or ends[-1] - starts[0] + 1 < 10:
        return nothing
    rows = slice(starts[0], ends[-1] + 1)
    toa, positions, emissions = toa[rows], positions[rows], emissions[rows]
    three_d = receivers.shape[1] == 3
    if three_d:  # the tracker's z is up
        up = np.array([1.0, 1.0, -1.0])
        receivers, positions = receivers * up, positions * up
        depth = None if depth is None else depth[rows]
        fx, fe, _, fused, _ = tt.fix_pings(toa, receivers, sound_speed, sigma_toa, depth=depth,
                                           depth_sigma=depth_sigma)
        settings = replace(tracker_settings(sound_speed, fe), sigma_toa=sigma_toa, depth_sigma=depth_sigma)
    else:
        fx, fe, _, fused, _ = tt.fix_pings(toa, receivers, sound_speed, sigma_toa)
        settings = replace(tracker_settings(sound_speed, fe), sigma_toa=sigma_toa)
    if ping_type == "sbi":  # the tracker's nominal interval Δ
        settings = replace(settings, interval=float(burst_interval[0]))
    if multipath is not None and multipath[0] > 0.0:
        settings = replace(settings, delay_share=float(multipath[0]), delay_mean=float(multipath[1]))
    schedule, _ = ping_schedule(toa, receivers, settings, ping_type, burst_interval if ping_type == "rbi" else None,
                                burst_sequence if ping_type == "pbi" else None)
    settings = replace(settings, interval=schedule.interval)
    settings, motion = motion_model(toa, receivers, settings, schedule, (fx, fe, fused), None)
    robust = tt.robust_track(toa, receivers, settings, (fx, fe, fused), None, schedule,
                             depth if three_d else None)
    error = robust.x[:, :2] - positions[:, :2]
    squared = np.sum(error**2, axis=1)
    nees = np.einsum("ki,kij,kj->k", error, np.linalg.inv(robust.P[:, :2, :2]), error)
    velocities = np.gradient(positions, emissions, axis=0)
    bound = tb.pcrb(positions, velocities, emissions, np.isfinite(toa), receivers, sound_speed, sigma_toa,
                    tb.MotionModel.of(settings), schedule)
    bound = np.sqrt(np.abs(np.trace(bound.B_smoothed[:, :2, :2], axis1=1, axis2=2))) if three_d else bound.smoothed
    rms, limit = float(np.sqrt(np.mean(squared))), float(np.sqrt(np.mean(np.square(bound))))
    return {"tracked_pings": int(len(toa)), "tracked_rms_m": rms, "tracked_bound_m": limit,
            "tracked_ratio": rms / limit if limit > 0.0 else math.nan, "tracked_nees": float(np.mean(nees)),
            "tracked_p95_m": float(np.percentile(np.sqrt(squared), 95)),
            "acceleration_psd_m2_s3": float(motion["acceleration_psd_m2_s3"])}


@dataclass
class SynchronisedArrivals:
    """A tag's arrivals read on the receivers' drawn clocks and corrected with the clocks fitted from the sync tags
    (:func:`synchronised_toa`).

    Attributes
    ----------
    toa : numpy.ndarray
        (K, n) [s] the corrected times of arrival, on the reference receiver's clock; NaN where not heard or at a
        receiver that could not be synchronised.
    offset0, drift : numpy.ndarray
        (n,) [s], [s/s] the drawn clocks (the reference receiver's 0: the true time).
    reference : int
        The reference receiver of the fit.
    synchronised : numpy.ndarray
        (n,) bool, the receivers the fit synchronised.
    fit : ClockFit
        The fitted clocks (times from the true time's origin).
    truth : numpy.ndarray
        (n, K+1) [s] the drawn clocks' true offsets against the reference's at the fit's bin edges (NaN where
        not synchronised).
    error : numpy.ndarray
        (m,) [s] each heard arrival's corrected time less its true time on the reference's clock (synchronised
        receivers only).
    arrivals : int
        The sync-tag arrivals the fit used.
    """

    toa: np.ndarray
    offset0: np.ndarray
    drift: np.ndarray
    reference: int
    synchronised: np.ndarray
    fit: ClockFit
    truth: np.ndarray
    error: np.ndarray
    arrivals: int

    @property
    def within_3_sigma(self) -> float:
        """[0–1] the share of the synchronised receivers' knots (receiver-bin edges; the reference's left out)
        whose fitted offset is within 3 of its sigmas of the drawn clock's."""
        rows = self.synchronised.copy()
        rows[self.reference] = False
        z = (self.fit.knots[rows] - self.truth[rows]) / self.fit.knot_sigma[rows]
        return float(np.mean(np.abs(z) <= 3.0)) if z.size else math.nan


def _true_offset(receiver: np.ndarray, time: np.ndarray, offset0: np.ndarray, drift: np.ndarray,
                 reference: int) -> np.ndarray:
    """(...) [s] the offset of ``receiver``'s clock at its reading ``time`` against the ``reference``'s clock at
    the same instant (:meth:`sblsim.models.sync.simulate.SimulatedSync.offset`)."""
    tau = (time - offset0[receiver]) / (1.0 + drift[receiver])
    return time - (tau + offset0[reference] + drift[reference] * tau)


def synchronised_toa(receivers: np.ndarray, toa: np.ndarray, hears: np.ndarray, sigma_toa: float,
                     sound_speed: float, rng: np.random.Generator, offset: float | None = None,
                     drift: float | None = None, interval: tuple[float, float] | None = None,
                     bin_width: float = SYNC_BIN) -> SynchronisedArrivals:
    """A tag's times of arrival through real clocks synchronised from sync tags (the module docstring).

    Each receiver's clock (:func:`~sblsim.models.sync.simulate.draw_clocks`, receiver 0 the true time); a sync tag
    at each receiver emitting at intervals ``U(interval)`` from time 0 until a maximum interval after the tag's
    last arrival, each emission heard with ``hears`` (:func:`~sblsim.models.sync.simulate.sync_tag_arrivals`, the
    straight line at ``sound_speed``, timing noise ``sigma_toa``); the arrivals read on the clocks, grouped into
    emissions (:func:`~sblsim.models.sync.emissions.group_emissions`, a third of the shortest interval), an emission
    heard by one receiver only left out and the clocks fitted (:func:`~sblsim.models.sync.clocks.fit_clocks`, the
    sound speed given, bins of ``bin_width``; the reference receiver 0, or the receiver with the most arrivals
    where 0 cannot be synchronised with the most, as ``sblsim sync`` chooses); then the tag's arrivals read on the
    clocks and each corrected by its receiver's fitted offset at its own clock's reading.

    Parameters
    ----------
    receivers : numpy.ndarray
        (n, 2) or (n, 3) [m].
    toa : numpy.ndarray
        (K, n) [s] the tag's arrivals in true time, NaN where not heard.
    hears : numpy.ndarray
        (n, n) [0–1], ``[i, j]`` the probability that receiver ``i`` hears the sync tag at receiver ``j``
        (:func:`~sblsim.models.design.sync_graph.sync_probabilities`).
    sigma_toa : float
        [s] the sync arrivals' timing noise.
    sound_speed : float
        [m/s].
    rng : numpy.random.Generator
        The clocks' and the sync tags' draws.
    offset, drift : float, optional
        [s], [s/s] the clocks' grade: offsets uniform in ±``offset``, drifts in ±``drift`` (default
        :data:`CLOCK_GRADE`'s).
    interval : (float, float), optional
        [s] the sync tags' burst interval (default :data:`CLOCK_GRADE`'s).
    bin_width : float
        [s] the sync model's bins.

    Returns
    -------
    SynchronisedArrivals

    Raises
    ------
    ModelError
        Fewer than two receivers hear common sync-tag emissions (:func:`~sblsim.models.sync.clocks.fit_clocks`).
    """
    receivers = np.asarray(receivers, float)
    n = len(receivers)
    offset = CLOCK_GRADE["receiver_clock_offset"] if offset is None else offset
    drift = CLOCK_GRADE["receiver_clock_drift_ppm"] * 1e-6 if drift is None else drift
    interval = (CLOCK_GRADE["sync_interval_min"], CLOCK_GRADE["sync_interval_max"]) if interval is None else interval
    offset0, drifts = draw_clocks(n, offset, drift, rng)
    span = float(np.nanmax(toa)) + interval[1]
    rec, tag, tau = sync_tag_arrivals(receivers, span, interval, sound_speed, np.asarray(hears, float).T,
                                      sigma_toa, rng)
    time = on_clocks(rec, tau, offset0, drifts)
    emission, duplicate, single = sync_emissions(tag, rec, time, np.full(n, interval[0] / 3.0))
    used = ~duplicate & ~single
    reference = 0
    linked = connected(rec[used], emission[used], n, reference)
    if linked.sum() < n:
        best = connected(rec[used], emission[used], n, int(np.argmax(np.bincount(rec[used], minlength=n))))
        if best.sum() > linked.sum():
            reference, linked = int(np.argmax(np.bincount(rec[used], minlength=n))), best
    distance = np.linalg.norm(receivers[tag] - receivers[rec], axis=1)
    fit = fit_clocks(rec, emission, time, distance, np.full(len(time), 1.0 / sound_speed), used, linked, reference,
                     bin_width)
    ping, j = np.nonzero(np.isfinite(toa))
    clock = on_clocks(j, toa[ping, j], offset0, drifts)
    keep = linked[j]
    corrected = clock[keep] - fit.offset(j[keep], clock[keep])
    out = np.full(toa.shape, np.nan)
    out[ping[keep], j[keep]] = corrected
    tau_heard = toa[ping[keep], j[keep]]
    error = corrected - (tau_heard + offset0[reference] + drifts[reference] * tau_heard)
    edges = np.broadcast_to(fit.edges, (n, len(fit.edges)))
    truth = np.where(linked[:, None], _true_offset(np.arange(n)[:, None], edges, offset0, drifts, reference), np.nan)
    return SynchronisedArrivals(out, offset0, drifts, reference, linked, fit, truth, error,
                                int(np.sum(used & linked[rec])))


def track_synchronised(receivers: np.ndarray, toa: np.ndarray, positions: np.ndarray, emissions: np.ndarray,
                       hears: np.ndarray, sound_speed: float, sigma_toa: float, burst_interval: tuple[float, float],
                       rng: np.random.Generator, tracked: dict | None = None, depth: np.ndarray | None = None,
                       depth_sigma: float = 0.3, ping_type: str = "rbi", burst_sequence: np.ndarray | None = None,
                       multipath: tuple[float, float] | None = None) -> dict:
    """The walk's pings tracked through clocks synchronised from sync tags (:func:`synchronised_toa`, then
    :func:`track_path`), beside the same pings tracked with the true clocks (``tracked``: :func:`track_path`'s row
    of the same pings, computed here where not given).

    Parameters
    ----------
    receivers, toa, positions, emissions, sound_speed, sigma_toa, burst_interval
        As :func:`track_path` (``toa`` in true time).
    hears : numpy.ndarray
        (n, n) [0–1], as :func:`synchronised_toa`.
    rng : numpy.random.Generator
        The clocks' and sync tags' draws.
    tracked : dict, optional
        :func:`track_path`'s row of the same pings with the true clocks.
    depth, depth_sigma
        As :func:`track_path` (3-D: the tag's depth readings [m] and their σ [m]).
    ping_type, burst_sequence, multipath
        As :func:`track_path` (the tag's ping type, a ``pbi`` tag's intervals [s] and the multipath modelled).

    Returns
    -------
    dict
        ``synced_pings``, ``synced_rms_m``, ``synced_nees``, ``synced_p95_m`` (:func:`track_path`'s figures through
        the synchronised clocks), ``synced_ratio`` (``synced_rms_m`` over the true clocks' ``tracked_rms_m``),
        ``sync_residual_m`` (the RMS of the corrected arrivals' clock error, times the sound speed [m]),
        ``sync_within_3_sigma`` (:attr:`SynchronisedArrivals.within_3_sigma`), ``sync_receivers`` (synchronised),
        ``sync_arrivals`` (the sync-tag arrivals fitted), ``sync_bins``, and the grade: ``clock_offset_s``,
        ``clock_drift_ppm``, ``sync_interval_s``. Where the fit refuses (fewer than two receivers hear common
        sync-tag emissions), the figures are NaN and ``sync_receivers`` 0.

    Raises
    ------
    ValueError
        ``toa`` without a heard arrival.
    """
    if not np.isfinite(toa).any():
        raise ValueError("track_synchronised: no arrival heard")
    if tracked is None:
        tracked = track_path(receivers, toa, positions, emissions, sound_speed, sigma_toa, burst_interval, depth,
                             depth_sigma, ping_type, burst_sequence, multipath)
    grade = {"clock_offset_s": CLOCK_GRADE["receiver_clock_offset"],
             "clock_drift_ppm": CLOCK_GRADE["receiver_clock_drift_ppm"],
             "sync_interval_s": [CLOCK_GRADE["sync_interval_min"], CLOCK_GRADE["sync_interval_max"]]}
    try:
        synced = synchronised_toa(receivers, toa, hears, sigma_toa, sound_speed, rng)
    except ModelError:
        return {"synced_pings": 0, "synced_rms_m": math.nan, "synced_nees": math.nan, "synced_p95_m": math.nan,
                "synced_ratio": math.nan, "sync_residual_m": math.nan, "sync_within_3_sigma": math.nan,
                "sync_receivers": 0, "sync_arrivals": 0, "sync_bins": 0} | grade
    row = track_path(receivers, synced.toa, positions, emissions, sound_speed, sigma_toa, burst_interval, depth,
                     depth_sigma, ping_type, burst_sequence, multipath)
    rms, truth = row["tracked_rms_m"], tracked["tracked_rms_m"]
    return {"synced_pings": row["tracked_pings"], "synced_rms_m": rms, "synced_nees": row["tracked_nees"],
            "synced_p95_m": row["tracked_p95_m"],
            "synced_ratio": rms / truth if math.isfinite(truth) and truth > 0.0 else math.nan,
            "sync_residual_m": float(sound_speed * np.sqrt(np.mean(synced.error ** 2))) if synced.error.size
            else math.nan,
            "sync_within_3_sigma": synced.within_3_sigma, "sync_receivers": int(synced.synchronised.sum()),
            "sync_arrivals": synced.arrivals, "sync_bins": int(len(synced.fit.edges) - 1)} | grade


__all__ = ["CLOCK_GRADE", "SYNC_BIN", "SYNC_STREAM", "SynchronisedArrivals", "synchronised_toa", "track_path",
           "track_synchronised"]

"""A recorded inverted-LBL track: the times of arrival through the single-ping fix, the EKF, the RTS smoother and
the robust smoother (:mod:`sblsim.models.tracking`), scored against a truth track (:mod:`.scoring`, :mod:`.bound`),
written to a folder (:mod:`.outputs`).

The track is the robust smoother's rows (``smooth``: every ping from the tracker's start), else the causal EKF's;
the other estimators are kept beside it. Before tracking, the array may be thinned (``receivers_kept``: the other
receivers' columns not used) and a share of the detections removed at random (``drop_detections``, seeded:
:mod:`.thinning`); the ping type and the steps between the pings are found
(:func:`~sblsim.orchestrator.tracks.tracker.ping_schedule`), the motion model's noise estimated
(:func:`~sblsim.orchestrator.tracks.tracker.motion_model`), the sound speed taken
(:mod:`.speed`), and each estimate checked against its own data (the ``quality`` column). A stationary tag's one
position is :mod:`.stationary`'s, the consider terms' pieces :mod:`.consider`'s, the checks for two tags under one
id (refused, or a second place's rows flagged ``two_places`` at their fixes) :mod:`.two_tags`' and the outcome's
shape :mod:`.outcome`'s.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking import quality as qa
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking.depth import check_given_depth
from sblsim.models.tracking.geometry import check_array
from sblsim.models.tracking.integrity import protection_levels
from sblsim.models.tracking.receivers import receiver_residuals
from sblsim.models.tracking.still_tag import still_tag
from sblsim.models.tracking.strays import SET_ASIDE_REASON
from sblsim.orchestrator.io.frames import frame_summary
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.tracks.bound import BOUND_COLUMNS, bound_along_track, bound_thirds
from sblsim.orchestrator.tracks.consider import _plus, survey_considered, survey_sigmas
from sblsim.orchestrator.tracks.depth import (
    check_water_depth,
    depth_term,
    plane_depth,
    prior_info,
    tag_depth,
    undetermined_depth,
)
from sblsim.orchestrator.tracks.outcome import SCORE_KEYS, TrackOutcome
from sblsim.orchestrator.tracks.row_flags import flag_interpolated, flag_rows, reason_counts
from sblsim.orchestrator.tracks.scoring import LAG_RANGE_S, score
from sblsim.orchestrator.tracks.speed import TEMPERATURE_SOURCE, Water, season_rescaled, sound_speed_stage
from sblsim.orchestrator.tracks.thinning import _usable, drop_detections
from sblsim.orchestrator.tracks.tracker import (
    DEPTH_SIGMA,
    motion_model,
    ping_schedule,
    set_aside,
    toa_noise,
    tracker_settings,
)
from sblsim.orchestrator.tracks.two_tags import _one_tag, at_second_place, second_place

#: The motion models of ``--motion``: a moving tag (the filters and smoothers), or a stationary one (one position for
#: all pings, :func:`~sblsim.models.tracking.still_tag.still_tag`).
MOTIONS = ("moving", "stationary")


#: The largest share of detections removed at random.
MAX_DROP = 0.99


#: The largest truth error per axis ``--truth-sigma`` takes [m].
MAX_TRUTH_SIGMA = 100.0


def track(toa_path: Path, receivers_path: Path, truth_path: Path | None = None, reference_path: Path | None = None,
          smooth: bool = True, sound_speed: float | None = None, receivers_kept: Sequence[str] | None = None,
          drop: float = 0.0, seed: int = 0, truth_sigma: float = 0.0, ping_type: str | None = None,
          burst_interval: tuple[float, float] | None = None, burst_sequence_path: Path | None = None,
          acceleration_psd: float | None = None, sound_speed_path: Path | None = None,
          temperature: float | None = None, salinity: float | None = None, motion: str = "moving",
          fixed_depth: float | None = None, depth_sigma: float = DEPTH_SIGMA,
          survey_sigma: float | None = None, crs: str | None = None, frame: str | None = None,
          time_origin: float | None = None, other_filters: bool = True, toa_sigma: float | None = None,
          temperature_path: Path | None = None, water_depth: float | None = None,
          force_interval: bool = False, survey_covariance: tuple[Sequence[str], np.ndarray] | None = None,
          clocks_interpolated: Sequence[tuple[float, float]] = (),
          study_speed: tuple[float, float] | None = None,
          study_speed_series: Sequence[Sequence[float]] | None = None) -> TrackOutcome:
    """Read, thin, track and score (module docstring); the sound speed as
    :func:`~sblsim.orchestrator.tracks.speed.sound_speed_stage` takes ``sound_speed``, ``sound_speed_path``,
    ``temperature`` and ``salinity``; the tag's depth as :func:`~sblsim.orchestrator.tracks.depth.tag_depth` takes
    ``fixed_depth`` and ``depth_sigma``; the receivers' survey error as
    :func:`~sblsim.orchestrator.tracks.consider.survey_sigmas` takes ``survey_sigma``, the moving tag's consider terms
    its receivers' correlated errors where ``survey_covariance`` gives them (names, (2N, 2N) [m²]: positions refined
    together, :func:`~sblsim.orchestrator.tracks.consider.survey_considered`); ``truth_sigma`` [m] the truth's
    own error per horizontal axis in the NEES (:func:`~sblsim.orchestrator.tracks.scoring.score`);
    ``ping_type``, ``burst_interval`` as :func:`~sblsim.orchestrator.tracks.tracker.ping_schedule`,
    ``burst_sequence_path`` the file of a ``pbi`` tag's intervals
    (:mod:`~sblsim.orchestrator.readers.burst_sequence`); ``acceleration_psd`` the motion model's ``q``
    [m²/s³] (None: estimated from the pings by EM, :mod:`sblsim.models.tracking.motion_noise`); ``crs`` and ``frame``
    as :func:`~sblsim.orchestrator.readers.receivers_file.read_receivers` takes them (receivers with a CRS: every row
    gains ``lat``, ``lon`` [° WGS 84], a truth may be in latitude and longitude); ``time_origin`` [s since 1970 UTC] the
    UTC time of the TOA file's zero (every row gains ``epoch_s`` and ``time_utc``, a truth or a sound-speed series
    may be in absolute times); ``other_filters`` False leaves out the causal filters the track does not need (the
    sequential EKF and the UKF, run beside for comparison: half the time of a track); ``toa_sigma`` [s] the timing
    noise of every arrival (None: each receiver's ``toa_sigma_s`` in the receivers file, as ``sblsim toa`` writes it
    from a synchronisation's residuals, else :data:`~sblsim.models.tracking.timing.SIGMA_TOA`:
    :func:`~sblsim.orchestrator.tracks.tracker.toa_noise`, ``summary["toa_noise"]``), in every estimator's
    measurement covariance and in the sound speed's calibration; ``temperature_path`` a water-temperature series made
    the sound speed by TEOS-10 at ``salinity`` (:func:`~sblsim.orchestrator.tracks.speed.sound_speed_stage`);
    ``water_depth`` [m] the water's depth, which bounds the tag's (:mod:`sblsim.orchestrator.tracks.depth`; receivers
    in one plane hold it at mid-water, else at their mean depth); the rows a stated interval (``burst_interval``,
    ``burst_sequence_path``) shows to be no pings set aside before anything is fitted
    (:func:`~sblsim.orchestrator.tracks.tracker.set_aside`: their rows kept in the outputs with no estimate and the
    reason, listed in ``set_aside``), a stated interval the rows contradict as a whole refused unless
    ``force_interval``; a row in one of ``clocks_interpolated`` ((start, end) [s since 1970 UTC]: the clocks linear
    across a stretch of too few pings, :mod:`.row_flags`) flagged ``clocks_interpolated``; ``study_speed`` the
    study's own speed and its σ [m/s] as the sound speed's fallback (:func:`~.speed.sound_speed_stage`), each ping's
    arrivals first rescaled to it from ``study_speed_series`` (a season's windows' speeds where they differ:
    :func:`~.speed.season_rescaled`) where no speed, series or temperature is given and ``time_origin`` is."""
    import pandas as pd

    from sblsim.models.receiver import toa_tracking as tt
    from sblsim.models.tracking.filter_consider import consider_terms_along
    from sblsim.models.tracking.fix import speed_fix_covariance, survey_fix_covariance
    from sblsim.models.tracking.smoother_covariance import consider_covariance
    from sblsim.orchestrator.readers.burst_sequence import read_burst_sequence
    from sblsim.orchestrator.readers.receivers_file import read_receivers
    from sblsim.orchestrator.readers.time_series import read_track
    from sblsim.orchestrator.readers.toa_matrix import read_toa

    start = time.perf_counter()
    matrix = read_toa(toa_path)
    receivers = read_receivers(receivers_path, crs, frame)
    truth = read_track(truth_path, "truth", origin=time_origin, frame=receivers.frame) \
        if truth_path is not None else None
    reference = read_track(reference_path, "reference", increasing=False, origin=time_origin,
                           frame=receivers.frame) if reference_path is not None else None
    burst_sequence = read_burst_sequence(burst_sequence_path) if burst_sequence_path is not None else None
    toa, positions, names = _usable(matrix, receivers, receivers_kept)
    sigma, noise_info = toa_noise(toa_sigma, None if receivers.toa_sigma is None else
                                  receivers.toa_sigma[[receivers.names.index(n) for n in names]], names)
    toa, dropped = drop_detections(toa, drop, seed)
    dim = positions.shape[1]
    check_array(positions, names, toa, tt.SOUND_SPEED_RANGE[0])
    ps.first_arrival_steps(toa)  # the rows in time order, before anything is fitted to them
    # the rows the stated interval shows to be no pings (a stray code, a collision), set aside before anything is
    # fitted to them; a stated interval the rows contradict as a whole refused (or, forced, said)
    read = toa
    toa, stray, aside, aside_warning = set_aside(toa, positions, tt.SOUND_SPEED_RANGE[1], burst_interval,
                                                 burst_sequence, force_interval, stable=ping_type == "sbi",
                                                 slowest=tt.SOUND_SPEED_RANGE[0])
    if truth is not None:
        first = ps.first_arrivals(toa)
        span = (float(np.nanmin(first)), float(np.nanmax(first))) if np.isfinite(first).any() else (np.nan, np.nan)
        if not (truth[0, 0] <= span[1] + LAG_RANGE_S and truth[-1, 0] >= span[0] - LAG_RANGE_S):
            raise ModelError(f"truth: its times [{truth[0, 0]:.10g}, {truth[-1, 0]:.10g}] s do not overlap the pings' "
                             f"[{span[0]:.10g}, {span[1]:.10g}] s; allowed: a truth on the time base of the times of "
                             "arrival")
    depth, depth_info = tag_depth(matrix.depth, len(toa), dim, fixed_depth, depth_sigma)
    check_water_depth(water_depth, positions, names, fixed_depth)
    water = Water.of_array(positions, receivers.frame, water_depth)
    plane = plane_depth(depth, positions, water_depth, depth_sigma)
    if plane is not None:  # receivers in one plane: the depth held before anything is fitted (free, it would trade
        # against the sound speed)
        depth, depth_sigma, depth_info = np.full(len(toa), plane.depth), plane.sigma, prior_info(plane, positions,
                                                                                                   water_depth)
    survey = survey_sigmas(receivers, names, survey_sigma)
    considered_survey = survey_considered(survey, names, dim, survey_covariance)  # correlated where refined together
    # each receiver's clock offset's own uncertainty, that averaged over the tag's arrivals and its times' rounding
    # (receivers.csv's clock_sigma_s, clock_mean_sigma_s, rounding_sigma_s): a still tag's verdict's and place's terms
    clock_sigma, clock_mean, rounding = (None if v is None else v[[receivers.names.index(n) for n in names]]
                                         for v in (receivers.clock_sigma, receivers.clock_mean, receivers.rounding))
    season = None
    if study_speed and study_speed_series and time_origin is not None and sound_speed is None and \
            sound_speed_path is None and temperature is None and temperature_path is None:  # the season's water
        toa, season = season_rescaled(toa, positions, study_speed_series, time_origin, study_speed[0], sigma)
    toa, c, speed = sound_speed_stage(toa, positions, sound_speed, sound_speed_path, temperature, salinity, depth,
                                      depth_sigma, time_origin, sigma_toa=sigma, temperature_path=temperature_path,
                                      water=water, still=motion == "stationary", study_speed=study_speed)
    speed |= {"season_windows": season} if season else {}
    if fixed_depth is not None:  # one depth given: against where the arrivals put the tag with its depth free, at a
        # speed the given depth did not calibrate
        free_c = c if speed["source"] in ("given", "measured series", TEMPERATURE_SOURCE) else sound_speed_stage(
            toa, positions, None, None, temperature, salinity, None, depth_sigma, sigma_toa=sigma, water=water,
            study_speed=study_speed)[1]
        free = tt.fix_pings(toa, positions, free_c, sigma)
        check_given_depth(fixed_depth, depth_sigma, free[0], free[2], free[3].sum(axis=1), positions)
    # the estimators solved with the receivers as surveyed; the survey error added to the covariances reported
    fx, fe, fc, fused, fchi2 = tt.fix_pings(toa, positions, c, sigma, depth=depth, depth_sigma=depth_sigma)
    prior = plane if plane is not None else undetermined_depth(depth, fx, fc, fused.sum(axis=1), positions,
                                                               water_depth)
    if prior is not None and plane is None:  # the arrivals do not determine the depth (or the water bounds it): the
        # speed calibrated (where it was) and the fixes made again with the prior
        depth, depth_sigma, depth_info = np.full(len(toa), prior.depth), prior.sigma, prior_info(prior, positions,
                                                                                                   water_depth)
        if sound_speed is None and sound_speed_path is None and temperature_path is None:  # calibrated from the
            # pings (or fallen back where they could not be fitted): again with the prior; the times of arrival as
            # read (or as the season's windows rescaled them)
            toa, c, speed = sound_speed_stage(toa, positions, None, None, temperature, salinity, depth, depth_sigma,
                                              sigma_toa=sigma, water=water, still=motion == "stationary",
                                              study_speed=study_speed)
            speed |= {"season_windows": season} if season else {}
        fx, fe, fc, fused, fchi2 = tt.fix_pings(toa, positions, c, sigma, depth=depth, depth_sigma=depth_sigma)
    trusted = qa.trusted_fixes(fx, fc, fused.sum(axis=1), np.isfinite(toa).sum(axis=1), fchi2, dim,
                               None if depth is None else np.isfinite(depth))
    _one_tag(toa_path, fx, fe, fc, trusted)
    # a second place heard at once (two tags on one id): its rows out of the track, written at their fixes, flagged
    toa, (fx, fe, fc, fused, fchi2), second = second_place(toa, (fx, fe, fc, fused, fchi2), trusted, protection_levels(
        positions, fx, fused, c, sigma), receivers.frame)
    settings = replace(tracker_settings(c, fe, sigma), depth_sigma=depth_sigma)
    # the speed's standard error where it came from the pings or a fallback (a given or measured speed has none), a
    # consider term of the fixes' and the robust track's covariances as reported
    speed_sigma = speed.get("sigma_m_s")
    schedule, seen = ping_schedule(toa, positions, settings, ping_type, burst_interval, burst_sequence)
    settings = replace(settings, interval=schedule.interval)
    interval = settings.interval
    stationary = motion == "stationary"
    if stationary:  # one position for all pings: no motion model, no filters
        motion_info: dict[str, Any] = {"model": "stationary", "acceleration_psd_m2_s3": None,
                                       "source": "not used (one position for all pings)"}
        record, filters = None, {}
    else:
        settings, motion_info = motion_model(toa, positions, settings, schedule, (fx, fe, fused), acceleration_psd)
        motion_info = {"model": "moving"} | motion_info
        # the filters' gates take the survey's and the speed's errors beside their own covariance
        gated = replace(settings, survey_sigma=survey, sound_speed_sigma=speed_sigma)
        tracker = tt.ToaTracker(positions, gated)
        # the fixes restart a lost filter, and screen a ping's arrivals that fail the set's test
        record = tracker.run(toa, (fx, fc, fused.sum(axis=1)), fused, schedule)
        filters = {name: kind(positions, gated).run(toa, (fx, fc, fused.sum(axis=1)), fused, schedule)
                   for name, kind in tt.CAUSAL_TRACKERS.items()
                   if name != "ekf" and other_filters}  # the EKF's record is the RTS's
    depth_known = None if depth is None else np.isfinite(depth)  # a measurement of each fix and row where given
    trusted, protection, fix_explained = _fix_checks(toa, positions, c, sigma, (fx, fc, fused, fchi2), depth_known)
    columns = ["x", "y", "z"][:dim]
    frames, covariances, flagged = {}, {}, {}
    segment_starts = np.array([a for a, _ in schedule.segments()[1:]], int)

    def placed(t: np.ndarray, p: np.ndarray) -> dict[str, Any]:
        """A row's time and place: the coordinates, and where known the UTC time and the latitude and longitude."""
        out: dict[str, Any] = {}
        if time_origin is not None:
            out |= {"epoch_s": t + time_origin, "time_utc": iso_utc(t + time_origin)}
        out |= {a: p[:, k] for k, a in enumerate(columns)}
        if receivers.frame is not None:
            out["lat"], out["lon"] = receivers.frame.to_latlon(p[:, 0], p[:, 1])
        return out

    def rows(estimator: str, ping: np.ndarray, t: np.ndarray, p: np.ndarray, cov: np.ndarray, heard: np.ndarray,
             restarts: np.ndarray | None = None, consider: np.ndarray | None = None, against: tuple | None = None):
        """An estimator's rows, checked against the data with its own covariance ``cov`` (the times of arrival, the
        fixes, their trust, the arrivals each explains and their protection levels: ``against``, else the
        record's); reported with ``consider`` (the consider terms: the receivers' survey, the sound speed, the
        depth's prior) added, which its own-uncertainty limit takes too."""
        times, fixes, fixes_cov, trust, fix_agree, levels = against or (toa, fx, fc, trusted, fix_explained,
                                                                        protection)
        reported = cov if consider is None else cov + consider[:, :dim, :dim]
        agree = qa.explained(times[ping], positions, p, c, sigma)
        checked = qa.check_track(t, p, cov, fixes[ping], fixes_cov[ping], trust[ping] & (estimator != "fix"),
                                 None if restarts is None else np.isin(ping, restarts),
                                 explained=agree, fix_used=fix_agree[ping], reported=reported,
                                 acceleration_psd=None if stationary else settings.acceleration_psd,
                                 known_depth=None if depth_known is None else depth_known[ping],
                                 fix_protection=levels[ping])
        if estimator == "robust":  # the track the other estimators' rows are checked against
            track_rows.update(ping=ping, p=p, cov=cov, agree=agree, ok=checked.quality == "ok")
        elif track_rows:  # another estimator's rows off the track where it is ok (qa.off_the_track)
            at = np.searchsorted(track_rows["ping"], ping).clip(0, len(track_rows["ping"]) - 1)
            on = track_rows["ping"][at] == ping
            checked = qa.with_track(checked, on & qa.off_the_track(
                p, cov, agree, track_rows["p"][at], track_rows["cov"][at], track_rows["agree"][at],
                track_rows["ok"][at] & on, None if depth_known is None else depth_known[ping],
                protection[ping] if estimator == "fix" else None))
        cov = reported
        with np.errstate(invalid="ignore"):
            # a negative variance (a covariance broken by round-off) is no sigma: NaN, never a confident 0
            sigmas = {f"sigma_{a}": np.sqrt(np.where(cov[:, k, k] >= 0, cov[:, k, k], np.nan))
                      for k, a in enumerate(columns)}
        frames[estimator] = pd.DataFrame({"estimator": estimator, "ping": ping, "time": t,
                                          **placed(t, p), **sigmas, "receivers_heard": heard,
                                          "quality": checked.quality, "quality_reason": checked.reason})
        covariances[estimator] = cov[:, :2, :2]
        flagged[estimator] = checked.flagged

    robust = None
    track_rows: dict[str, np.ndarray] = {}  # the robust track's pings, places, covariances, arrivals and marks
    if stationary:  # one place (or two, where it moved beyond its error terms: the rows from the change flagged)
        still = still_tag(toa, positions, c, (fx, fe, fc, fused), trusted, sigma, survey, speed, clock_sigma,
                          clock_mean, rounding)
        rows("stationary", still.pings, still.emissions, still.places, still.covariances, still.heard, None,
             still.consider, _checked_against(still.corrected, toa, positions, c, sigma, depth, depth_sigma))
        motion_info |= still.summary | {"consider_terms": [term for term, known in (  # the speed's: where not fitted
            ("survey", survey is not None),
            ("sound speed", bool(speed_sigma) and still.summary["still"]["speed_change_m_s"] is None),
            ("clocks", clock_sigma is not None and bool(np.nan_to_num(clock_sigma).any()))) if known]}
        # a place refuted by the tag's own fixes (no row after the change is a place to take), or one nothing checks
        for marked, reason in ((still.moved, "tag_moved"), (np.full(len(still.moved), still.unchecked),
                                                            "motion_unchecked")):
            if marked.any():
                flagged["stationary"] = flag_rows(frames["stationary"], marked, reason)
    else:
        positioned = record.used.any(axis=1) & np.isfinite(record.x_filtered[:, 0])
        k = np.flatnonzero(positioned)
        # the filters' and the RTS smoother's consider terms of the same survey and speed errors, a block of pings
        # at a time (the sensitivity, (pings, states, receivers × dim + 1) numbers, is never made whole)
        considered = survey is not None or bool(speed_sigma)
        terms, smoothed = consider_terms_along(record, positions, c, sigma, k, considered_survey, speed_sigma, smooth) \
            if considered else (None, None)
        if smooth:
            xs, Ps = tracker.smooth(record)
            k0 = record.start
            if k0 < len(toa) - 1:
                robust = tt.robust_track(toa[k0:], positions, settings, (fx[k0:], fe[k0:], fused[k0:]), xs[k0:],
                                         schedule.sliced(k0), None if depth is None else depth[k0:])
                kr = np.arange(k0, len(toa))
                # the survey's error and the speed's (calibrated or fallen back to: its error in every range)
                extra = None if survey is None and not speed_sigma else consider_covariance(
                    toa[k0:], positions, replace(settings, survey_sigma=considered_survey), robust.x, speed_sigma,
                    schedule.sliced(k0), None if depth is None else depth[k0:])[:, :dim, :dim]
                extra = _plus(extra, depth_term(prior, robust.P[:, :dim, :dim]))
                rows("robust", kr, robust.x[:, -2], robust.x[:, :dim], robust.P[:, :dim, :dim],
                     (robust.weights >= tt.ROBUST_KEPT_WEIGHT).sum(axis=1), segment_starts, extra)
            rows("rts", k, xs[k, -2], xs[k, :dim], Ps[k][:, :dim, :dim], record.used[k].sum(axis=1),
                 np.r_[record.restarts, segment_starts], smoothed)
        rows("ekf", k, record.x_filtered[k, -2], record.x_filtered[k, :dim], record.P_filtered[k][:, :dim, :dim],
             record.used[k].sum(axis=1), np.r_[record.restarts, segment_starts],
             terms)
        for name, other in filters.items():
            u = np.flatnonzero(other.used.any(axis=1) & np.isfinite(other.x_filtered[:, 0]))
            rows(name, u, other.x_filtered[u, -2], other.x_filtered[u, :dim], other.P_filtered[u][:, :dim, :dim],
                 other.used[u].sum(axis=1), np.r_[other.restarts, segment_starts],
                 consider_terms_along(other, positions, c, sigma, u, considered_survey, speed_sigma)[0]
                 if considered else None)
    f = np.flatnonzero(np.isfinite(fe))
    fix_extra = _plus(None if survey is None else survey_fix_covariance(positions, c, sigma, fx[f], fe[f], fc[f],
                                                                        fused[f], considered_survey)[:, :dim, :dim],
                      depth_term(prior, fc[f][:, :dim, :dim]))
    if speed_sigma:
        fix_extra = _plus(fix_extra, speed_fix_covariance(positions, c, sigma, fx[f], fe[f], fc[f], fused[f],
                                                          speed_sigma)[:, :dim, :dim])
    rows("fix", f, fe[f], fx[f], fc[f][:, :dim, :dim], fused[f].sum(axis=1), None, fix_extra)
    # a fix the checks do not trust (no arrival to spare, or its own chi2 test failed) is a position its own data
    # cannot vouch for: on the full array 39 of the 112 such rows were more than 10 m from the GPS
    flagged["fix"] = flag_rows(frames["fix"], ~trusted[f], "untrusted_fix")
    # the stationary fix, else the robust smoother where it ran, else the causal EKF
    main = next(iter(frames)) if smooth or stationary else "ekf"
    if stray.any():  # the rows set aside: in the track with no estimate and their reason, the row numbering kept
        extra = np.setdiff1d(np.flatnonzero(stray), frames[main]["ping"])
        combined = pd.concat([frames[main], pd.DataFrame({"estimator": main, "ping": extra})], ignore_index=True)
        order = np.argsort(combined["ping"].to_numpy(), kind="stable")
        frames[main] = combined.iloc[order].reset_index(drop=True)
        covariances[main] = np.concatenate([covariances[main], np.full((len(extra), 2, 2), np.nan)])[order]
        for estimator, frame in frames.items():
            at = np.isin(frame["ping"].to_numpy(), np.flatnonzero(stray))
            if at.any():
                frame.loc[at, [k for k in frame.columns if k not in ("estimator", "ping")]] = np.nan
                frame.loc[at, "receivers_heard"] = 0
                frame.loc[at, "quality"] = "flagged"
                frame.loc[at, "quality_reason"] = SET_ASIDE_REASON
                frame["receivers_heard"] = frame["receivers_heard"].astype(int)
                flagged[estimator] = int((frame["quality"] == "flagged").sum())
    if second is not None:
        at_second_place(frames, covariances, flagged, main, second, placed)
    flag_interpolated(frames, flagged, clocks_interpolated, time_origin)
    estimates = pd.concat(frames.values(), ignore_index=True)
    chosen = frames[main].drop(columns=["estimator", "ping"]).reset_index(drop=True)
    at = np.full((len(toa), dim), np.nan)
    emitted = np.full(len(toa), np.nan)
    ping = frames[main]["ping"].to_numpy()
    at[ping], emitted[ping] = frames[main][columns].to_numpy(), frames[main]["time"].to_numpy()
    judged = receiver_residuals(toa, positions, at, emitted, c, sigma)
    summary: dict[str, Any] = {
        "track": main, "pings": int(len(toa)), "receivers": names,
        "robust_smoother": None if robust is None else {
            "start": robust.start_names[robust.start], "iterations": robust.iterations, "cost": robust.cost},
        "receivers_kept": None if receivers_kept is None else list(receivers_kept),
        "drop_detections": drop, "seed": seed if drop > 0 else None, "detections_dropped": dropped,
        "dimensions": dim, "sound_speed": speed, "sigma_toa_s": noise_info["sigma_s"], "toa_noise": noise_info,
        "ping_interval_s": interval,
        "motion": motion_info, "depth": depth_info,
        "survey_sigma_m": None if survey is None else dict(zip(names, map(float, survey))),
        "survey_correlated": considered_survey is not survey,  # the refined positions' joint errors considered
        "clock_sigma_s": None if clock_sigma is None else {n: None if np.isnan(v) else float(v)
                                                           for n, v in zip(names, clock_sigma)},
        "ping_type": {"type": schedule.kind, "source": schedule.source,
                      "burst_interval_s": None if schedule.bounds is None else list(schedule.bounds),
                      "seen": {"typical_step_s": seen.interval, "steps_s": list(seen.bounds),
                               "spread_s": seen.spread, "type": seen.kind}},
        "set_aside": aside | {"warning": aside_warning}, "two_places": None if second is None else second.summary,
        "segments": [[int(a), int(b - 1)] for a, b in schedule.segments()],
        "gaps_s": [float(schedule.steps()[g]) for g in schedule.gaps],
        "restarts": 0 if record is None else len(record.restarts),
        "fixed": {e: int(len(fr)) for e, fr in frames.items()},
        "flagged": flagged, "flag_reasons": reason_counts(frames[main]["quality_reason"]),
        "trusted_fixes": int(trusted.sum()),
        "receivers_late": [{"receiver": names[k], "arrivals": int(judged.arrivals[k]),
                            "median_residual_sigmas": float(judged.median_z[k]), "kept_share": float(judged.kept[k])}
                           for k in np.flatnonzero(judged.late)],
        "time_origin_utc": None if time_origin is None else iso_utc([time_origin])[0],
        "time_origin_epoch_s": time_origin,
        "frame": frame_summary(receivers.frame, positions[:, 0], positions[:, 1]),
        "truth": None if truth_path is None else str(truth_path),
        "reference": None if reference_path is None else str(reference_path)}
    errors = result = bound = None
    if truth is not None:
        parts, entries = [], {}

        def scored(estimator: str, ping: Any, t: np.ndarray, p: np.ndarray, cov: np.ndarray | None,
                   quality: np.ndarray | None = None) -> None:
            stats, err, err3 = score(t, p, truth, cov, truth_sigma=truth_sigma)
            entries[estimator] = {"n_pings": int(len(toa)), "n_fixed": int(len(t)),
                                  "share_fixed": len(t) / len(toa)} | stats
            if quality is not None:
                ok = (quality != "flagged") & np.isfinite(err)
                entries[estimator] |= {
                    "n_flagged": int((quality == "flagged").sum()),
                    "share_flagged": float((quality == "flagged").mean()) if len(quality) else 0.0,
                    "max_error_unflagged_m": float(err[ok].max()) if ok.any() else None}
            parts.append(pd.DataFrame({"estimator": estimator, "ping": ping, "time": t, "error_2d_m": err,
                                       **({} if err3 is None else {"error_3d_m": err3})}))

        for estimator, frame in frames.items():
            kept = (frame["quality_reason"] != SET_ASIDE_REASON).to_numpy()  # a row set aside is no estimate
            scored(estimator, frame["ping"].to_numpy()[kept], frame["time"].to_numpy()[kept],
                   frame[columns].to_numpy()[kept], covariances[estimator][kept], frame["quality"].to_numpy()[kept])
        if reference is not None:
            scored("reference", -1, reference[:, 0], reference[:, 1:], None)
        errors = pd.concat(parts, ignore_index=True)
        if not stationary:
            source = record.x_filtered if not smooth else xs
            bound = bound_along_track(toa, positions, source[:, -2], truth, settings, schedule, source[:, :dim])
        first = entries.pop(main)
        result = {key: first.get(key) for key in SCORE_KEYS}
        result |= {key: value for key, value in first.items() if key not in result}
        result |= {"estimator": main, "others": entries, "truth_sigma_m": truth_sigma}
        if bound is not None:
            result["bound"] = {"robust_rms": "median / sqrt(ln 2)", "columns": BOUND_COLUMNS,
                               "thirds": bound_thirds(bound, errors)}
    summary["wall_time_s"] = time.perf_counter() - start
    return TrackOutcome(chosen, estimates, errors, result, summary, bound, truth, (names, positions),
                        _set_aside_table(read, stray, names, time_origin) if aside["shortest_s"] is not None
                        else None)


def _checked_against(corrected: np.ndarray | None, toa: np.ndarray, positions: np.ndarray, c: float,
                     sigma: np.ndarray, depth: np.ndarray | None, depth_sigma: float) -> tuple | None:
    """What a still tag's rows are checked against where the sound speed's change over its record was fitted at its
    place (``corrected`` (m, n) [s]: the times of arrival less it, :class:`~sblsim.models.tracking.still_tag.
    StillTag`): those times, their single-ping fixes at ``c`` [m/s], which of those are trusted, the arrivals each
    explains and their protection levels (as the record's own, made again); None where nothing was corrected (the
    record's own). A fix made at one speed, where the water's warmed by metres a second over a season, lies off the
    place fitted with the speed's change by more than the two covariances allow, and the row was flagged."""
    from sblsim.models.receiver import toa_tracking as tt

    if corrected is None or np.array_equal(corrected, toa, equal_nan=True):
        return None
    fx, _, fc, used, chi2 = tt.fix_pings(corrected, positions, c, sigma, depth=depth, depth_sigma=depth_sigma)
    trusted, levels, agree = _fix_checks(corrected, positions, c, sigma, (fx, fc, used, chi2),
                                         None if depth is None else np.isfinite(depth))
    return corrected, fx, fc, trusted, agree, levels


def _fix_checks(toa: np.ndarray, positions: np.ndarray, c: float, sigma: np.ndarray, fixes: tuple,
                depth_known: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the rows are checked against of the single-ping fixes ``fixes`` (positions, covariances, arrivals used,
    χ²) of ``toa`` (m, n) [s]: which are trusted (:func:`~sblsim.models.tracking.quality.trusted_fixes`), how far
    one reflection could move each unseen by its own test (its protection level [m]: a fix that far from a row
    refutes nothing; NaN where the depth was given) and the arrivals each explains."""
    fx, fc, used, chi2 = fixes
    trusted = qa.trusted_fixes(fx, fc, used.sum(axis=1), np.isfinite(toa).sum(axis=1), chi2, positions.shape[1],
                               depth_known)
    protection = np.where(depth_known if depth_known is not None else False, np.nan,
                          protection_levels(positions, fx, used, c, sigma))
    return trusted, protection, qa.explained(toa, positions, fx, c, sigma)


def _set_aside_table(toa: np.ndarray, stray: np.ndarray, names: list[str], time_origin: float | None):
    """``set_aside.csv``: each row set aside (``ping``, 0-based as ``estimates.csv`` counts them), its first arrival
    [s] on the times of arrival's base (and in UTC where the origin is known), the receivers that heard it and
    why."""
    import pandas as pd

    rows = np.flatnonzero(stray)
    first = ps.first_arrivals(toa[rows])
    table = {"ping": rows, "time": first}
    if time_origin is not None:
        table["time_utc"] = iso_utc(first + time_origin)
    heard = np.isfinite(toa[rows])
    return pd.DataFrame(table | {"receivers_heard": heard.sum(axis=1),
                                 "heard": [";".join(n for n, h in zip(names, row) if h) for row in heard],
                                 "reason": SET_ASIDE_REASON})


__all__ = ["MAX_DROP", "MAX_TRUTH_SIGMA", "MOTIONS", "track"]

"""One pinger tracked from its recorded times of arrival at a fixed array (an inverted LBL): ``sblsim.replay_toa``,
the function of ``sblsim replay TOA_FILE --format toa`` (docs/tracking.md), its arguments checked
(:mod:`~sblsim.orchestrator.tracks.options`), tracked (:func:`~sblsim.orchestrator.tracks.track.track`) and written
(:mod:`~sblsim.orchestrator.tracks.outputs`); a folder of tags is :mod:`~sblsim.orchestrator.tracks.many`'s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Sequence

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.arguments import path_argument, prepare_out
from sblsim.orchestrator.tracks.options import check_depth_sigma, toa_options
from sblsim.orchestrator.tracks.outputs import write
from sblsim.orchestrator.tracks.track import track

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd


@dataclass
class TrackResult:
    """The outcome of :func:`replay_toa`.

    Attributes
    ----------
    track : pandas.DataFrame
        ``track.csv``: one row per ping with a fix, of the robust smoother (``smooth``: every ping from the
        tracker's start) or else the causal EKF: ``time`` (the estimated emission time) [s], ``x``, ``y``[,
        ``z``] [m], ``sigma_x``, ``sigma_y``[, ``sigma_z``] [m], ``receivers_heard`` (the arrivals the estimate
        used; the robust smoother's: those it did not weigh down as outliers).
    score : dict or None
        ``score.json`` (with a truth track): for the track ``n_pings``, ``n_fixed``, ``mean_m``, ``median_m``,
        ``rms_m``, ``p90_m``, ``p95_m`` (2-D errors [m]), ``nees`` (the mean 2-D NEES), ``lag_s`` (the truth's
        time shift that minimises the RMS error, reported, not applied) and further keys (``share_fixed``,
        ``n_scored``, ``rms_at_lag_m``, ``along_track_m``, ``across_track_m``, the ``*_3d_m`` errors where both
        have z); ``others``: the same per other estimator (``rts``, ``ekf``, ``ekf-seq``, ``ukf``, ``fix``) and the
        ``reference``.
    summary : dict
        ``summary.json``: how the run went: the receivers used, the thinning and detections dropped, the sound
        speed (given or calibrated), the ping interval, the EKF's restarts, the pings each estimator fixed, the
        wall time.
    estimates : pandas.DataFrame
        ``estimates.csv``: every estimator's rows (``estimator`` ``robust``, ``rts``, ``ekf``, ``ekf-seq``, ``ukf``,
        ``fix``; ``ping``, the row of the TOA matrix) with the columns of ``track``.
    errors : pandas.DataFrame or None
        ``errors.csv`` (with a truth track): ``estimator``, ``ping``, ``time`` [s], ``error_2d_m``[,
        ``error_3d_m``] [m].
    out : Path or None
    bound : pandas.DataFrame or None
        ``bound.csv`` (with a truth track): the accuracy limit per ping at the truth
        (:func:`sblsim.orchestrator.tracks.bound.bound_along_track`); its thirds are ``score["bound"]``.
    """

    track: pd.DataFrame
    score: dict[str, Any] | None
    summary: dict[str, Any]
    estimates: pd.DataFrame
    errors: pd.DataFrame | None
    out: Path | None = None
    bound: pd.DataFrame | None = None


def replay_toa(toa: str | Path, *, receivers: str | Path, truth: str | Path | None = None,
               reference: str | Path | None = None, smooth: bool = True, sound_speed: float | None = None,
               receivers_kept: str | Sequence[str] | None = None, drop_detections: float = 0.0, seed: int = 0,
               truth_sigma: float = 0.0, ping_type: str | None = None,
               burst_interval: str | tuple[float, float] | None = None, burst_sequence: str | Path | None = None,
               acceleration_psd: float | None = None, sound_speed_file: str | Path | None = None,
               temperature: float | None = None, salinity: float | None = None, motion: str = "moving",
               tag_depth: float | None = None, depth_sigma: float | None = None, survey_sigma: float | None = None,
               crs: str | None = None, frame: str | None = None, time_origin: str | float | None = None,
               toa_sigma: float | None = None, temperature_file: str | Path | None = None,
               water_depth: float | None = None, force_interval: bool = False, other_filters: bool = True,
               out: str | Path | None = None, force: bool = False) -> TrackResult:
    """Track a pinger from recorded times of arrival at a fixed array (an inverted LBL): ``sblsim replay TOA_FILE
    --format toa`` (docs/tracking.md).

    Parameters
    ----------
    toa : str or Path
        The TOA matrix: one row per ping, one column per receiver [s], ``NA`` or empty where not heard.
    receivers : str or Path
        The receivers' positions: a CSV (name, ``x_m``, ``y_m``[, ``z_m``][, ``status``]) or a TOML file.
    truth : str or Path, optional
        A truth track (``x y t`` [m, m, s] under a header, e.g. GPS): the score and the errors.
    reference : str or Path, optional
        Another solution (``x y t``) scored beside, on its own rows.
    smooth : bool
        Run the RTS smoother and the robust smoother, and make the robust smoother's rows the track (else the
        causal EKF's).
    sound_speed : float, optional
        [m/s] in [1300, 1700]; default calibrated from the pings (a robust joint fit of the sound speed and the
        pings' positions and emission times, docs/tracking.md); where the array cannot determine it, the fallback
        of ``temperature`` and ``salinity``, else 1,500 m/s (stated in ``summary["sound_speed"]``).
    sound_speed_file : str or Path, optional
        A measured sound-speed series (a file key): ``time_s`` [s] on the times of arrival's time base and
        ``sound_speed_m_s`` [m/s] under a header; each ping's arrivals rescaled to the series' median
        (:mod:`sblsim.models.tracking.sound_speed`). Not with ``sound_speed``.
    temperature, salinity : float, optional
        The water's temperature [°C] in [-2, 40] and practical salinity (PSS-78) in [0, 42], both or neither: the
        fallback sound speed (TEOS-10) where the pings cannot determine it, and the speeds the water can have (a
        calibration outside them is replaced by the fallback, said in ``summary["sound_speed"]``).
    temperature_file : str or Path, optional
        A water-temperature series (a file key): a time column (``time_s`` on the times of arrival's base, or ISO
        8601 / epoch seconds in UTC with ``time_origin``) and ``temperature_c`` [°C] under a header, made the sound
        speed by TEOS-10 at ``salinity`` (needed with it) and taken as a measured series
        (:mod:`sblsim.orchestrator.readers.water`). Not with ``sound_speed``, ``sound_speed_file``, ``temperature``.
    water_depth : float, optional
        The water's depth [m] in (0, 11000] (receivers with ``z_m``, none below it): the tag's depth is held within
        the water column (a prior over it), at mid-water where the receivers lie in one plane.
    receivers_kept : str or sequence of str, optional
        Use only these receivers (their names in the receivers file; a text separated by commas, or a list):
        a thinned array. Default every receiver.
    drop_detections : float
        In [0, 0.99]: remove each detection with this probability before tracking (seeded by ``seed``).
    seed : int
        In [0, 2**31 − 1]: the seed of ``drop_detections``'s draw (``numpy.random.default_rng``).
    truth_sigma : float
        In [0, 100] m: the truth's own error per horizontal axis (a GPS's, the tow's lever arm), added to each
        estimate's covariance in the NEES against it (``score.json``'s ``nees``, ``nees_median`` and
        ``truth_sigma_m``); default 0, the truth taken as exact.
    ping_type : str, optional
        ``sbi`` (a stable burst interval), ``rbi`` (random) or ``pbi`` (pseudo-random, a known sequence); default
        the one the first arrivals' spacing shows (``summary["ping_type"]``; :mod:`sblsim.models.tracking.schedule`).
    burst_interval : str or (float, float), optional
        ``rbi``: the interval's bounds, ``"MIN:MAX"`` [s] (e.g. ``"20:40"``).
    burst_sequence : str or Path, optional
        ``pbi``: a file of the tag's intervals [s] in order, one per row (a file key).
    acceleration_psd : float, optional
        The motion model's white-noise acceleration ``q`` [m²/s³] in (0, 1]; default estimated from the pings by EM
        (``summary["motion"]``; :mod:`sblsim.models.tracking.motion_noise`).
    tag_depth : float, optional
        The tag's depth [m] in [-10, 11000] at every ping (receivers with ``z_m``), where the TOA file has no
        ``depth_m`` column (a pressure sensor's reading per ping, positive down, ``NA`` where none): the fix and the
        robust smoother take either as a measurement of the height ``z = −depth``.
    depth_sigma : float, optional
        A depth reading's standard deviation [m] in (0, 100] (default 0.3); only with a depth (``tag_depth`` or a
        ``depth_m`` column: refused without one, where it has no effect).
    survey_sigma : float, optional
        The receivers' survey error per axis [m] in [0, 1000], for those without a ``sigma_m`` column in the
        receivers file: the fix's and the robust smoother's covariances hold it (a consider covariance,
        :mod:`sblsim.models.tracking.smoother`); the causal filters' do not.
    motion : str
        ``moving`` (default: the filters and smoothers) or ``stationary`` (a sync or reference tag: one position
        for all pings, :mod:`sblsim.models.tracking.stationary`, the estimator ``stationary``).
    crs : str, optional
        The receivers file's CRS (``EPSG:…``): ``lat``, ``lon`` columns in a geographic one (WGS 84 by default where
        the file has them), ``x_m``, ``y_m`` in a projected one (kept in it). With a CRS every row of the outputs
        has ``lat``, ``lon`` [° WGS 84], and a truth may be given in latitude and longitude.
    frame : str, optional
        The metric frame latitude and longitude are projected to (a projected CRS in metres; default the UTM zone of
        the array's centre).
    time_origin : str or float, optional
        The UTC time of the TOA file's zero (ISO 8601, or seconds since 1970): every row of the outputs has
        ``epoch_s`` and ``time_utc``, and a truth or sound-speed series may be in absolute times (ISO 8601, or
        ``epo`` seconds since 1970).
    toa_sigma : float, optional
        The timing noise of every time of arrival [s] in [1e-6, 1], in every estimator's measurement covariance;
        default each receiver's ``toa_sigma_s`` in the receivers file (what ``sblsim toa`` writes from a
        synchronisation's residuals), else 0.15 ms (``summary["toa_noise"]`` says which).
    force_interval : bool
        Take the stated ``burst_interval`` (or ``burst_sequence``) where the rows contradict it as a whole (more than
        10 % of them set aside as no pings; refused otherwise); ``summary["set_aside"]["warning"]`` says how much it
        sets aside.
    other_filters : bool
        Run the causal filters beside the EKF for comparison (the sequential EKF and the UKF: their rows in
        ``estimates.csv``, their scores in ``score["others"]``, their fixes in ``summary["fixed"]``); False leaves them
        out, as a study tracks its tags: the track, the EKF's, the RTS and the robust smoother's rows and the fixes
        are the same, in about half the time.
    out : str or Path, optional
        Write ``track.csv``, ``estimates.csv``, ``summary.json``, ``track.png``, with a truth ``score.json`` and
        ``errors.csv``, and ``set_aside.csv`` (the rows a stated interval set aside) there.
    force : bool
        Replace an earlier result in ``out``.

    Returns
    -------
    TrackResult

    Raises
    ------
    ModelError, ConfigError
        A file that cannot be read or holds a value outside its range (one line naming the file, line and
        column), bad options.
    """
    toa = path_argument(toa, "toa", optional=False)
    receivers = path_argument(receivers, "receivers", optional=False)
    truth = path_argument(truth, "truth")
    reference = path_argument(reference, "reference")
    target = prepare_out(out, force, "track.csv", "track")
    options = toa_options(smooth, sound_speed, receivers_kept, drop_detections, seed, truth_sigma, ping_type,
                          burst_interval, burst_sequence, acceleration_psd, sound_speed_file, temperature, salinity,
                          motion, tag_depth, depth_sigma, survey_sigma, crs, frame, time_origin, toa_sigma,
                          temperature_file, water_depth, force_interval, other_filters)
    check_depth_sigma(toa, tag_depth, depth_sigma, ("tag_depth", "depth_sigma"))
    outcome = track(toa, receivers, truth, reference, **options)
    check_positioned(outcome, toa)
    if target is not None:
        write(outcome, target)
    return TrackResult(outcome.track, outcome.score, outcome.summary, outcome.estimates, outcome.errors, target,
                       outcome.bound)


def check_positioned(outcome: Any, toa: Path) -> None:
    """Refuse a track in which no estimator positioned a single ping (every ping heard by too few receivers: a
    fix needs ``dimensions + 1`` with a position), before anything is written: it has no track to write.

    Raises
    ------
    ModelError
        One line naming the file, its pings and what a fix needs.
    """
    s = outcome.summary
    if any(s["fixed"].values()):
        return
    dropped = (f" after {s['detections_dropped']} detections were removed at random (drop {s['drop_detections']:g})"
               if s["drop_detections"] else "")
    raise ModelError(f"toa: {str(toa)!r}: no ping could be positioned: no estimator placed any of its {s['pings']} "
                     f"pings{dropped} (a fix, and every estimator's start, needs a ping heard by at least "
                     f"{s['dimensions'] + 1} of its {len(s['receivers'])} receivers with a position); nothing "
                     "written")

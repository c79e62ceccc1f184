"""``sblsim replay`` and ``sblsim.replay``: a receiver on a recorded log (docs/log-format.md), with its errors and
consistency against a truth track when one is given (:mod:`sblsim.orchestrator.replay`).
"""

from __future__ import annotations

import argparse
import inspect
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.declarations import ModelError
from sblsim.models.tracking.schedule import PING_TYPES
from sblsim.orchestrator.commands.common import (
    MAX_SEED,
    Overrides,
    add_water_arguments,
    check_engine,
    check_seed,
    flag_argument,
    names_argument,
    override_items,
    path_argument,
    prepare_out,
    real_argument,
    sound_speed_arguments,
    text_argument,
    water_arguments,
)
from sblsim.orchestrator.commands.console import FMU_DIR_HELP, output_folder, print_metrics
from sblsim.orchestrator.cosim.config import MODEL_PREFIX, ConfigError, external_path
from sblsim.orchestrator.cosim.engines import ENGINES
from sblsim.orchestrator.cosim.plan import Config, RunPlan, thaw
from sblsim.orchestrator.io.frames import check_crs, check_metric
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.io.times import parse_instant
from sblsim.orchestrator.tracks.depth import prior_line
from sblsim.orchestrator.tracks.many import tag_files, track_tags
from sblsim.orchestrator.tracks.outputs import write
from sblsim.orchestrator.tracks.speed import replaced_line
from sblsim.orchestrator.tracks.track import ESTIMATOR_NAMES, MAX_DROP, MAX_TRUTH_SIGMA, MOTIONS, track
from sblsim.orchestrator.tracks.tracker import DEPTH_SIGMA, TOA_SIGMA_RANGE, noise_line

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import pandas as pd
    from matplotlib.figure import Figure


@dataclass
class ReplayResult:
    """The outcome of :func:`replay`.

    Attributes
    ----------
    config : Config
        The configuration the receiver ran with.
    source : str
        Where that configuration came from.
    engine : str
    summary : dict
        ``summary.json``: a run's keys (errors None without a truth track), ``log`` (what was read of the
        log) and ``truth``.
    timeseries : pandas.DataFrame
        One row per macro step: ``time`` [s] on the log's clock, ``log_row``, the receiver's inputs and
        outputs; with a truth track ``true_*`` [m], ``pcrb`` and the errors ``e_*`` [m].
    out : Path or None
    """

    config: Config
    source: str
    engine: str
    summary: dict[str, Any]
    timeseries: pd.DataFrame
    out: Path | None = None
    resolve_plan: Any = field(default=None, repr=False)

    def plot(self) -> dict[str, Figure]:
        """The figures of a run over the steps the truth track covers (empty without truth)."""
        from sblsim.orchestrator.io.plots import run_figures

        ts = self.timeseries
        covered = ts[np.isfinite(ts["true_x"].to_numpy())] if "true_x" in ts else ts.iloc[:0]
        if not len(covered):
            return {}
        receiver = self._plan.receiver_label if self._plan is not None else self.config.plan().receiver_label
        if "replicate" not in covered:
            covered = covered.assign(replicate=0)
        return run_figures(covered, f"replay of {self.summary['log']['file']}, {receiver} ({self.engine})", receiver)


def replay(log: str | Path, *, receiver: str | None = None, config: str | Path | None = None,
           truth: str | Path | None = None, engine: str = "local", set: Overrides = None,
           fmu_dir: str | Path | None = None, out: str | Path | None = None, force: bool = False) -> ReplayResult:
    """Run a receiver on a recorded log: ``sblsim replay``.

    Parameters
    ----------
    log : str or Path
        The log, ``.csv`` or ``.parquet`` (the log-format page; ``sblsim run --export-log`` writes one).
    receiver : str, optional
        ``ekf``, ``ekf-seq``, ``ukf``, ``lsq``, ``model:PATH.py`` or ``fmu:PATH`` (default the
        configuration's).
    config : str or Path, optional
        The receiver's parameters, T and rate ratio: a built-in scenario or ``CONFIG.toml`` (default the
        configuration an exported log carries, else the semicircle scenario's).
    truth : str or Path, optional
        Truth track (``time_s``, ``n_m``, ``e_m``, ``d_m``): errors, consistency and figures.
    engine, set, fmu_dir
        As for :func:`run`.
    out : str or Path, optional
        Write ``summary.json``, ``config.toml``, ``timeseries.parquet`` and the figures there.
    force : bool
        Replace an earlier replay in ``out``.

    Returns
    -------
    ReplayResult

    Raises
    ------
    ConfigError, SblsimError
        A log or truth track that cannot be read (the message names the row and column), bad options.
    """
    from sblsim.orchestrator.replay import replay_config

    check_engine(engine)
    log = path_argument(log, "log", optional=False)
    truth = path_argument(truth, "truth")
    fmu_dir = path_argument(fmu_dir, "fmu_dir")
    receiver = text_argument(receiver, "receiver")
    config = None if config is None else str(path_argument(config, "config"))
    prepare_out(out, force, "summary.json", "replay")  # before any work (and again once the log is read)
    plan, source = replay_config(log, config, receiver, override_items(set))
    return _replay_plan(plan, source, log, truth, engine, fmu_dir,
                        lambda: prepare_out(out, force, "summary.json", "replay"))


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


@dataclass
class TagsResult:
    """The outcome of :func:`replay_toa_tags`.

    Attributes
    ----------
    table : pandas.DataFrame
        ``tags.csv``: one row per tag (``tag``, ``status`` ``tracked`` or ``refused``, ``reason``, ``pings``,
        ``positioned``, ``flagged``, ``share_flagged``, ``track`` (the estimator), ``sound_speed_m_s``,
        ``sound_speed_source``, ``ping_type``, ``segments``, ``wall_time_s``).
    tracks : dict of str to TrackResult
        Each tracked tag's result, by its name.
    out : Path or None
    """

    table: pd.DataFrame
    tracks: dict[str, TrackResult]
    out: Path | None = None


#: What ``receivers_kept`` names, as its refusals say.
RECEIVER_NAMES = "receiver names of the receivers file"
#: The ping types ``--ping-type`` takes (:data:`sblsim.models.tracking.schedule.PING_TYPES`).
PING_TYPE_NAMES = tuple(PING_TYPES)
#: The burst intervals ``--burst-interval`` takes [s].
BURST_LIMITS = (0.1, 86400.0)


def burst_interval_argument(value: Any, where: str) -> tuple[float, float] | None:
    """A random burst interval: None, ``"MIN:MAX"`` [s] or a pair of numbers, 0.1 ≤ MIN ≤ MAX ≤ 86,400 s."""
    if value is None:
        return None
    allowed = f"MIN:MAX [s] with {BURST_LIMITS[0]:g} <= MIN <= MAX <= {BURST_LIMITS[1]:g}, e.g. 20:40"
    if isinstance(value, str):
        parts = value.split(":")
        try:
            pair = tuple(float(p) for p in parts)
        except ValueError:
            raise ConfigError(f"{where}: {value[:40]!r}; allowed: {allowed}") from None
    elif isinstance(value, (list, tuple)):
        pair = tuple(value)
    else:
        raise ConfigError(f"{where}: {type(value).__name__}; allowed: {allowed}")
    if len(pair) != 2 or not all(isinstance(p, (int, float)) and not isinstance(p, bool) for p in pair) or \
            not all(np.isfinite(pair)) or not BURST_LIMITS[0] <= pair[0] <= pair[1] <= BURST_LIMITS[1]:
        raise ConfigError(f"{where}: {str(value)[:40]!r}; allowed: {allowed}")
    return float(pair[0]), float(pair[1])


def ping_type_arguments(ping_type: Any, burst_interval: Any, burst_sequence: Any, names: tuple[str, str, str]
                        ) -> tuple[str | None, tuple[float, float] | None, Path | None]:
    """The ping type's arguments checked together (``names``: how the three are called where they were given)."""
    if ping_type is not None and ping_type not in PING_TYPE_NAMES:
        raise ConfigError(f"{names[0]}: {str(ping_type)[:40]!r}; allowed: {', '.join(PING_TYPE_NAMES)}")
    interval = burst_interval_argument(burst_interval, names[1])
    sequence = path_argument(burst_sequence, names[2])
    if interval is not None and ping_type not in (None, "rbi"):
        raise ConfigError(f"{names[1]}: only with a random burst interval ({names[0]} rbi)")
    if sequence is not None and ping_type not in (None, "pbi"):
        raise ConfigError(f"{names[2]}: only with a pseudo-random burst interval ({names[0]} pbi)")
    if interval is not None and sequence is not None:
        raise ConfigError(f"{names[1]}: not with {names[2]} (one ping type: rbi or pbi)")
    if ping_type == "pbi" and sequence is None:
        raise ConfigError(f"{names[0]} pbi: needs {names[2]} (the tag's intervals [s], one per row)")
    return ping_type, interval, sequence


def medium_arguments(sound_speed: Any, sound_speed_file: Any, temperature: Any, salinity: Any, motion: Any,
                     acceleration_psd: Any, names: tuple[str, ...], temperature_file: Any = None,
                     file_name: str = "temperature_file") -> tuple:
    """The sound speed's and the motion model's arguments checked (``names``: how the caller spells
    ``sound_speed``, ``sound_speed_file``, ``temperature``, ``salinity``, ``motion``, ``acceleration_psd``; a
    ``temperature_file`` spelled ``file_name`` checked against them, :func:`water_arguments` takes it on): returns
    them as :func:`~sblsim.orchestrator.tracks.track.track` takes them.

    Raises
    ------
    ConfigError
        A value outside its range, or options that exclude each other (one line).
    """
    speed, series, temperature, salinity = sound_speed_arguments(sound_speed, sound_speed_file, temperature,
                                                                 salinity, names[:4], temperature_file, file_name)
    motion = "moving" if motion is None else motion
    if motion not in MOTIONS:
        raise ConfigError(f"{names[4]}: {str(motion)[:40]!r} is not allowed; allowed: {', '.join(MOTIONS)}")
    if acceleration_psd is not None:
        if motion == "stationary":
            raise ConfigError(f"{names[5]}: not with {names[4]} stationary (one position for all pings: no motion "
                              "model)")
        acceleration_psd = real_argument(acceleration_psd, names[5], 0.0, 1.0, "m²/s³", low_open=True)
    return speed, series, temperature, salinity, motion, acceleration_psd


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
               water_depth: float | None = None, force_interval: bool = False, out: str | Path | None = None,
               force: bool = False) -> TrackResult:
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
        (:mod:`sblsim.orchestrator.tracks.water`). Not with ``sound_speed``, ``sound_speed_file``, ``temperature``.
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
                          temperature_file, water_depth, force_interval)
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


def check_depth_sigma(toa: Path, tag_depth: Any, depth_sigma: Any, names: tuple[str, str]) -> None:
    """Refuse the tag's depth σ given without a depth to weigh (``names``: how the caller spells ``tag_depth`` and
    ``depth_sigma``): no ``tag_depth`` and no ``depth_m`` column in the times of arrival ``toa`` (a folder of tags:
    not checked, the σ applies to the tags with a depth).

    Raises
    ------
    ConfigError
        One line naming the option, its value and what it needs.
    """
    if depth_sigma is None or tag_depth is not None or Path(toa).is_dir():
        return
    from sblsim.orchestrator.tracks.toa import read_toa

    if read_toa(toa).depth is None:
        raise ConfigError(f"{names[1]}: {float(depth_sigma):g} m has no effect: no depth of the tag is given (no "
                          f"{names[0]}, no depth_m column in {str(toa)!r}); allowed: with {names[0]} or a depth_m "
                          "column (the σ of that depth)")


def geometry_arguments(tag_depth: Any, depth_sigma: Any, survey_sigma: Any, names: tuple[str, str, str]) -> dict:
    """The tag's depth and the receivers' survey error checked (``names``: how the caller spells ``tag_depth``,
    ``depth_sigma``, ``survey_sigma``), as :func:`~sblsim.orchestrator.tracks.track.track`'s keyword arguments.

    Raises
    ------
    ConfigError
        A value outside its range (one line).
    """
    from sblsim.orchestrator.tracks.toa import DEPTH_RANGE, SURVEY_SIGMA_RANGE

    return {"fixed_depth": None if tag_depth is None else real_argument(tag_depth, names[0], *DEPTH_RANGE, "m"),
            "depth_sigma": DEPTH_SIGMA if depth_sigma is None else real_argument(depth_sigma, names[1], 0.0, 100.0,
                                                                                 "m", low_open=True),
            "survey_sigma": None if survey_sigma is None else real_argument(survey_sigma, names[2],
                                                                            *SURVEY_SIGMA_RANGE, "m")}


def place_arguments(crs: Any, frame: Any, time_origin: Any, names: tuple[str, str, str]) -> dict[str, Any]:
    """The receivers' CRS, the metric frame and the TOA file's time origin checked (``names``: how the caller spells
    them), as :func:`~sblsim.orchestrator.tracks.track.track`'s keyword arguments.

    Raises
    ------
    ConfigError, ModelError
        A CRS pyproj does not know, a frame that is not metric, a time that is neither ISO 8601 nor epoch seconds.
    """
    crs, frame = text_argument(crs, names[0]), text_argument(frame, names[1])
    return {"crs": None if crs is None else check_crs(crs, names[0]),
            "frame": None if frame is None else check_metric(frame, names[1]),
            "time_origin": None if time_origin is None else parse_instant(time_origin, names[2])}


def toa_options(smooth: Any = True, sound_speed: Any = None, receivers_kept: Any = None, drop_detections: Any = 0.0,
                seed: Any = 0, truth_sigma: Any = 0.0, ping_type: Any = None, burst_interval: Any = None,
                burst_sequence: Any = None, acceleration_psd: Any = None, sound_speed_file: Any = None,
                temperature: Any = None, salinity: Any = None, motion: Any = "moving", tag_depth: Any = None,
                depth_sigma: Any = None, survey_sigma: Any = None, crs: Any = None, frame: Any = None,
                time_origin: Any = None, toa_sigma: Any = None, temperature_file: Any = None,
                water_depth: Any = None, force_interval: Any = False) -> dict[str, Any]:
    """:func:`replay_toa`'s tracking arguments checked (each named as the function names it), as keyword arguments
    of :func:`~sblsim.orchestrator.tracks.track.track`.

    Raises
    ------
    ConfigError, ModelError
        One line naming the argument and the allowed values.
    """
    smooth = flag_argument(smooth, "smooth")
    sound_speed, series, temperature, salinity, motion, acceleration_psd = medium_arguments(
        sound_speed, sound_speed_file, temperature, salinity, motion, acceleration_psd,
        ("sound_speed", "sound_speed_file", "temperature", "salinity", "motion", "acceleration_psd"), temperature_file)
    kept = names_argument(receivers_kept, "receivers_kept", RECEIVER_NAMES)
    drop = real_argument(drop_detections, "drop_detections", 0.0, MAX_DROP, "")
    seed = check_seed(seed)
    if seed is None:
        raise ConfigError(f"seed: None is not allowed; allowed: an integer in [0, {MAX_SEED}]")
    truth_sigma = real_argument(truth_sigma, "truth_sigma", 0.0, MAX_TRUTH_SIGMA, "m")
    kind, interval, sequence = ping_type_arguments(ping_type, burst_interval, burst_sequence,
                                                   ("ping_type", "burst_interval", "burst_sequence"))
    return {"smooth": smooth, "sound_speed": sound_speed, "receivers_kept": kept, "drop": drop, "seed": seed,
            "truth_sigma": truth_sigma, "ping_type": kind, "burst_interval": interval, "burst_sequence_path": sequence,
            "acceleration_psd": acceleration_psd, "sound_speed_path": series, "temperature": temperature,
            "salinity": salinity, "motion": motion, "toa_sigma": toa_sigma_argument(toa_sigma, "toa_sigma"),
            "force_interval": flag_argument(force_interval, "force_interval")} | geometry_arguments(
        tag_depth, depth_sigma, survey_sigma, ("tag_depth", "depth_sigma", "survey_sigma")) | place_arguments(
        crs, frame, time_origin, ("crs", "frame", "time_origin")) | water_arguments(
        temperature_file, water_depth, ("temperature_file", "water_depth"))


def toa_sigma_argument(value: Any, where: str) -> float | None:
    """The timing noise given [s] checked (None: not given), in
    :data:`~sblsim.orchestrator.tracks.tracker.TOA_SIGMA_RANGE`.

    Raises
    ------
    ConfigError
        A value outside it (one line).
    """
    return None if value is None else real_argument(value, where, *TOA_SIGMA_RANGE, "s")


def replay_toa_tags(folder: str | Path, *, receivers: str | Path, workers: int | None = None,
                    scheduler: str | None = None, out: str | Path | None = None, force: bool = False,
                    **options: Any) -> TagsResult:
    """Track many tags at one array in parallel: ``sblsim replay FOLDER --format toa`` (docs/tracking.md).

    Parameters
    ----------
    folder : str or Path
        A folder of one times-of-arrival file per tag (``*.txt``, ``*.csv``, ``*.toa``; the tag named by the
        file's stem), each as :func:`replay_toa` reads one.
    receivers : str or Path
        The receivers' positions, shared by the tags.
    workers : int, optional
        Worker processes in [1, 256] (default the CPU count; 1: one tag after another in this process).
    scheduler : str, optional
        A Dask scheduler, ``tcp://HOST:PORT`` or ``local``: the tags run on its workers.
    out : str or Path, optional
        Write each tag's folder (``out/TAG/``) and ``tags.csv`` there, all or nothing.
    force : bool
        Replace an earlier result in ``out``.
    **options
        :func:`replay_toa`'s tracking arguments (``smooth``, ``sound_speed``, ``ping_type``, ...), the same for every
        tag; no ``truth`` or ``reference`` (one per tag).

    Returns
    -------
    TagsResult

    Raises
    ------
    ModelError, ConfigError
        A folder without tag files, a bad option (one line). A tag whose own file is refused is a row of
        ``tags.csv`` (``status`` ``refused``, the reason), the others tracked.
    """
    folder = path_argument(folder, "folder", optional=False)
    receivers = path_argument(receivers, "receivers", optional=False)
    if not folder.is_dir():
        raise ConfigError(f"folder: {str(folder)!r} is not a folder; allowed: a folder of one times-of-arrival file "
                          "per tag (replay_toa tracks one file)")
    unknown = sorted(set(options) - set(inspect.signature(toa_options).parameters) - {"truth_sigma"})
    if unknown or "truth_sigma" in options:
        raise ConfigError(f"{(unknown or ['truth_sigma'])[0]}: not an option of replay_toa_tags; allowed: "
                          f"{', '.join(k for k in inspect.signature(toa_options).parameters if k != 'truth_sigma')}")
    if workers is not None:
        workers = int(real_argument(workers, "workers", 1, 256, ""))
    if scheduler is not None:
        from sblsim.orchestrator.campaign.executors import check_address

        scheduler = check_address(str(scheduler))
    files = tag_files(folder)
    target = prepare_out(out, force, "tags.csv", "tags")
    done = track_tags(files, receivers, toa_options(**options), workers, scheduler, target)
    return TagsResult(done.table, {name: TrackResult(o.track, o.score, o.summary, o.estimates, o.errors,
                                                     None if target is None else target / name, o.bound)
                                   for name, o in done.outcomes.items()}, target)


def _replay_plan(plan: RunPlan, source: str, log: Path, truth: Path | None, engine: str,
                 fmu_dir: str | Path | None, prepare: Callable[[], Path | None]) -> ReplayResult:
    """:func:`replay` of a plan (and ``sblsim replay``): read the log and the truth track, ``prepare()`` the
    output folder (None: nothing is written), replay and write."""
    from sblsim.orchestrator.receiver_log import read_log, read_truth
    from sblsim.orchestrator.replay import replay as _replay
    from sblsim.orchestrator.replay import write_replay

    data = read_log(log, plan.n_beacons, plan.system, plan["acoustics"]["sound_speed_assumed"], plan["acoustics"])
    track = read_truth(truth) if truth is not None else None
    target = prepare()
    result = _replay(data, plan, engine, fmu_dir, track)
    if target is not None:
        write_replay(result, target)
    return ReplayResult(Config(thaw(result.config)), source, result.engine, result.summary, result.timeseries,
                        target, result.config)


NAME = "replay"
HELP = "run a receiver on a recorded log (docs/log-format.md)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim replay``'s arguments."""
    p.add_argument("log", type=Path, help="the log: .csv or .parquet (sblsim run --export-log writes one); with "
                   "--format toa, the matrix of times of arrival (docs/tracking.md), or a folder of one per tag")
    p.add_argument("--format", choices=("log", "toa", "detections", "yaps", "vue", "fathom", "glatos", "otn"),
                   default="log",
                   help="log: a receiver's log (default); toa: times of arrival of a pinger at a fixed array "
                        "(an inverted LBL), tracked by the single-ping fix, the EKF and (--smooth) the RTS and robust "
                        "smoothers; detections (the format read from the file's first line), yaps, vue, fathom, "
                        "glatos or otn: raw detections, with --sync and --tag, made into the tag's times of arrival "
                        "as sblsim toa makes them, then tracked")
    p.add_argument("--sync", type=Path, default=None, metavar="DIR",
                   help="raw detections: the synchronisation's folder (sblsim sync --out DIR)")
    p.add_argument("--tag", default=None, metavar="ID", help="raw detections: the tag's full ID or id")
    p.add_argument("--receivers", type=Path, default=None, metavar="FILE",
                   help="--format toa: the receivers' positions (CSV name,x_m,y_m[,z_m][,status], or TOML)")
    p.add_argument("--reference", type=Path, default=None, metavar="FILE",
                   help="--format toa: another solution (x y t) scored beside against --truth")
    p.add_argument("--smooth", action="store_true",
                   help="--format toa: also the RTS and the robust smoother, the robust smoother's rows as the "
                        "track (default: the causal EKF's)")
    p.add_argument("--sound-speed", type=float, default=None, metavar="M_S",
                   help="--format toa: the sound speed [m/s] (default: calibrated from the pings)")
    p.add_argument("--receivers-kept", default=None, metavar="NAMES",
                   help="--format toa: use only these receivers (their names, separated by commas): a thinned array")
    p.add_argument("--drop-detections", type=float, default=None, metavar="SHARE",
                   help="--format toa: remove each detection with this probability in [0, 0.99] before tracking "
                        "(seeded by --seed)")
    p.add_argument("--seed", type=int, default=None,
                   help="--format toa: the seed of --drop-detections's draw (default 0)")
    p.add_argument("--receiver", default=None,
                   help="ekf, ekf-seq, ukf, lsq, model:PATH.py or fmu:PATH (default: the configuration's)")
    p.add_argument("--config", default=None, metavar="CONFIG",
                   help="the receiver's parameters, T and rate ratio: a built-in scenario or CONFIG.toml (default: "
                        "the configuration an exported log carries, else the semicircle scenario's)")
    p.add_argument("--ping-type", choices=PING_TYPE_NAMES, default=None,
                   help="--format toa: the tag's ping type: sbi (stable burst interval), rbi (random), pbi "
                        "(pseudo-random, --burst-sequence); default inferred from the first arrivals' spacing")
    p.add_argument("--burst-interval", default=None, metavar="MIN:MAX",
                   help="--format toa: a random burst interval's bounds [s], e.g. 20:40 (rbi)")
    p.add_argument("--burst-sequence", type=Path, default=None, metavar="FILE",
                   help="--format toa: a pseudo-random tag's intervals [s] in order, one per row (pbi)")
    p.add_argument("--force-interval", action="store_true",
                   help="take the stated --burst-interval or --burst-sequence where the detections contradict it as "
                        "a whole (refused otherwise); a warning says how much it sets aside")
    p.add_argument("--acceleration-psd", type=float, default=None, metavar="M2_S3",
                   help="--format toa: the motion model's white-noise acceleration [m²/s³] in (0, 1] (default: "
                        "estimated from the pings by EM)")
    p.add_argument("--sound-speed-file", type=Path, default=None, metavar="CSV",
                   help="--format toa: a measured sound-speed series (time_s, sound_speed_m_s under a header; the "
                        "times on the times of arrival's base)")
    p.add_argument("--temperature", type=float, default=None, metavar="C",
                   help="--format toa: the water's temperature [°C] for the fallback sound speed (TEOS-10) where the "
                        "pings cannot determine it (with --salinity; default fallback 1500 m/s)")
    p.add_argument("--salinity", type=float, default=None, metavar="S",
                   help="--format toa: the water's practical salinity (PSS-78) for the fallback or --temperature-file "
                        "(0 fresh water, about 35 the open sea)")
    add_water_arguments(p, "--format toa: ")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="--format toa with a folder of tags: worker processes in [1, 256] (default: the CPU count)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="--format toa with a folder of tags: a Dask scheduler (tcp://HOST:PORT, or local) whose "
                        "workers track the tags")
    p.add_argument("--tag-depth", type=float, default=None, metavar="M",
                   help="--format toa: the tag's depth [m] at every ping (a tag at a known depth; receivers with z_m), "
                        "where the times of arrival carry no depth_m column")
    p.add_argument("--depth-sigma", type=float, default=None, metavar="M",
                   help="--format toa: the standard deviation of a depth reading [m] in (0, 100] (default 0.3); "
                        "only with a depth (--tag-depth or a depth_m column)")
    p.add_argument("--survey-sigma", type=float, default=None, metavar="M",
                   help="--format toa: the receivers' survey error per axis [m] in [0, 1000], for those without a "
                        "sigma_m column, in the fix's and the smoother's covariances")
    p.add_argument("--motion", choices=MOTIONS, default=None,
                   help="--format toa: moving (default) or stationary (a sync or reference tag: one position for all "
                        "pings)")
    p.add_argument("--toa-sigma", type=float, default=None, metavar="S",
                   help="--format toa: the timing noise of every time of arrival [s] in [1e-6, 1] (default: each "
                        "receiver's toa_sigma_s in the receivers file, from a synchronisation's residuals; else "
                        "0.00015)")
    p.add_argument("--truth-sigma", type=float, default=None, metavar="M",
                   help="--format toa: the truth's own error per horizontal axis [m] in [0, 100] (GPS, lever arm), "
                        "in the NEES against it (default 0: the truth taken as exact)")
    p.add_argument("--crs", default=None, metavar="EPSG",
                   help="--format toa: the receivers file's CRS (lat,lon in a geographic one, WGS 84 by default; x_m,"
                        "y_m in a projected one): the outputs gain lat, lon")
    p.add_argument("--frame", default=None, metavar="EPSG",
                   help="--format toa: the metric frame lat, lon are projected to (default: the UTM zone of the "
                        "array's centre)")
    p.add_argument("--time-origin", default=None, metavar="UTC",
                   help="--format toa: the UTC time of the TOA file's zero (ISO 8601 or epoch seconds): the outputs "
                        "gain epoch_s and time_utc, and a truth or sound-speed series may be in UTC")
    p.add_argument("--truth", type=Path, default=None, metavar="FILE",
                   help="truth track (time_s, n_m, e_m, d_m; .csv or .parquet): errors, consistency, figures; with "
                        "--format toa: x y t [m, m, s] under a header (e.g. GPS)")
    p.add_argument("--engine", choices=ENGINES, default="local", help="component engine (default local)")
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/replay_LOGNAME)")
    p.add_argument("--force", action="store_true", help="replace an earlier replay in --out")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="override a configuration key, e.g. receiver.q_horizontal=0.05 (repeatable)")
    p.add_argument("--fmu-dir", type=Path, default=None, help=FMU_DIR_HELP)


def main(args: argparse.Namespace) -> int:
    """``sblsim replay`` from its parsed arguments: its lines printed, its exit status returned."""
    if args.format in ("detections", "yaps", "vue", "fathom", "glatos", "otn"):  # raw detections: the tag's matrix
        # (sblsim toa), then tracked
        from sblsim.orchestrator.sync.toa import replay_matrix

        with replay_matrix(args) as toa_args:
            return _main_toa(toa_args)
    if args.sync is not None or args.tag is not None:
        raise ConfigError(f"{'--sync' if args.sync is not None else '--tag'}: only with --format detections, yaps, "
                          "vue, fathom, glatos or otn (raw detections)")
    if args.format == "toa":
        return _main_toa(args)
    given = [o for o, v in (("--receivers", args.receivers), ("--reference", args.reference),
                            ("--smooth", args.smooth), ("--sound-speed", args.sound_speed),
                            ("--receivers-kept", args.receivers_kept), ("--drop-detections", args.drop_detections),
                            ("--seed", args.seed is not None), ("--truth-sigma", args.truth_sigma is not None),
                            ("--ping-type", args.ping_type), ("--burst-interval", args.burst_interval),
                            ("--burst-sequence", args.burst_sequence), ("--force-interval", args.force_interval),
                            ("--acceleration-psd", args.acceleration_psd is not None),
                            ("--sound-speed-file", args.sound_speed_file),
                            ("--temperature", args.temperature is not None),
                            ("--salinity", args.salinity is not None), ("--motion", args.motion),
                            ("--temperature-file", args.temperature_file),
                            ("--water-depth", args.water_depth is not None),
                            ("--workers", args.workers is not None), ("--scheduler", args.scheduler),
                            ("--tag-depth", args.tag_depth is not None),
                            ("--depth-sigma", args.depth_sigma is not None),
                            ("--survey-sigma", args.survey_sigma is not None),
                            ("--toa-sigma", args.toa_sigma is not None),
                            ("--crs", args.crs), ("--frame", args.frame), ("--time-origin", args.time_origin)) if v]
    if given:
        raise ConfigError(f"{given[0]}: only with --format toa (times of arrival); allowed for a log: --receiver, "
                          "--config, --truth, --engine, --set, --fmu-dir, --out, --force")
    from sblsim.orchestrator.replay import replay_config

    notes: list[str] = []
    plan, source = replay_config(args.log, args.config, args.receiver, args.overrides, notes)
    receiver = plan.receiver
    if external_path(receiver, MODEL_PREFIX) or external_path(receiver):
        given = "--receiver" if args.receiver else "--set" if any("receiver=" in o for o in args.overrides) \
            else "--config"
        notes.append(f"the receiver is your own program, {receiver} ({given}): it runs as you")

    def prepare() -> Path:  # after the log and truth track are read, before the replay
        out = output_folder(args.out, Path("results") / f"replay_{folder_name(args.log.stem)}", args.force,
                      "summary.json", "replay")
        for note in notes:
            print(f"note: {note}", file=sys.stderr)
        return out

    result = _replay_plan(plan, source, args.log, args.truth, args.engine, args.fmu_dir, prepare)
    out, truth = result.out, args.truth
    s, c = result.summary, result.summary["log"]
    sim = plan["simulation"]
    print(f"replay of {args.log} on the {s['engine']} engine (receiver {s['receiver']}, configuration {source}): "
          f"{s['steps']} steps of {sim['sampling_time']:g} s from {s['start_time']:.10g} s in {s['wall_time']:.2f} s")
    skipped = c["duplicate"] + c["unknown_beacon"] + c["same_step"] + c["not_reached"]
    print(f"  log: {c['rows']} rows, {c['used']} used ({c['depth_only']} depth readings only), {skipped} skipped "
          f"({c['duplicate']} duplicated, {c['unknown_beacon']} with an unknown beacon id, {c['same_step']} in a step "
          f"that used {LANES} newer rows" + (f", {c['not_reached']} after the last step" if c["not_reached"] else "")
          + f"), {c['out_of_order']} out of order (sorted); rows every {c['typical_gap_s']:.6g} s (median), the "
          f"longest gap {c['longest_gap_s']:.6g} s"
          + (f" (before its {c['longest_gap_before']})" if c["longest_gap_s"] > 1.5 * c["typical_gap_s"] else "")
          + (f"; ignored columns: {', '.join(c['ignored_columns'])}" if c["ignored_columns"] else ""))
    if truth is not None:
        t = s["truth"]
        print(f"  truth: {args.truth}, interpolated at {t['steps']} of {s['steps']} steps"
              + (f" ({t['steps_without']} outside its span: no errors there)" if t["steps_without"] else ""))
    print_metrics(s, truth is not None)
    if c["same_step"]:
        print(f"sblsim: warning: {c['same_step']} rows of the log fell in a step that used {LANES} newer rows (at "
              f"most {LANES} rows per step of {sim['sampling_time'] / sim['ekf_rate_ratio']:g} s, on the lanes of a "
              "delivery): a smaller simulation.sampling_time or a larger simulation.ekf_rate_ratio (--set) uses them",
              file=sys.stderr)
    if truth is not None and s["diverged"]:
        print(f"sblsim: warning: the {s['receiver']} receiver diverged: its numbers mean nothing; see "
              "error_bounds.png", file=sys.stderr)
    if s["updates"] == 0:
        print(f"sblsim: warning: the {s['receiver']} receiver never made a fix: no row of the log brought a range "
              "it used", file=sys.stderr)
    print(f"  written to {out}/ (summary.json, config.toml, timeseries.parquet, figures)")
    return 0


def ping_type_line(summary: dict[str, Any]) -> str:
    """The console's line on the ping type and the gaps of a track's ``summary``."""
    p = summary["ping_type"]
    seen = p["seen"]
    how = "given" if p["source"] == "given" else (
        f"inferred from the first arrivals' spacing: steps of {seen['steps_s'][0]:.4g}-{seen['steps_s'][1]:.4g} s, "
        f"90 % within {seen['spread_s']:.3g} s of a whole number of {seen['typical_step_s']:.4g} s")
    bounds = f" [{p['burst_interval_s'][0]:.4g}, {p['burst_interval_s'][1]:.4g}] s" if p["burst_interval_s"] else ""
    gaps = summary["gaps_s"]
    segments = (f"; {len(gaps)} gap{'s' * (len(gaps) > 1)} (longest {max(gaps):.0f} s): {len(gaps) + 1} track "
                "segments") if gaps else ""
    return f"ping type {p['type']} ({PING_TYPES[p['type']]}{bounds}; {how}){segments}"


def quality_line(summary: dict[str, Any]) -> str:
    """The console's line on the track's quality marks."""
    main = summary["track"]
    flagged = summary["flagged"].get(main, 0)
    n = summary["fixed"].get(main, 0)
    why = ", ".join(f"{name} {count}" for name, count in summary.get("flag_reasons", {}).items())
    return (f"quality: {flagged} of {n} track rows ({ESTIMATOR_NAMES[main]}) flagged"
            f"{f' ({why}: the quality_reason column)' if why else ''}, {summary['restarts']} restarts of the EKF, "
            f"{summary['trusted_fixes']} trusted fixes")


def _main_tags(args: argparse.Namespace, options: dict[str, Any]) -> int:
    """``sblsim replay FOLDER --format toa``: each tag's line as it ends, then the table's summary."""
    given = [o for o, v in (("--truth", args.truth), ("--reference", args.reference)) if v]
    if given:
        raise ConfigError(f"{given[0]}: not with a folder of tags (one truth per tag: replay each tag's file)")
    workers = None if args.workers is None else int(real_argument(args.workers, "--workers", 1, 256, ""))
    scheduler = None
    if args.scheduler is not None:
        from sblsim.orchestrator.campaign.executors import check_address

        scheduler = check_address(args.scheduler)
    files = tag_files(args.log)
    out = output_folder(args.out, Path("results") / f"tags_{folder_name(args.log.name)}", args.force, "tags.csv",
                        "tags")

    def progress(row: dict[str, Any], count: int, total: int) -> None:
        if row["status"] == "tracked":
            print(f"  [{count}/{total}] {row['tag']}: {row['pings']} pings, {row['positioned']} positioned, "
                  f"{row['flagged']} flagged, {row['ping_type']}, {row['wall_time_s']:.1f} s", flush=True)
        else:
            print(f"sblsim: warning: [{count}/{total}] tag {row['tag']} refused: {row['reason']}", file=sys.stderr,
                  flush=True)

    where = f"on {scheduler}" if scheduler else f"in {workers or os.cpu_count() or 1} worker processes"
    print(f"tracking {len(files)} tags of {args.log} at {args.receivers} {where}", flush=True)
    done = track_tags(files, args.receivers, options, workers, scheduler, out, progress)
    table = done.table
    tracked = table[table["status"] == "tracked"]
    print(f"  {len(tracked)} of {len(table)} tags tracked, {int(tracked['flagged'].sum())} of "
          f"{int(tracked['positioned'].sum())} rows flagged; written to {out}/ (tags.csv, one folder per tag)")
    return 0


def _main_toa(args: argparse.Namespace) -> int:
    """``sblsim replay TOA_FILE --format toa``: the track's lines printed."""
    if args.receivers is None:
        raise ConfigError("--receivers: required with --format toa (the receivers' positions, a CSV or TOML file)")
    other = [o for o, v in (("--receiver", args.receiver), ("--config", args.config), ("--set", args.overrides),
                            ("--fmu-dir", args.fmu_dir)) if v]
    if other or args.engine != "local":
        raise ConfigError(f"{other[0] if other else '--engine'}: not used with --format toa; allowed: --receivers, "
                          "--truth, --truth-sigma, --reference, --smooth, --sound-speed, --receivers-kept, "
                          "--drop-detections, --seed, --ping-type, --burst-interval, --burst-sequence, "
                          "--force-interval, "
                          "--acceleration-psd, --sound-speed-file, --temperature, --salinity, --temperature-file, "
                          "--motion, --workers, --scheduler, --tag-depth, --depth-sigma, --survey-sigma, "
                          "--water-depth, --toa-sigma, --crs, --frame, --time-origin, --out, --force")
    speed, series, temperature, salinity, motion, q = medium_arguments(
        args.sound_speed, args.sound_speed_file, args.temperature, args.salinity, args.motion, args.acceleration_psd,
        ("--sound-speed", "--sound-speed-file", "--temperature", "--salinity", "--motion", "--acceleration-psd"),
        args.temperature_file, "--temperature-file")
    kept = names_argument(args.receivers_kept, "--receivers-kept", RECEIVER_NAMES)
    drop = 0.0 if args.drop_detections is None else real_argument(args.drop_detections, "--drop-detections", 0.0,
                                                                  MAX_DROP, "")
    seed = check_seed(0 if args.seed is None else args.seed, "--seed")
    if args.seed is not None and not drop:
        raise ConfigError("--seed: only with --drop-detections (the seed of its draw)")
    truth_sigma = 0.0
    if args.truth_sigma is not None:
        if args.truth is None:
            raise ConfigError("--truth-sigma: only with --truth (the truth's own error in the NEES against it)")
        truth_sigma = real_argument(args.truth_sigma, "--truth-sigma", 0.0, MAX_TRUTH_SIGMA, "m")
    kind, interval, sequence = ping_type_arguments(args.ping_type, args.burst_interval, args.burst_sequence,
                                                   ("--ping-type", "--burst-interval", "--burst-sequence"))
    options = {"smooth": args.smooth, "sound_speed": speed, "receivers_kept": kept, "drop": drop, "seed": seed,
               "truth_sigma": truth_sigma, "ping_type": kind, "burst_interval": interval,
               "burst_sequence_path": sequence, "acceleration_psd": q, "sound_speed_path": series,
               "temperature": temperature, "salinity": salinity, "motion": motion,
               "toa_sigma": toa_sigma_argument(args.toa_sigma, "--toa-sigma"),
               "force_interval": args.force_interval} | geometry_arguments(
        args.tag_depth, args.depth_sigma, args.survey_sigma, ("--tag-depth", "--depth-sigma", "--survey-sigma")) | \
        place_arguments(args.crs, args.frame, args.time_origin, ("--crs", "--frame", "--time-origin")) | \
        water_arguments(args.temperature_file, args.water_depth, ("--temperature-file", "--water-depth"))
    if args.log.is_dir():
        return _main_tags(args, options)
    if args.workers is not None or args.scheduler is not None:
        raise ConfigError(f"{'--workers' if args.workers is not None else '--scheduler'}: only with a folder of tags "
                          "(one times-of-arrival file per tag, tracked in parallel)")
    check_depth_sigma(args.log, args.tag_depth, args.depth_sigma, ("--tag-depth", "--depth-sigma"))
    outcome = track(args.log, args.receivers, args.truth, args.reference, **options)
    check_positioned(outcome, args.log)
    out = output_folder(args.out, Path("results") / f"track_{folder_name(args.log.stem)}", args.force,
                        "track.csv", "track")
    write(outcome, out)
    s = outcome.summary
    c = s["sound_speed"]
    thinned = (f" (kept {len(kept)} of the receivers file's)" if kept is not None else "") + \
        (f", {s['detections_dropped']} detections removed at random ({drop:g}, seed {seed})" if drop else "")
    print(f"track of {args.log}: {s['pings']} pings at "
          f"{len(s['receivers'])} receivers{thinned}, sound speed {c['sound_speed_m_s']:.1f} m/s ({c['source']}), "
          f"ping interval {s['ping_interval_s']:.4f} s, in {s['wall_time_s']:.1f} s")
    print("  " + ping_type_line(s))
    aside = s["set_aside"]
    if aside["count"]:
        print(f"  {aside['count']} rows set aside as no pings of the tag's schedule (first arrivals closer than "
              f"{aside['shortest_s']:g} s, less the crossing time, to a row heard by more receivers or as many and "
              "earlier): set_aside.csv, their rows kept in track.csv with no estimate")
    if aside["warning"]:
        print(f"sblsim: warning: {aside['warning']}", file=sys.stderr)
    print("  " + noise_line(s["toa_noise"]))
    if c["source"] == "fallback":
        print(f"sblsim: warning: the pings do not determine the sound speed ({c['calibration']}); taken: "
              f"{c['method']} (every range scales with it: give --sound-speed, --sound-speed-file or --temperature "
              "with --salinity)", file=sys.stderr)
    elif c["source"] == "calibrated with the fallback's prior":
        print(f"sblsim: warning: the pings determine the sound speed only to {c['calibrated_sigma_m_s']:.2g} m/s "
              f"({c['calibrated_m_s']:.1f} m/s); combined with {c['prior']} (± {c['prior_sigma_m_s']:.2g} m/s): "
              f"{c['sound_speed_m_s']:.1f} ± {c['sigma_m_s']:.2g} m/s, the two {c['disagreement_sigmas']:.1f} σ apart "
              "(every range scales with it: give --sound-speed, --sound-speed-file or --temperature with --salinity)",
              file=sys.stderr)
    if c.get("disagrees"):
        print(f"sblsim: warning: the sound speed given, {c['sound_speed_m_s']:.1f} m/s, is "
              f"{c['disagreement_sigmas']:.1f} σ from the pings' own calibration ({c['calibrated_m_s']:.1f} ± "
              f"{c['calibrated_sigma_m_s']:.2g} m/s): every range scales with it, by "
              f"{100 * abs(c['sound_speed_m_s'] / c['calibrated_m_s'] - 1):.2g} %; the track takes the speed given",
              file=sys.stderr)
    if replaced_line(c):
        print(f"sblsim: warning: {replaced_line(c)}", file=sys.stderr)
    if prior_line(s["depth"]):
        print(f"sblsim: warning: {prior_line(s['depth'])}", file=sys.stderr)
    if c.get("pings_outside_series"):
        print(f"sblsim: warning: {c['pings_outside_series']} of {s['pings']} pings lie outside the sound-speed "
              f"series' times [{c['series_time_s'][0]:.10g}, {c['series_time_s'][1]:.10g}] s: their arrivals take "
              "the speed at its nearer end", file=sys.stderr)
    m = s["motion"]
    if m.get("moved"):
        t = m["moved_test"]
        print(f"sblsim: warning: the tag moved: its {t['trusted_fixes']} trusted single-ping fixes lie in order in "
              f"time (successive ones {t['successive_ratio']:.2f} of their spread apart, below every one of "
              f"{t['permutations']} random orders); every row flagged (track it with --motion moving)",
              file=sys.stderr)
    quality = quality_line(s)
    print("  " + quality)
    for late in s["receivers_late"]:
        print(f"sblsim: warning: receiver {late['receiver']} is out of line of sight: its arrivals are late by "
              f"{late['median_residual_sigmas']:.1f} σ in the median over {late['arrivals']} (the track kept "
              f"{100 * late['kept_share']:.0f} % of them)", file=sys.stderr)
    if s["flagged"].get(s["track"]):
        print(f"sblsim: warning: {quality}; see the quality column of track.csv", file=sys.stderr)
    names = ESTIMATOR_NAMES
    if outcome.score is not None:
        r = outcome.score
        print(f"  2-D error against {args.truth} at each estimated emission time [m] (no lag applied):")
        print(f"  {'estimator':<16} {'fixed':>6} {'scored':>6} {'mean':>7} {'median':>7} {'RMS':>8} {'p90':>7} "
              f"{'p95':>7} {'NEES':>7} {'lag [s]':>7}")
        for key, e in [(r["estimator"], r)] + list(r["others"].items()):
            if e.get("median_m") is not None:
                nees = "-" if e["nees"] is None else f"{e['nees']:.3g}"
                lag = "-" if e["lag_s"] is None else f"{e['lag_s']:+.2f}"
                print(f"  {names[key]:<16} {e['n_fixed']:>6} {e['n_scored']:>6} {e['mean_m']:>7.3f} "
                      f"{e['median_m']:>7.3f} {e['rms_m']:>8.3f} {e['p90_m']:>7.3f} {e['p95_m']:>7.3f} {nees:>7} "
                      f"{lag:>7}")
        if not r.get("n_scored"):
            print(f"  no ping inside the truth's times [{outcome.truth[0, 0]:.10g}, {outcome.truth[-1, 0]:.10g}] s: "
                  f"none of the {names[r['estimator']]}'s {r['n_fixed']} positions scored")
        if r["nees"] is not None:
            print(f"  NEES of the {names[r['estimator']]} against the truth: mean {r['nees']:.3g}, median "
                  f"{r['nees_median']:.3g} (2 and 1.39 when consistent), the truth's own error "
                  f"{r['truth_sigma_m']:g} m per axis in the budget (--truth-sigma)")
        if r["lag_s"] is not None:
            print(f"  lag_s {r['lag_s']:+.2f} s: the truth's time shift (searched in ±{r['lag_range_s']:g} s) that "
                  f"minimises the {names[r['estimator']]}'s RMS error ({r['rms_at_lag_m']:.3f} m there); reported, "
                  "not applied" + (f"; mean error along the truth's heading {r['along_track_m']:+.3f} m, across "
                                   f"{r['across_track_m']:+.3f} m" if "along_track_m" in r else ""))
    else:
        for key, n in s["fixed"].items():
            print(f"  {names[key]}: {n} pings positioned")
    print(f"  written to {out}/ (track.csv, estimates.csv, summary.json, "
          f"{'score.json, errors.csv, bound.csv, ' if outcome.score is not None else ''}track.png)")
    return 0

"""An inverted LBL's run as the raw detections of a telemetry array (``sblsim run --export-detections DIR``): what
its hydrophones would log on their own clocks, with a sync tag at each, in the YAPS tables ``sblsim sync`` and
``sblsim toa`` read (:mod:`~sblsim.orchestrator.readers.detections`), and the truth to check them against.

* **The clocks**: hydrophone ``j`` reads the true time τ (the run's time) as ``τ + a_j + b_j τ``
  (:func:`sblsim.models.sync.simulate.on_clocks`), ``a_j`` uniform in ±``acoustics.receiver_clock_offset`` [s] and
  ``b_j`` in ±``acoustics.receiver_clock_drift_ppm``, drawn from the run's seed and replicate (numpy's generator on
  its own stream: no draw of the run moves); the first hydrophone (``H1``) keeps the true time, the reference
  receiver a GPS-timed array has, so that times synchronised to it are the truth's.
* **The tag** (``T1``, the diver's pinger): each packet the run delivered is a detection, its time of arrival the one
  the receivers were given, ``tx_time + range / c_assumed`` (the arrival plus the range noise and any multipath
  excess, as time), read on its hydrophone's clock; a lost packet is no detection.
* **The sync tags** (``S1`` … at each hydrophone's surveyed position): bursts at intervals uniform between
  ``acoustics.sync_interval_min`` and ``sync_interval_max``, heard by every hydrophone (its own too) with the
  channel's probability ``1 − loss_pct / 100``, along the **straight line** at the sound speed of the profile at the
  hydrophones' mean depth (the FMU channel carries the diver's pings only, so the sync tags are simulated here, not
  by its eigenrays or its signal-to-noise detection), with the channel's range noise as time
  (``sigma_range / c_assumed``), without outliers.

The receivers of the run (``ekf-seq``, ``ukf``) are given synchronised times as before: the clocks are in the export
only, and every number of a run is what it was.

Files: ``detections.csv`` (``epo, frac, tag, serial``: whole seconds since 1970-01-01 UTC and the fraction to the
nanosecond, the run's t = 0 at :data:`EPOCH`; the rows in the order of time, so each receiver's in its own),
``hydrophones.csv`` (``serial, sync_tag, x, y, z``: N, E and up [m], the surveyed positions the packets carry),
``clocks.csv`` (the truth: ``serial, offset_s, drift`` of each clock) and ``truth.csv`` (the diver's true track:
``time_s`` the run's, ``epo`` on the files' time, ``x, y, z`` N, E, up [m]).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from sblsim.models.acoustics.sound_speed import profile_table
from sblsim.models.declarations import ModelError
from sblsim.models.sync.simulate import draw_clocks, on_clocks, sync_tag_arrivals
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.io.output import write_together
from sblsim.orchestrator.logs.log_export import log_frames

#: The files' time of the run's t = 0 [s since 1970-01-01 UTC] (2024-01-01 00:00:00 UTC).
EPOCH = 1_704_067_200
#: The tag's id; the hydrophones' serials and their sync tags' ids are these prefixes and 1 … N.
TAG, SERIAL, SYNC = "T1", "H", "S"
#: The files written into the folder.
FILES = ("detections.csv", "hydrophones.csv", "clocks.csv", "truth.csv")
#: The stream of the clocks' and sync tags' draws (beside the run's seed and replicate).
STREAM = 0x5C10C


@dataclass
class DetectionExport:
    """A run as raw detections (the module docstring): the four tables of :data:`FILES`, and ``arrivals`` the
    detections' true times τ [s] (the run's time, before any clock), row by row of ``detections``."""

    detections: pd.DataFrame
    hydrophones: pd.DataFrame
    clocks: pd.DataFrame
    truth: pd.DataFrame
    arrivals: np.ndarray


def check_keys(acoustics: dict[str, Any]) -> None:
    """Refuse sync-tag intervals whose bounds are not in order (one line naming the keys)."""
    low, high = acoustics["sync_interval_min"], acoustics["sync_interval_max"]
    if not low <= high:
        raise ModelError(f"acoustics.sync_interval_min: {low:g} s is above acoustics.sync_interval_max ({high:g} s); "
                         "allowed min <= max")


def _speed(acoustics: dict[str, Any], depth: float) -> float:
    """The sound speed [m/s] of the run's profile at ``depth`` [m] (the constant true speed without a table)."""
    table = profile_table(acoustics["sound_speed_profile"], acoustics.get("sound_speed_table", ""),
                          acoustics["temperature"], acoustics["salinity"])
    if len(table) == 0:
        return float(acoustics["sound_speed_true"])
    return float(np.interp(depth, table[:, 0], table[:, 1]))


def detections_of(result: Any) -> DetectionExport:
    """The raw detections of a run's first replicate (the module docstring).

    Parameters
    ----------
    result : RunResult or RunRecord
        An inverted LBL's run (``platform.system = 'ilbl'``; :func:`sblsim.run`'s result or the kernel's record) with
        its time series.

    Raises
    ------
    ModelError
        Another system, or sync intervals out of order.
    """
    result = getattr(result, "_result", None) or result  # sblsim.run's result holds the kernel's record
    cfg = result.config
    if "toa" not in SYSTEMS[cfg["platform"]["system"]].ranging:  # the system whose receivers hear the pinger
        raise ModelError(f"--export-detections: raw detections are an inverted LBL's (platform.system = 'ilbl'); "
                         f"this run's system is {cfg['platform']['system']!r}")
    acoustics = cfg["acoustics"]
    check_keys(acoustics)
    ts = result.timeseries
    replicate = int(ts["replicate"].iloc[0])
    ts = ts[ts["replicate"] == replicate]
    log, truth = log_frames(ts)
    n = int(cfg["platform"]["beacons"])
    heard = log[log["beacon_id"].notna()]
    receiver = heard["beacon_id"].to_numpy(dtype=int) - 1
    tau_tag = heard["time_s"].to_numpy(dtype=float) + heard["range_m"].to_numpy(dtype=float) / float(
        acoustics["sound_speed_assumed"])
    ned = np.full((n, 3), np.nan)
    for j, row in heard.groupby(receiver).first().iterrows():  # the surveyed positions the packets carry
        ned[j] = row[["beacon_n_m", "beacon_e_m", "beacon_d_m"]].to_numpy(dtype=float)
    if np.isnan(ned).any():
        missing = ", ".join(f"{SERIAL}{j + 1}" for j in np.flatnonzero(np.isnan(ned).any(axis=1)))
        raise ModelError(f"--export-detections: hydrophone {missing} delivered no packet, so its surveyed position "
                         "is not known; run longer or with a smaller acoustics.loss_pct")
    rng = np.random.default_rng([int(cfg["run"]["seed"]), replicate, STREAM])
    offset0, drift = draw_clocks(n, float(acoustics["receiver_clock_offset"]),
                                 float(acoustics["receiver_clock_drift_ppm"]) * 1e-6, rng)
    span = float(ts["time"].iloc[-1])
    c = _speed(acoustics, float(np.mean(ned[:, 2])))
    s_rec, s_tag, s_tau = sync_tag_arrivals(
        ned, span, (float(acoustics["sync_interval_min"]), float(acoustics["sync_interval_max"])), c,
        1.0 - float(acoustics["loss_pct"]) / 100.0, float(acoustics["sigma_range"]) / float(
            acoustics["sound_speed_assumed"]), rng)
    rec = np.r_[receiver, s_rec]
    tau = np.r_[tau_tag, s_tau]
    tags = np.r_[np.full(len(receiver), TAG), [f"{SYNC}{i + 1}" for i in s_tag]].astype(object)
    clock = on_clocks(rec, tau, offset0, drift) + EPOCH
    order = np.lexsort((rec, clock))
    clock, rec, tags, tau = clock[order], rec[order], tags[order], tau[order]
    epo = np.floor(clock).astype(np.int64)
    frac = np.round((clock - epo) * 1e9).astype(np.int64)
    carry = frac >= 1_000_000_000
    epo, frac = epo + carry, np.where(carry, 0, frac)
    detections = pd.DataFrame({"epo": epo, "frac": [f"0.{f:09d}" for f in frac], "tag": tags,
                               "serial": [f"{SERIAL}{j + 1}" for j in rec]})
    serials = [f"{SERIAL}{j + 1}" for j in range(n)]
    hydrophones = pd.DataFrame({"serial": serials, "sync_tag": [f"{SYNC}{j + 1}" for j in range(n)],
                                "x": ned[:, 0], "y": ned[:, 1], "z": -ned[:, 2]})
    clocks = pd.DataFrame({"serial": serials, "offset_s": offset0, "drift": drift})
    track = pd.DataFrame({"time_s": truth["time_s"], "epo": truth["time_s"] + EPOCH, "x": truth["n_m"],
                          "y": truth["e_m"], "z": -truth["d_m"]})
    return DetectionExport(detections, hydrophones, clocks, track, tau)


def check_folder(folder: Path, force: bool) -> None:
    """Refuse ``--export-detections`` before the run: a file in its place, or earlier files without ``force``.

    Raises
    ------
    ModelError
        Naming ``--export-detections``.
    """
    if folder.exists() and not folder.is_dir():
        raise ModelError(f"--export-detections: {str(folder)!r} is not a folder")
    found = [name for name in FILES if (folder / name).exists()]
    if found and not force:
        raise ModelError(f"--export-detections: {str(folder)!r} holds {', '.join(found)}; add --force to replace "
                         "them or choose another folder")


def export_detections(result: Any, folder: Path | str) -> DetectionExport:
    """Write a run's raw detections (the module docstring's files) into ``folder``, all of them or none.

    Returns
    -------
    DetectionExport

    Raises
    ------
    ModelError
        As :func:`detections_of`, or a write that fails (nothing replaced).
    """
    folder = Path(folder)
    export = detections_of(result)
    frames = dict(zip(FILES, (export.detections, export.hydrophones, export.clocks, export.truth)))

    def writer(frame: pd.DataFrame):
        return lambda tmp: frame.to_csv(tmp, index=False, float_format=lambda v: repr(float(v)))

    try:
        write_together({folder / name: writer(frame) for name, frame in frames.items()})
    except OSError as exc:
        raise ModelError(f"--export-detections: {exc.strerror or type(exc).__name__}; nothing written in "
                         f"{str(folder)!r}") from None
    return export


__all__ = ["DetectionExport", "EPOCH", "FILES", "check_folder", "check_keys", "detections_of", "export_detections"]

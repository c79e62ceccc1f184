"""A times-of-arrival matrix (:class:`~sblsim.orchestrator.sync.toa.ToaOutcome`) written as the replay reads it:
``toa.txt`` (with the tag's depth per ping first where its sensor gives one in 3-D: :func:`sensor_depth`) and
``receivers.csv`` (:func:`write_matrix`), and ``sblsim toa``'s folder with ``pings.csv`` and ``toa.json`` beside
them (:func:`write_toa_folder`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.readers.toa_matrix import DEPTH_COLUMN
from sblsim.orchestrator.sync.toa import ToaOutcome, header_line


def sensor_depth(outcome: ToaOutcome) -> tuple[np.ndarray | None, str | None]:
    """The tag's depth per ping from its depth sensor (``pings``' ``depth_m``: readings in metres, a VUE export's
    calibrated depth or a tag sheet's conversion) for the tracker, where the receivers are in 3-D; else None, and a
    note where readings are left to ``pings.csv`` (a 2-D array has no depth to take them).

    Returns
    -------
    depth : ndarray, (P,) or None
        [m] per ping, NaN where the ping has no reading.
    note : str or None
    """
    if "depth_m" not in outcome.pings or not np.isfinite(outcome.pings["depth_m"].to_numpy(float)).any():
        return None, None
    if outcome.positions.shape[1] != 3:
        return None, (f"tag {outcome.summary['tag']}: its depth readings are not used by the tracker (the receivers "
                      "have no depths: 2-D); they are in its pings.csv")
    return outcome.pings["depth_m"].to_numpy(float), None


def write_toa_folder(outcome: ToaOutcome, out: Path) -> None:
    """:func:`write_toa_files` into ``out``, all or nothing."""
    with staged_directory(out) as tmp:
        write_toa_files(outcome, tmp)


def write_toa_files(outcome: ToaOutcome, folder: Path, notes: list[str] | None = None) -> None:
    """``toa.txt`` (the replay's format: a header of receiver names, ``NA`` where not heard, [s] from
    ``origin_epoch_s``; no header where every name is a number:
    :func:`~sblsim.orchestrator.sync.toa.header_line`; the tag's depth per ping
    first where its sensor gives one in 3-D, :func:`sensor_depth`), ``receivers.csv`` (``name, x_m, y_m[, z_m]``),
    ``pings.csv`` and ``toa.json`` into ``folder`` (made where missing); the sensor's note, where there is one,
    appended to ``notes``."""
    folder.mkdir(parents=True, exist_ok=True)
    depth, note = sensor_depth(outcome)
    if note and notes is not None:
        notes.append(note)
    write_matrix(outcome, folder, depth)
    outcome.pings.to_csv(folder / "pings.csv", index=False, float_format="%.9f")
    (folder / "toa.json").write_text(json.dumps(outcome.summary, indent=2, allow_nan=False) + "\n")


def write_matrix(outcome: ToaOutcome, folder: Path, depth: np.ndarray | None = None) -> tuple[Path, Path]:
    """``toa.txt`` and ``receivers.csv`` in ``folder`` (what the replay reads); returns their paths. With ``depth``
    (P,) [m] the tag's depth per ping (NaN where none), ``toa.txt`` has a ``depth_m`` column first (and a header
    whatever the receivers' names: the column's name is not a number). ``receivers.csv`` has each receiver's
    timing noise (``toa_sigma_s`` [s]), its clock offset's uncertainty (``clock_sigma_s`` [s]) and that averaged
    over the tag's arrivals at it (``clock_mean_sigma_s`` [s]) where the synchronisation gives them, the rounding σ
    of its logged times (``rounding_sigma_s`` [s]) where known, and each
    one's survey error (``sigma_m`` [m per horizontal axis]) where the synchronisation took the one it saw, or a
    study's refined positions give each one's (``outcome.survey_sigma``)."""
    frame = pd.DataFrame(outcome.toa, columns=outcome.names)
    if depth is not None:
        frame.insert(0, DEPTH_COLUMN, depth)
    toa = folder / "toa.txt"
    frame.to_csv(toa, sep=" ", na_rep="NA", index=False, float_format="%.9f",
                 header=depth is not None or header_line(outcome.names))
    axes = ["x_m", "y_m", "z_m"][:outcome.positions.shape[1]]
    receivers = folder / "receivers.csv"
    table = pd.DataFrame(outcome.positions, columns=axes)
    table.insert(0, "name", outcome.names)
    if outcome.toa_sigma is not None:  # seconds: significant figures, not the positions' four decimals
        table["toa_sigma_s"] = [f"{v:.6g}" for v in outcome.toa_sigma]
    if outcome.clock_sigma is not None:
        table["clock_sigma_s"] = [f"{v:.6g}" for v in outcome.clock_sigma]
    if outcome.clock_mean is not None:
        table["clock_mean_sigma_s"] = [f"{v:.6g}" for v in outcome.clock_mean]
    if outcome.rounding is not None:
        table["rounding_sigma_s"] = [f"{v:.6g}" for v in outcome.rounding]
    if outcome.survey_sigma is not None:
        table["sigma_m"] = np.broadcast_to(np.asarray(outcome.survey_sigma, float), (len(outcome.names),))
    table.to_csv(receivers, index=False, float_format="%.4f")
    return toa, receivers


__all__ = ["sensor_depth", "write_matrix", "write_toa_files", "write_toa_folder"]

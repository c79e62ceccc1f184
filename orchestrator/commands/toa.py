"""``sblsim toa`` and ``sblsim.toa``: one tag's times-of-arrival matrix from raw detections and a synchronisation
(``sblsim sync --out DIR``), the tracker's input (``sblsim replay toa.txt --format toa``); the work is
:mod:`sblsim.orchestrator.sync.toa`, the grouping :mod:`sblsim.models.sync.pings`.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sblsim.orchestrator.commands.console import add_receivers, output_folder
from sblsim.orchestrator.io.arguments import flag_argument, path_argument, prepare_out, text_argument
from sblsim.orchestrator.io.output import folder_name
from sblsim.orchestrator.readers.formats import FORMATS
from sblsim.orchestrator.sync.toa_console import run_lines, say_warnings
from sblsim.orchestrator.tracks.options import PING_TYPE_NAMES, ping_type_arguments

if TYPE_CHECKING:  # the heavy modules are imported when a function runs
    import numpy as np
    import pandas as pd

#: The detections' formats (None: read from the file's first line).


@dataclass
class ToaResult:
    """The outcome of :func:`toa`.

    Attributes
    ----------
    toa : numpy.ndarray
        (pings, receivers) [s] the synchronised times of arrival from ``summary["origin_epoch_s"]``, NaN where not
        heard (``toa.txt``).
    receivers : list of str
        The matrix's columns: the synchronised receivers of the receivers table, in its order.
    pings : pandas.DataFrame
        ``pings.csv``: ``ping``, ``time`` (the first arrival [s since 1970 UTC, reference clock]), ``time_utc`` (the
        same, ISO 8601), ``time_toa`` (on
        ``toa.txt``'s base [s]), ``receivers`` (how many heard it), ``heard`` (their names, ``;``-separated),
        ``spread_s``; from a VUE file the tag's sensor values per ping (``depth_m``, ``temperature_c``, ...).
    summary : dict
        ``toa.json``: the detections used, the multipath echoes dropped (per receiver), those outside the
        synchronised span or at receivers not synchronised, the window and echo limit [s], the shortest burst
        interval and where it came from, the time.
    out : Path or None
    """

    toa: np.ndarray
    receivers: list[str]
    pings: pd.DataFrame
    summary: dict[str, Any]
    out: Path | None = None


def toa(detections: str | Path, *, receivers: str | Path, sync: str | Path, tag: str, format: str | None = None,
        ping_type: str | None = None, burst_interval: str | tuple[float, float] | None = None,
        burst_sequence: str | Path | None = None, out: str | Path | None = None, force: bool = False,
        crs: str | None = None, frame: str | None = None, force_interval: bool = False) -> ToaResult:
    """One tag's times-of-arrival matrix from raw detections on synchronised clocks: ``sblsim toa``.

    Parameters
    ----------
    detections : str or Path
        Raw detections: the YAPS table (``epo, frac, tag, serial``), a VUE export, a Fathom (VDAT) CSV, a GLATOS or
        an OTN detection extract.
    receivers : str or Path
        The receivers: ``serial, sync_tag, x_m, y_m[, z_m]``, or a study's deployments (the table the
        synchronisation was made with).
    sync : str or Path
        A synchronisation's folder (``sblsim sync --out DIR``): its ``offsets.csv`` is read, nothing else.
    tag : str
        The tag: its full ID (``A69-1602-4555``) or its id.
    format : str, optional
        one of :data:`~sblsim.orchestrator.readers.formats.FORMATS`; default read from the file's first line.
    ping_type : str, optional
        ``sbi``, ``rbi`` (with ``burst_interval``) or ``pbi`` (with ``burst_sequence``): the shortest burst
        interval, below which a second arrival at one receiver is a multipath echo; default as the detections show
        it.
    burst_interval : str or (float, float), optional
        ``rbi``: ``"MIN:MAX"`` [s].
    burst_sequence : str or Path, optional
        ``pbi``: the tag's intervals [s], one per row.
    out : str or Path, optional
        Write ``toa.txt``, ``receivers.csv``, ``pings.csv`` and ``toa.json`` there.
    force : bool
        Replace an earlier result in ``out``.
    crs, frame : str, optional
        The receivers' CRS and the metric frame (as :func:`sync` takes them).
    force_interval : bool
        Take a stated interval the detections contradict as a whole (more than 10 % of a receiver's steps below its
        shortest: refused otherwise); ``summary["warnings"]`` says how many detections it drops.

    Returns
    -------
    ToaResult

    Raises
    ------
    ModelError, ConfigError
        One line naming the file, line and column or the option, and the allowed values: a file that cannot be
        read or a cell outside its range, a tag never detected, a shortest interval too short for the array, a
        stated interval the detections contradict (without ``force_interval``).
    """
    detections = path_argument(detections, "detections", optional=False)
    receivers = path_argument(receivers, "receivers", optional=False)
    sync = path_argument(sync, "sync", optional=False)
    tag = text_argument(tag, "tag", optional=False)
    from sblsim.orchestrator.sync.toa import build

    kind, interval, sequence = ping_type_arguments(ping_type, burst_interval, burst_sequence,
                                                   ("ping_type", "burst_interval", "burst_sequence"), stated=True,
                                                   example="60:120")
    target = prepare_out(out, force, "toa.txt", "times of arrival")
    outcome = build(detections, receivers, sync, tag, format, kind, interval, sequence, text_argument(crs, "crs"),
                    text_argument(frame, "frame"), flag_argument(force_interval, "force_interval"))
    if target is not None:
        from sblsim.orchestrator.sync.matrix_files import write_toa_folder

        write_toa_folder(outcome, target)
    return ToaResult(outcome.toa, outcome.names, outcome.pings, outcome.summary, target)


NAME = "toa"
HELP = "one tag's times-of-arrival matrix from raw detections and a synchronisation (sblsim sync)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim toa``'s arguments."""
    p.add_argument("detections", type=Path, help="raw detections: a YAPS table (epo,frac,tag,serial), a VUE export, "
                   "a Fathom (VDAT) CSV, a GLATOS or an OTN detection extract, or a store (sblsim store)")
    add_receivers(p)
    p.add_argument("--sync", type=Path, required=True, metavar="DIR",
                   help="the synchronisation's folder (sblsim sync --out DIR): its offsets.csv")
    p.add_argument("--tag", required=True, metavar="ID", help="the tag: its full ID (A69-1602-4555) or id")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="the detections' format (default: read from the file's first line)")
    add_ping_type(p)
    p.add_argument("--out", type=Path, default=None, help="output directory (default results/toa_TAG)")
    p.add_argument("--force", action="store_true", help="replace an earlier result in --out")


def add_ping_type(p: argparse.ArgumentParser) -> None:
    """``--ping-type``, ``--burst-interval``, ``--burst-sequence``."""
    p.add_argument("--ping-type", choices=PING_TYPE_NAMES, default=None,
                   help="the tag's ping type: sbi (stable burst interval), rbi (random, --burst-interval), pbi "
                        "(pseudo-random, --burst-sequence); its shortest interval bounds multipath echoes (default: "
                        "as the detections show it)")
    p.add_argument("--burst-interval", default=None, metavar="MIN:MAX",
                   help="a random burst interval's bounds [s], e.g. 60:120 (rbi)")
    p.add_argument("--burst-sequence", type=Path, default=None, metavar="FILE",
                   help="a pseudo-random tag's intervals [s] in order, one per row (pbi)")
    p.add_argument("--force-interval", action="store_true",
                   help="take the stated --burst-interval or --burst-sequence where the detections contradict it as "
                        "a whole (refused otherwise); a warning says how many detections it drops")


def main(args: argparse.Namespace) -> int:
    """``sblsim toa`` from its parsed arguments: its lines printed, its exit status returned."""
    from sblsim.orchestrator.sync.toa import build

    kind, interval, sequence = ping_type_arguments(args.ping_type, args.burst_interval, args.burst_sequence,
                                                   ("--ping-type", "--burst-interval", "--burst-sequence"),
                                                   stated=True, example="60:120")
    outcome = build(args.detections, args.receivers, args.sync, args.tag, args.format, kind, interval, sequence,
                    args.crs, args.frame, args.force_interval)
    out = output_folder(args.out, Path("results") / f"toa_{folder_name(args.tag)}", args.force, "toa.txt",
                        "times of arrival")
    from sblsim.orchestrator.sync.matrix_files import write_toa_folder

    write_toa_folder(outcome, out)
    for line in run_lines(outcome, str(out)):
        print(line)
    say_warnings(outcome.summary)
    s = outcome.summary
    for what, names in (("not in the receivers table", s["receivers_not_in_table"]),
                        ("not synchronised", s["receivers_not_synchronised"])):
        if names:
            print(f"note: the tag's detections at receivers {what} left out: {', '.join(names[:20])}",
                  file=sys.stderr)
    return 0


__all__ = ["ToaResult", "toa"]

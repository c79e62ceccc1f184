"""``sblsim replay`` of raw detections (``--format detections|yaps|vue|...``): the tag's times-of-arrival matrix
built as ``sblsim toa`` builds it (:func:`~sblsim.orchestrator.sync.toa.build`), written into a temporary folder and
replayed as ``--format toa`` (:func:`replay_matrix`).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np

from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.readers.detections import FORMATS as DETECTION_FORMATS
from sblsim.orchestrator.sync.matrix_files import sensor_depth, write_matrix
from sblsim.orchestrator.sync.toa import build
from sblsim.orchestrator.sync.toa_console import run_lines, say_warnings
from sblsim.orchestrator.tracks.options import geometry_arguments, ping_type_arguments

#: ``sblsim replay --format``'s names of raw detections (``detections``: read from the file's first line).
REPLAY_FORMATS = {"detections": None, **{f: f for f in DETECTION_FORMATS}}


@contextmanager
def replay_matrix(args: argparse.Namespace) -> Iterator[argparse.Namespace]:
    """``sblsim replay DETECTIONS --format detections|yaps|vue --receivers HYDROPHONES --sync DIR --tag ID``: the
    tag's matrix built as ``sblsim toa`` builds it (its lines printed), written with its receivers into a temporary
    folder (named by the tag, so the track's default folder is ``results/track_TAG``), and yielded as the arguments
    of ``replay --format toa`` on them; the folder is removed when the replay ends. The survey error the
    synchronisation saw and took, or on its refined positions each one's error, is each receiver's ``sigma_m``
    there (the tracker's σ hold it, as a study given that folder), unless ``--survey-sigma`` states another (0: the
    positions as exact).

    Raises
    ------
    ConfigError, ModelError
        ``--sync``, ``--tag`` or ``--receivers`` missing, ``--survey-sigma`` out of its range; what
        :func:`~sblsim.orchestrator.sync.toa.build` refuses.
    """
    missing = [o for o, v in (("--receivers", args.receivers), ("--sync", args.sync), ("--tag", args.tag)) if v is None]
    if missing:
        raise ConfigError(f"{missing[0]}: required with --format {args.format} (raw detections: --receivers "
                          "HYDROPHONES --sync DIR --tag ID)")
    kind, interval, sequence = ping_type_arguments(args.ping_type, args.burst_interval, args.burst_sequence,
                                                   ("--ping-type", "--burst-interval", "--burst-sequence"),
                                                   stated=True, example="60:120")
    stated = geometry_arguments(None, None, args.survey_sigma, ("--tag-depth", "--depth-sigma", "--survey-sigma"))
    outcome = build(args.log, args.receivers, args.sync, args.tag, REPLAY_FORMATS[args.format], kind, interval,
                    sequence, args.crs, args.frame, args.force_interval)
    seen = outcome.survey_sigma
    if stated["survey_sigma"] is not None and seen is not None:  # the error stated in place of the folder's
        refined = outcome.summary.get("positions")
        if refined:
            refined["sigma_m"] = None
        else:
            outcome.summary["survey_sigma_m"] = None
        outcome.survey_sigma = None
        print(f"note: --survey-sigma {stated['survey_sigma']:g} m stated in place of " + (
            f"each refined position's error ({np.min(seen):.3g} to {np.max(seen):.3g} m per axis)" if refined else
            f"the survey error the synchronisation saw ({seen:.3g} m per axis)"), file=sys.stderr)
    for line in run_lines(outcome, ""):
        print(line, flush=True)
    say_warnings(outcome.summary)
    with tempfile.TemporaryDirectory(prefix="sblsim-toa-") as tmp:
        folder = Path(tmp) / "".join(c if c.isalnum() or c in "._-" else "_" for c in args.tag)
        folder.mkdir()
        depth, note = sensor_depth(outcome)
        if note:
            print(f"note: {note}", file=sys.stderr)
        toa, receivers = write_matrix(outcome, folder, depth)
        named = toa.with_name(f"{folder.name}.txt")
        toa.rename(named)
        yield argparse.Namespace(**{**vars(args), "log": named, "receivers": receivers, "format": "toa",
                                    "sync": None, "tag": None, "time_origin": outcome.origin,
                                    "crs": None if outcome.frame is None else outcome.frame.crs, "frame": None})


__all__ = ["REPLAY_FORMATS", "replay_matrix"]

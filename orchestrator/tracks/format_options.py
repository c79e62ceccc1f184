"""Which of ``sblsim replay``'s options each ``--format`` takes: the times-of-arrival options a receiver's log
refuses (:func:`refuse_toa_only`), and the options of a times-of-arrival file checked and read into
:func:`~sblsim.orchestrator.tracks.options.toa_options` (:func:`toa_arguments`); each refusal is one line naming the
first option given.
"""

from __future__ import annotations

import argparse
from typing import Any

from sblsim.models.errors import ConfigError
from sblsim.orchestrator.tracks.options import NEGATED, TOA_OPTIONS, option_spelling, toa_options

#: The options of ``--format toa`` (times of arrival) a log refuses, in the order the refusal names the first given;
#: :data:`NUMBERS` are given when set (0 too), :data:`~sblsim.orchestrator.tracks.options.NEGATED` when false
#: (``--no-other-filters``), the others when true (a flag, a file, a text, a number other than 0).
TOA_ONLY = ("receivers", "reference", "smooth", "sound_speed", "receivers_kept", "drop_detections", "seed",
            "truth_sigma", "ping_type", "burst_interval", "burst_sequence", "force_interval", "acceleration_psd",
            "sound_speed_file", "temperature", "salinity", "motion", "temperature_file", "water_depth", "workers",
            "scheduler", "tag_depth", "depth_sigma", "survey_sigma", "toa_sigma", "crs", "frame", "time_origin",
            "other_filters")
NUMBERS = {"seed", "truth_sigma", "acceleration_psd", "temperature", "salinity", "water_depth", "workers", "tag_depth",
           "depth_sigma", "survey_sigma", "toa_sigma"}


def refuse_toa_only(args: argparse.Namespace) -> None:
    """Refuse an option of ``--format toa`` given to ``sblsim replay LOG`` (a receiver's log, :data:`TOA_ONLY`).

    Raises
    ------
    ConfigError
        Naming the first given, and the options a log takes.
    """
    given = [option_spelling(k) for k in TOA_ONLY
             if (getattr(args, k) is not None if k in NUMBERS else not getattr(args, k) if k in NEGATED
                 else getattr(args, k))]
    if given:
        raise ConfigError(f"{given[0]}: only with --format toa (times of arrival); allowed for a log: --receiver, "
                          "--config, --truth, --engine, --set, --fmu-dir, --out, --force")


def toa_arguments(args: argparse.Namespace) -> dict[str, Any]:
    """The options of ``sblsim replay TOA --format toa`` checked (``--receivers`` required, a log's ``--receiver``,
    ``--config``, ``--set``, ``--fmu-dir`` and ``--engine`` refused, ``--truth-sigma`` only with ``--truth``,
    ``--seed`` only with ``--drop-detections``) and read as :func:`~sblsim.orchestrator.tracks.options.toa_options`
    returns them.

    Raises
    ------
    ConfigError
        Naming the first option refused; as
        :func:`~sblsim.orchestrator.tracks.options.toa_options`.
    """
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
                          "--water-depth, --toa-sigma, --crs, --frame, --time-origin, --no-other-filters, --out, "
                          "--force")
    if args.truth_sigma is not None and args.truth is None:
        raise ConfigError("--truth-sigma: only with --truth (the truth's own error in the NEES against it)")
    unset = {"drop_detections": 0.0, "seed": 0, "truth_sigma": 0.0}  # the defaults of options not given
    options = toa_options(**{k: unset[k] if k in unset and getattr(args, k) is None else getattr(args, k)
                             for k in TOA_OPTIONS}, spell=option_spelling)
    if args.seed is not None and not options["drop"]:
        raise ConfigError("--seed: only with --drop-detections (the seed of its draw)")
    return options


__all__ = ["NUMBERS", "TOA_ONLY", "refuse_toa_only", "toa_arguments"]

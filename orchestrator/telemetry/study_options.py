"""The options of a telemetry study (``sblsim track``, :func:`sblsim.track`) checked, each refused in one line naming
it as the caller spells it, the value and the allowed range: returned as
:func:`~sblsim.orchestrator.telemetry.study.run_study`'s keyword arguments.
"""

from __future__ import annotations

from typing import Any

from sblsim.models.sync.identifiability import SURVEY_SIGMA, SURVEY_SIGMA_RANGE
from sblsim.models.tracking.timing import TOA_SIGMA_RANGE
from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.io.arguments import flag_argument, names_argument, real_argument, text_argument
from sblsim.orchestrator.io.frames import check_crs, check_metric
from sblsim.orchestrator.readers.formats import FORMATS
from sblsim.orchestrator.readers.local_times import study_zone

#: The detections' formats (None: read from the file's first line).
#: The synchronisation's bins [h] and the sound speeds [m/s] taken.
BIN_HOURS = (0.05, 168.0)
SOUND_SPEED = (1300.0, 1700.0)
#: The most worker processes.
MAX_WORKERS = 256


def survey_sigma_argument(value: Any, refine: bool, where: str) -> float | None:
    """The survey σ [m] checked: with the refinement its prior, in :data:`SURVEY_SIGMA_RANGE` (default
    :data:`SURVEY_SIGMA`); without, the survey's stated error, in a stated error's range from 0
    (:data:`sblsim.orchestrator.readers.receivers_file.SURVEY_SIGMA_RANGE`; 0: the positions taken as exact;
    default None: the error the synchronisation's residuals show where seen, else exact).

    Raises
    ------
    ConfigError
        Out of its range (one line naming ``where``).
    """
    from sblsim.orchestrator.readers.receivers_file import SURVEY_SIGMA_RANGE as STATED_RANGE

    if value is None:
        return SURVEY_SIGMA if refine else None
    return real_argument(value, where, *(SURVEY_SIGMA_RANGE if refine else STATED_RANGE), "m")


def _options(format: Any, crs: Any, frame: Any, tag: Any, bin_hours: Any, workers: Any, scheduler: Any,
             medium: tuple, names: dict[str, str], toa_sigma: Any = None, force_interval: Any = False,
             tz: Any = None, refine_positions: Any = False, survey_sigma: Any = None) -> dict[str, Any]:
    """Every option of a study checked (``names``: how each is spelled where it was given; ``tz``, the study's IANA
    time zone, where given), as :func:`~sblsim.orchestrator.telemetry.study.run_study`'s keyword arguments."""
    if format is not None and format not in FORMATS:
        raise ConfigError(f"{names['format']}: {str(format)[:40]!r}; allowed: {', '.join(FORMATS)} (or none: read "
                          "from the file's first line)")
    crs, frame = text_argument(crs, names["crs"]), text_argument(frame, names["frame"])
    speed, series, temperature, salinity = medium
    if workers is not None:
        workers = int(real_argument(workers, names["workers"], 1, MAX_WORKERS, ""))
    if scheduler is not None:
        from sblsim.orchestrator.campaign.executors import check_address

        scheduler = check_address(str(scheduler))
    return {"format": format, "crs": None if crs is None else check_crs(crs, names["crs"]),
            "frame": None if frame is None else check_metric(frame, names["frame"]),
            "chosen": names_argument(tag, names["tag"], "transmitters (full IDs or ids)"), "sound_speed": speed,
            "sound_speed_file": series, "temperature": temperature, "salinity": salinity,
            "bin_hours": real_argument(bin_hours, names["bin_hours"], *BIN_HOURS, "h"), "workers": workers,
            "scheduler": scheduler, "toa_sigma": None if toa_sigma is None else real_argument(
                toa_sigma, names["toa_sigma"], *TOA_SIGMA_RANGE, "s"),
            "force_interval": flag_argument(force_interval, names["force_interval"]),
            "tz": None if tz is None else study_zone(tz, names["tz"]).key,
            "refine_positions": flag_argument(refine_positions, names["refine_positions"]),
            "survey_sigma": survey_sigma_argument(survey_sigma, bool(refine_positions), names["survey_sigma"])}


__all__ = ["BIN_HOURS", "FORMATS", "MAX_WORKERS", "SOUND_SPEED",
           "survey_sigma_argument"]

"""The error sources of ``sblsim budget`` and how each is switched off: the ``--set`` overrides that set a source
to zero (:data:`SOURCES`), and a configuration's plan with them applied and its receiver kept (:func:`switched_off`).

Each random stream is keyed by its purpose (:mod:`sblsim.models.philox`), so switching one source to zero leaves
every other random number of a run unchanged (docs/model.md, "Error budget"); the budget itself is
:mod:`sblsim.orchestrator.montecarlo.budget`'s.
"""

from __future__ import annotations

import re
from typing import Sequence

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.config import ConfigError, parse_override
from sblsim.orchestrator.cosim.plan import RunPlan, make_plan, thaw

#: Error source -> (what it is, the ``--set`` overrides that switch it off). A value ``{section.key}`` is that
#: key's value in the configured (all-on) configuration.
SOURCES: dict[str, tuple[str, tuple[str, ...]]] = {
    "gps": ("GPS error of the platform position", ("platform.gps_sigma=0",)),
    "imu_noise": ("IMU attitude noise", ("platform.imu_sigma_deg=0",)),
    "imu_bias": ("IMU attitude bias and gyro-bias drift", ("platform.imu_bias_deg=0", "platform.imu_gyro_bias=0")),
    "imu_scale_misalignment": ("IMU scale factor and axis misalignment",
                               ("platform.imu_scale_factor_ppm=0", "platform.imu_misalignment_deg=0")),
    "waves": ("wave motion of the platform (Beaufort sea state)", ("platform.beaufort=0",)),
    "range_noise": ("white range noise (with its growth with range, acoustics.range_k)",
                    ("acoustics.sigma_range=0", "acoustics.range_k=0")),
    "sound_speed": ("true sound speed other than the assumed one",
                    ("acoustics.sound_speed_profile=constant",
                     "acoustics.sound_speed_true={acoustics.sound_speed_assumed}")),
    "clock_drift": ("receiver clock drift", ("acoustics.clock_drift_ppm=0",)),
    "moving_ocean": ("the moving ocean: the sound speed's smooth change in time (nadir total delay)",
                     ("acoustics.ntd_sigma_ppm=0",)),
    "multipath": ("multipath: ranges from a reflected path (outliers, or the surface and sea-floor eigenrays)",
                  ("acoustics.outlier_pct=0", "acoustics.water_depth=0")),
    "ambient_noise": ("ambient noise: arrivals missed and timing and angle noise grown below the reference SNR",
                      ("acoustics.source_level=250",)),
    "packet_loss": ("lost packets", ("acoustics.loss_pct=0",)),
    "depth_sensor": ("depth-sensor noise", ("target.depth_sigma=0",)),
    "survey": ("LBL transponders' survey error", ("platform.survey_sigma=0",)),
    "installation": ("transducer installation error", ("platform.installation_sigma=0",)),
    "turnaround_jitter": ("two-way ranging: turnaround jitter", ("acoustics.turnaround_sigma=0",)),
    "ping_jitter": ("inverted LBL: the pinger's interval jitter (its emission epochs a random walk)",
                    ("acoustics.ping_jitter=0",)),
    "usbl_angle": ("USBL direction-of-arrival noise", ("platform.usbl_angle_sigma_deg=0",)),
    "usbl_misalignment": ("USBL array misalignment", ("platform.usbl_misalignment_deg=0",)),
    "latency": ("the receiver's processing latency (the diver sees an older estimate)", ("receiver.latency=0",)),
    "profile_error": ("profile error: the receiver's sound-speed profile other than the true one",
                      ("receiver.sound_speed_profile=acoustics",)),
}
#: Sources that exist only for a receiver that ranges with its own profile (``receiver.sound_speed_profile`` not
#: ``assumed``): a receiver of the single assumed speed has them off (its error is the ``sound_speed`` source).
PROFILE_SOURCES = frozenset({"profile_error"})
#: Sources that exist only with detection by signal-to-noise (``acoustics.detection = "snr"``); a source level
#: of 250 dB re 1 µPa at 1 m hears every eigenray there is, at the configured accuracy.
SNR_SOURCES = frozenset({"ambient_noise"})

_REFERENCE = re.compile(r"^\{(\w+)\.(\w+)\}$")


def switched_off(cfg: RunPlan | dict[str, dict], overrides: Sequence[str]) -> RunPlan:
    """The plan of the configuration ``cfg`` with ``overrides`` applied and its receiver kept.

    The overrides go into a copy of the resolved configuration, whose plan is
    made (:func:`~sblsim.orchestrator.cosim.plan.make_plan`: it is resolved again, once): every receiver key is then
    given, so no tie retunes the
    receiver (its R stays the configured one, e.g. when ``acoustics.sigma_range``
    is 0); only a receiver key an override names changes.

    Raises
    ------
    ConfigError
        If an override names a key the configuration does not have, or a value outside its range.
    """
    raw = thaw(cfg)
    receiver = dict(cfg["receiver"])
    for item in overrides:
        section, name, value = parse_override(item)
        if section not in raw or name not in raw[section]:
            raise ConfigError(f"{section}.{name}: not a key of this configuration")
        if isinstance(value, str) and _REFERENCE.match(value):
            ref_section, ref_name = _REFERENCE.match(value).groups()
            value = cfg[ref_section][ref_name]
        raw[section][name] = value
        if section == "receiver":
            receiver[name] = value
    out = make_plan(raw)
    if out["receiver"] != receiver or out["simulation"] != cfg["simulation"]:  # the ties above: never
        raise ModelError("budget: switching a source off changed the receiver or the simulation settings")
    return out


#: The switched-off plans of the plans of this process's budgets, by the plan's id: (plan, switches); each plan's
#: switches are made once (:func:`~sblsim.orchestrator.montecarlo.budget.configurations` checks them,
#: :func:`~sblsim.orchestrator.montecarlo.budget.budgets` counts and runs them).
_SWITCHED: dict[int, tuple[RunPlan, tuple[dict[str, RunPlan], RunPlan]]] = {}
_KEEP = 64


def _switches(cfg: RunPlan) -> tuple[dict[str, RunPlan], RunPlan]:
    """Each source's switched-off plan, and the floor's (every source off): made once per plan."""
    kept = _SWITCHED.get(id(cfg))
    if kept is not None and kept[0] is cfg:
        return kept[1]
    names = {name: _overrides(cfg, name, overrides) for name, (_, overrides) in SOURCES.items()}
    off = {name: switched_off(cfg, overrides) for name, overrides in names.items()}
    switches = off, switched_off(cfg, [o for overrides in names.values() for o in overrides])
    if len(_SWITCHED) >= _KEEP:
        _SWITCHED.pop(next(iter(_SWITCHED)))
    _SWITCHED[id(cfg)] = (cfg, switches)
    return switches


def _overrides(cfg: RunPlan, name: str, overrides: tuple[str, ...]) -> tuple[str, ...]:
    """The overrides that switch the source ``name`` off in ``cfg``: none (the source is off) for a profile
    source of a receiver that ranges with the single assumed speed (or declares no profile), and for a source of
    detection by signal-to-noise with fixed detection."""
    if name in PROFILE_SOURCES and cfg["receiver"].get("sound_speed_profile", "assumed") == "assumed":
        return ()
    if name in SNR_SOURCES and cfg["acoustics"]["detection"] != "snr":
        return ()
    return overrides


__all__ = ["PROFILE_SOURCES", "SNR_SOURCES", "SOURCES", "switched_off"]

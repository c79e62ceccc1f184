"""The configuration's sections and keys: the scenarios built in, the sections (``run``, ``simulation`` and one per
component), the declarations of the ``run`` and ``simulation`` sections and of the keys the orchestrator keeps in the
``receiver`` section (:data:`RECEIVER_KEYS`), the FMU parameters it fills (:data:`SAMPLING_TIES`, :data:`KEY_TIES`),
and what a ``simulation.receiver`` value names (a built-in receiver, ``model:PATH.py``, ``fmu:PATH``) with that
receiver's declarations.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from sblsim.models import COMPONENTS, RECEIVER_MODELS
from sblsim.models.declarations import (
    SEED_NAMES,
    SEED_PARAMETERS,
    UNITS,
    FileKey,
    ModelError,
    Variable,
)
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.cosim.fmu_files import read_description
from sblsim.orchestrator.cosim.master import ALGORITHMS
from sblsim.orchestrator.cosim.plugins import user_model

BUILTIN_SCENARIOS = ("semicircle", "spiral", "random", "square", "harbour", "random-walk", "usbl-deep", "lbl-field")
SECTIONS = ("run", "simulation", *COMPONENTS)
EXTERNAL_PREFIX = "fmu:"
MODEL_PREFIX = "model:"
RUN_VARIABLES: tuple[Variable, ...] = (
    Variable("scenario", "parameter", "String", "custom", description="Scenario name", scope="config"),
) + SEED_PARAMETERS
SIMULATION_VARIABLES: tuple[Variable, ...] = (
    Variable("sampling_time", "parameter", "Real", 0.1, "s",
             "Sampling time T: round-robin slot and communication step of the physics", min=0.001, max=60.0),
    Variable("ekf_rate_ratio", "parameter", "Integer", 1, description="EKF steps per measurement slot",
             min=1, max=1000),
    Variable("duration", "parameter", "Real", 0.0, "s", "Simulated time (0: one pass of the trajectory)",
             min=0.0, max=1e6),
    Variable("master", "parameter", "String", "gauss-seidel",
             description="Master algorithm: gauss-seidel, jacobi as FMI hosts step an SSP, or event (FMI 3.0 "
                         "FMUs: a step ends at each acoustic arrival)",
             choices=ALGORITHMS, scope="config"),
    Variable("receiver", "parameter", "String", "ekf", scope="config",
             file=FileKey(prefixes=(MODEL_PREFIX, EXTERNAL_PREFIX)),
             description="Receiver component: ekf (the paper's), ekf-seq, ukf, lsq, model:PATH.py or fmu:PATH"),
    Variable("fmi_version", "parameter", "Integer", 2, scope="config", min=2, max=3,
             description="FMI version of the fmu engine's FMUs: 2, or 3 (the fmi3 folder of the FMU folder; "
                         "the same numbers)"),
)
#: Keys of the ``receiver`` section that the orchestrator implements for every receiver (built-in, a user's model
#: or FMU): configuration keys only, never parameters of the receiver component
#: (:meth:`sblsim.orchestrator.cosim.plan.RunPlan.component_parameters`).
RECEIVER_KEYS: tuple[Variable, ...] = (
    Variable("latency", "parameter", "Real", 0.0, "s",
             "Processing latency: the estimate a diver sees is the one the receiver computed this long ago "
             "(a whole number of sampling times)", min=0.0, max=60.0, scope="config"),
)
RECEIVER_KEY_NAMES = frozenset(v.name for v in RECEIVER_KEYS)
#: FMU parameters filled with ``simulation.sampling_time``: (component, parameter).
SAMPLING_TIES = (("platform", "sample_period"), ("target", "sample_period"), ("acoustics", "slot_period"))
#: FMU parameters filled from a configuration key of another section: (component, parameter) <- (section, key).
KEY_TIES = ((("acoustics", "usbl_angle_sigma_deg"), ("platform", "usbl_angle_sigma_deg")),
            (("receiver", "sound_speed_assumed"), ("acoustics", "sound_speed_assumed")),
            (("receiver", "ranging"), ("acoustics", "ranging")),
            (("acoustics", "beaufort"), ("platform", "beaufort")))


def external_path(value: Any, prefix: str = EXTERNAL_PREFIX) -> str:
    """The path of ``fmu:PATH`` (or of ``model:PATH`` with that prefix); empty for any other value."""
    return value[len(prefix):] if isinstance(value, str) and value.startswith(prefix) else ""


def receiver_model(value: str) -> type | Path:
    """What a ``simulation.receiver`` value names: a model class (built-in or a user's file), or an FMU path."""
    if value in RECEIVER_MODELS:
        return RECEIVER_MODELS[value]
    if external_path(value, MODEL_PREFIX):
        return user_model(external_path(value, MODEL_PREFIX))
    return Path(external_path(value))


def section_variables(section: str, receiver: str = "ekf") -> tuple[Variable, ...]:
    """Declarations of a configuration section (component parameters without the seed keys).

    Parameters
    ----------
    section : str
    receiver : str
        The ``simulation.receiver`` whose declarations the ``receiver`` section holds.

    Raises
    ------
    ConfigError
        If the section is unknown, or the receiver declares a parameter named like one of
        :data:`RECEIVER_KEYS`.
    """
    if section == "run":
        return RUN_VARIABLES
    if section == "simulation":
        return SIMULATION_VARIABLES
    if section == "receiver":
        model = receiver_model(receiver)
        if isinstance(model, Path):
            own = external_receiver_variables(model)
        else:
            own = tuple(v for v in model.config_parameters() if v.name not in SEED_NAMES)
        clash = sorted(RECEIVER_KEY_NAMES & {v.name for v in own})
        if clash:
            raise ConfigError(f"receiver.{clash[0]}: the {receiver} receiver declares a parameter {clash[0]!r}, "
                              "a key the orchestrator keeps for every receiver; rename the receiver's parameter")
        return own + RECEIVER_KEYS
    if section in COMPONENTS:
        return tuple(v for v in COMPONENTS[section].config_parameters() if v.name not in SEED_NAMES)
    raise ConfigError(f"{section}: unknown section; one of {', '.join(SECTIONS)}")


def external_receiver_variables(path: Path) -> tuple[Variable, ...]:
    """The parameters of a user's receiver FMU as declarations (name, type, unit, start, range).

    Raises
    ------
    ConfigError
        If the FMU cannot be read.
    ArchiveError
        If the FMU's archive is not safe to read (checked before fmpy reads it).
    """
    try:
        md = read_description("receiver", Path(path))
    except ModelError as exc:  # it names the FMU and what is wrong with it
        raise ConfigError(str(exc)) from None

    def number(x):
        return None if x is None else float(x)

    out = []
    for v in md.modelVariables:
        if v.causality != "parameter" or v.type not in ("Real", "Integer", "Boolean") or v.name in SEED_NAMES:
            continue
        start = {"Real": float, "Integer": int, "Boolean": lambda x: str(x).lower() in ("true", "1")}[v.type](
            v.start if v.start is not None else 0)
        out.append(Variable(v.name, "parameter", v.type, start, v.unit or ("1" if v.type == "Real" else "")
                            if (v.unit or "1") in UNITS else "1", v.description or "",
                            min=number(v.min), max=number(v.max)))
    return tuple(out)


def check_receiver(receiver: str, where: str = "simulation.receiver") -> str:
    """A ``simulation.receiver`` value: a built-in receiver, ``model:PATH.py`` of a user's receiver model,
    or ``fmu:PATH`` of an existing FMU file.

    Raises
    ------
    ConfigError
        Naming ``where``, the value and what is allowed.
    """
    if receiver in RECEIVER_MODELS:
        return receiver
    if external_path(receiver, MODEL_PREFIX):
        try:
            user_model(external_path(receiver, MODEL_PREFIX))
        except ConfigError as exc:
            raise ConfigError(str(exc).replace("simulation.receiver", where, 1)) from None
        return receiver
    path = external_path(receiver)
    if not path:
        raise ConfigError(f"{where}: {receiver!r} is not allowed; one of {', '.join(RECEIVER_MODELS)}, "
                          "model:PATH.py or fmu:PATH")
    if Path(path).is_dir():
        raise ConfigError(f"{where}: {path!r} is a directory, not an FMU file")
    if not Path(path).is_file():
        raise ConfigError(f"{where}: no FMU file at {path!r}")
    return receiver


def receiver_label(cfg: dict[str, dict]) -> str:
    """What a figure or table calls the receiver that ran: ``ekf``, ``ekf-seq``, ``ukf``, ``lsq``, a user
    model's ``label`` (else its name) or the FMU's file name."""
    value = cfg["simulation"]["receiver"]
    if value in RECEIVER_MODELS:
        return value
    model = receiver_model(value)
    return Path(model).stem if isinstance(model, Path) else str(getattr(model, "label", model.name))

"""A run resolved once: the typed, immutable plan of a validated configuration.

:func:`make_plan` is the one place a configuration is resolved for a run: it validates the configuration
(:func:`sblsim.orchestrator.cosim.config.resolve`: every key, range and tie; an invalid one raises one
:class:`~sblsim.models.errors.ConfigError` here, never later) and derives, once, everything a run asks of it:
the positioning system object (:data:`sblsim.models.systems.SYSTEMS`), what implements each component (a
built-in model's name, a user's model class, a user's FMU path), each component's FMU parameters, the
receiver's label, its latency in steps of the record, the lever arms and the horizontal spread of the
transducers, the macro step, the EKF rate ratio, the step count, the master algorithm, the bound's
parameters and the seed keys. :func:`load_plan` reads a scenario or file with ``--set`` overrides and makes
its plan.

``run``, ``compare``, ``budget``, ``map``, ``replay``, ``campaign`` and ``ssp export`` take a
:class:`RunPlan` and read its fields; none of them reads the raw configuration again. A plan is frozen: its
fields cannot be set and its configuration (:attr:`RunPlan.config`, whose sections a plan also gives as a
read-only mapping, ``plan["platform"]["baseline"]``) refuses every change; a changed configuration is a new
plan (``make_plan`` of a changed copy: :func:`thaw`). The replicates of one configuration share its plan
(:meth:`RunPlan.with_replicate` sets ``run.replicate`` without resolving anything again).
"""

from __future__ import annotations

import copy
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from sblsim.fmus.compiled_functions import compiled_exact_points, compiled_family_levels, compiled_family_points
from sblsim.models import MODELS, RECEIVERS
from sblsim.models.errors import ConfigError, ModelError
from sblsim.models.platform.geometry import transducer_span
from sblsim.models.receiver.interface import filter_parameters
from sblsim.models.receiver.profile import resolve_channel_profile
from sblsim.models.systems import SYSTEMS, System
from sblsim.models.target.core import Target
from sblsim.orchestrator.cosim.config import (
    KEY_TIES,
    MIN_SIGMA,
    RECEIVER_KEY_NAMES,
    SAMPLING_TIES,
    load_raw,
    receiver_label,
    receiver_model,
    resolve,
    to_toml,
)
from sblsim.orchestrator.cosim.handles import Source, paper_sources
from sblsim.orchestrator.cosim.limits import step_count


class FrozenMapping(dict):
    """A read-only :class:`dict`: every change raises :class:`TypeError` (reading, ``==``, JSON and TOML
    writing work as for a dict). ``copy.copy`` and ``copy.deepcopy`` give a plain, changeable dict (deep: the
    sections too)."""

    __slots__ = ()

    def _refuse(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError("a run plan's configuration is read-only; change a copy (copy.deepcopy) and make a new "
                        "plan of it")

    __setitem__ = __delitem__ = __ior__ = _refuse  # type: ignore[assignment]
    clear = pop = popitem = setdefault = update = _refuse  # type: ignore[assignment]

    def __reduce__(self) -> tuple:
        return type(self), (dict(self),)

    def __copy__(self) -> dict:
        return dict(self)

    def __deepcopy__(self, memo: dict) -> dict:
        return thaw(self)


def freeze(cfg: Mapping[str, Mapping[str, Any]]) -> FrozenMapping:
    """A read-only copy of a configuration (each section read-only; its values deep-copied)."""
    return FrozenMapping({s: FrozenMapping(copy.deepcopy(dict(t))) for s, t in cfg.items()})


def thaw(cfg: Mapping[str, Mapping[str, Any]]) -> dict[str, dict]:
    """A plain, changeable deep copy of a (frozen) configuration."""
    return {s: ({k: copy.deepcopy(v) for k, v in t.items()} if isinstance(t, Mapping) else copy.deepcopy(t))
            for s, t in cfg.items()}


#: The Kalman-type receivers' parameter defaults (the bound's motion model for a receiver without one).
_FILTER_DEFAULTS = {v.name: v.start for v in filter_parameters()}


@dataclass(frozen=True, eq=False)
class RunPlan(Mapping):
    """Everything a run needs, resolved once from a validated configuration (:func:`make_plan`).

    Reading a plan as a mapping reads its configuration (``plan["platform"]["baseline"]`` [m]), read-only.
    Two plans are equal when their configurations are (a plan is a function of its configuration).

    Attributes
    ----------
    config : FrozenMapping
        The resolved configuration, section -> key -> value, read-only (:func:`thaw` for a changeable copy).
    system : System
        The positioning system object (:data:`sblsim.models.systems.SYSTEMS`, ``platform.system``).
    n_beacons : int
        The size of the components' interfaces (the system's :meth:`~sblsim.models.systems.System.beacon_count`).
    receiver : str
        ``simulation.receiver`` (``ekf``, ``ekf-seq``, ``ukf``, ``lsq``, ``model:PATH.py`` or ``fmu:PATH``).
    receiver_label : str
        What figures and tables call it (:func:`sblsim.orchestrator.cosim.config.receiver_label`).
    sources : FrozenMapping
        Component -> what implements it: a built-in model's name (:data:`sblsim.models.MODELS`), a user's model
        class or the path of a user's FMU (the receiver's source, built-in, ``model:`` or ``fmu:``).
    parameters : FrozenMapping
        Component -> its FMU parameter values (the component's section through its model, the sampling ties,
        the clock and the seed keys; a user's FMU: those it may take, filtered by :meth:`component_parameters`).
    latency_steps : int
        ``receiver.latency`` in steps of the record (sampling times T), ≥ 0.
    lever_arms : ndarray, shape (n_beacons, 3)
        The transducers' positions about the platform reference [m] (the system's
        :meth:`~sblsim.models.systems.System.lever_arms`), read-only.
    horizontal_spread : float
        How far apart the transducers are horizontally [m] (the system's
        :meth:`~sblsim.models.systems.System.horizontal_spread`).
    sampling_time : float
        The macro step T [s].
    ekf_rate_ratio : int
        Receiver steps per macro step.
    master : str
        The master algorithm (``gauss-seidel`` or ``jacobi``).
    duration : float
        Simulated time [s].
    n_steps : int
        Macro steps of a run.
    bound : FrozenMapping
        The parameters of the position PCRB (:func:`bound_parameters`).
    scenario : str
    seed, replicate : int
        ``run.seed`` and ``run.replicate``.
    """

    config: FrozenMapping
    system: System
    n_beacons: int
    receiver: str
    receiver_label: str
    sources: FrozenMapping
    parameters: FrozenMapping
    latency_steps: int
    lever_arms: np.ndarray
    horizontal_spread: float
    sampling_time: float
    ekf_rate_ratio: int
    master: str
    duration: float
    n_steps: int
    bound: FrozenMapping
    scenario: str
    seed: int
    replicate: int

    # ---------------------------------------------------------------- the configuration, read-only
    def __getitem__(self, section: str) -> Mapping[str, Any]:
        return self.config[section]

    def __iter__(self) -> Iterator[str]:
        return iter(self.config)

    def __len__(self) -> int:
        return len(self.config)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, RunPlan):
            return self.config == other.config
        return self.config == other if isinstance(other, Mapping) else NotImplemented

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return (f"RunPlan({self.scenario!r}, system={self.system.name!r}, receiver={self.receiver!r}, "
                f"n_beacons={self.n_beacons}, n_steps={self.n_steps}, seed={self.seed}, replicate={self.replicate})")

    # ---------------------------------------------------------------- what a run asks
    @property
    def rates(self) -> dict[str, int]:
        """Communication steps per macro step of the components stepped faster than T (the receiver's)."""
        return {"receiver": self.ekf_rate_ratio}

    def model(self, component: str) -> type | None:
        """The model class that implements a component (None: a user's FMU)."""
        source = self.sources[component]
        if isinstance(source, Path):
            return None
        return source if isinstance(source, type) else MODELS[source]

    def component_parameters(self, component: str, accepted: frozenset[str] | None = None) -> dict[str, Any]:
        """A component's FMU parameter values (a new dict): those ``accepted`` names (the parameters of the
        FMU or model that implements it, e.g. a user's receiver FMU) when given.

        String choices stay text (each engine encodes them); the orchestrator's receiver keys (``latency``) are
        never among them.
        """
        params = self.parameters[component]
        if accepted is None:
            return dict(params)
        return {k: v for k, v in params.items() if k in accepted}

    def with_replicate(self, replicate: int) -> RunPlan:
        """The same plan for another ``run.replicate`` (nothing is resolved again)."""
        replicate = int(replicate)
        if replicate == self.replicate:
            return self
        run = FrozenMapping({**self.config["run"], "replicate": replicate})
        config = FrozenMapping({**self.config, "run": run})
        params = FrozenMapping({c: (FrozenMapping({**p, "replicate": replicate}) if "replicate" in p else p)
                                for c, p in self.parameters.items()})
        new = copy.copy(self)
        object.__setattr__(new, "config", config)
        object.__setattr__(new, "parameters", params)
        object.__setattr__(new, "replicate", replicate)
        return new

    def __copy__(self) -> RunPlan:
        new = object.__new__(RunPlan)
        for name in _FIELDS:
            object.__setattr__(new, name, getattr(self, name))
        return new

    def __deepcopy__(self, memo: dict) -> RunPlan:
        return self  # immutable

    def __reduce__(self) -> tuple:
        # the system object and a user's model class go by name (a user's model is imported again from its file)
        state = {f.name: getattr(self, f.name) for f in fields(self) if f.name not in ("system", "sources")}
        return _restore, (state,)


#: The fields of a plan, in order (:meth:`RunPlan.__copy__` copies them once per replicate).
_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(RunPlan))


def _restore(state: dict[str, Any]) -> RunPlan:
    """A plan from :meth:`RunPlan.__reduce__` (a campaign's worker process receives its chunk's plans so)."""
    plan = object.__new__(RunPlan)
    for name, value in state.items():
        object.__setattr__(plan, name, value)
    object.__setattr__(plan, "system", SYSTEMS[state["config"]["platform"]["system"]])
    object.__setattr__(plan, "sources", _sources(state["receiver"]))
    plan.lever_arms.flags.writeable = False
    return plan


# ---------------------------------------------------------------------------------------------- the builder

def _sources(receiver: str) -> FrozenMapping:
    """What implements each component: the paper's built-in models, the receiver as ``simulation.receiver``
    names it (a built-in model's name, a user's model class, a user's FMU path)."""
    sources: dict[str, Source] = paper_sources()
    sources["receiver"] = RECEIVERS[receiver] if receiver in RECEIVERS else receiver_model(receiver)
    return FrozenMapping(sources)


def _model(source: Source) -> type | None:
    if isinstance(source, Path):
        return None
    return source if isinstance(source, type) else MODELS[source]


def _component_parameters(cfg: Mapping[str, Mapping[str, Any]], component: str, model: type | None,
                          n_beacons: int) -> FrozenMapping:
    """The FMU parameter values of one component of a resolved configuration.

    The component's section turned into FMU parameters by its model
    (:meth:`sblsim.models.component.Component.fmu_parameters`: tables from files, custom offsets), the
    sampling ties (:data:`sblsim.orchestrator.cosim.config.SAMPLING_TIES`), the key ties
    (:data:`sblsim.orchestrator.cosim.config.KEY_TIES`), the receiver's clock ``communication_step`` = T / ratio and
    the seed keys it declares. A user's FMU (``model`` None) declares what it declares: every candidate is
    kept, and :meth:`RunPlan.component_parameters` keeps those of the FMU's parameters.
    """
    section = cfg[component]
    if component == "receiver":  # the orchestrator's keys are not the receiver's parameters
        section = {k: v for k, v in section.items() if k not in RECEIVER_KEY_NAMES}
        if "sound_speed_profile" in section:  # its own profile: ``acoustics`` is the channel's, teos10 at its water
            section = resolve_channel_profile(section, cfg["acoustics"])
    if model is None:
        params = dict(section)
        declared = None
    else:
        params = model.fmu_parameters(section, n_beacons)
        declared = model.fmu_parameter_names(n_beacons)

    def takes(name: str) -> bool:
        return declared is None or name in declared

    sim = cfg["simulation"]
    for owner, name in SAMPLING_TIES:
        if owner == component and takes(name):
            params[name] = sim["sampling_time"]
    for (owner, name), (tied, key) in KEY_TIES:
        if owner == component and takes(name):
            params[name] = cfg[tied][key]
    if component == "receiver" and takes("communication_step"):  # the receiver's own clock: T / ratio
        params["communication_step"] = sim["sampling_time"] / sim["ekf_rate_ratio"]
    params.update({k: v for k, v in cfg["run"].items() if takes(k)})
    if component == "acoustics" and model is not None and takes("ray_table_rows") \
            and model.uses_ray_table(cfg["acoustics"], params):
        box = ray_box(cfg)
        if box is not None:  # the channel's tables over the geometries the run keeps to
            params.update(model.table_parameters(cfg["acoustics"], params, box, compiled_exact_points,
                                                 compiled_family_points, compiled_family_levels))
    return FrozenMapping(params)


#: Margins of the eigenray table's box around the geometry the configuration gives [m]: depths, distance.
RAY_BOX_MARGINS = (1.0, 5.0)


def ray_box(cfg: Mapping[str, Mapping[str, Any]]) -> tuple[float, ...] | None:
    """The box of geometries of a run's eigenray table (:data:`sblsim.models.acoustics.ray_tables.RAY_BOUNDS`), or
    None when the configuration does not bound them (a random walk, a spiral).

    The source depths are where the system's transducers go (:func:`~sblsim.models.platform.geometry.transducer_span`:
    with the platform's heave), the receiver's the diver's depths, the horizontal distances those between the
    transducers' horizontal circle and the diver's (:meth:`~sblsim.models.target.core.Target.reach`), each
    widened by :data:`RAY_BOX_MARGINS`; no depth below ``acoustics.water_depth`` (where the bottom-reflected family
    ceases to exist). A geometry outside the box is solved exactly, so the box only decides the speed.
    """
    reach = Target.reach(cfg["target"])
    if reach is None:
        return None
    depths, r_lo, r_hi = reach
    dz, dx = RAY_BOX_MARGINS
    # within the water: the profile's end speed is extended above the surface (a kink the table would straddle),
    # and a family's existence changes at the floor
    floor = float(cfg["acoustics"].get("water_depth", 0.0)) or np.inf
    zs_lo, zs_hi, r_beacon = transducer_span(cfg["platform"], dz)
    return (zs_lo, min(zs_hi, floor), max(float(depths.min()) - dz, 0.0), min(float(depths.max()) + dz, floor),
            max(r_lo - r_beacon - 2.0 * dx, 0.0), r_hi + r_beacon + 2.0 * dx)


def bound_parameters(cfg: Mapping[str, Mapping[str, Any]], system: System) -> dict[str, float]:
    """The parameters of the position PCRB of a resolved configuration (:func:`sblsim.models.bound.pcrb`).

    The motion model and prior are the random walk's for ``random-walk`` (the
    bound is then a true bound), else the receiver's (``q_horizontal``,
    ``q_vertical``, ``p0_position``, ``p0_velocity``; the defaults of the
    Kalman-type receivers for one that has none). The measurement variances
    are the configured white error sources: ``acoustics.sigma_range²`` plus the
    broadcast position's variance and the attitude variance of the system
    (:meth:`~sblsim.models.systems.System.position_errors`: ``platform.gps_sigma²``
    and ``platform.imu_sigma_deg`` [rad]²; LBL: ``platform.survey_sigma²`` and 0), and
    ``target.depth_sigma²`` (floored at 1 mm). The USBL bound takes the range's and the transceiver
    position's apart: ``range_variance = acoustics.sigma_range²`` and ``position_variance``, the broadcast
    position's isotropic variance per axis as the receivers' R takes it, the position error's plus the largest
    lever arm turned by the attitude error (``σ² + (σ_att a)²``, a the receivers' ``beacon_arm`` tie,
    :meth:`~sblsim.models.systems.System.receiver_ties`); ``angle_sigma_deg``, the USBL
    direction-of-arrival std on the array's axis, ``platform.usbl_angle_sigma_deg``
    [deg] (floored at 1 mdeg, as the receivers' ``sigma_angle_deg``; the USBL bound,
    :func:`sblsim.models.systems.usbl_bound.pcrb`); the error states of the bound, the system's
    :meth:`~sblsim.models.systems.System.bound_errors` (a Gauss-Markov GPS error then leaves the white
    variances); ``sigma_range`` and ``range_k``, the range law's σ₀ and k (``acoustics.range_k``: each bound adds
    :func:`sblsim.models.bound.law_variance` at the true range).
    """
    target, platform = cfg["target"], cfg["platform"]
    names = ("q_horizontal", "q_vertical", "p0_position", "p0_velocity")
    if target["trajectory"] == "random-walk":
        motion = {k: target[f"walk_{k}"] for k in names}
    else:
        motion = {k: cfg["receiver"].get(k, _FILTER_DEFAULTS[k]) for k in names}
    position, attitude = system.position_errors(platform)
    errors = system.bound_errors(cfg)
    if errors["gps_sigma"] > 0.0:  # a Gauss-Markov GPS error is a state of the bound, not white noise
        position = 0.0
    arm = system.receiver_ties(platform)["beacon_arm"]
    return {**motion, "noise_variance": cfg["acoustics"]["sigma_range"] ** 2 + position ** 2,
            "range_variance": cfg["acoustics"]["sigma_range"] ** 2,
            "position_variance": position ** 2 + (attitude * arm) ** 2,
            "attitude_variance": attitude ** 2,
            "depth_variance": max(target["depth_sigma"], MIN_SIGMA) ** 2,
            "angle_sigma_deg": system.angle_sigma_deg(platform), **errors,
            "sigma_range": cfg["acoustics"]["sigma_range"], "range_k": cfg["acoustics"].get("range_k", 0.0)}


def make_plan(config: Mapping[str, Any]) -> RunPlan:
    """Validate a configuration and resolve it into the plan of a run: the one resolution of a run.

    Parameters
    ----------
    config : mapping
        A configuration, raw (as read from a file, with overrides applied) or resolved (a
        :func:`~sblsim.orchestrator.cosim.config.load_config` result, a :class:`RunPlan`'s, an API ``Config``): it is
        validated (again) either way.

    Returns
    -------
    RunPlan

    Raises
    ------
    ConfigError
        Naming the field and its allowed range (one error; nothing later re-reads the configuration): a value
        outside its declared range too (the declarations raise a plain ``ModelError``, turned into this).
    ArchiveError
        A file the configuration names that is not safe to read (a user's receiver FMU).
    """
    try:
        cfg = resolve(thaw(config))
    except ModelError as exc:
        if type(exc) is not ModelError:
            raise
        raise ConfigError(str(exc)) from None
    platform, sim, run = cfg["platform"], cfg["simulation"], cfg["run"]
    system = SYSTEMS[platform["system"]]
    n_beacons = system.beacon_count(platform)
    receiver = sim["receiver"]
    sources = _sources(receiver)
    parameters = FrozenMapping({c: _component_parameters(cfg, c, _model(s), n_beacons) for c, s in sources.items()})
    arms = np.array(system.lever_arms(platform), dtype=float)
    arms.flags.writeable = False
    T = sim["sampling_time"]
    return RunPlan(
        config=freeze(cfg), system=system, n_beacons=n_beacons, receiver=receiver,
        receiver_label=receiver_label(cfg), sources=sources, parameters=parameters,
        latency_steps=int(round(cfg["receiver"]["latency"] / T)), lever_arms=arms,
        horizontal_spread=float(system.horizontal_spread(platform)), sampling_time=T,
        ekf_rate_ratio=int(sim["ekf_rate_ratio"]), master=sim["master"], duration=sim["duration"],
        n_steps=step_count(sim["duration"], T), bound=FrozenMapping(bound_parameters(cfg, system)),
        scenario=str(run["scenario"]), seed=int(run["seed"]), replicate=int(run["replicate"]))


def load_plan(source: str | Path, overrides: Iterable[str] = (), seed: int | None = None) -> RunPlan:
    """The plan of a built-in scenario or TOML file with ``section.key=value`` overrides and the seed.

    Raises
    ------
    ConfigError
        As :func:`sblsim.orchestrator.cosim.config.load_config` (an unknown scenario, section or key, invalid TOML) and
        :func:`make_plan`; nothing has been written.
    """
    return make_plan(load_raw(source, overrides, seed))


class Config(dict):
    """A resolved, validated configuration: section -> key -> value, every key present.

    A :class:`dict` (``cfg["platform"]["baseline"]`` [m]) with the sections ``run``, ``simulation``,
    ``platform``, ``acoustics``, ``target`` and ``receiver`` (the keys and their units: the model page and
    ``sblsim fmus variables``). Made by ``sblsim.load``; any function that takes a scenario takes one. A
    changed copy is made by ``sblsim.load(cfg, set={...})``, which validates it again. :meth:`plan` resolves it
    into the plan of a run (what every function makes of it, once per call).
    """

    @property
    def scenario(self) -> str:
        """``run.scenario``: the scenario's name."""
        return str(self["run"]["scenario"])

    def to_toml(self) -> str:
        """The configuration as TOML text (what ``config.toml`` of a run holds; ``sblsim run FILE`` reads it)."""
        return to_toml(self)

    def plan(self) -> RunPlan:
        """The plan of a run of this configuration, validated again (:func:`make_plan`; a later change of the
        configuration does not change the plan).

        Raises
        ------
        ConfigError, ModelError
            If the configuration was changed into an invalid one.
        """
        return make_plan(self)


def as_plan(config: RunPlan | Mapping[str, Any]) -> RunPlan:
    """A plan as it is, or the plan of a configuration (:func:`make_plan`: one resolution)."""
    return config if isinstance(config, RunPlan) else make_plan(config)


def with_replicates(plan: RunPlan | Mapping[str, Any], replicates: Iterable[int]) -> list[RunPlan]:
    """One plan per replicate (``run.replicate`` set), sharing everything else: a plan is not resolved again, a
    configuration is resolved into its plan once (:func:`as_plan`)."""
    base = as_plan(plan)
    return [base.with_replicate(r) for r in replicates]


__all__ = ["Config", "FrozenMapping", "RunPlan", "as_plan", "bound_parameters", "freeze", "load_plan", "make_plan",
           "thaw", "with_replicates"]

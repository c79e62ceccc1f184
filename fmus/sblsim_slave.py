"""Generic pythonfmu slave over a component core (the thin FMU wrapper).

A component's FMU script subclasses :class:`CoreSlave` and names its core
class; everything else comes from the core's declarations. The wrapper copies
parameters into the core at the end of initialization, inputs before each
doStep, and outputs back after it. There is no physics here.

FMU state (``canGetAndSetFMUstate``): pythonfmu's C wrapper keeps the object
returned by ``_get_fmu_state`` as the ``fmi2FMUstate`` (a reference, released
by ``fmi2FreeFMUstate``) and passes that same object to ``_set_fmu_state``.
So the state is a deep copy of everything that evolves (variable values,
start time, and the core with its random generators, filter and held values),
and restoring copies it again, so that one state can be restored many times.
It is not serializable (``canSerializeFMUstate`` stays false): pythonfmu
serializes with JSON, which cannot hold the core.
"""

from __future__ import annotations

import copy
from typing import Any, ClassVar

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability
from pythonfmu.variables import Boolean, Integer, Real, String

_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_CAST = {"Real": float, "Integer": int, "Boolean": bool, "String": str}


class CoreSlave(Fmi2Slave):
    """FMI 2.0 Co-Simulation slave stepping one component core with B = 1.

    Attributes
    ----------
    core_class : type
        The :class:`models.core.ComponentCore` subclass to wrap.
    n_beacons : int
        Number of beacons of the interface.
    """

    core_class: ClassVar[type]
    n_beacons: ClassVar[int] = 4
    author = "sblsim"
    license = "MIT"

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.modelName = f"sblsim_{self.core_class.name}"
        self.description = (self.core_class.__doc__ or "").strip().splitlines()[0]
        self.declarations = self.core_class.variables(self.n_beacons)
        self.values: dict[str, Any] = {v.name: v.start for v in self.declarations}
        self.start_time = 0.0
        self.core = None
        for v in self.declarations:
            self.register_variable(_TYPES[v.type](
                v.name, causality=Fmi2Causality[v.causality], variability=Fmi2Variability[v.variability],
                description=v.description, getter=self._getter(v.name),
                setter=None if v.causality == "output" else self._setter(v.name, _CAST[v.type])))

    def _getter(self, name: str):
        return lambda: self.values[name]

    def _setter(self, name: str, cast):
        def setter(value):
            self.values[name] = cast(value)
        return setter

    def setup_experiment(self, start_time: float, stop_time: float | None, tolerance: float | None) -> None:
        self.start_time = float(start_time)

    def exit_initialization_mode(self) -> None:
        params = {v.name: self.values[v.name] for v in self.declarations if v.causality == "parameter"}
        self.core = self.core_class(params, n_beacons=self.n_beacons)
        self.core.set_inputs({n: self.values[n] for n in self.core.inputs})
        self.core.initialize(self.start_time)
        self._publish()

    def do_step(self, current_time: float, step_size: float) -> bool:
        self.core.set_inputs({n: self.values[n] for n in self.core.inputs})
        self.core.step(current_time, step_size)
        self._publish()
        return True

    def _get_fmu_state(self) -> dict[str, Any]:
        """fmi2GetFMUstate: a deep copy of the full state (the wrapper holds it until fmi2FreeFMUstate)."""
        return copy.deepcopy({"values": self.values, "start_time": self.start_time, "core": self.core})

    def _set_fmu_state(self, state: dict[str, Any]) -> None:
        """fmi2SetFMUstate: restore a copy of a saved state, leaving it intact for further restores."""
        state = copy.deepcopy(state)
        self.values, self.start_time, self.core = state["values"], state["start_time"], state["core"]

    def _publish(self) -> None:
        for name, value in self.core.outputs.items():
            self.values[name] = value[0].item()

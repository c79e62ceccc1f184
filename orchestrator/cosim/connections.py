"""Connections between components, declared as data and checked at load time.

A connection copies one output to one input at every communication point:
``from_component.variable -> to_component.variable``. Before a run the
orchestrator checks every connection against the variables the engine
actually exposes (the core declarations, or an FMU's model description):
existence, causality, type and unit; and that every input is fed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

from sblsim.models.acoustics.channel.interface import ARRIVAL, PACKET, TARGET_INPUTS
from sblsim.models.acoustics.channel.lanes import lane_of, lane_variables
from sblsim.models.declarations import ModelError, Variable
from sblsim.models.platform.core import USBL_ATTITUDES, beacon_names
from sblsim.models.receiver.interface import OPTIONAL_OUTPUTS
from sblsim.models.systems import interface_system

#: What the channel sends every receiver: the packet, then its arrival epoch.
PACKET_FIELDS = tuple(v.name for v in PACKET + ARRIVAL)


class ConnectionMismatch(ModelError):
    """A connection does not match the components' variables."""


@dataclass(frozen=True)
class Connection:
    """``source.output -> destination.input``."""

    source: str
    output: str
    destination: str
    input: str

    def __str__(self) -> str:
        return f"{self.source}.{self.output} -> {self.destination}.{self.input}"


def default_connections(n_beacons: int = 4) -> list[Connection]:
    """The system: platform and target feed the channel; channel and target feed the receiver (the interface of a
    system that measures a direction, USBL's, adds the array's and the IMU's attitude to the channel and the
    direction of arrival with the attitude it was turned with to the receiver)."""
    conns = [Connection("platform", n, "acoustics", n)
             for kind in ("true", "broadcast") for n in beacon_names(n_beacons, kind)]
    conns += [Connection("target", out, "acoustics", inp)
              for out, inp in zip(("pos_x", "pos_y", "pos_z", "vel_x", "vel_y", "vel_z"), TARGET_INPUTS)]
    conns += [Connection("acoustics", n, "receiver", n) for n in PACKET_FIELDS]
    conns.append(Connection("target", "depth_measured", "receiver", "depth"))
    system = interface_system(n_beacons)
    if system.measures_direction:
        conns += [Connection("platform", f"{prefix}_{a}", "acoustics", f"{prefix}_{a}")
                  for prefix, _, _ in USBL_ATTITUDES for a in ("roll", "pitch", "yaw")]
    # what the system adds to the packet (USBL's direction of arrival and the attitude it was turned with)
    conns += [Connection("acoustics", v.name, "receiver", v.name)
              for v in system.receiver_inputs() + system.receiver_late_inputs()]
    # the lanes of a delivery: the packets that arrived in the same step after lane 1's
    conns += [Connection("acoustics", v.name, "receiver", v.name) for v in lane_variables(n_beacons, "input")]
    return conns


def check_connections(connections: Sequence[Connection], interfaces: Mapping[str, Sequence[Variable]]) -> None:
    """Check connections against the components' variables.

    Parameters
    ----------
    connections : sequence of Connection
    interfaces : mapping
        Component name -> its variables (as the engine exposes them).

    Raises
    ------
    ConnectionMismatch
        Naming the first connection with a missing component or variable, a
        wrong causality, a type or unit mismatch, or an input fed twice or never.
    """
    by_name = {c: {v.name: v for v in vs} for c, vs in interfaces.items()}
    fed: dict[tuple[str, str], Connection] = {}
    for conn in connections:
        ends = []
        for comp, name, causality in ((conn.source, conn.output, "output"), (conn.destination, conn.input, "input")):
            if comp not in by_name:
                raise ConnectionMismatch(f"connection {conn}: no component {comp!r}; have {', '.join(by_name)}")
            var = by_name[comp].get(name)
            if var is None:
                raise ConnectionMismatch(f"connection {conn}: {comp} has no variable {name!r}")
            if var.causality != causality:
                raise ConnectionMismatch(f"connection {conn}: {comp}.{name} has causality {var.causality}, "
                                       f"expected {causality}")
            ends.append(var)
        out, inp = ends
        if out.type != inp.type:
            raise ConnectionMismatch(f"connection {conn}: type {out.type} does not match {inp.type}")
        if out.unit != inp.unit:
            raise ConnectionMismatch(f"connection {conn}: unit {out.unit!r} does not match {inp.unit!r}")
        key = (conn.destination, conn.input)
        if key in fed:
            raise ConnectionMismatch(f"connection {conn}: {conn.destination}.{conn.input} is already fed by {fed[key]}")
        fed[key] = conn
    for comp, variables in by_name.items():
        for name, var in variables.items():
            if var.causality == "input" and (comp, name) not in fed:
                raise ConnectionMismatch(f"{comp}.{name}: input is not connected")


#: An interface's refusal (:func:`check_interface`) names this many of its mismatches and counts the rest.
SHOWN_PROBLEMS = 5


def check_interface(component: str, ports: Sequence[Variable], expected: Sequence[Variable], where: object) -> None:
    """Check that a user's FMU offers a component's inputs and outputs (name, causality, type, unit).

    Parameters
    ----------
    component : str
        The component it stands in for (e.g. ``receiver``).
    ports : sequence
        The FMU's variables (``name``, ``causality``, ``type``, ``unit``).
    expected : sequence of Variable
        The component's declarations; its parameters are not required.
    where : object
        The FMU (named in the message).

    A receiver may lack the inputs of the later lanes of a delivery (``lane<m>_*``) altogether: it is then given
    lane 1 alone, and a run in which a packet arrived in a step after another is refused
    (:func:`sblsim.orchestrator.cosim.run.run_batch`). It may lack the outputs every built-in receiver added later
    (:data:`~sblsim.models.receiver.interface.OPTIONAL_OUTPUTS`: ``est_valid``): a run records them where it has them.

    Raises
    ------
    ConnectionMismatch
        In one line: the first :data:`SHOWN_PROBLEMS` of the missing variables, the causalities, types or units
        that differ and the extra inputs (each would stay unconnected), and how many more there are.
    """
    have = {p.name: p for p in ports}
    wanted = [v for v in expected if v.causality != "parameter"]
    names = {v.name for v in wanted}
    lanes = {v.name for v in wanted if lane_of(v.name)}
    if component == "receiver" and not lanes & set(have):
        # a receiver without the later lanes of a delivery: allowed (a run refuses to leave a packet on them unused)
        wanted = [v for v in wanted if v.name not in lanes]
    if component == "receiver":  # an output added after a user's FMU was written: checked where it has it
        wanted = [v for v in wanted if v.name not in OPTIONAL_OUTPUTS or v.name in have]
    problems = []
    for v in wanted:
        p = have.get(v.name)
        if p is None:
            problems.append(f"missing {v.causality} {v.name!r} ({v.type}{', ' + v.unit if v.unit else ''})")
            continue
        for field in ("causality", "type", "unit"):
            got, exp = getattr(p, field) or "", getattr(v, field)
            if got != exp:
                problems.append(f"{v.name!r} has {field} {got!r}, expected {exp!r}")
    problems += [f"extra input {p.name!r}" for p in ports if p.causality == "input" and p.name not in names]
    if problems:
        more = len(problems) - SHOWN_PROBLEMS
        raise ConnectionMismatch(f"{component}: {where} does not match the {component} interface: "
                                 + "; ".join(problems[:SHOWN_PROBLEMS])
                                 + (f"; ... and {more} more ({len(problems)} in all)" if more > 0 else ""))


def execution_order(components: Sequence[str], connections: Sequence[Connection]) -> list[str]:
    """Gauss-Seidel order: a topological order of the connection graph (ties keep ``components`` order).

    Raises
    ------
    ConnectionMismatch
        If the connections form an algebraic loop.
    """
    deps = {c: {k.source for k in connections if k.destination == c and k.source != c} for c in components}
    order: list[str] = []
    while len(order) < len(components):
        ready = [c for c in components if c not in order and deps[c] <= set(order)]
        if not ready:
            raise ConnectionMismatch("connections: algebraic loop between " + ", ".join(
                c for c in components if c not in order))
        order.append(ready[0])
    return order

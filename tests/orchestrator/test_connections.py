"""Connection checks against the exposed ports, and the Gauss-Seidel execution order."""

from __future__ import annotations

import pytest

from sblsim.models import COMPONENTS
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.connections import Connection, check_connections, default_connections, execution_order
from sblsim.orchestrator.cosim.engines import make_handles
from sblsim.orchestrator.cosim.handles import Port
from sblsim.orchestrator.cosim.local_engine import LocalHandle
from sblsim.orchestrator.cosim.run import run


@pytest.fixture
def interfaces() -> dict[str, list[Port]]:
    return {name: list(h.ports) for name, h in make_handles("local").items()}


def replace_port(ports: list[Port], name: str, **changes) -> list[Port]:
    assert any(p.name == name for p in ports), name
    return [p._replace(**changes) if p.name == name else p for p in ports]


def test_default_connections_pass_on_local_ports(interfaces):
    check_connections(default_connections(), interfaces)  # raises on any mismatch


def test_default_connections_feed_every_input_exactly_once(interfaces):
    """Independent check of what check_connections accepts: each declared input has one source."""
    conns = default_connections()
    inputs = {(c, p.name) for c, ports in interfaces.items() for p in ports if p.causality == "input"}
    fed = [(k.destination, k.input) for k in conns]
    assert sorted(fed) == sorted(inputs)
    by_name = {c: {p.name: p for p in ports} for c, ports in interfaces.items()}
    for k in conns:
        out, inp = by_name[k.source][k.output], by_name[k.destination][k.input]
        assert out.causality == "output" and (out.type, out.unit) == (inp.type, inp.unit), str(k)


def test_default_connections_pass_on_fmu_ports(fmu_dir):
    """The ports read from the built FMUs' model descriptions (no instantiation) pass the checks too."""
    from fmpy import read_model_description

    from sblsim.fmus.build import fmu_path

    fmu_ports = {}
    for name in COMPONENTS:
        md = read_model_description(str(fmu_path(fmu_dir, name)), validate=False)
        fmu_ports[name] = [Port(v.name, v.causality, v.type, v.unit or "") for v in md.modelVariables]
    check_connections(default_connections(), fmu_ports)
    local = {name: set(LocalHandle(name).ports) for name in COMPONENTS}
    assert {name: set(ports) for name, ports in fmu_ports.items()} == local


def _raises(interfaces, connections=None) -> str:
    with pytest.raises(ModelError) as info:
        check_connections(default_connections() if connections is None else connections, interfaces)
    return str(info.value)


def test_missing_variable(interfaces):
    interfaces["receiver"] = [p for p in interfaces["receiver"] if p.name != "range"]
    message = _raises(interfaces)
    assert "'range'" in message and "receiver" in message


def test_missing_output_variable(interfaces):
    interfaces["target"] = [p for p in interfaces["target"] if p.name != "depth_measured"]
    message = _raises(interfaces)
    assert "'depth_measured'" in message and "target" in message


def test_wrong_causality(interfaces):
    interfaces["acoustics"] = replace_port(interfaces["acoustics"], "range", causality="parameter")
    message = _raises(interfaces)
    assert "acoustics.range" in message and "causality" in message and "expected output" in message


def test_wrong_causality_on_input_side(interfaces):
    interfaces["receiver"] = replace_port(interfaces["receiver"], "depth", causality="output")
    message = _raises(interfaces)
    assert "receiver.depth" in message and "expected input" in message


def test_unit_mismatch(interfaces):
    interfaces["receiver"] = replace_port(interfaces["receiver"], "range", unit="s")
    message = _raises(interfaces)
    assert "receiver.range" in message and "unit" in message and "'m'" in message and "'s'" in message


def test_type_mismatch(interfaces):
    interfaces["receiver"] = replace_port(interfaces["receiver"], "beacon_id", type="Real", unit="1")
    message = _raises(interfaces)
    assert "beacon_id" in message and "type" in message and "Integer" in message and "Real" in message


def test_unconnected_input(interfaces):
    interfaces["receiver"] = interfaces["receiver"] + [Port("sound_speed", "input", "Real", "m/s")]
    message = _raises(interfaces)
    assert "receiver.sound_speed" in message and "not connected" in message


def test_input_fed_twice(interfaces):
    conns = default_connections() + [Connection("target", "pos_z", "receiver", "depth")]
    message = _raises(interfaces, conns)
    assert "receiver.depth" in message and "already fed" in message


def test_unknown_component(interfaces):
    conns = default_connections() + [Connection("sonar", "x", "receiver", "depth")]
    assert "'sonar'" in _raises(interfaces, conns)


def test_run_checks_connections_before_stepping():
    """A handle exposing a port that does not match stops the run with the variable named."""
    handles = make_handles("local")
    handles["receiver"].ports = replace_port(handles["receiver"].ports, "tx_time", unit="m")
    cfg = load_config("semicircle", ["simulation.duration=1"])
    with pytest.raises(ModelError, match="tx_time"):
        run(cfg, "local", handles=handles)
    assert handles["receiver"].batch is None  # nothing was set up


# --------------------------------------------------------------------------- execution order

@pytest.mark.parametrize("components", [
    list(COMPONENTS),
    list(reversed(COMPONENTS)),
    ["receiver", "acoustics", "platform", "target"],
])
def test_execution_order(components):
    order = execution_order(components, default_connections())
    assert sorted(order) == sorted(components)
    pos = {c: i for i, c in enumerate(order)}
    assert pos["platform"] < pos["acoustics"]
    assert pos["target"] < pos["acoustics"]
    assert pos["acoustics"] < pos["receiver"]
    # every connection goes forward in the order
    for k in default_connections():
        assert pos[k.source] < pos[k.destination], str(k)


def test_execution_order_ties_keep_given_order():
    assert execution_order(list(COMPONENTS), default_connections())[:2] == ["platform", "target"]
    assert execution_order(["target", "platform", "acoustics", "receiver"],
                           default_connections())[:2] == ["target", "platform"]


def test_algebraic_loop_raises():
    conns = default_connections() + [Connection("receiver", "est_x", "platform", "feedback")]
    with pytest.raises(ModelError, match="algebraic loop") as info:
        execution_order(list(COMPONENTS), conns)
    for name in ("platform", "acoustics", "receiver"):
        assert name in str(info.value)


def test_two_component_loop_raises():
    conns = [Connection("a", "y", "b", "u"), Connection("b", "y", "a", "u")]
    with pytest.raises(ModelError, match="algebraic loop"):
        execution_order(["a", "b"], conns)
    assert execution_order(["a", "b"], conns[:1]) == ["a", "b"]
    assert execution_order(["a", "b"], conns[1:]) == ["b", "a"]

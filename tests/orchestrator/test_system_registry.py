"""Every system-specific table is reached through the registry (``sblsim.models.systems.SYSTEMS``): take a system
out of it, or change what its object says, and the command line, the compare defaults, the run's time series, the
replay log, the map and the components' interfaces follow; no other module names a system.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from sblsim.fmus import contract
from sblsim.models import component
from sblsim.models.platform.core import Platform
from sblsim.models.systems import SYSTEMS, System, interface_system
from sblsim.orchestrator import cli
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run
from sblsim.orchestrator.cosim.systems import describe_defaults, parse_systems, system_overrides
from sblsim.orchestrator.logs.log_export import log_frames
from sblsim.orchestrator.maps import system_line

ROOT = Path(__file__).resolve().parents[2]
#: Where a system may be named: its own module (and the registry, which names none).
SYSTEM_MODULES = {ROOT / "models" / "systems" / f"{name}.py" for name in ("sbl", "lbl", "usbl", "ilbl")}


def _clear_caches() -> None:
    """Forget what was derived from the registry (the declarations' choices, the programs, the C contract)."""
    for cached in (component._config_parameters, component._by_causality, component._fmu_variables,
                   component._program, contract.contract_tables, contract.contract_header):
        cached.cache_clear()


@pytest.fixture
def without_lbl():
    """The registry without LBL, restored after the test in its order (the platform's ``system`` choices, hence
    the codes the FMUs encode, are the registry's order), with nothing derived from it while LBL was out kept."""
    saved = dict(SYSTEMS)
    _clear_caches()
    del SYSTEMS["lbl"]
    try:
        yield
    finally:
        SYSTEMS.clear()
        SYSTEMS.update(saved)
        _clear_caches()


def test_the_registry_lists_the_systems_in_the_order_of_their_codes():
    assert list(SYSTEMS) == ["sbl", "lbl", "usbl", "ilbl"]
    assert [s.code for s in SYSTEMS.values()] == [0, 1, 2, 3]
    assert all(isinstance(s, System) and s.name == name for name, s in SYSTEMS.items())
    # the platform's system parameter is the registry, in order (the FMUs encode a choice by its index)
    choice = next(v for v in Platform.variables(4) if v.name == "system")
    assert choice.choices == tuple(SYSTEMS)


def test_compare_refuses_a_system_taken_out_of_the_registry_with_the_registrys_list(without_lbl, capsys):
    with pytest.raises(Exception, match=r"--systems: 'lbl' is not one of sbl, usbl, ilbl$"):
        parse_systems("sbl,lbl")
    status = cli.main(["compare", "semicircle", "--systems", "sbl,lbl", "--replicates", "1", "--out",
                       str(ROOT / "results" / "never_written")])
    assert status == 2
    err = capsys.readouterr().err
    assert err.strip() == "sblsim: error: --systems: 'lbl' is not one of sbl, usbl, ilbl"
    assert not (ROOT / "results" / "never_written").exists()
    # the command line's words come from the registry too
    named = [part.split(":")[0] for part in describe_defaults().split("; ")]
    assert named == ["sbl", "usbl", "ilbl"] and "usbl:" in describe_defaults()
    with pytest.raises(Exception, match="not one of sbl, usbl, ilbl"):
        system_overrides("lbl")


def test_the_command_lines_choices_are_the_registrys(without_lbl, capsys, tmp_path):
    with pytest.raises(SystemExit) as exc:
        cli._parser().parse_args(["codegen", "receiver", "--system", "lbl", "--out", str(tmp_path / "x")])
    assert exc.value.code == 2
    assert "invalid choice: 'lbl' (choose from 'sbl', 'usbl', 'ilbl')" in capsys.readouterr().err


def test_the_compare_defaults_are_the_objects(monkeypatch):
    monkeypatch.setattr(SYSTEMS["lbl"], "compare_defaults", ("platform.layout=circle", "platform.beacons=5",
                                                             "platform.baseline=40"))
    cfg = load_config("semicircle", system_overrides("lbl"))
    assert cfg["platform"]["beacons"] == 5 and cfg["platform"]["baseline"] == 40.0
    assert "platform.beacons=5" in describe_defaults(["lbl"])


def test_the_time_series_and_log_columns_are_the_objects(monkeypatch):
    cfg = load_config("semicircle", ["platform.system=usbl", "simulation.duration=3"], seed=1)
    usbl = SYSTEMS["usbl"]
    full = run(cfg).timeseries
    assert set(usbl.timeseries_columns) <= set(full.columns)
    monkeypatch.setattr(usbl, "timeseries_columns", {"azimuth": "acoustics.azimuth"})
    fewer = run(cfg).timeseries
    assert "azimuth" in fewer.columns and "elevation" not in fewer.columns and "array_roll" not in fewer.columns
    np.testing.assert_array_equal(fewer["azimuth"], full["azimuth"])
    log, _ = log_frames(full, usbl)
    assert {"azimuth_rad", "elevation_rad"} <= set(log.columns)
    monkeypatch.setattr(usbl, "log_columns", {"bearing_rad": "azimuth"})
    log, _ = log_frames(full, usbl)
    assert "bearing_rad" in log.columns and "azimuth_rad" not in log.columns


def test_the_map_title_and_the_interfaces_ask_the_object(monkeypatch):
    cfg = load_config("semicircle", ["platform.system=usbl"])
    monkeypatch.setattr(SYSTEMS["usbl"], "describe", lambda platform: "a transceiver of the test")
    assert system_line(cfg) == "a transceiver of the test"
    assert interface_system(1) is SYSTEMS["usbl"] and interface_system(4) is SYSTEMS["sbl"]
    # the USBL FMUs' own defaults describe a USBL: the platform of the one-transceiver interface starts as one
    assert next(v for v in Platform.variables(1) if v.name == "system").start == "usbl"
    assert next(v for v in Platform.variables(4) if v.name == "system").start == "sbl"


def _string_literals(path: Path) -> set[str]:
    """The string constants of a module, without its docstrings."""
    tree = ast.parse(path.read_text())
    docs = {id(node.body[0].value) for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body
            and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    return {node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs}


@pytest.mark.slow
def test_no_module_outside_the_system_modules_names_a_system():
    """No string constant of the package (docstrings aside) is a system's name, outside the system modules: every
    branch asks the registry."""
    names = set(SYSTEMS)
    offenders = []
    for folder in ("models", "fmus", "orchestrator"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path in SYSTEM_MODULES:
                continue
            named = names & _string_literals(path)
            if named:
                offenders.append(f"{path.relative_to(ROOT)}: {sorted(named)}")
    assert not offenders, offenders

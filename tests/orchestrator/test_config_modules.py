"""The configuration (orchestrator/cosim/config*.py): the sections' keys, the scenario's source and the files it names,
the notes, the overrides, the checks across keys and the resolving, each a module of one job, read bottom up, none a
chapter; every name still importable from ``sblsim.orchestrator.cosim.config`` (ConfigError's home for importers)."""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import sblsim.orchestrator.cosim as cosim
import sblsim.orchestrator.cosim.config as config
from sblsim.models.errors import ConfigError
from tests.module_order import out_of_order, top_level_names
from tests.module_order import sources as module_sources

PACKAGE = "sblsim.orchestrator.cosim"
#: Bottom up: each module imports only the ones before it here (of these).
ORDER = ("config_keys", "config_sources", "config_notes", "config_overrides", "config_checks", "config")
ROOT = Path(cosim.__file__).parent
SOURCES = module_sources(ROOT, ORDER)


def _wrong(sources: dict[str, str]) -> list[tuple[str, str]]:
    """(module, imported) pairs breaking the order: one of ``ORDER`` not before the importer."""
    return out_of_order(sources, ORDER, PACKAGE)


def test_each_module_imports_only_the_modules_before_it():
    assert _wrong(SOURCES) == []


def test_the_order_rule_can_fail():
    bad = dict(SOURCES)
    bad["config_keys"] += f"\nfrom {PACKAGE}.config import resolve\n"
    bad["config_notes"] += f"\nfrom {PACKAGE}.config_checks import turnaround\n"
    assert _wrong(bad) == [("config_keys", f"{PACKAGE}.config"), ("config_notes", f"{PACKAGE}.config_checks")]


@pytest.mark.parametrize("name", ORDER)
def test_no_module_is_a_chapter(name):
    assert len(SOURCES[name].splitlines()) <= 400


def test_each_name_is_defined_once():
    seen: dict[str, str] = {}
    for name in ORDER:
        for defined in top_level_names(SOURCES[name]) - {"__all__"}:
            assert defined not in seen, (defined, seen.get(defined), name)
            seen[defined] = name


def test_config_re_exports_every_public_name_and_configerror():
    """An importer of ``sblsim.orchestrator.cosim.config`` finds every name where it was: the very objects of the
    modules that define them, and ConfigError the models' one."""
    assert config.ConfigError is ConfigError
    for name in ORDER[:-1]:
        module = importlib.import_module(f"{PACKAGE}.{name}")
        public = {n for n in top_level_names(SOURCES[name]) if not n.startswith("_")}
        assert public, name
        assert public <= set(config.__all__), (name, public - set(config.__all__))
        assert all(getattr(config, n) is getattr(module, n) for n in public)


def test_the_resolving_module_reads_and_resolves_only():
    assert top_level_names(SOURCES["config"]) == {"load_config", "load_raw", "resolve", "to_toml", "__all__"}


def test_no_configuration_module_loads_code_or_computes_geometry():
    """As the layering test says of config.py, for each of its modules: a user's receiver is loaded by
    :mod:`~sblsim.orchestrator.cosim.plugins`, the beacons' geometry is model code."""
    for name in ORDER:
        tree = ast.parse(SOURCES[name])
        modules = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        modules |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert not modules & {"importlib.util", "importlib.machinery", "runpy"}, name
        assert "exec_module" not in SOURCES[name] and "spec_from_file_location" not in SOURCES[name]
        assert not top_level_names(SOURCES[name]) & {"beacon_offsets", "beacon_arms", "platform_offsets", "lever_arms"}


def test_a_note_said_by_a_check_reaches_the_command_line():
    """The notes are one list whichever module says them: a site key no detection reads, given by the scenario
    (fixed detection), is noted by the checks and taken through the re-exported collector."""
    cfg = config.load_config("semicircle", ["acoustics.detection=fixed"])
    cfg["acoustics"]["frequency"] = cfg["acoustics"]["frequency"] * 2  # a site key fixed detection does not read
    with config.collected_notes():
        config.check_site_keys([cfg], [], "semicircle")
        notes = config.take_notes()
    assert len(notes) == 1 and "acoustics.frequency" in notes[0] and "no effect" in notes[0]
    with pytest.raises(ConfigError, match=r"acoustics\.frequency: .* has no effect at this site"):
        config.check_site_keys([cfg], ["acoustics.frequency=1000"], "semicircle")

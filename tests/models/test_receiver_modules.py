"""What every receiver shares (models/receiver/): one job per module, read bottom up, none a chapter; ``core`` the
Kalman-type receivers' base alone."""

from __future__ import annotations

from pathlib import Path

import pytest

import sblsim.models.receiver as receiver
from tests.module_order import out_of_order, top_level_names
from tests.module_order import sources as module_sources

PACKAGE = "sblsim.models.receiver"
#: Bottom up: each module imports only the ones before it here (of these; the receivers import any of them).
ORDER = ("interface", "ranging", "packets", "instrument", "pings", "slots", "reacquisition", "core")
ROOT = Path(receiver.__file__).parent
SOURCES = module_sources(ROOT, ORDER)


def _wrong(sources: dict[str, str]) -> list[tuple[str, str]]:
    """(module, imported) pairs breaking the order: one of ``ORDER`` not before the importer, or the orchestrator."""
    return out_of_order(sources, ORDER, PACKAGE, forbidden=("sblsim.orchestrator", "sblsim.fmus"))


def test_each_module_imports_only_the_modules_before_it():
    assert _wrong(SOURCES) == []


def test_the_order_rule_can_fail():
    bad = dict(SOURCES)
    bad["packets"] += f"\nfrom {PACKAGE}.slots import SLOT_SLACK\n"
    bad["interface"] += "\nfrom sblsim.orchestrator.cosim.engines import ENGINES\n"
    assert _wrong(bad) == [("interface", "sblsim.orchestrator.cosim.engines"), ("packets", f"{PACKAGE}.slots")]


@pytest.mark.parametrize("name", ORDER)
def test_no_module_is_a_chapter(name):
    assert len(SOURCES[name].splitlines()) <= 400


def test_every_name_is_defined_once_and_the_questions_have_one_module_each():
    defined = {name: top_level_names(source) - {"__all__"} for name, source in SOURCES.items()}
    seen: dict[str, str] = {}
    for module, names in defined.items():
        for n in names - {"_AXES"}:  # the axis labels: the interface's alone
            assert n not in seen, (n, seen.get(n), module)
            seen[n] = module
    # when a slot falls, what a receiver declares, the base class, an inverted LBL's pings
    assert (seen["slot_due"], seen["receiver_interface"], seen["KalmanReceiver"], seen["ping_anchor"]) == (
        "slots", "interface", "core", "pings")

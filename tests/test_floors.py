"""The picture of the floors on docs/architecture.md (docs/floors.py): every module of the package on a floor, no
import up a floor, and the page's table of the floors the one the code gives now (so the page cannot go stale)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def floors():
    spec = importlib.util.spec_from_file_location("floors", ROOT / "docs" / "floors.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_every_module_is_on_a_floor_and_no_import_goes_up(floors):
    found = floors.modules()
    assert len(found) > 200 and "sblsim" in found and "sblsim.orchestrator.commands.run" in found
    assert {floors.floor_of(name) for name in found} == set(range(len(floors.FLOORS)))
    rooms, arrows = floors.house()
    assert sum(m for floor in rooms.values() for m, _ in floor.values()) == len(found)
    assert {pair: n for pair, n in arrows.items() if pair[1] < pair[0]} == {}
    assert arrows[(floors.floor_of("sblsim.orchestrator.commands.run"), floors.floor_of("sblsim.models"))] > 0


def test_the_floors_can_tell_a_room_and_an_import_up(floors, tmp_path):
    assert floors.floor_of("sblsim.orchestrator.tracks.track") == 2  # the commands' work
    assert floors.floor_of("sblsim.orchestrator.cosim.run") == 3 and floors.floor_of("sblsim.models.bound") == 6
    assert floors.room_of("sblsim.orchestrator.tracks.track", Path("track.py")) == "tracks"
    assert floors.room_of("sblsim.models.bound", Path("bound.py")) == "models/*.py"
    module = tmp_path / "low.py"
    module.write_text("from sblsim.orchestrator.commands import run\nimport sblsim.models.bound\n")
    known = {"sblsim.orchestrator.commands.run": module, "sblsim.models.bound": module, "sblsim.models.low": module}
    assert floors.imports("sblsim.models.low", module, known) == ["sblsim.orchestrator.commands.run",
                                                                   "sblsim.models.bound"]


@pytest.mark.slow
def test_the_page_s_table_of_the_floors_is_the_code_s(floors):
    page = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    block = re.search(r"python docs/floors\.py[^\n]*\n```\n+```text\n(.*?)```", page, flags=re.S)
    assert block, "docs/architecture.md: no ```text block after the block running docs/floors.py"
    assert block.group(1).strip() == floors.table(*floors.house())

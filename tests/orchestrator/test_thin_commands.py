"""Thin commands (issue 89): a module of ``orchestrator/commands/`` reads its arguments, calls the library and prints,
so none grows past :data:`LIMIT` lines; the tracking's functions and results are the tracking room's
(``orchestrator/tracks/``), re-exported by the public API."""

from __future__ import annotations

from pathlib import Path

import pytest

import sblsim
import sblsim.orchestrator.commands
from tests.module_order import longer_than

#: The most lines a command's module may have.
LIMIT = 300
#: The modules not yet thinned to :data:`LIMIT`, each held to the lines it has (none left: every command is thin).
NOT_YET: dict[str, int] = {}


def too_long(folder: Path, limit: int = LIMIT, allowed: dict[str, int] | None = None) -> dict[str, int]:
    """The modules of ``folder`` (it has no subfolders) longer than ``limit`` lines (or than their own cap in
    ``allowed``, default :data:`NOT_YET`): name -> lines."""
    return longer_than(folder, limit, NOT_YET if allowed is None else allowed)


def test_no_command_module_is_longer_than_the_limit():
    folder = Path(sblsim.orchestrator.commands.__file__).parent
    assert len(list(folder.glob("*.py"))) >= 15  # the commands are found
    assert too_long(folder) == {}
    assert set(NOT_YET) <= {path.name for path in folder.glob("*.py")}  # no cap left for a module gone


def test_the_line_limit_can_fail(tmp_path):
    (tmp_path / "short.py").write_text("x = 1\n" * LIMIT)
    (tmp_path / "long.py").write_text("x = 1\n" * (LIMIT + 1))
    (tmp_path / "capped.py").write_text("x = 1\n" * (LIMIT + 20))
    assert too_long(tmp_path, allowed={"capped.py": LIMIT + 20}) == {"long.py": LIMIT + 1}
    assert too_long(tmp_path, allowed={}) == {"long.py": LIMIT + 1, "capped.py": LIMIT + 20}


@pytest.mark.parametrize("name, home", [("replay_toa", "sblsim.orchestrator.tracks.replay"),
                                        ("TrackResult", "sblsim.orchestrator.tracks.replay"),
                                        ("replay_toa_tags", "sblsim.orchestrator.tracks.many"),
                                        ("TagsResult", "sblsim.orchestrator.tracks.many")])
def test_the_tracking_s_public_names_are_the_tracking_room_s(name, home):
    assert getattr(sblsim, name).__module__ == home

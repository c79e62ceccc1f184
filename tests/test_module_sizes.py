"""The house (issue 89): no module of the package above :data:`LIMIT` lines, and no loose work module in the
orchestrator's root, so that a reader looking for one job opens a module of one job.

The generated code is C, written at build time (``fmus/codegen.py``), so the limit holds for every ``.py`` file the
package installs; the commands' own, lower cap is ``tests/orchestrator/test_thin_commands.py``'s.
"""

from __future__ import annotations

from pathlib import Path

import sblsim.fmus
import sblsim.models
import sblsim.orchestrator
from tests.module_order import longer_than

#: The most lines a module of the package may have (its docstring included).
LIMIT = 500
#: The modules the orchestrator's root may hold: the API, the command line, the package marker; all work is in rooms.
ROOT_MODULES = {"__init__.py", "api.py", "cli.py"}
FOLDERS = [Path(package.__file__).parent for package in (sblsim.models, sblsim.orchestrator, sblsim.fmus)]


def test_no_module_of_the_package_is_longer_than_the_limit():
    assert sum(len(list(folder.rglob("*.py"))) for folder in FOLDERS) > 200  # the package's modules are found
    assert {folder.name: longer_than(folder, LIMIT) for folder in FOLDERS} == {folder.name: {} for folder in FOLDERS}


def test_the_orchestrator_s_root_holds_no_work_module():
    root = Path(sblsim.orchestrator.__file__).parent
    assert {path.name for path in root.glob("*.py")} <= ROOT_MODULES


def test_the_limit_can_fail(tmp_path):
    (tmp_path / "room").mkdir()
    (tmp_path / "room" / "short.py").write_text("x = 1\n" * LIMIT)
    (tmp_path / "room" / "long.py").write_text("x = 1\n" * (LIMIT + 1))
    assert longer_than(tmp_path, LIMIT) == {str(Path("room") / "long.py"): LIMIT + 1}

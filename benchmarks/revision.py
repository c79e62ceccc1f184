"""Run a snippet of Python in an earlier git revision of this repository (a temporary worktree).

Used by the benchmarks to time an earlier engine in the same run as today's. Snippets import the
package by its installed names (``sblsim.orchestrator``, ...). The revision's own folders are put
first on the path under those names, so the snippet runs the revision's code, not this checkout's;
for revisions from before the ``sblsim`` namespace, the snippet's ``sblsim.`` prefixes are dropped
(their folders were imported as top-level ``models``, ``orchestrator`` and ``fmus``).
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("models", "orchestrator", "fmus")


@contextlib.contextmanager
def checkout(revision: str) -> Iterator[Callable[..., str]]:
    """A temporary worktree of ``revision`` for as long as the context lasts; yields ``run(code, *args,
    wrapper=())``, which runs ``code`` there (its own modules first; under the command ``wrapper`` when given, e.g.
    a profiler's) and returns its stdout.

    Raises
    ------
    subprocess.CalledProcessError
        If the checkout or a snippet fails.
    """
    with tempfile.TemporaryDirectory(prefix="sblsim_old_") as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), revision], check=True,
                       capture_output=True)
        try:
            namespaced = "sblsim.models" in (tree / "pyproject.toml").read_text()
            if namespaced:
                shim = Path(tmp) / "shim"
                (shim / "sblsim").mkdir(parents=True)
                for name in PACKAGES:
                    (shim / "sblsim" / name).symlink_to(tree / name, target_is_directory=True)
                path = str(shim)
            else:
                path = str(tree)
            env = {**os.environ, "PYTHONPATH": path}

            def run(code: str, *args: str, wrapper: Sequence[str] = ()) -> str:
                if not namespaced:
                    code = code.replace("sblsim.", "")
                done = subprocess.run([*wrapper, sys.executable, "-c", code, *args], cwd=tree, env=env,
                                      capture_output=True, text=True, check=True)
                return done.stdout

            yield run
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], capture_output=True)


def run_at(revision: str, code: str, *args: str) -> str:
    """Run ``code`` with ``args`` in a checkout of ``revision`` (its own modules first); return its stdout.

    Raises
    ------
    subprocess.CalledProcessError
        If the checkout or the snippet fails.
    """
    with checkout(revision) as run:
        return run(code, *args)

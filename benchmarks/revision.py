"""Run a snippet of Python in an earlier git revision of this repository (a temporary worktree).

Used by the benchmarks to time an earlier engine in the same run as today's.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_at(revision: str, code: str, *args: str) -> str:
    """Run ``code`` with ``args`` in a checkout of ``revision`` (its own modules first); return its stdout.

    Raises
    ------
    subprocess.CalledProcessError
        If the checkout or the snippet fails.
    """
    with tempfile.TemporaryDirectory(prefix="sblsim_old_") as tmp:
        tree = Path(tmp) / "tree"
        subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), revision], check=True,
                       capture_output=True)
        try:
            env = {**os.environ, "PYTHONPATH": str(tree)}
            done = subprocess.run([sys.executable, "-c", code, *args], cwd=tree, env=env, capture_output=True,
                                  text=True, check=True)
            return done.stdout
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], capture_output=True)

"""``sblsim report DIR``: a telemetry study's report (``report.html``: one self-contained page, opened offline)
written again into a study's folder from its files, for a study already run (every ``sblsim track`` writes it):
:mod:`sblsim.orchestrator.telemetry.report`.
"""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "report"
HELP = "write a telemetry study's report (report.html, one page opened offline) into its folder from its files"


def report(folder: str | Path) -> Path:
    """A study's report written into its folder (``sblsim report DIR``).

    Parameters
    ----------
    folder : str or Path
        The study's folder (``sblsim track --out DIR``).

    Returns
    -------
    Path
        ``report.html`` in ``folder``.

    Raises
    ------
    ModelError
        One line: not a study's folder, one of its files refused (a file that leaves the folder, too large, not as
        ``sblsim track`` writes it), or a ``report.html`` there that sblsim did not write.
    """
    from sblsim.orchestrator.telemetry.report.page import write_report  # pandas and matplotlib: loaded here

    return write_report(Path(folder), "DIR")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sblsim report``'s arguments."""
    p.add_argument("folder", type=Path, metavar="DIR",
                   help="a study's folder (sblsim track --out DIR): its report.html is written there, replacing "
                        "the one an earlier sblsim wrote")


def main(args: argparse.Namespace) -> int:
    """``sblsim report`` from its parsed arguments: its line printed, its exit status returned."""
    path = report(args.folder)
    print(f"wrote {path} ({path.stat().st_size / 2**20:.1f} MiB): open it in a browser, no network needed")
    return 0


__all__ = ["report"]

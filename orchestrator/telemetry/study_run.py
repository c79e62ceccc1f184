"""A telemetry study run for ``sblsim track`` and :func:`sblsim.track`: into its folder, all or nothing (staged; a
temporary folder where none is asked for; the tags finished by an interrupted run of that folder kept:
:mod:`~sblsim.orchestrator.tracks.resume`), its progress reported (a bar as the tags end, and on the console the
study's opening lines: :mod:`.study_report`).
"""

from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Any

from sblsim.orchestrator.cosim.config import ConfigError
from sblsim.orchestrator.io.output import staged_directory
from sblsim.orchestrator.io.progress import ProgressSpec, progress_of
from sblsim.orchestrator.telemetry.study_report import opening_lines
from sblsim.orchestrator.tracks.resume import Resume


def _run(detections: Path, receivers: Path, tags: Path | None, sync: Path | None, options: dict[str, Any],
         target: Path | None, progress: ProgressSpec, lines: bool = False):
    """The study run into ``target`` (all or nothing; a temporary folder where None), its progress reported.

    Raises
    ------
    ConfigError
        ``refine_positions`` with a synchronisation's folder given (``sync``), before any work: the refinement
        synchronises the clocks again on the positions it refines, round by round, and a folder's clocks are fixed
        (its refined positions would also stand in place of the study's).
    """
    if sync is not None and options.get("refine_positions"):
        raise ConfigError("--refine-positions: not with --sync (a synchronisation's folder given): the refinement "
                          "synchronises the clocks again on the positions it refines, and a folder's clocks are "
                          "fixed; allowed: one or the other (sblsim sync --refine-positions refines the positions "
                          "with the clocks, and its folder given as --sync carries them and their errors)")
    from sblsim.orchestrator.telemetry.outputs import write_study
    from sblsim.orchestrator.telemetry.study import run_study

    bar: list[Any] = []

    def started(folders: list[str], summary: dict[str, Any]) -> None:
        if bar:  # the study made again (its positions refined): a bar of its own, the opening lines said once
            bar.pop().close()
            bar.append(progress_of(progress, len(folders), "tracking again", "tag")[0])
            return
        if lines:
            for line in opening_lines(detections, summary, len(folders), options):
                print(line, flush=True)
        bar.append(progress_of(progress, len(folders), "tracking", "tag")[0])

    def ended(row: dict[str, Any]) -> None:
        if bar:
            bar[0].update(1)

    try:
        if target is None:
            with tempfile.TemporaryDirectory(prefix="sblsim-study-") as tmp:
                return run_study(detections, receivers, tags, workdir=Path(tmp), sync=sync, started=started,
                                 ended=ended, **options)
        resume = Resume(target)  # the tags of an interrupted run of this output, each tag kept as it ends
        with staged_directory(target) as tmp:
            outcome = run_study(detections, receivers, tags, workdir=tmp, sync=sync, started=started, ended=ended,
                                resume=resume, write_tags=True, **options)
            if bar:
                bar[0].close()
            write_study(outcome, tmp)
        resume.remove()
        return outcome
    finally:
        if bar:
            bar[0].close()

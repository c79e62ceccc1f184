"""A study's report: ``report.html``, one self-contained page a telemetry user opens offline (``sblsim report DIR``,
and every ``sblsim track``).

The page is rendered by Jinja2 from the package's template (``templates/report.html.j2``, autoescaped: every text a
file holds is shown as text) with the values of :func:`~.context.page_context`; its figures are inline PNGs, its
style inline, it runs no script and names no other file or address (it opens from a USB stick on a boat, with no
network). A study of a hundred tags is one page of a few megabytes: a table of the tags linked to each tag's section.
"""

from __future__ import annotations

import time
from pathlib import Path

import jinja2

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.manifest import refuse_foreign, write_manifest
from sblsim.orchestrator.io.output import write_atomic
from sblsim.orchestrator.io.times import iso_utc
from sblsim.orchestrator.io.version import installed_version
from sblsim.orchestrator.telemetry.report.context import page_context
from sblsim.orchestrator.telemetry.report.daily import write_daily
from sblsim.orchestrator.telemetry.report.folder import StudyFolder, read_folder

#: The report's file in a study's folder.
REPORT_FILE = "report.html"
#: The size a report keeps within [bytes] (a study of 100 tags: 2.8 MiB; the tags drawn are capped:
#: :data:`~.context.MAX_TAG_FIGURES`), checked by the browser tests; never a reason to lose a study's files.
MAX_REPORT_BYTES = 20 * 2**20
TEMPLATE = "report.html.j2"


def _environment() -> jinja2.Environment:
    """Jinja2 with the package's templates, every value escaped, undefined values refused."""
    return jinja2.Environment(loader=jinja2.FileSystemLoader(Path(__file__).parent / "templates"),
                              autoescape=True, undefined=jinja2.StrictUndefined, trim_blocks=True,
                              lstrip_blocks=True)


def render(study: StudyFolder, generated: float | None = None) -> str:
    """The report's HTML for a study's folder as read (:func:`~.folder.read_folder`).

    Parameters
    ----------
    study : StudyFolder
    generated : float, optional
        [s since 1970 UTC] the time the page says it was made (default now).

    Returns
    -------
    str

    Raises
    ------
    ModelError
        ``study.json`` not a study's summary as ``sblsim track`` writes it (a value of another type; one line).
    """
    try:
        values = page_context(study)
    except (TypeError, AttributeError, KeyError) as exc:  # a value of another type than sblsim writes
        raise ModelError(f"report: {study.name!r}: its files are not a study as sblsim track writes them "
                         f"({type(exc).__name__}: {str(exc)[:120]}); allowed: a study's folder (sblsim track "
                         "--out)") from None
    when = iso_utc([time.time() if generated is None else generated])[0][:19] + "Z"
    return _environment().get_template(TEMPLATE).render(**values, generated=when, version=installed_version())


def report_bytes(folder: Path | str, label: str | None = None) -> bytes:
    """The report of a study's folder (read by :func:`~.folder.read_folder`, rendered by :func:`render`) as UTF-8.

    Raises
    ------
    ModelError
        One line: not a study's folder, or a file of it refused.
    """
    return render(read_folder(folder, label)).encode("utf-8")


def write_report(folder: Path | str, where: str = "DIR") -> Path:
    """``report.html`` in a study's folder (:func:`report_bytes`), replacing an earlier report sblsim wrote, never a
    file of that name it did not (:mod:`sblsim.orchestrator.io.manifest`); its path.

    Parameters
    ----------
    folder : Path or str
        The study's folder (``sblsim track --out``), as the caller gave it (refusals name it).
    where : str
        The argument that names the folder, for a refusal.

    Raises
    ------
    ModelError
        One line: :func:`report_bytes`'s refusals, or a ``report.html`` there that sblsim did not write.
    """
    folder = Path(folder)
    if folder.is_dir():  # refused before the work
        refuse_foreign(folder, [REPORT_FILE], where)
    data = report_bytes(folder)
    write_atomic(folder / REPORT_FILE, lambda path: path.write_bytes(data))
    write_manifest(folder, [REPORT_FILE])
    return folder / REPORT_FILE


def study_report(outcome, folder: Path) -> None:
    """A study's report as ``sblsim track`` writes it, into the folder being staged (its other files there):
    ``detections_daily.csv`` from the study's outcome, then ``report.html`` from the folder's files."""
    write_daily(outcome.daily, folder)
    (folder / REPORT_FILE).write_bytes(report_bytes(folder, "the study"))


__all__ = ["MAX_REPORT_BYTES", "REPORT_FILE", "render", "report_bytes", "study_report", "write_report"]

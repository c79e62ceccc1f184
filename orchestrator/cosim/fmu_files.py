"""An FMU file before it is stepped: where the FMU of each component is (:func:`fmu_paths`), its model description
read and checked (:func:`read_description`, once per file and again when it changes), its String choices as their
indices, and the FMI 2.0 status of a call (:func:`check_status`).
"""

from __future__ import annotations

import os
import zipfile
from functools import lru_cache
from pathlib import Path
from typing import Any

from sblsim.fmus.build import DEFAULT_DIR, beacons_dir, cached_fmu, fmu_path, version_dir
from sblsim.models import MODELS
from sblsim.models.declarations import ModelError
from sblsim.models.errors import FMICallError, SblsimError
from sblsim.orchestrator.cosim.handles import Port, Source, paper_sources
from sblsim.orchestrator.io.archives import check_members

#: Beacons of the FMUs ``sblsim fmus build`` writes by default (other numbers: a folder per number, or the cache).
FMU_BEACONS = 4
#: The FMI 2.0 status values (``fmi2Status``) by number.
FMI2_STATUS = ("fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending")
#: The last status that is not a failure, and the one before it.
FMI2_OK, FMI2_WARNING = 0, 1
#: Log messages an FMU handle keeps (the latest explains a refused call).
LOG_LINES = 20


def check_status(status: int, function: str, where: str, reason: str = "") -> None:
    """Raise if an FMI 2.0 function's status is a failure (above ``fmi2Warning``, as fmpy's checked calls).

    Parameters
    ----------
    status : int
        What the function returned.
    function : str
        Its name, e.g. ``fmi2DoStep``.
    where : str
        The FMU file and component instance, for the message.
    reason : str
        What the FMU logged about it (empty: it logged nothing we kept).

    Raises
    ------
    FMICallError
        E.g. ``fmu: receiver.fmu (receiver): fmi2DoStep returned fmi2Error (3): <the FMU's message>`` (its
        ``function``, ``status`` and ``log`` as given).
    """
    if status > FMI2_WARNING:
        name = FMI2_STATUS[status] if 0 <= status < len(FMI2_STATUS) else "an unknown status"
        raise FMICallError(f"fmu: {where}: {function} returned {name} ({status}): "
                           f"{reason or 'the FMU logged no reason'}", function, status, reason)


def one_line(text: str, limit: int = 400) -> str:
    """A message on one line (blanks and line breaks collapsed), shortened past ``limit`` characters."""
    text = " ".join(text.split())
    return text if len(text) <= limit else text[:limit] + " ..."


def read_description(component: str, path: Path, versions: tuple[str, ...] = ("2.0",)) -> Any:
    """The model description of an FMI 2.0 (or, in ``versions``, 3.0) Co-Simulation FMU.

    Raises
    ------
    ModelError
        If the file is missing or unreadable, not Co-Simulation of one of ``versions``, or an archive that is not
        safe to unpack (:func:`sblsim.orchestrator.io.archives.check_members`: checked before its description is
        read).
    """
    from fmpy import read_model_description

    if path.is_dir():
        raise ModelError(f"fmu: {str(path)!r} is a directory, not an FMU file")
    if not path.is_file():
        raise ModelError(f"fmu: {component} FMU not found at {str(path)!r}; build it with `sblsim fmus build`")
    try:
        with zipfile.ZipFile(path) as archive:
            check_members(archive, f"fmu: {path.name} ({component})")
        md = read_model_description(str(path), validate=False)
    except SblsimError:  # an ArchiveError of check_members
        raise
    except Exception as exc:  # fmpy raises plain exceptions on unreadable archives
        raise ModelError(f"fmu: {str(path)!r} is not a readable FMU ({exc})") from None
    if md.fmiVersion not in versions or md.coSimulation is None:
        raise ModelError(f"fmu: {str(path)!r} must be an FMI {' or '.join(versions)} Co-Simulation FMU")
    return md


def fmu_ports(component: str, path: Path | str) -> list[Port]:
    """An FMU's variables as :class:`~sblsim.orchestrator.cosim.handles.Port` records, read without loading it.

    Raises
    ------
    ModelError
        As :func:`read_description`.
    """
    return _ports(read_description(component, Path(path)))


def _ports(md: Any) -> list[Port]:
    return [Port(v.name, v.causality, v.type, v.unit or "") for v in md.modelVariables]


#: Model descriptions read in this process, by file and FMI versions allowed: (file signature, description).
_DESCRIPTIONS: dict[tuple[str, tuple[str, ...]], tuple[tuple, Any]] = {}


def _description(component: str, path: Path, resolved: Path, versions: tuple[str, ...]
                 ) -> tuple[Any, os.stat_result]:
    """:func:`read_description` of a file (``path`` as given, ``resolved`` its resolved path), read again only when
    the file has changed (its size, modification time or inode) since this process last read it (a pooled instance
    is reopened for every run), and its ``stat``."""
    key = (str(resolved), versions)
    try:
        stat = resolved.stat()
    except OSError:  # read_description names what is wrong
        stat = None
    cached = _DESCRIPTIONS.get(key)
    if stat is not None and cached is not None and cached[0] == (stat.st_size, stat.st_mtime_ns, stat.st_ino):
        return cached[1], stat
    md = read_description(component, path, versions)
    stat = resolved.stat()
    _DESCRIPTIONS[key] = ((stat.st_size, stat.st_mtime_ns, stat.st_ino), md)
    return md, stat


@lru_cache(maxsize=None)
def _choice_index(name: str, value: str) -> int:
    """The index of ``value`` among the choices sblsim's models declare for the String parameter ``name`` (the
    FMUs take a choice as its index).

    Raises
    ------
    ModelError
        When no model declares ``value`` as a choice of ``name``.
    """
    for model in MODELS.values():
        for variable in model.fmu_parameters_declared(1):
            if variable.name == name and variable.choices is not None and value in variable.choices:
                return variable.choices.index(value)
    raise ModelError(f"fmu: parameter {name!r} is an Integer; the value {value!r} is none of its choices")


def fmu_paths(fmu_dir: Path | str | None = None, sources: dict[str, Source] | None = None,
              n_beacons: int = FMU_BEACONS, fmi_version: int = 2) -> dict[str, Path]:
    """The FMU file of every component: built ones in ``fmu_dir``, a user's FMU, or a model built into the
    cache (:func:`sblsim.fmus.build.cached_fmu`).

    Without ``fmu_dir``, a built-in model's FMU is the one ``sblsim fmus build`` wrote into
    :data:`sblsim.fmus.build.DEFAULT_DIR` (:func:`sblsim.fmus.build.beacons_dir` for the number of beacons)
    when it is there, else it is built once into the user's cache and reused: the ``fmu`` engine runs
    every configuration out of the box, and writes nothing into the installed package. With ``fmu_dir``, the
    paper's 4-beacon FMUs must be there (a folder given is a folder meant); another number of beacons is
    built into the cache when that folder does not hold it. FMI 3.0 (``fmi_version`` 3): the same, in the
    folders' ``fmi3`` folder (:func:`sblsim.fmus.build.version_dir`).

    Raises
    ------
    ModelError
        If an FMU is missing.
    CompileError
        If an FMU must be built and the compiler is missing or fails.
    """
    directory = version_dir(beacons_dir(Path(fmu_dir) if fmu_dir is not None else DEFAULT_DIR, n_beacons),
                            fmi_version)
    sources = sources if sources is not None else paper_sources()
    paths = {}
    for name, src in sources.items():
        if isinstance(src, Path):
            paths[name] = src
        elif isinstance(src, type):
            paths[name] = cached_fmu(src, n_beacons, fmi_version)
        else:
            built = fmu_path(directory, src)
            given = fmu_dir is not None and n_beacons == FMU_BEACONS
            paths[name] = built if built.is_file() or given else cached_fmu(MODELS[src], n_beacons, fmi_version)
    for name, path in paths.items():
        if not path.is_file():
            raise ModelError(f"fmu: {name} FMU not found at {str(path)!r}; build it with `sblsim fmus build"
                             f"{' --fmi-version 3' if fmi_version == 3 else ''}`")
    return paths

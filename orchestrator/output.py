"""Writing results safely: everything into a staging folder, moved into place only when complete."""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator

from sblsim.models.declarations import ModelError


def write_atomic(path: Path | str, write: Callable[[Path], object]) -> None:
    """Write one file through a temporary file in its folder, moved into place when ``write(temporary)``
    returns; if it raises, ``path`` is left as it was and the temporary file is removed."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def staged_directory(out: Path | str) -> Iterator[Path]:
    """A staging folder beside ``out`` whose files replace those of the same name in ``out`` on success.

    Files of ``out`` with other names are kept. If the body raises, nothing
    in ``out`` changes (a new ``out`` is not even created) and the staging
    folder is removed. The staging folder's name holds this process's id,
    so that the folders of a killed process are found and removed the next
    time (:func:`remove_stale`).

    Yields
    ------
    Path
        The staging folder to write into.
    """
    out = Path(out).absolute()
    out.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(out)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.{os.getpid()}.", dir=out.parent))
    try:
        yield tmp
        out.mkdir(exist_ok=True)
        for item in list(tmp.iterdir()):
            target = out / item.name
            if item.is_dir() and target.is_dir():  # os.replace cannot overwrite a non-empty directory
                os.replace(target, tmp / f".old.{item.name}")
            os.replace(item, target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def remove_stale(out: Path) -> list[Path]:
    """Remove the staging folders of ``out`` that a killed process left behind (their process is gone)."""
    removed = []
    for folder in out.parent.glob(f".{out.name}.*"):
        parts = folder.name[len(out.name) + 2:].split(".")
        if not folder.is_dir() or not parts[0].isdigit() or _alive(int(parts[0])):
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed.append(folder)
    return removed


def _alive(pid: int) -> bool:
    """Whether a process with this id exists (a pid reused since is taken as alive: its folder stays)."""
    if pid == os.getpid() or os.name == "nt":  # on Windows os.kill(pid, 0) would end the process
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


__all__ = ["remove_stale", "staged_directory"]


def check_output(out: Path, force: bool, marker: str, what: str, where: str = "--out") -> None:
    """Refuse an output directory that cannot be written, or that holds an earlier result (its ``marker``
    file) unless ``force``: before any work.

    Raises
    ------
    ModelError
        Naming ``where`` (the option or argument) and what to do.
    """
    out = Path(out)
    check_writable(out, where)
    if (out / marker).exists() and not force:
        hint = ("add --force to replace it or choose another --out" if where.startswith("--")
                else f"pass force=True to replace it or choose another {where}")
        raise ModelError(f"{where}: {str(out)!r} holds an earlier {what}; {hint}")


def check_writable(directory: Path, where: str = "--out") -> None:
    """Refuse an output directory that cannot be created or written, before any work.

    Checked by doing, not by asking (``os.access`` says yes to root everywhere, even under
    ``/proc``): a probe folder with a probe file is created in the deepest existing folder on the
    way to ``directory`` and removed again, so nothing stays on disk.

    Raises
    ------
    ModelError
        Naming the directory and why.
    """
    directory = Path(directory)
    if directory.exists() and not directory.is_dir():
        raise ModelError(f"{where}: {str(directory)!r} exists and is not a directory")
    probe = directory.absolute()
    while not probe.exists():
        probe = probe.parent
    if not probe.is_dir():
        raise ModelError(f"{where}: {str(directory)!r} cannot be created ({str(probe)!r} is not a directory)")
    try:
        folder = Path(tempfile.mkdtemp(prefix=".sblsim-probe.", dir=probe))
        try:
            (folder / "probe").write_bytes(b"sblsim")
        finally:
            shutil.rmtree(folder, ignore_errors=True)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise ModelError(f"{where}: {str(directory)!r} cannot be written ({reason} in {str(probe)!r})") from None

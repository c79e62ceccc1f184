"""Writing results safely: everything into a staging folder, moved into place only when complete."""

from __future__ import annotations

import errno
import os
import re
import shutil
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterable, Iterator

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.manifest import refuse_foreign, write_manifest

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: OutputLock takes no lock
    fcntl = None


def write_atomic(path: Path | str, write: Callable[[Path], object]) -> None:
    """Write one file through a temporary file in its folder, moved into place when ``write(temporary)``
    returns; if it raises, ``path`` is left as it was and the temporary file is removed.

    The file gets the mode a file created with :func:`open` gets (0666 without the process's umask), like
    the other files of a command, not the private 0600 of :func:`tempfile.mkstemp`.
    """
    write_together({Path(path): write}, parents=False)


def write_together(writers: dict[Path, Callable[[Path], object]], parents: bool = True) -> None:
    """Write several files as one: each through a temporary file in its folder (:func:`write_atomic`'s mode), all
    moved into place only when every one is written; if any write fails, no file is replaced, the temporary files
    are removed and so are the folders made for them (``parents``: the missing folders are made,
    :func:`make_parents`).

    Parameters
    ----------
    writers : dict
        Each file's path -> a function writing it (given the temporary file's path).
    parents : bool
        Make the missing folders above the files (else a missing one is an error).
    """
    created: list[Path] = []
    done: list[tuple[str, Path]] = []
    try:
        for path, write in writers.items():
            path = Path(path)
            if parents:
                created += make_parents(path)
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
            os.close(fd)
            done.append((tmp, path))
            os.chmod(tmp, 0o666 & ~current_umask())  # mkstemp's file is 0600: the mode any other file here has
            write(Path(tmp))
        for tmp, path in done:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in done:
            Path(tmp).unlink(missing_ok=True)
        remove_empty(created)
        raise


def current_umask() -> int:
    """The process's file-mode creation mask: from ``/proc/self/status`` where Linux gives it, else read by
    setting it and setting it back."""
    try:
        with open("/proc/self/status") as handle:
            for line in handle:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: Characters a scenario name keeps in a default output folder's name; any other becomes ``_``.
_NAME_CHARACTERS = re.compile(r"[^A-Za-z0-9._+-]")


def folder_name(name: str, fallback: str = "run") -> str:
    """A scenario name (a configuration file's or an SSP system's ``run.scenario``: anyone's text) as one
    folder name: letters, digits, ``. _ + -`` kept, any other character (``/``, ``\\``, ``:``, spaces, control
    characters) ``_``, leading dots removed, at most 100 characters; ``fallback`` when nothing is left. The
    default output folder ``results/<name>`` therefore always lies inside ``results/``."""
    cleaned = _NAME_CHARACTERS.sub("_", str(name)).lstrip(".")[:100]
    return cleaned or fallback


@contextmanager
def staged_directory(out: Path | str) -> Iterator[Path]:
    """A staging folder beside ``out`` whose files replace those of the same name in ``out`` on success.

    Files of ``out`` with other names are kept; a file of the same name that sblsim did not write (no earlier run's
    own output: :mod:`sblsim.orchestrator.io.manifest`) is never replaced: the whole write is refused before anything
    moves, and the entries moved in are recorded in the folder's manifest. If the body raises, nothing
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
    created = make_parents(out)
    done = False
    try:
        remove_stale(out)
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.{os.getpid()}.", dir=out.parent))
        try:
            yield tmp
            names = [item.name for item in tmp.iterdir()]
            if out.exists():  # never a file sblsim did not write: refused before anything is replaced
                refuse_foreign(out, names, "out")
            out.mkdir(exist_ok=True)
            for item in list(tmp.iterdir()):
                target = out / item.name
                # os.replace cannot overwrite a non-empty directory (a link to one is replaced, not followed)
                if item.is_dir() and target.is_dir() and not target.is_symlink():
                    os.replace(target, tmp / f".old.{item.name}")
                os.replace(item, target)
            write_manifest(out, names)
            done = True
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    finally:
        if not done:
            remove_empty(created)


def make_parents(path: Path) -> list[Path]:
    """Create the missing folders above ``path`` (as ``mkdir -p`` of its parent) and return them, the
    deepest last, so that a command that fails can remove what it created (:func:`remove_empty`).

    A dangling symbolic link on the way is not followed: ``mkdir`` fails on it (``FileExistsError``).
    """
    folder, missing = Path(path).absolute().parent, []
    while not os.path.lexists(folder):
        missing.append(folder)
        folder = folder.parent
    created = []
    try:
        for item in reversed(missing):
            item.mkdir()
            created.append(item)
    except BaseException:
        remove_empty(created)
        raise
    return created


def refuse_link(path: Path, where: str) -> None:
    """Refuse a folder or file that a command would write into or over but that is a symbolic link it was not
    given (e.g. ``chunks/`` inside a campaign directory): writing through it would write where it points.

    Raises
    ------
    ModelError
        Naming ``where`` and the link.
    """
    if os.path.islink(path):
        raise ModelError(f"{where}: {str(path)!r} is a symbolic link; sblsim never writes through a link it was "
                         "not given: remove it (or choose another folder)")


def remove_empty(folders: list[Path]) -> None:
    """Remove the folders :func:`make_parents` created that stayed empty, the deepest first."""
    for item in reversed(folders):
        try:
            item.rmdir()
        except OSError:  # it holds something now (the results): kept
            pass
    folders.clear()


def remove_stale(out: Path) -> list[Path]:
    """Remove the staging folders of ``out`` that a killed process left behind (their process is gone)."""
    removed = []
    for folder in out.parent.glob(f".{out.name}.*"):
        parts = folder.name[len(out.name) + 2:].split(".")
        if folder.is_symlink() or not folder.is_dir() or not parts[0].isdigit() or _alive(int(parts[0])):
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


class OutputLock:
    """An exclusive lock on an output folder while a command writes it (:meth:`acquire`, :meth:`release`).

    The lock is ``fcntl.flock`` on the file ``.<name>.lock`` beside the folder, taken without waiting: a
    second command into the same folder while the first runs is refused (its results would silently replace
    the first's). The lock file is opened without following a symbolic link (``O_NOFOLLOW``: a link of that
    name, dangling or not, would make us create or lock a file where it points, outside the folder the user
    named) and must be a regular file; anything else is refused in one line. The lock file is removed on
    release, and any folder created to hold it when nothing was written into it; the kernel releases the lock
    of a killed process. Where ``fcntl`` does not exist (Windows) no lock is taken.
    """

    def __init__(self, out: Path | str, option: str = "--out") -> None:
        self.out = Path(out).absolute()
        self.path = self.out.parent / f".{self.out.name}.lock"
        self.option = option
        self._fd: int | None = None
        self._created: list[Path] = []

    def acquire(self) -> "OutputLock":
        """Take the lock.

        Raises
        ------
        ModelError
            Naming the option and the folder, when another command holds it, or when the lock file's name is
            a symbolic link or not a regular file.
        """
        if fcntl is None:  # pragma: no cover - Windows
            return self
        self._created = make_parents(self.path)
        while True:
            fd = self._open()
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                self._remove_created()
                raise ModelError(f"{self.option}: {str(self.out)!r} is being written by another sblsim command "
                                 "right now; wait until it ends or choose another folder") from None
            try:  # the holder before may have removed the file between our open and our lock: lock the new one
                same = os.lstat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self._fd = fd
                return self
            os.close(fd)

    def _open(self) -> int:
        """The lock file, created if missing, never through a symbolic link; a regular file only."""
        flags = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0)
        try:
            fd = os.open(self.path, flags, 0o666)
        except OSError as exc:
            if exc.errno != errno.ELOOP and not os.path.islink(self.path):
                raise
            self._remove_created()
            raise ModelError(f"{self.option}: the lock file {str(self.path)!r} beside {str(self.out)!r} is a "
                             "symbolic link; sblsim never creates a file through a link it was not given: remove "
                             "it (or choose another folder)") from None
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            self._remove_created()
            raise ModelError(f"{self.option}: the lock file {str(self.path)!r} beside {str(self.out)!r} is not a "
                             "regular file; remove it (or choose another folder)")
        return fd

    def release(self) -> None:
        """Remove the lock file and release the lock (and remove folders created for it that stayed empty)."""
        if self._fd is not None:
            try:
                os.unlink(self.path)
            except FileNotFoundError:
                pass
            os.close(self._fd)
            self._fd = None
        self._remove_created()

    def _remove_created(self) -> None:
        remove_empty(self._created)




def check_output(out: Path, force: bool, marker: str, what: str, where: str = "--out",
                 writes: Iterable[str] = ()) -> None:
    """Refuse an output directory that cannot be written, that holds a file of the output's names (``marker`` and
    ``writes``) that sblsim did not write (:func:`~sblsim.orchestrator.io.manifest.refuse_foreign`: an input, say,
    with or without ``force``), or that holds an earlier result (its ``marker`` file) unless ``force``: before any
    work.

    Raises
    ------
    ModelError
        Naming ``where`` (the option or argument) and what to do.
    """
    out = Path(out)
    check_writable(out, where)
    if out.is_dir():
        refuse_foreign(out, [marker, *writes], where)
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


__all__ = ["OutputLock", "check_output", "check_writable", "current_umask", "folder_name", "make_parents",
           "refuse_link", "remove_empty", "remove_stale", "staged_directory", "write_atomic", "write_together"]

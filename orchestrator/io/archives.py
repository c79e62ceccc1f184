"""Unpacking archives from someone else (an ``.ssp`` package, a user's ``.fmu``): checked before a byte is written.

An SSP package or an FMU is a zip file that may come from anywhere. :func:`safe_extract` refuses,
with one line naming the entry, what a hostile or broken archive could do to the disk: entries with
an absolute name or a ``..`` that climbs out of the folder, symbolic links, more entries or more
bytes than any real package holds (a "zip bomb": a small file that inflates to gigabytes), and an
entry compressed far beyond what real files allow. Sizes are the ones declared in the archive's
directory; Python's ``zipfile`` never reads an entry past its declared size (and checks its CRC), so
the declared total is a true bound of what is written.
"""

from __future__ import annotations

import shutil
import stat
import zipfile
from pathlib import Path, PurePosixPath

from sblsim.models.errors import ArchiveError

#: At most this many entries in one archive.
MAX_ENTRIES = 10_000
#: At most this many bytes unpacked from one archive [B] (sblsim's own FMUs, all platforms: a few MB).
MAX_BYTES = 1 << 30
#: An entry larger than :data:`RATIO_FROM` bytes may be at most this many times its compressed size.
MAX_RATIO = 200
RATIO_FROM = 1 << 20


def check_members(archive: zipfile.ZipFile, label: str) -> list[zipfile.ZipInfo]:
    """The archive's file entries, after every check of the module docstring.

    Raises
    ------
    ArchiveError
        Naming ``label`` and the offending entry.
    """
    members = archive.infolist()
    if len(members) > MAX_ENTRIES:
        raise ArchiveError(f"{label}: {len(members)} entries; at most {MAX_ENTRIES} are unpacked")
    total = 0
    for info in members:
        name = info.filename
        path = PurePosixPath(name.replace("\\", "/"))
        if "\x00" in name or path.is_absolute() or (path.parts and path.parts[0].endswith(":")):
            raise ArchiveError(f"{label}: entry {name!r} has an absolute name")
        if ".." in path.parts:
            raise ArchiveError(f"{label}: entry {name!r} climbs out of the package ('..')")
        if stat.S_ISLNK(info.external_attr >> 16):
            raise ArchiveError(f"{label}: entry {name!r} is a symbolic link; links are not unpacked")
        if info.file_size > RATIO_FROM and info.file_size > MAX_RATIO * max(info.compress_size, 1):
            raise ArchiveError(f"{label}: entry {name!r} inflates {info.file_size / max(info.compress_size, 1):.0f} "
                               f"times (at most {MAX_RATIO}); not unpacked")
        total += info.file_size
        if total > MAX_BYTES:
            raise ArchiveError(f"{label}: unpacks to more than {MAX_BYTES >> 20} MiB; not unpacked")
    return members


def safe_extract(path: Path | str, dest: Path | str, label: str) -> Path:
    """Unpack the zip archive ``path`` into the folder ``dest`` after :func:`check_members`.

    Parameters
    ----------
    path : path
        The archive.
    dest : path
        An existing, empty folder of ours.
    label : str
        What the messages call the archive (e.g. ``"--ssp: s.ssp"``).

    Returns
    -------
    Path
        ``dest``.

    Raises
    ------
    ArchiveError
        Not a zip file, or an entry refused (module docstring); nothing of it is left in ``dest``'s place
        for the caller to use (the caller removes ``dest``).
    """
    dest = Path(dest).resolve()
    try:
        with zipfile.ZipFile(path) as archive:
            for info in check_members(archive, label):
                target = dest.joinpath(*PurePosixPath(info.filename.replace("\\", "/")).parts)
                if not target.resolve().is_relative_to(dest):  # e.g. through a folder entry that is a file
                    raise ArchiveError(f"{label}: entry {info.filename!r} lands outside the package folder")
                if info.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                with archive.open(info) as src, open(target, "wb") as out:
                    shutil.copyfileobj(src, out, 1 << 20)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError) as exc:
        raise ArchiveError(f"{label}: not a valid zip archive ({exc})") from None
    except (FileExistsError, NotADirectoryError, IsADirectoryError) as exc:
        raise ArchiveError(f"{label}: entries collide with each other ({exc.filename})") from None
    return dest


def inside(root: Path, relative: str) -> Path | None:
    """``root / relative`` if that names a place inside ``root`` (no absolute path, no climbing out), else None."""
    path = PurePosixPath(relative.replace("\\", "/"))
    if not relative or path.is_absolute() or ".." in path.parts or (path.parts and path.parts[0].endswith(":")):
        return None
    target = Path(root).joinpath(*path.parts)
    return target if target.resolve().is_relative_to(Path(root).resolve()) else None


__all__ = ["ArchiveError", "MAX_BYTES", "MAX_ENTRIES", "MAX_RATIO", "check_members", "inside", "safe_extract"]

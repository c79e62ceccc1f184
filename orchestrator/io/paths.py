"""The one rule for a file that a file names.

A design file's ``site.area.file`` and ``tag.burst_sequence``, a scenario file's file keys, a synchronisation
folder's ``offsets.csv`` and ``positions.csv`` and a tag sheet's sequence files are files that another file names.
Each is taken from the folder of the file that names it and refused, in one line, where the resolved path (every
symbolic link followed, ``..`` applied, an absolute path taken as it is) leaves that folder: a file or folder somebody
sent names what its folder holds, never a private file elsewhere. The user names any other file on the command line
(``--set``, or the option that takes it). A refusal names the key and the path as written, never a line of the file
(which is not opened).
"""

from __future__ import annotations

import os
from pathlib import Path

from sblsim.models.errors import ModelError


def inside(folder: Path | str, text: str, where: str, owner: str) -> Path:
    """The file ``text`` names, taken from ``folder``, refused where it leaves ``folder``.

    Parameters
    ----------
    folder : path
        The folder of the file that names ``text`` (a design file's, a tag sheet's, a synchronisation's folder).
    text : str
        The path as the naming file gives it (relative, absolute or with ``~``).
    where : str
        The key or column that names it, for the message (``site.area.file``).
    owner : str
        What names it, for the message (``design file``, ``tag sheet``).

    Returns
    -------
    Path
        The resolved path (links followed), within ``folder``.

    Raises
    ------
    ModelError
        One line naming ``where``, the path as written (at most 200 characters) and the folder, where the resolved
        path is outside ``folder`` or cannot be resolved (a loop of links).
    """
    base = Path(folder)
    shown = repr(text[:200])
    plain = Path(os.path.normpath(base / Path(text).expanduser()))
    try:
        root, path = base.resolve(), plain.resolve()
    except (OSError, RuntimeError):
        raise ModelError(f"{where}: {shown} cannot be resolved (a loop of symbolic links?); allowed: a file in the "
                         f"folder of the {owner} that names it") from None
    if not path.is_relative_to(root):
        how = (f"leads through a symbolic link to {str(path)!r}, outside" if plain.absolute().is_relative_to(
            base.absolute()) else "is outside")
        raise ModelError(f"{where}: {shown} {how} the folder of the {owner} that names it ({str(base)!r}); "
                         "allowed: a file in that folder, named relative to it (name another file on the command "
                         "line)")
    return path

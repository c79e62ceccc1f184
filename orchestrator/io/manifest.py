"""What an output folder holds that sblsim wrote: a manifest of the entries each staged write put there, so that a
run replaces only an earlier run's own outputs and never a file it did not write (a user's input, a file of another
program, an output the user has since edited).

The manifest (:data:`MANIFEST`, a small JSON file in the folder) records, for each entry a run moved into the folder,
its kind and, for a file, its size and modification time as written. An entry is **sblsim's own** where the manifest
records it and, for a file, its size and modification time are still those recorded; anything else in the folder is
**foreign** (:func:`foreign`) and is never replaced (:func:`refuse_foreign`). The manifest is read as hostile input:
at most :data:`MAX_MANIFEST_BYTES`, and a manifest that cannot be read as written makes every entry foreign (nothing
is replaced on its word).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any, Iterable

from sblsim.models.declarations import ModelError

#: The manifest's name in an output folder (hidden: it is not a result).
MANIFEST = ".sblsim-outputs.json"
#: The largest manifest read [bytes].
MAX_MANIFEST_BYTES = 4 * 2**20
#: The entries named in one refusal (the rest counted).
SHOWN = 4


def _record(path: Path) -> dict[str, Any] | None:
    """An entry's kind and, for a file, its size [bytes] and modification time [ns]; None where it does not exist."""
    try:
        status = path.lstat()
    except OSError:
        return None
    if path.is_dir() and not path.is_symlink():
        return {"kind": "folder"}
    return {"kind": "file", "size": status.st_size, "mtime_ns": status.st_mtime_ns}


def recorded(out: Path) -> dict[str, dict[str, Any]]:
    """The manifest of ``out``: each entry's name -> its record as written; empty where there is none or it cannot be
    read as sblsim writes it."""
    path = Path(out) / MANIFEST
    try:
        if not path.is_file() or path.is_symlink() or path.stat().st_size > MAX_MANIFEST_BYTES:
            return {}
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return {}
    written = data.get("written") if isinstance(data, dict) else None
    if not isinstance(written, dict):
        return {}
    return {str(k): v for k, v in written.items() if isinstance(v, dict)}


def foreign(out: Path, names: Iterable[str]) -> list[str]:
    """The entries of ``names`` that exist in ``out`` and are not sblsim's own (the module docstring), sorted."""
    out = Path(out)
    own = recorded(out)
    found = []
    for name in sorted(set(names)):
        now = _record(out / name)
        if now is None or name == MANIFEST:
            continue
        then = own.get(name)
        if then is None or then.get("kind") != now["kind"] or (
                now["kind"] == "file" and (then.get("size"), then.get("mtime_ns")) != (now["size"], now["mtime_ns"])):
            found.append(name)
    return found


def refuse_foreign(out: Path, names: Iterable[str], where: str = "--out") -> None:
    """Refuse, before anything is replaced, a write into ``out`` of entries named ``names`` where one of them exists
    there and is not sblsim's own.

    Raises
    ------
    ModelError
        One line naming the folder and the entries (the first :data:`SHOWN`, the rest counted).
    """
    found = foreign(out, names)
    if found:
        shown = ", ".join(found[:SHOWN]) + (f" and {len(found) - SHOWN} more" if len(found) > SHOWN else "")
        raise ModelError(f"{where}: {str(out)!r} holds {shown}, which this output would replace and sblsim did not "
                         "write (an input, another program's file, or a result edited since); nothing written; "
                         "allowed: a new folder, or an earlier result's own folder")


def write_manifest(out: Path, names: Iterable[str]) -> None:
    """Record ``names`` (entries just moved into ``out``) in its manifest, beside the entries recorded before that
    still exist; written atomically (a temporary file replaced)."""
    out = Path(out)
    own = {name: record for name, record in recorded(out).items() if (out / name).exists()}
    for name in names:
        record = _record(out / name)
        if record is not None:
            own[name] = record
    temporary = out / f"{MANIFEST}.{os.getpid()}.tmp"
    temporary.write_text(json.dumps({"written": own}, indent=1, sort_keys=True) + "\n", encoding="utf-8")
    os.replace(temporary, out / MANIFEST)


def file_digest(path: Path) -> str:
    """SHA-256 of a file's bytes (hex), read a MiB at a time: what a campaign's manifest records of its series and
    what a rerun's kept work is keyed by (:mod:`sblsim.orchestrator.tracks.resume`)."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


__all__ = ["MANIFEST", "MAX_MANIFEST_BYTES", "file_digest", "foreign", "recorded", "refuse_foreign", "write_manifest"]

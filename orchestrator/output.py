"""Writing results safely: everything into a staging folder, moved into place only when complete."""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


@contextmanager
def staged_directory(out: Path | str) -> Iterator[Path]:
    """A staging folder beside ``out`` whose files replace those of the same name in ``out`` on success.

    Files of ``out`` with other names are kept. If the body raises, nothing
    in ``out`` changes (a new ``out`` is not even created) and the staging
    folder is removed.

    Yields
    ------
    Path
        The staging folder to write into.
    """
    out = Path(out).absolute()
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
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


__all__ = ["staged_directory"]

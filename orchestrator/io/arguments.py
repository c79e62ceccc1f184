"""The checks of the API's arguments every function shares: a seed, a count, a number in its range, a path, a
flag, a text, a list of names and an output folder, each refused in one line naming the argument, its value and the
allowed range (:class:`~sblsim.models.errors.ConfigError`). The command line spells the argument as its option
(``where``); nothing here knows a command.
"""

from __future__ import annotations

import math
import os
from numbers import Real
from pathlib import Path
from typing import Any

import numpy as np

from sblsim.models.declarations import shown
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.io.output import check_output

#: The largest seed (``run.seed``, ``seed=``, ``--seed``): a 31-bit integer.
MAX_SEED = 2**31 - 1


def whole(value: Any) -> int | None:
    """``value`` as a Python integer when it is one or a numpy integer scalar (``numpy.int64(3)``); else None (a
    bool is not one)."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return int(value)
    return None


def check_seed(seed: Any, where: str = "seed") -> int | None:
    """A seed argument: None or an integer (a numpy one too) in [0, :data:`MAX_SEED`] (``where`` names it in the
    error), returned as a Python integer."""
    if seed is None:
        return None
    number = whole(seed)
    if number is None or not 0 <= number <= MAX_SEED:
        raise ConfigError(f"{where}: {shown(seed if number is None else number)} is outside the allowed range "
                          f"[0, {MAX_SEED}] (an integer)")
    return number


def check_count(value: Any, where: str, low: int, high: int) -> int:
    """An integer argument (a numpy one too; a bool is not one) in [low, high], returned as a Python integer."""
    number = whole(value)
    if number is None or not low <= number <= high:
        raise ConfigError(f"{where}: {shown(value) if number is None else number} is outside the allowed range "
                          f"[{low}, {high}] (an integer)")
    return number


def check_integer(value: Any, where: str) -> int | None:
    """An integer argument (a numpy one too) or None, whose range the work it sets checks; returned as a Python
    integer."""
    if value is None:
        return None
    number = whole(value)
    if number is None:
        raise ConfigError(f"{where}: {shown(value)} is not an integer or None")
    return number


def path_argument(value: Any, where: str, optional: bool = True) -> Path | None:
    """A file or folder argument (a text or a path; None where it is optional) as a :class:`Path`."""
    if value is None and optional:
        return None
    text = os.fspath(value) if isinstance(value, (str, os.PathLike)) else None
    if not isinstance(text, str) or not text or "\0" in text:
        allowed = "a file or folder: a text or a pathlib.Path" + (", or None" if optional else "")
        raise ConfigError(f"{where}: {shown(value)} is not {allowed}")
    return Path(text)


def flag_argument(value: Any, where: str) -> bool:
    """A true-or-false argument (``force=\"no\"`` would replace an earlier result)."""
    if not isinstance(value, (bool, np.bool_)):
        raise ConfigError(f"{where}: {shown(value)} is not True or False")
    return bool(value)


def real_argument(value: Any, where: str, low: float, high: float, unit: str, low_open: bool = False) -> float:
    """A finite real number argument in ``[low, high]`` (``(low, high]`` with ``low_open``)."""
    allowed = f"{'(' if low_open else '['}{low:g}, {high:g}] {unit}".rstrip()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, Real):
        raise ConfigError(f"{where}: {shown(value)} is not a number; allowed: {allowed}")
    if not math.isfinite(value) or not (value > low if low_open else value >= low) or not value <= high:
        raise ConfigError(f"{where}: {shown(value)} is outside the allowed range {allowed}")
    return float(value)


def text_argument(value: Any, where: str, optional: bool = True) -> str | None:
    """A text argument (None where it is optional)."""
    if value is None and optional:
        return None
    if not isinstance(value, str):
        raise ConfigError(f"{where}: {shown(value)} is not a text" + (" or None" if optional else ""))
    return value


def names_argument(value: Any, where: str, what: str) -> list[str] | None:
    """A list of names: None, a text of names separated by commas, or a sequence of texts; each named once.

    Raises
    ------
    ConfigError
        Naming ``where`` and ``what`` the names are (one line).
    """
    if value is None:
        return None
    names = value.split(",") if isinstance(value, str) else value
    if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
        raise ConfigError(f"{where}: expected {what} (a list, or separated by commas), got {type(value).__name__}")
    names = [n.strip() for n in names]
    if not names or not all(names) or len(set(names)) != len(names):
        raise ConfigError(f"{where}: {','.join(names)[:80]!r}: allowed: distinct, non-empty {what}, separated by "
                          "commas")
    return names


def prepare_out(out: str | Path | None, force: bool, marker: str, what: str) -> Path | None:
    """``out`` checked before any work (writable; an earlier result only with ``force``)."""
    out = path_argument(out, "out")
    force = flag_argument(force, "force")
    if out is None:
        return None
    check_output(out, force, marker, what, "out")
    return out

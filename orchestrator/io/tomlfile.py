"""TOML text read with a bounded nesting depth: anyone's file, a log's configuration lines or a ``--set`` value.

:func:`tomllib.loads` parses nested arrays and inline tables by recursion, so a text nesting them thousands
deep ends in :class:`RecursionError` (a traceback), and one nesting them a few hundred deep parses into a
value that later recursive code (copying, writing, messages) cannot handle. :func:`loads` refuses both as
invalid TOML (:class:`tomllib.TOMLDecodeError`, which every reader of a configuration already turns into one
line), and nothing sblsim reads nests deeper than :data:`MAX_DEPTH`.
"""

from __future__ import annotations

import tomllib
from typing import Any

#: The deepest nesting of tables and arrays accepted (a configuration nests 2 deep, a study 3).
MAX_DEPTH = 32


def depth(value: Any) -> int:
    """The nesting depth of a parsed TOML value (a scalar 0, a table or array 1 + its deepest item), found
    without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, level = stack.pop()
        if isinstance(item, dict):
            children = item.values()
        elif isinstance(item, list):
            children = item
        else:
            deepest = max(deepest, level)
            continue
        deepest = max(deepest, level + 1)
        if level + 1 <= MAX_DEPTH:  # deeper than that is refused anyway: stop looking
            stack.extend((child, level + 1) for child in children)
    return deepest


def loads(text: str) -> dict[str, Any]:
    """Parse TOML text like :func:`tomllib.loads`, refusing a nesting deeper than :data:`MAX_DEPTH`.

    Raises
    ------
    tomllib.TOMLDecodeError
        Invalid TOML, or tables and arrays nested deeper than :data:`MAX_DEPTH`.
    """
    try:
        data = tomllib.loads(text)
    except RecursionError:
        raise tomllib.TOMLDecodeError(f"tables or arrays nested deeper than {MAX_DEPTH}") from None
    if depth(data) > MAX_DEPTH:
        raise tomllib.TOMLDecodeError(f"tables or arrays nested deeper than {MAX_DEPTH}")
    return data


__all__ = ["MAX_DEPTH", "depth", "loads"]

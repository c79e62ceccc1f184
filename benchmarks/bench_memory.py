"""The benchmarks' peak resident memory: the process's high-water mark, reset before a stage where Linux allows."""

from __future__ import annotations

import resource
from pathlib import Path


def reset_peak() -> bool:
    """Reset the process's resident high-water mark (Linux's ``clear_refs`` 5); whether it could."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


def _status(key: str) -> int | None:
    """A memory figure of this process's ``/proc/self/status`` (``VmHWM``, ``VmRSS``) [bytes]; None off Linux."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(f"{key}:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


def peak_bytes() -> int:
    """The process's resident high-water mark [bytes]: ``VmHWM`` (its own: ``ru_maxrss`` of a spawned process carries
    its parent's, kept across fork and exec), else ``ru_maxrss``."""
    peak = _status("VmHWM")
    return peak if peak is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def resident_bytes() -> int:
    """The process's resident memory now [bytes] (``VmRSS``; 0 off Linux)."""
    return _status("VmRSS") or 0

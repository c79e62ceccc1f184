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


def peak_bytes() -> int:
    """The process's resident high-water mark [bytes] (``VmHWM``, else ``ru_maxrss``)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024

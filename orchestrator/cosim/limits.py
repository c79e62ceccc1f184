"""What fits: the memory a run's record takes, checked before any work.

A run keeps every step of its record in memory: the compiled master loop
writes every output of every component at every macro step (8 bytes each),
and a run with a time series then builds its table from it (the cast
columns, the errors and the bound, the table and the data frame handed to
the Parquet writer: about :data:`TABLE_COPIES` copies of its
:func:`timeseries_columns` columns). A campaign chunk records only the
metrics' inputs. :func:`check_steps` refuses, before anything is simulated or
written, a run whose estimate exceeds :data:`MEMORY_SHARE` of the memory
available here (``MemAvailable`` of ``/proc/meminfo``, else the physical
memory), so a too-long run ends with one line instead of running out of
memory after minutes. :func:`check_replicates` holds the replicate count of a command that runs replicates of
a configuration.
"""

from __future__ import annotations

import math
import os

from sblsim.models import COMPONENTS
from sblsim.models.columns import METRIC_INPUTS, TIMESERIES_COLUMNS
from sblsim.models.declarations import ModelError

#: Bytes of one recorded value (a float64).
VALUE_BYTES = 8
#: Copies of the time-series columns alive at the peak of a run with a time series (measured: a 200 000-step
#: semicircle run peaks at about 2.1 kB per step).
TABLE_COPIES = 4
#: Share of the available memory a run may plan to use.
MEMORY_SHARE = 0.75
#: Assumed available memory where the system does not say [bytes].
FALLBACK_MEMORY = 4 * 2**30
#: The most replicates a command (compare, budget) runs of a configuration.
MAX_REPLICATES = 100_000


def check_replicates(replicates: int, least: int = 1, why: str = "") -> None:
    """Refuse a replicate count outside [least, :data:`MAX_REPLICATES`] (``why``: what needs ``least``).

    Raises
    ------
    ModelError
        Naming ``--replicates`` and the range.
    """
    if not least <= replicates <= MAX_REPLICATES:
        raise ModelError(f"--replicates: {replicates} is outside the allowed range [{least}, {MAX_REPLICATES}]"
                         + (f" ({why})" if why else ""))


def available_memory() -> int:
    """Memory available to a new run here [bytes]: ``MemAvailable`` (Linux), else the physical memory, else
    :data:`FALLBACK_MEMORY`."""
    try:
        with open("/proc/meminfo") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return FALLBACK_MEMORY


def _system_outputs() -> int:
    return sum(len(model.outputs()) for model in COMPONENTS.values())


def timeseries_columns() -> int:
    """Columns of a run's time-series table: the recorded ones, time, replicate, the bound and 8 errors."""
    return len(TIMESERIES_COLUMNS) + 11


def bytes_per_step(timeseries: bool = True) -> int:
    """Estimated peak memory of one replicate's step [bytes]: the record of every output and, with a time
    series, :data:`TABLE_COPIES` copies of its columns; without, the metrics' inputs only."""
    if not timeseries:
        return VALUE_BYTES * len(METRIC_INPUTS)
    return VALUE_BYTES * (_system_outputs() + TABLE_COPIES * timeseries_columns())


def max_steps(replicates: int = 1, timeseries: bool = True, concurrent: int = 1) -> int:
    """The most macro steps that fit in memory here for ``replicates`` runs stepped together (each of
    ``concurrent`` processes holding such a batch)."""
    budget = MEMORY_SHARE * available_memory() / max(1, concurrent)
    return int(budget // (bytes_per_step(timeseries) * max(1, replicates)))


def step_count(duration: float, sampling_time: float) -> int:
    """Macro steps of a run: ``floor(duration / T)`` (to 1e-9 of a step)."""
    return int(math.floor(duration / sampling_time + 1e-9))


def check_steps(duration: float, sampling_time: float, replicates: int = 1, timeseries: bool = True,
                concurrent: int = 1, what: str = "") -> int:
    """The step count of a run, refused when its record would not fit in memory.

    Parameters
    ----------
    duration : float
        Simulated time [s].
    sampling_time : float
        Macro step T [s].
    replicates : int
        Runs stepped together (one record).
    timeseries : bool
        Whether the time series is built (else only the metrics' inputs are recorded).
    concurrent : int
        Processes that each hold such a record at once (campaign workers).
    what : str
        Where the duration comes from, for the message (default ``simulation.duration``).

    Returns
    -------
    int
        Macro steps.

    Raises
    ------
    ModelError
        ``simulation.duration: ... at most N steps fit in memory here (...)``.
    """
    steps = step_count(duration, sampling_time)
    most = max_steps(replicates, timeseries, concurrent)
    if steps > most:
        many = f" x {replicates} replicates" if replicates > 1 else ""
        workers = f" in each of {concurrent} workers" if concurrent > 1 else ""
        gib = available_memory() / 2**30
        longest = most * sampling_time
        raise ModelError(f"simulation.duration: {what or f'{duration:.10g} s'} at T = {sampling_time:g} s is "
                         f"{steps} steps{many}; at most {most} steps fit in memory here ({gib:.1f} GiB available, "
                         f"about {bytes_per_step(timeseries)} bytes per step and replicate{workers}): allowed "
                         f"[sampling_time, {longest:.6g}] s")
    return steps

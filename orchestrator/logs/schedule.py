"""The schedule of a log's replay (:mod:`sblsim.orchestrator.logs.replay`): which row of the log the receiver is
shown in each communication step, and where the replay starts and ends.

Timing (the slot rule of the receivers, :func:`sblsim.models.receiver.slots.slot_due`).
The replay runs on the grid of the configuration: macro steps of T =
``simulation.sampling_time``, each of ``simulation.ekf_rate_ratio``
communication steps of the receiver. It starts at the last multiple of T
before the first row's time (``start_time``; an inverted LBL's log, whose first
row is a ping's nominal epoch, a ping interval before it, where its run
started) and ends with the macro step
that reaches the last row's arrival. A row's arrival is its ``rx_time``
(an exported log's: when the packet reached the diver), else its ``time_s``;
rows are taken in the order of arrival. In each communication step
``[t, t + Δt]`` the receiver is shown the newest row whose arrival the step's
end has reached (``t + Δt ≥ rx_time − 1 ns``, the receiver's own slot test),
so it uses each row in the step that reaches its arrival, as it uses a packet
in a run (``tx_time`` is the row's ``time_s``).
A row's arrival within its float resolution of a slot epoch k T is taken as that
epoch (:func:`stamp_tolerance`), so that Unix-time stamps replay as times from 0.
Rows that fall in one step are shown together on the lanes of a delivery, in
order (the receiver takes them one after the other at the step's end, as the
packets that arrive in one step of a run); beyond the
:data:`~sblsim.models.acoustics.channel.interface.LANES` newest of them the others are
skipped and counted (``same_step``). With ``simulation.master = "jacobi"`` a row is shown one macro step
later, as the Jacobi master hands the receiver its inputs (so that the log
of a Jacobi run replays to the run; the rows of the last macro step are then
not used).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sblsim.models.acoustics.channel.interface import LANES
from sblsim.models.declarations import ModelError
from sblsim.models.receiver.slots import SLOT_SLACK
from sblsim.orchestrator.cosim.limits import max_steps
from sblsim.orchestrator.logs.receiver_log import Log


@dataclass
class Schedule:
    """Which row the receiver is shown in each communication step (:func:`schedule`)."""

    #: The replay's start time on the log's clock [s] (a multiple of T).
    start: float
    #: Macro steps.
    steps: int
    #: Rows shown in each communication step on the lanes of a delivery, shape (steps · ratio, LANES); −1: none.
    fed: np.ndarray
    #: Rows the time series records at each macro step (the last ones shown), shape (steps, LANES); −1: none.
    shown: np.ndarray
    #: The rows the receiver is shown (in order).
    used: np.ndarray
    #: Rows skipped because another row of the same step was used.
    same_step: int
    #: Rows not reached (a Jacobi replay: the rows of the last macro step).
    not_reached: int
    #: Each row's time from the start [s]: a time within :func:`stamp_tolerance` of a slot epoch k T is that epoch.
    rel: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _step_ends(n_steps: int, T: float, ratio: int) -> np.ndarray:
    """The end ``t + h`` of every communication step, computed as the master computes t and h."""
    sub = T / ratio
    k = np.repeat(np.arange(n_steps), ratio)
    j = np.tile(np.arange(ratio), n_steps)
    t = (0.0 + k * T) + j * sub
    return t + sub


def schedule(log: Log, T: float, ratio: int, jacobi: bool = False, lead: float = 0.0) -> Schedule:
    """The replay's start, length and the row of every communication step (module docstring, "Timing"); ``lead``
    [s]: how long before the first row's ``time_s`` less T the run started (an inverted LBL's: its pinger's
    interval less T, its first ping's nominal epoch being an interval after the start).

    Raises
    ------
    ModelError
        When the log's span is more macro steps than fit in memory (naming its longest gap).
    """
    tol = stamp_tolerance(log, T)
    first = float(np.min(log.transmit)) - lead  # the grid starts before the first transmission (the run's slot grid)
    start = T * (math.ceil(first / T - max(1e-9, tol / T)) - 1)
    rel = log.time - start
    slot = 0.0 + np.rint(rel / T) * T  # the slot epochs k T as the channel computes them (t0 + k T, t0 = 0)
    rel = np.where(np.abs(rel - slot) <= tol, slot, rel)
    last = float(rel[-1])
    steps = max(1, math.ceil(last / T - 1e-9))
    most = max_steps(1, True)
    if steps > most:
        gap, where = log.longest_gap
        raise ModelError(f"log: {str(log.path)!r} spans {log.time[-1] - log.time[0]:.6g} s, {steps} steps of "
                         f"T = {T:g} s; at most {most} fit in memory here. Its longest gap is {gap:.6g} s, before "
                         f"its {where} (a clock jump forward?): replay the rows before and from there as two logs, "
                         "or give a larger simulation.sampling_time")
    def end(n: int) -> float:  # the end of the last communication step of n macro steps, as the master has it
        sub = T / ratio
        return ((0.0 + (n - 1) * T) + (ratio - 1) * sub) + sub

    while end(steps) < last - SLOT_SLACK:
        steps += 1
    while steps > 1 and end(steps - 1) >= last - SLOT_SLACK:
        steps -= 1
    ends = _step_ends(steps, T, ratio)
    # newest row the end of each macro step has reached (the receiver's slot test, in its arithmetic): the rows the
    # channel of a run delivers at its end, which the receiver then takes in its communication steps, each in the
    # first that reaches its arrival (the Jacobi master hands them over a macro step later)
    newest = np.searchsorted(rel - SLOT_SLACK, ends[ratio - 1::ratio], side="right") - 1
    if jacobi:
        newest = np.concatenate([[-1], newest[:-1]])
    shown = np.full((steps, LANES), -1, dtype=np.int64)
    previous = -1
    for k, top in enumerate(newest):
        if top > previous:  # the rows reached since, on the lanes in order (the newest LANES of them)
            rows = np.arange(max(previous + 1, top + 1 - LANES), top + 1)
            shown[k, :rows.size] = rows
            previous = top
        elif k:
            shown[k] = shown[k - 1]  # the last delivery, held
    fed = np.repeat(shown, ratio, axis=0)
    used = np.unique(fed[fed >= 0])
    if jacobi:  # the rows the end of the last macro step but one reached
        reached = int(newest[-1] + 1)
    else:
        reached = len(rel)
    return Schedule(start=start, steps=steps, fed=fed, shown=shown, used=used, same_step=reached - used.size,
                    not_reached=len(rel) - reached, rel=rel)


def stamp_tolerance(log: Log, T: float) -> float:
    """How far a row's time may lie from a slot epoch and still be taken as it [s]: the slot test's slack
    (:data:`sblsim.models.receiver.slots.SLOT_SLACK`), or four times the resolution of a float64 at the log's
    times where that is coarser (Unix times near 1.7e9 s are resolved to 2.4e-7 s only).

    Raises
    ------
    ModelError
        When that resolution is coarser than a tenth of the sampling time.
    """
    largest = float(max(abs(log.time[0]), abs(log.time[-1])))
    tol = max(SLOT_SLACK, 4.0 * float(np.spacing(largest)))
    if tol > T / 10:
        raise ModelError(f"log: {str(log.path)!r}: its times (up to {largest:.6g} s) are resolved to "
                         f"{float(np.spacing(largest)):.3g} s only, too coarse for simulation.sampling_time = {T:g} s; "
                         "subtract a start time from time_s")
    return tol


__all__ = ["Schedule", "schedule", "stamp_tolerance"]

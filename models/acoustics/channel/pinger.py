"""The pinger's schedule: when the tag pings (an inverted LBL, ``ranging = "toa"``), and the sync tags' intervals
and the hydrophones' clocks of its raw detections.

The target's pinger emits ping c at ``e_c = e_{c−1} + P (1 + δ) + j_c`` on its own clock (P = ``ping_interval``, 0
taking the round-robin cycle ``n T``; δ the drift ``clock_drift_ppm``; ``j_c`` uniform of zero mean and std
``ping_jitter``), one of three types (:data:`PING_TYPES`, YAPS's names):

* the **stable burst interval** (``ping_type = "sbi"``): P plus the jitter, as above;
* the **random burst interval** (``rbi``): ``e_c = e_{c−1} + U(burst_interval_min, burst_interval_max)(1 + δ)``,
  the same with P the uniform's mean and ``j_c`` its zero-mean part, stretched too;
* the **pseudo-random burst interval** (``pbi``): P_c from its known table ``burst_sequence`` in turn, cycled, plus
  the jitter.

The receivers know the schedule, not the emissions: a ping's nominal epoch is ``t0 + c P`` (``pbi``: ``t0 +
Σ_{k≤c} P_k``; :func:`ping_nominal`), what its packets carry as ``tx_time`` (:func:`sent_epoch`); the emission
walks away from it by the drawn intervals (:func:`ping_interval_drawn`). :func:`ping_schedule` derives the
schedule's numbers the channel's program reads, :func:`ping_due` is the guard of a ping's legs (heard at the fixed
receivers: :mod:`~sblsim.models.acoustics.channel.toa`). In numbers: :func:`ping_intervals`, :func:`ping_spread`,
:func:`nominal_ping_interval`; :func:`check_pinger` refuses a pinger the channel cannot emit.

References
----------
Baktoft, Gjelland, Økland, Thygesen, "Positioning of aquatic animals based on time-of-arrival and random walk
models using YAPS (Yet Another Positioning Solver)", Scientific Reports 7:14294, 2017 (the ping types).
"""

from __future__ import annotations

import math
import re
from typing import Any, Mapping

import casadi as ca
import numpy as np

from sblsim.models.acoustics.channel.interface import ARRIVAL_SLACK, TOA
from sblsim.models.declarations import Column, Table, Variable, shown
from sblsim.models.errors import ModelError
from sblsim.models.expressions import cumulative_sum, get_row
from sblsim.models.table_text import parse_table

#: The pinger's types (Baktoft et al. 2017, YAPS's names; the tracker's, :mod:`sblsim.models.tracking.schedule`): a
#: stable burst interval (``sbi``: every ``ping_interval``, plus a uniform jitter), a random one (``rbi``: each
#: interval a uniform draw ``U(burst_interval_min, burst_interval_max)``), a pseudo-random one (``pbi``: the intervals
#: of a known table, ``burst_sequence``, in turn, plus the jitter).
PING_TYPES = ("sbi", "rbi", "pbi")
#: The indices of ``rbi`` and ``pbi`` in :data:`PING_TYPES` (the ``ping_type`` parameter's encoding).
RBI, PBI = PING_TYPES.index("rbi"), PING_TYPES.index("pbi")
#: Most intervals of a ``pbi`` pinger's table.
MAX_BURSTS = 64
#: The longest interval between two pings [s].
MAX_PING_INTERVAL = 3600.0
#: A ``pbi`` pinger's intervals in the order it emits them (cycled), carried in FMU arrays as the sound-speed
#: table is: one column, ``burst_sequence_rows`` rows in use.
BURSTS = Table(columns=(Column("burst_sequence_interval", "s", "pbi: interval of the pinger's table", 1e-3,
                               MAX_PING_INTERVAL),),
               max_rows=MAX_BURSTS, min_rows=1, when=("ping_type", "pbi"))
#: The target's pinger of an inverted LBL (``ranging = "toa"``; declared after every other variable of the
#: channel, the lanes included: their value references stay; the ping types' after the first two, for the same
#: reason): its type, the pings' nominal interval and their jitter (``sbi``, the jitter also ``pbi``'s), a random
#: interval's bounds (``rbi``) and a pseudo-random interval's table (``pbi``).
PING_VARIABLES: tuple[Variable, ...] = (
    Variable("ping_interval", "parameter", "Real", 0.0, "s",
             "toa: the target pinger's nominal interval between pings on its own clock (0: the round-robin cycle, "
             "beacons x slot_period: one range per receiver per cycle, as SBL and LBL)", min=0.0,
             max=MAX_PING_INTERVAL),
    Variable("ping_jitter", "parameter", "Real", 0.0, "s",
             "toa: std of each interval's random part (uniform, zero mean: a tag's random delay; the emission "
             "epochs then walk away from the nominal schedule, unknown to the receivers)", min=0.0, max=600.0),
    Variable("ping_type", "parameter", "String", "sbi", choices=PING_TYPES,
             description="toa: the pinger's intervals: stable (sbi: ping_interval plus ping_jitter), random (rbi: "
                         "each a uniform draw between burst_interval_min and burst_interval_max) or pseudo-random "
                         "(pbi: burst_sequence's in turn, plus ping_jitter)"),
    Variable("burst_interval_min", "parameter", "Real", 0.0, "s",
             "toa, rbi: the shortest interval between pings on the pinger's clock (0: not set)", min=0.0,
             max=MAX_PING_INTERVAL),
    Variable("burst_interval_max", "parameter", "Real", 0.0, "s",
             "toa, rbi: the longest interval between pings on the pinger's clock (0: not set)", min=0.0,
             max=MAX_PING_INTERVAL),
    Variable("burst_sequence", "parameter", "String", "", scope="config",
             description=f"toa, pbi: the pinger's intervals in the order it emits them, cycled, 'interval; ...' "
                         f"or 'interval interval ...' [s] (1 to {MAX_BURSTS})"),
    Variable("burst_sequence_rows", "parameter", "Integer", 0, scope="fmu", table=BURSTS,
             description="toa, pbi: intervals of the pinger's table in use (burst_sequence)", min=0, max=MAX_BURSTS),
)

#: The hydrophones' own clocks and their sync tags (an inverted LBL's raw detections: ``sblsim run
#: --export-detections``). Configuration keys only, declared after every other variable: the channel and the
#: receivers never read them (their packets keep synchronised times), so no FMU and no number of a run changes.
#: The grade: a VR2-class telemetry receiver's clock drifts by up to 4 s a day (46 ppm) by its manufacturer's
#: specification (VEMCO, "VR2 Troubleshooting", http://www.vemco.com/support/vr2_troubleshoot.php); the default
#: ±20 ppm (1.7 s a day) is a common watch crystal's tolerance, inside that grade.
RECEIVER_CLOCK_VARIABLES: tuple[Variable, ...] = (
    Variable("receiver_clock_offset", "parameter", "Real", 2.0, "s",
             "ilbl raw detections: each hydrophone's clock offset at the run's start, uniform in +-this (drawn "
             "from the run's seed; a clock set by hand at deployment)", min=0.0, max=86400.0, scope="config"),
    Variable("receiver_clock_drift_ppm", "parameter", "Real", 20.0, "ppm",
             "ilbl raw detections: each hydrophone's clock drift, uniform in +-this (a VR2-class crystal: up to "
             "46 ppm, 4 s a day; 20 ppm is 1.7 s a day)", min=0.0, max=1000.0, scope="config"),
    Variable("sync_interval_min", "parameter", "Real", 540.0, "s",
             "ilbl raw detections: the shortest burst interval of the sync tag at each hydrophone (each interval "
             "uniform between sync_interval_min and sync_interval_max)", min=1.0, max=MAX_PING_INTERVAL,
             scope="config"),
    Variable("sync_interval_max", "parameter", "Real", 660.0, "s",
             "ilbl raw detections: the longest burst interval of the sync tags", min=1.0, max=MAX_PING_INTERVAL,
             scope="config"),
)


def nominal_ping_interval(ping_interval: float, n_beacons: int, slot_period: float) -> float:
    """The pinger's nominal interval [s] of an inverted LBL's run (numbers): ``ping_interval``, or where it is 0 the
    round-robin cycle ``n T`` (the channel's ``prepare`` derives the same)."""
    return ping_interval if ping_interval > 0 else n_beacons * slot_period


#: The keys of ``[acoustics]`` each ping type reads beyond ``ping_type`` (a key of another type, given with a value
#: other than its default, is refused: :func:`check_pinger`).
PING_KEYS = {"sbi": ("ping_interval", "ping_jitter"), "rbi": ("burst_interval_min", "burst_interval_max"),
             "pbi": ("burst_sequence", "ping_jitter")}
_PING_DEFAULTS = {v.name: v.start for v in PING_VARIABLES}


def burst_sequence(text: str, where: str = "acoustics.burst_sequence") -> np.ndarray:
    """A ``pbi`` pinger's intervals from their text: values separated by ``;``, commas or blanks.

    Returns
    -------
    ndarray, shape (rows, 1)
        The intervals [s] (0 rows for a blank text).

    Raises
    ------
    ModelError
        Naming ``where``: a value that is not a number, outside ``[0.001, 3600]`` s, or more than
        :data:`MAX_BURSTS` of them.
    """
    return parse_table(";".join(s for s in re.split(r"[;,\s]+", text) if s), BURSTS, where)


def ping_intervals(acoustics: Mapping[str, Any], n_beacons: int, slot_period: float) -> np.ndarray:
    """The pinger's nominal intervals [s] in the order they repeat (numbers; the channel's ``prepare`` derives the
    same): ``sbi`` its one interval (:func:`nominal_ping_interval`), ``rbi`` the uniform's mean
    ``(min + max) / 2``, ``pbi`` its table.

    Returns
    -------
    ndarray, shape (L,)
    """
    kind = acoustics.get("ping_type", "sbi")
    if kind == "rbi":
        return np.array([0.5 * (acoustics["burst_interval_min"] + acoustics["burst_interval_max"])])
    if kind == "pbi":
        return burst_sequence(acoustics.get("burst_sequence", ""))[:, 0]
    return np.array([nominal_ping_interval(acoustics["ping_interval"], n_beacons, slot_period)])


def ping_spread(acoustics: Mapping[str, Any]) -> float:
    """The std [s] of the random step the emission's offset from the nominal schedule takes at each ping (numbers;
    the receivers' ``ping_jitter``): the uniform ``U(min, max)``'s ``(max − min) / √12`` for ``rbi``, the jitter
    ``ping_jitter`` for ``sbi`` and ``pbi``."""
    if acoustics.get("ping_type", "sbi") == "rbi":
        return (acoustics["burst_interval_max"] - acoustics["burst_interval_min"]) / math.sqrt(12.0)
    return float(acoustics["ping_jitter"])


def check_pinger(acoustics: Mapping[str, Any], given: set[str] | frozenset[str], n_beacons: int,
                 slot_period: float) -> None:
    """Refuse an inverted LBL's pinger the channel cannot emit (``acoustics`` the resolved section, ``given`` the
    keys the user set, the channel's ``n_beacons`` receivers and slot period [s]).

    Raises
    ------
    ModelError
        One line naming the key and what is allowed: a key of another ping type given with a value other than its
        default (:data:`PING_KEYS`), an ``rbi`` without ``0 < burst_interval_min < burst_interval_max``, a ``pbi``
        without a table (or a bad one, :func:`burst_sequence`), a jitter whose uniform (``±√3`` std) would reach
        the shortest interval.
    """
    kind = acoustics.get("ping_type", "sbi")
    own = PING_KEYS[kind]
    for key in sorted({key for keys in PING_KEYS.values() for key in keys} - set(own)):
        if key not in given or acoustics.get(key, _PING_DEFAULTS[key]) == _PING_DEFAULTS[key]:
            continue
        readers = " or ".join(repr(other) for other, keys in PING_KEYS.items() if key in keys)
        raise ModelError(f"acoustics.{key}: {shown(acoustics[key])} is read by acoustics.ping_type = {readers}, "
                         f"not by {kind!r} (which reads {', '.join(own)}); allowed: its default "
                         f"{shown(_PING_DEFAULTS[key])}, or ping_type = {readers}")
    if kind == "rbi":
        low, high = acoustics["burst_interval_min"], acoustics["burst_interval_max"]
        if low <= 0.0:
            upper = f"{high:g}" if high > 0.0 else "burst_interval_max"
            raise ModelError(f"acoustics.burst_interval_min: {low:g} s; ping_type = 'rbi' draws each interval "
                             f"from U(burst_interval_min, burst_interval_max): allowed (0, {upper}) s")
        if high <= low:
            raise ModelError(f"acoustics.burst_interval_max: {high:g} s; ping_type = 'rbi' draws each interval "
                             f"from U(burst_interval_min, burst_interval_max): allowed ({low:g}, "
                             f"{MAX_PING_INTERVAL:g}] s")
        return
    if kind == "pbi" and not burst_sequence(acoustics.get("burst_sequence", "")).shape[0]:
        raise ModelError(f"acoustics.burst_sequence: empty; ping_type = 'pbi' cycles a known table of intervals: "
                         f"allowed 1 to {MAX_BURSTS} intervals in [0.001, {MAX_PING_INTERVAL:g}] s, e.g. "
                         f"'0.6 0.9 0.7'")
    if acoustics.get("ranging") != "toa":
        return  # the pinger's interval is the inverted LBL's (another system does not read it)
    shortest = float(ping_intervals(acoustics, n_beacons, slot_period).min())
    limit = shortest / math.sqrt(3.0)
    if acoustics["ping_jitter"] >= limit:
        what = "ping interval" if kind == "sbi" else "shortest interval of burst_sequence"
        raise ModelError(f"acoustics.ping_jitter: {acoustics['ping_jitter']:g} s; a uniform jitter reaches "
                         f"sqrt(3) times its std, and the {what} ({shortest:g} s) must stay positive: "
                         f"allowed [0, {limit:.6g}) s")


def ping_nominal(x, d, ping) -> ca.SX:
    """The nominal epoch [s] of ping ``ping`` (1, 2, …; symbolic, whole), what the receivers know of the schedule:
    ``t0 + q S + Σ_{k<r} Δ_k`` with ``ping = q L + r`` (the pinger's derived intervals ``ping_steps`` Δ, ``L``
    of them in a cycle of ``S`` seconds: ``pbi``'s table; ``sbi`` and ``rbi`` one, ``t0 + c P``)."""
    rows = d["ping_rows"]
    cycles = ca.floor(ping / rows)
    return x["t0"] + cycles * d["ping_cycle"] + get_row([d["ping_prefix"]], ping - cycles * rows)[0]


def ping_interval_drawn(p, d, ping, uniform) -> ca.SX:
    """The pinger's interval [s] before ping ``ping`` (1, 2, …; symbolic), on its own clock, drawn with the uniform
    number ``uniform`` in [0, 1): its nominal interval Δ (:func:`ping_nominal`'s) stretched by the drift δ plus a
    uniform of zero mean and std σ (``ping_spread``): ``sbi`` and ``pbi`` ``Δ (1 + δ) + j``, ``j`` the jitter;
    ``rbi`` ``(Δ + j)(1 + δ)``, ``U(min, max)`` stretched (its mean Δ, its std ``(max − min) / √12``)."""
    rows = d["ping_rows"]
    r = ping - 1.0 - ca.floor((ping - 1.0) / rows) * rows
    drift = 1.0 + p["clock_drift_ppm"] * 1e-6
    jitter = d["ping_spread"] * math.sqrt(3.0) * (2.0 * uniform - 1.0)
    return get_row([d["ping_steps"]], r)[0] * drift + ca.if_else(p["ping_type"] == RBI, jitter * drift, jitter)


def ping_due(x, u, p, d, t, h):
    """Guard of a ping's legs (``ranging = "toa"``): the emission epoch has been reached by the end of the step."""
    return x["ping_epoch"] <= t + h + ARRIVAL_SLACK


def sent_epoch(x, p, d, seq, n: int):
    """The transmit epoch a packet's slot counter ``seq`` gives [s]: slot k's ``t0 + k T``, or (``ranging =
    "toa"``) its ping's nominal epoch (:func:`ping_nominal`), ping c = ⌈seq / n⌉ of a channel of ``n``
    receivers."""
    ping = ca.floor((seq - 1) / n) + 1
    return ca.if_else(p["ranging"] == TOA, ping_nominal(x, d, ping), x["t0"] + seq * p["slot_period"])


def ping_schedule(p, n: int) -> dict[str, Any]:
    """toa: the pinger's derived numbers (symbolic; the channel's ``prepare``) of a channel of ``n`` receivers from its
    parameters ``p``: its nominal intervals (``ping_steps``: ``pbi``'s table, zeros past its rows; ``sbi``,
    ``rbi`` one, P or the uniform's mean), their count, the running sums from 0, the cycle's length, the
    shortest and the std of an interval's random part (:func:`ping_nominal`,
    :func:`ping_interval_drawn`)."""
    rbi, pbi = p["ping_type"] == RBI, p["ping_type"] == PBI
    # sbi: ping_interval, 0 taking the round-robin cycle of the n receivers
    single = ca.if_else(rbi, 0.5 * (p["burst_interval_min"] + p["burst_interval_max"]),
                        ca.if_else(p["ping_interval"] > 0, p["ping_interval"], n * p["slot_period"]))
    table, rows = p[BURSTS.columns[0].name], p["burst_sequence_rows"]
    in_use = ca.DM(list(range(MAX_BURSTS))) < rows
    first = ca.DM([1.0] + [0.0] * (MAX_BURSTS - 1))
    steps = ca.if_else(pbi, table * in_use, first * single)
    shortest = ca.if_else(pbi, ca.mmin(table + (1 - in_use) * 2.0 * MAX_PING_INTERVAL),
                          ca.if_else(rbi, p["burst_interval_min"], single))
    return {"ping_steps": steps, "ping_prefix": ca.vertcat(0.0, cumulative_sum(steps)),
            "ping_rows": ca.if_else(pbi, ca.fmax(rows, 1), 1), "ping_cycle": ca.sum1(steps),
            "ping_shortest": shortest,
            "ping_spread": ca.if_else(rbi, (p["burst_interval_max"] - p["burst_interval_min"])
                                      / math.sqrt(12.0), p["ping_jitter"])}


__all__ = ["burst_sequence", "BURSTS", "check_pinger", "MAX_BURSTS", "MAX_PING_INTERVAL", "nominal_ping_interval",
           "PBI", "ping_due", "ping_interval_drawn", "ping_intervals", "PING_KEYS", "ping_nominal", "ping_schedule",
           "ping_spread", "PING_TYPES", "PING_VARIABLES", "RBI", "RECEIVER_CLOCK_VARIABLES", "sent_epoch"]

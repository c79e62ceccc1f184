"""The receivers' positions checked against the sync tags' travel times: is the table in metres?

A receivers table in kilometres, or in degrees under metre columns, gives distances a thousand or a hundred thousand
times too small; the clock fit then takes the travel times into the clocks' offsets and reports residuals of tens of
metres, and every track made on it is off by the array's size. The travel times between the receivers tell the
distances without any clock: for two receivers ``A`` and ``B`` hearing one emission of sync tag ``t``, the
difference of their arrivals (each on its own clock) is

    r_B − r_A = (d_tB − d_tA) / c + o_B − o_A,

and the same difference for a second tag ``u`` (at a nearby time, the clocks' difference interpolated between the
first tag's emissions) cancels the offsets: the **double difference** ``((d_uB − d_uA) − (d_tB − d_tA)) / c``
(for the tags at ``A`` and at ``B``, twice the distance ``AB`` over ``c``: the two-way travel time). Each pair of
receivers and tag gives one, its median over the emissions; the table predicts the same from its positions. Their
ratio (:func:`distance_scale`: the median over the items whose predicted value is among the larger half) is 1 for a
table in metres (within the sync tags' hanging, the depths and the sound speed: percent), about 1,000 for one in
kilometres, 0.3048 for feet and about 10⁵ for degrees (a degree of latitude is 111 km).

Where the times are rounded (a whole second, a tenth: ``quantum``), one double difference is a sum of four
roundings and its median over the emissions is itself rounded, off by up to half a quantum (a whole second's
median of zero says the receivers are at one place); their **mean** is not, the roundings being uniform over the
quantum whatever the clocks (a dithered quantiser: Widrow & Kollár, *Quantization Noise*, Cambridge University
Press 2008, ch. 19), so where an item's spread is within the quantum its mean within :data:`TRIM` quanta of its
median is taken instead.

The ratio is judged by the sound speed it implies (:func:`check_scale`): the table's distances are right at the
speed ``c / scale`` (``c`` the speed the double differences were taken at). Water's speed lies within
:data:`SPEED_TOLERANCE` (7 %) of :data:`NOMINAL_SOUND_SPEED`, 1,376–1,584 m/s (fresh water near freezing to a warm
sea); a table needing a speed beyond that by more than :data:`REFUSE_FACTOR` is refused naming the unit it looks like
(:func:`likely_unit`: feet, yards, kilometres, degrees, ...), one within it is said in a warning line; a speed given
by the user that the travel times contradict by more than :data:`SPEED_TOLERANCE` is said too.

Units: seconds [s], metres [m] (the table's unit, whatever it is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError

#: The water's typical sound speed [m/s], the speed the double differences are taken at where none is given.
NOMINAL_SOUND_SPEED = 1480.0
#: The water's sound speed lies within this share of :data:`NOMINAL_SOUND_SPEED` (1,376–1,584 m/s).
SPEED_TOLERANCE = 0.07
#: A table whose distances need a sound speed beyond the water's range by more than this factor is refused; within
#: it, said (a 2-D table of receivers at very different depths, yards in warm water).
REFUSE_FACTOR = 1.25
#: Where the times are rounded: an item's double differences within this many quanta of their median are averaged.
TRIM = 4.0
#: The fewest emissions of one tag a pair of receivers must share for its double differences.
MIN_EMISSIONS = 3
#: The fewest double differences (pairs of receivers and tags) a scale is given on; fewer: no check.
MIN_ITEMS = 3
#: The longest interpolation of the clocks' difference between two emissions of the reference tag [s].
MAX_BRIDGE = 6 * 3600.0
#: The most pairs of arrivals of one emission the check forms (beyond, evenly spaced emissions are taken).
MAX_PAIRS = 1_000_000


@dataclass(frozen=True)
class Scale:
    """What :func:`distance_scale` found: ``scale`` (the travel times' distances over the table's), the double
    differences it rests on (``items``) over ``pairs`` pairs of receivers, and the medians of their absolute values
    [m] by sound (``acoustic_m``) and by the table (``table_m``)."""

    scale: float
    items: int
    pairs: int
    acoustic_m: float
    table_m: float


def _centre(values: np.ndarray, quantum: float) -> float:
    """An item's double difference [s] from its values over the emissions: their median, or where the times are
    rounded to ``quantum`` [s] and the values spread no wider than it, their mean within :data:`TRIM` quanta of the
    median (the module docstring)."""
    middle = float(np.median(values))
    if quantum <= 0 or float(np.median(np.abs(values - middle))) > quantum:
        return middle
    return float(np.mean(values[np.abs(values - middle) <= TRIM * quantum]))


def double_differences(receiver: np.ndarray, tag: np.ndarray, emission: np.ndarray, time: np.ndarray,
                       distance: np.ndarray, sound_speed: float, quantum: float = 0.0
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The clock-free double differences of the sync tags' arrivals and the table's (module docstring).

    Parameters
    ----------
    receiver, tag, emission : ndarray of int, (n,)
        Each arrival's receiver, sync tag and emission (one tag per emission).
    time : ndarray, (n,)
        [s] each arrival on its receiver's own clock.
    distance : ndarray, (n,)
        [m] the table's distance from the arrival's tag to its receiver.
    sound_speed : float
        [m/s].
    quantum : float
        [s] the times' rounding (:func:`sblsim.models.sync.resolution.time_quantum`; 0: none).

    Returns
    -------
    acoustic : ndarray, (k,)
        [m] each double difference's median (or mean, where rounded: the module docstring) times the sound speed.
    table : ndarray, (k,)
        [m] the table's value of each.
    pair : ndarray of int, (k,)
        Which pair of receivers each is of (a number per pair).
    """
    receiver, tag, emission = (np.asarray(a, np.int64) for a in (receiver, tag, emission))
    time, distance = np.asarray(time, float), np.asarray(distance, float)
    empty = np.empty(0), np.empty(0), np.empty(0, np.int64)
    if not len(receiver):
        return empty
    # the emissions taken (every one, or evenly spaced ones where their pairs of arrivals would exceed MAX_PAIRS)
    ems, local, size = np.unique(emission, return_inverse=True, return_counts=True)
    stride = int(np.ceil(np.sum(size * (size - 1) / 2) / MAX_PAIRS))
    keep = (local % max(stride, 1)) == 0
    receiver, tag, local, time, distance = receiver[keep], tag[keep], local[keep], time[keep], distance[keep]
    order = np.lexsort((receiver, local))
    receiver, tag, local, time, distance = (v[order] for v in (receiver, tag, local, time, distance))
    # every pair of arrivals of one emission, the lower receiver first
    first, second = [], []
    for gap in range(1, int(size.max())):
        same = np.flatnonzero(local[gap:] == local[:-gap])
        if not len(same):
            break
        first.append(same)
        second.append(same + gap)
    if not first:
        return empty
    i, j = np.concatenate(first), np.concatenate(second)
    i, j = i[receiver[i] != receiver[j]], j[receiver[i] != receiver[j]]  # a receiver's second arrival: no pair
    n_rec = int(receiver.max()) + 1
    key = receiver[i] * n_rec + receiver[j]  # receiver[i] < receiver[j]: sorted within an emission
    sd, g, t, who = time[j] - time[i], distance[j] - distance[i], time[i], tag[i]
    order = np.lexsort((t, who, key))
    key, sd, g, t, who = key[order], sd[order], g[order], t[order], who[order]
    acoustic, table, pairs = [], [], []
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    for a, b in zip(starts, np.r_[starts[1:], len(key)]):
        if b - a < 2 * MIN_EMISSIONS:
            continue
        tags, counts = np.unique(who[a:b], return_counts=True)
        if (counts >= MIN_EMISSIONS).sum() < 2:
            continue
        ref = tags[np.argmax(counts)]
        mine = slice(a, b)
        is_ref = who[mine] == ref
        t_ref, sd_ref, g_ref = t[mine][is_ref], sd[mine][is_ref], float(np.median(g[mine][is_ref]))
        for u in tags[(counts >= MIN_EMISSIONS) & (tags != ref)]:
            other = who[mine] == u
            tu = t[mine][other]
            k = np.searchsorted(t_ref, tu)
            kk = np.clip(k, 1, len(t_ref) - 1)
            inside = (k > 0) & (k < len(t_ref)) & ((t_ref[kk] - t_ref[kk - 1]) <= MAX_BRIDGE)
            if inside.sum() < MIN_EMISSIONS:
                continue
            dd = sd[mine][other][inside] - np.interp(tu[inside], t_ref, sd_ref)
            acoustic.append(_centre(dd, quantum) * sound_speed)
            table.append(float(np.median(g[mine][other])) - g_ref)
            pairs.append(int(key[a]))
    return np.array(acoustic), np.array(table), np.array(pairs, np.int64)


def distance_scale(acoustic: np.ndarray, table: np.ndarray, pair: np.ndarray) -> Scale | None:
    """The factor between the travel times' distances and the table's (module docstring), or None where fewer than
    :data:`MIN_ITEMS` double differences are not zero in the table.

    Parameters
    ----------
    acoustic, table : ndarray, (k,)
        [m] the double differences by sound and by the table (:func:`double_differences`).
    pair : ndarray of int, (k,)
        Their pairs of receivers.
    """
    acoustic, table, pair = np.asarray(acoustic, float), np.asarray(table, float), np.asarray(pair)
    size = np.abs(table)
    usable = np.isfinite(acoustic) & np.isfinite(table) & (size > 0)
    if usable.sum() < MIN_ITEMS:
        return None
    large = usable & (size >= np.median(size[usable]))
    ratio = acoustic[large] / table[large]
    return Scale(float(np.median(ratio)), int(large.sum()), int(len(np.unique(pair[large]))),
                 float(np.median(np.abs(acoustic[large]))), float(np.median(size[large])))


def looks_like_degrees(x: np.ndarray, y: np.ndarray) -> bool:
    """Whether coordinates look like longitudes ``x`` and latitudes ``y`` in degrees: every value within [-180, 180]
    × [-90, 90], spread over less than a unit, and the place away from (0, 0) by more than its spread."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    if not len(x) or not (np.isfinite(x).all() and np.isfinite(y).all()):
        return False
    spread = max(float(np.ptp(x)), float(np.ptp(y)))
    centre = float(np.hypot(np.mean(x), np.mean(y)))
    return bool(np.abs(x).max() <= 180.0 and np.abs(y).max() <= 90.0 and spread < 1.0 and centre > spread)


#: The units a receivers table may be in by mistake: the factor of their distances to metres' (the double
#: differences' scale, :func:`distance_scale`) and how far in log10 a scale may be from it to be named (near 1 the
#: water's sound speed, ±7 %, and the estimate's spread; far from it an order of magnitude's half).
UNITS = {"kilometres": (1e3, 0.3), "centimetres": (1e-2, 0.3), "millimetres": (1e-3, 0.3),
         "feet": (0.3048, 0.06), "yards": (0.9144, 0.06)}


def likely_unit(scale: float, degrees: bool) -> str:
    """The unit a table seems to be in, given the factor ``scale`` its distances are below the travel times' (at
    :data:`NOMINAL_SOUND_SPEED`) and whether its values look like degrees (:func:`looks_like_degrees`): the nearest
    of :data:`UNITS` within its reach, else the factor."""
    if not np.isfinite(scale) or scale <= 0:
        return "not metres (the travel times do not follow the table's distances)"
    if degrees and scale > 1e4:
        return "degrees (latitude and longitude)"
    off = {name: abs(np.log10(scale / factor)) for name, (factor, _) in UNITS.items()}
    name = min(off, key=off.get)
    return name if off[name] < UNITS[name][1] else f"metres × {1.0 / scale:.3g}"


def check_scale(found: Scale | None, where: str, x: np.ndarray, y: np.ndarray, allowed: str,
                sound_speed: float = NOMINAL_SOUND_SPEED, given: bool = False) -> str | None:
    """Judge a receivers table's distances by the sound speed the travel times need of them (module docstring).

    Parameters
    ----------
    found : Scale or None
        :func:`distance_scale`'s (None: too few double differences; a table of degrees refused all the same).
    where : str
        The declaration the message names (e.g. the receivers file).
    x, y : ndarray
        The table's coordinates (for :func:`looks_like_degrees`).
    allowed : str
        What the message allows.
    sound_speed : float
        [m/s] the speed the double differences were taken at.
    given : bool
        Whether the user gave that speed (a constant or a series; else :data:`NOMINAL_SOUND_SPEED`).

    Returns
    -------
    str or None
        One warning line: the speed the table needs outside the water's range within :data:`REFUSE_FACTOR`, or a
        given speed it contradicts by more than :data:`SPEED_TOLERANCE`; else None.

    Raises
    ------
    ModelError
        One line naming ``where``, the factor, the distances by sound and by the table, the speed they need, the unit
        the table looks like, and ``allowed``; or, with no double difference to judge by, a table of degrees.
    """
    degrees = looks_like_degrees(x, y)
    if found is None:
        if degrees:
            raise ModelError(f"{where}: the positions span less than a unit around ({np.mean(x):.6g}, "
                             f"{np.mean(y):.6g}): they look like degrees (latitude and longitude); allowed: {allowed}")
        return None
    low, high = NOMINAL_SOUND_SPEED * (1 - SPEED_TOLERANCE), NOMINAL_SOUND_SPEED * (1 + SPEED_TOLERANCE)
    needed = sound_speed / found.scale if found.scale > 0 else np.inf
    told = (f"the sync tags' travel times put the receivers {found.scale:.4g} times as far apart as the positions do "
            f"(median {found.acoustic_m:.4g} m by sound at {sound_speed:.4g} m/s, {found.table_m:.4g} by the table, "
            f"over {found.pairs} pairs of receivers, clock-free: the table's distances need a sound speed of "
            f"{needed:.4g} m/s, the water's is {low:.0f}-{high:.0f})")
    if np.isfinite(needed) and low <= needed <= high:
        if given and abs(needed / sound_speed - 1) > SPEED_TOLERANCE:
            return (f"{where}: the sync tags' travel times fit the table's distances at {needed:.4g} m/s, not at the "
                    f"{sound_speed:.4g} m/s given ({100 * abs(needed / sound_speed - 1):.3g} % apart, over "
                    f"{found.pairs} pairs of receivers, clock-free): the sound speed given, or the positions' unit, "
                    "is off")
        return None
    unit = likely_unit(NOMINAL_SOUND_SPEED / needed if np.isfinite(needed) else 0.0, degrees)
    if np.isfinite(needed) and low / REFUSE_FACTOR <= needed <= high * REFUSE_FACTOR:
        depths = ", or the receivers' depths missing (a 2-D table)" if needed < low else ""
        return f"{where}: {told}; the positions may be in {unit}{depths}"
    raise ModelError(f"{where}: {told}; the positions look like {unit}; allowed: {allowed}")


__all__ = ["MAX_BRIDGE", "MAX_PAIRS", "MIN_EMISSIONS", "MIN_ITEMS", "NOMINAL_SOUND_SPEED", "REFUSE_FACTOR",
           "SPEED_TOLERANCE", "Scale", "TRIM", "UNITS", "check_scale", "distance_scale", "double_differences",
           "likely_unit", "looks_like_degrees"]

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
kilometres and about 10⁵ for degrees (a degree of latitude is 111 km); beyond :data:`SCALE_LIMIT` either way the
table is refused (:func:`check_scale`) naming the unit it looks like (:func:`likely_unit`).

Units: seconds [s], metres [m] (the table's unit, whatever it is).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sblsim.models.declarations import ModelError

#: The largest factor between the table's distances and the travel times' before the table is refused (either way).
SCALE_LIMIT = 10.0
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


def double_differences(receiver: np.ndarray, tag: np.ndarray, emission: np.ndarray, time: np.ndarray,
                       distance: np.ndarray, sound_speed: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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

    Returns
    -------
    acoustic : ndarray, (k,)
        [m] each double difference's median times the sound speed.
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
            acoustic.append(float(np.median(dd)) * sound_speed)
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


def likely_unit(scale: float, degrees: bool) -> str:
    """The unit a table seems to be in, given the factor ``scale`` its distances are below the travel times' and
    whether its values look like degrees (:func:`looks_like_degrees`)."""
    if not np.isfinite(scale) or scale <= 0:
        return "not metres (the travel times do not follow the table's distances)"
    if degrees and scale > 1e4:
        return "degrees (latitude and longitude)"
    named = {1e3: "kilometres", 1e-2: "centimetres", 1e-3: "millimetres", 3.28084e-1: "feet"}
    for factor, name in named.items():
        if abs(np.log10(scale / factor)) < 0.3:
            return name
    return f"metres × {1.0 / scale:.3g}"


def check_scale(found: Scale | None, where: str, x: np.ndarray, y: np.ndarray, allowed: str) -> None:
    """Refuse a receivers table whose distances differ from the travel times' by more than :data:`SCALE_LIMIT`.

    Parameters
    ----------
    found : Scale or None
        :func:`distance_scale`'s (None: nothing to check).
    where : str
        The declaration the message names (e.g. the receivers file).
    x, y : ndarray
        The table's coordinates (for :func:`looks_like_degrees`).
    allowed : str
        What the message allows.

    Raises
    ------
    ModelError
        One line naming ``where``, the factor, the distances by sound and by the table, the unit the table looks
        like, and ``allowed``.
    """
    if found is None or 1.0 / SCALE_LIMIT <= found.scale <= SCALE_LIMIT:
        return
    unit = likely_unit(found.scale, looks_like_degrees(x, y))
    raise ModelError(f"{where}: the sync tags' travel times put the receivers {found.scale:.4g} times as far apart "
                     f"as the positions do (median {found.acoustic_m:.4g} m by sound, {found.table_m:.4g} by the "
                     f"table, over {found.pairs} pairs of receivers, clock-free); the positions look like {unit}; "
                     f"allowed: {allowed}")


__all__ = ["MAX_BRIDGE", "MAX_PAIRS", "MIN_EMISSIONS", "MIN_ITEMS", "SCALE_LIMIT", "Scale", "check_scale",
           "distance_scale", "double_differences", "likely_unit", "looks_like_degrees"]

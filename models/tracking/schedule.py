"""When a tag pings: the field's ping types as the time between successive rows of a TOA matrix.

A tag emits on its own clock. The ping types of acoustic telemetry (Baktoft et al. 2017; YAPS's ``pingType``):

* ``sbi``, a **stable burst interval**: every ``Δ`` seconds, ``Δ`` known only roughly and drifting slowly (the
  tracker's state carries it). Successive rows of the matrix are ``n_k Δ`` apart, ``n_k`` the pings elapsed
  (1, or more where rows are missing: a gap, a ping nobody heard);
* ``rbi``, a **random burst interval**: each emission a uniform draw ``U(min, max)`` after the previous one (the
  collision avoidance of Innovasea/Vemco, Thelma Biotel and Lotek fish tags, e.g. 20–40 s or 60–180 s). The
  interval is not a state that drifts: each step is its own unknown;
* ``pbi``, a **pseudo-random burst interval**: the intervals follow a sequence the maker gives (a table), aligned
  here to the rows by their first arrivals.

The tracker's motion model runs on **time, not ping count**: step k (from row k to row k + 1) lasts
``T_k = n_k Δ + o_k`` [s], where ``(n_k, o_k)`` is ``(n_k, 0)`` for ``sbi`` and ``(0, o_k)`` for ``rbi`` and ``pbi``
(``o_k`` the step's own duration), and the white-noise acceleration's covariance grows with ``T_k`` (Bar-Shalom, Li
& Kirubarajan, *Estimation with Applications to Tracking and Navigation*, Wiley 2001, § 6.2), so gaps, missing
rows and random intervals are one case.

How the random interval enters a Gaussian filter and the smoother's quadratic cost: the emission time's step is
``T_k`` with a Gaussian error ``σ_k``. For ``rbi`` its centre ``o_k`` is the step of the rows' **first arrivals**
(each ping's earliest time of arrival), which differs from the step of the emissions by the change of the first
arrival's travel time, at most the array's crossing time ``D / c`` (D the largest distance between two receivers):
``σ_k = D / c``. This is tighter than the uniform's own spread (its standard deviation ``(max − min) / √12``, 5.8 s
for U(20, 40) s) by two orders of magnitude, and it holds for any ``min``, ``max`` and any missing row; the
arrivals then fix each emission time to ``σ_toa`` (the uniform's bounds add nothing the arrivals do not). The
bounds are kept as a check (:func:`build_schedule`).

Units: seconds [s].

References
----------
Baktoft, Gjelland, Økland, Thygesen, "Positioning of aquatic animals based on time-of-arrival and random walk
models using YAPS (Yet Another Positioning Solver)", Scientific Reports 7:14294, 2017,
doi:10.1038/s41598-017-14278-z (the ping types and their emission-time models).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.tracking.burst_sequence import align_sequence

#: The ping types, by the field's names.
PING_TYPES = {"sbi": "stable burst interval", "rbi": "random burst interval",
              "pbi": "pseudo-random burst interval (a known sequence)"}
#: A step counts as a gap (a new track segment, reported) when it is longer than this many typical steps and than
#: :data:`GAP_MIN_S`.
GAP_FACTOR = 10.0
GAP_MIN_S = 60.0
#: The smallest emission-time step error of ``rbi`` and ``pbi`` steps [s] (a compact array's crossing time).
MIN_STEP_SIGMA = 1e-3
#: A stable interval stated for a tag is refused where the rows' steps miss whole multiples of their best interval
#: by more than this many crossing times (90 % of them; the inference calls a spread of 2 stable,
#: :func:`~sblsim.models.tracking.ping_type.infer_ping_type`), or by more than :data:`SBI_SHARE` of the interval
#: (:func:`check_stable`).
SBI_CROSSINGS = 4.0
SBI_SHARE = 0.02
#: The divisors of the typical step tried as the stable interval (a tag heard at every second ping or less).
SBI_DIVISORS = (1, 2, 3, 4)


@dataclass(frozen=True)
class PingSchedule:
    """The steps between successive rows of a TOA matrix (m rows, m − 1 steps).

    Attributes
    ----------
    kind : str
        ``sbi``, ``rbi`` or ``pbi`` (:data:`PING_TYPES`).
    interval : float
        The nominal interval Δ [s] (``sbi``: the state's start; ``rbi``, ``pbi``: the typical step).
    count : ndarray, (m − 1,)
        ``n_k``: intervals Δ in step k (``sbi``; 0 otherwise).
    offset : ndarray, (m − 1,)
        ``o_k``: the step's fixed duration [s] (``rbi``, ``pbi``; 0 for ``sbi``).
    te_sigma : ndarray, (m − 1,)
        The standard deviation of the emission time's step about ``n_k Δ + o_k`` [s].
    drift_sigma : ndarray, (m − 1,)
        The standard deviation of Δ's random-walk step [s].
    bounds : tuple of float or None
        ``rbi``: the interval's (min, max) [s], given or seen.
    gaps : tuple of int
        The steps longer than the gap bound (:data:`GAP_FACTOR`): each starts a new track segment.
    source : str
        How the type was chosen: ``given`` or ``inferred``.
    """

    kind: str
    interval: float
    count: np.ndarray
    offset: np.ndarray
    te_sigma: np.ndarray
    drift_sigma: np.ndarray
    bounds: tuple[float, float] | None = None
    gaps: tuple[int, ...] = ()
    source: str = "given"

    def steps(self, interval: float | None = None) -> np.ndarray:
        """The steps' durations ``n_k Δ + o_k`` [s] (m − 1,), at Δ = ``interval`` (default the nominal one)."""
        return self.count * (self.interval if interval is None else interval) + self.offset

    def times(self) -> np.ndarray:
        """The rows' times from the first [s] (m,) at the nominal Δ."""
        return np.r_[0.0, np.cumsum(self.steps())]

    def segments(self) -> list[tuple[int, int]]:
        """The track's segments: (first row, last row + 1) between the gaps."""
        edges = [0, *[g + 1 for g in self.gaps], len(self.count) + 1]
        return list(zip(edges[:-1], edges[1:]))

    def sliced(self, start: int) -> PingSchedule:
        """The schedule of the rows from ``start`` on."""
        return replace(self, count=self.count[start:], offset=self.offset[start:], te_sigma=self.te_sigma[start:],
                       drift_sigma=self.drift_sigma[start:], gaps=tuple(g - start for g in self.gaps if g >= start))

    def rows(self, first: int, end: int) -> PingSchedule:
        """The schedule of the rows ``first`` to ``end`` − 1 alone (their steps, and the gaps among them)."""
        last = max(end - 1, first)  # the steps first .. end − 2
        return replace(self, count=self.count[first:last], offset=self.offset[first:last],
                       te_sigma=self.te_sigma[first:last], drift_sigma=self.drift_sigma[first:last],
                       gaps=tuple(g - first for g in self.gaps if first <= g < last))

    @classmethod
    def stable(cls, m: int, interval: float, jitter: float, drift: float) -> PingSchedule:
        """Every row one interval after the previous (the stable burst interval with no row missing)."""
        ones = np.ones(max(m - 1, 0))
        return cls("sbi", float(interval), ones, 0.0 * ones, jitter * ones, drift * ones)


def first_arrivals(toa: np.ndarray) -> np.ndarray:
    """Each row's earliest time of arrival [s] (m,), NaN where nobody heard the ping; ``toa`` (m, n) [s]."""
    toa = np.asarray(toa, float)
    heard = np.isfinite(toa).any(axis=1)
    out = np.full(len(toa), np.nan)
    out[heard] = np.nanmin(toa[heard], axis=1)
    return out


def first_arrival_steps(toa: np.ndarray) -> np.ndarray:
    """The steps of the rows' first arrivals [s] (m − 1,); a row nobody heard takes a share of the step across it
    (its time interpolated by row), and one before the first row heard or after the last the heard rows' median
    step per row (its time extrapolated: a step of no duration would have no process noise).

    Raises
    ------
    ModelError
        If fewer than 2 rows were heard, or the first arrivals decrease (the rows are not in time order).
    """
    first = first_arrivals(toa)
    heard = np.flatnonzero(np.isfinite(first))
    if len(heard) < 2:
        raise ModelError(f"toa: {len(heard)} pings heard; allowed: at least 2")
    back = np.flatnonzero(np.diff(first[heard]) <= 0)
    if len(back):
        k = heard[back[0] + 1]
        j = heard[back[0]]
        raise ModelError(f"toa: row {k + 1}'s first arrival ({first[k]:.6f} s) is not after row {j + 1}'s "
                         f"({first[j]:.6f} s); allowed: rows of successive pings in time order")
    return _row_steps(first[heard], heard, len(first))


def _row_steps(times: np.ndarray, heard: np.ndarray, m: int) -> np.ndarray:
    """The steps of m rows [s] (m − 1,) from the times [s] of the rows ``heard`` (increasing indices): a row between
    heard ones takes its time interpolated by row, one before the first or after the last the heard rows' median
    step per row."""
    rows = np.arange(m)
    out = np.interp(rows, heard, times)
    per_row = float(np.median(np.diff(times) / np.diff(heard)))
    out = np.where(rows < heard[0], times[0] - (heard[0] - rows) * per_row, out)
    out = np.where(rows > heard[-1], times[-1] + (rows - heard[-1]) * per_row, out)
    return np.diff(out)


def crossing_time(receivers: np.ndarray, c: float) -> float:
    """The array's crossing time [s]: the largest distance between two receivers (n, dim) [m] over the sound speed
    ``c`` [m/s], at least :data:`MIN_STEP_SIGMA`."""
    r = np.asarray(receivers, float)
    span = float(np.max(np.linalg.norm(r[:, None] - r[None], axis=2))) if len(r) > 1 else 0.0
    return max(span / c, MIN_STEP_SIGMA)


def check_stable(toa: np.ndarray, crossing: float) -> float | None:
    """Refuse a stable burst interval (``sbi``) that the rows' first arrivals contradict: their steps are not whole
    multiples of one interval within the tolerance, ``max(SBI_CROSSINGS × crossing, SBI_SHARE × interval)`` for 90 %
    of them, at the best of the typical step divided by :data:`SBI_DIVISORS` (a tag heard at every second ping or
    less has a typical step of several intervals), each refined by least squares on its whole numbers over the steps
    within the tolerance of them (a stray row's two part-steps left out).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    crossing : float
        The array's crossing time [s] (:func:`crossing_time`): how much the first arrival's travel time may change.

    Returns
    -------
    float or None
        The stable interval the steps fit [s] (least squares on their whole numbers); None where fewer than three
        steps say anything.

    Raises
    ------
    ModelError
        One line naming the stated type, the range of the steps the pings show, their misfit and what is allowed;
        as :func:`first_arrival_steps`.
    """
    first_arrival_steps(toa)  # the rows in time order
    first = first_arrivals(toa)
    d = np.diff(first[np.isfinite(first)])  # between heard rows: a row heard by nobody is missed or set aside
    positive = d[d > 0]
    if len(positive) < 3:
        return None
    typical = float(np.median(positive))
    best = (np.inf, typical, np.inf)
    for k in SBI_DIVISORS:
        delta = typical / k
        n = np.maximum(np.round(d / delta), 1.0)
        # the interval that fits these whole numbers best, from the steps within the tolerance of them (a stray row
        # splits a step into two that are no multiples: left in, they pull the interval off the pings' own)
        near = np.abs(d - n * delta) <= max(SBI_CROSSINGS * crossing, SBI_SHARE * delta)
        fit = near if near.sum() >= 3 else np.ones_like(near)
        delta = float(np.sum(n[fit] * d[fit]) / np.sum(n[fit] * n[fit]))
        n = np.maximum(np.round(d / delta), 1.0)
        spread = float(np.percentile(np.abs(d - n * delta), 90))
        tolerance = max(SBI_CROSSINGS * crossing, SBI_SHARE * delta)
        if spread <= tolerance:
            return delta
        if spread / tolerance < best[0]:
            best = (spread / tolerance, delta, spread)
    n = np.maximum(np.round(d / typical), 1.0)
    single = d[n == 1] if (n == 1).any() else d
    low, high = np.percentile(single, [2, 98])
    raise ModelError(f"ping type sbi: the pings' first arrivals are {low:.4g} to {high:.4g} s apart (2nd to 98th "
                     f"percentile of {len(d)} steps), not whole multiples of one interval: at the best, "
                     f"{best[1]:.4g} s, 90 % of the steps are off by up to {best[2]:.3g} s, beyond the "
                     f"{max(SBI_CROSSINGS * crossing, SBI_SHARE * best[1]):.3g} s a stable interval allows; allowed: "
                     f"the tag's own ping type (a random interval: rbi with --burst-interval {np.floor(low):g}:"
                     f"{np.ceil(high):g}; or none, inferred)")


def build_schedule(toa: np.ndarray, kind: str, interval: float, jitter: float, drift: float, crossing: float,
                   bounds: tuple[float, float] | None = None, sequence: np.ndarray | None = None,
                   source: str = "given") -> PingSchedule:
    """The steps between the rows of ``toa`` for a ping type (module docstring).

    Parameters
    ----------
    toa : ndarray, (m, n)
        Times of arrival [s], NaN where not heard.
    kind : str
        ``sbi``, ``rbi`` or ``pbi``.
    interval : float
        The nominal interval Δ [s] (``sbi``), or the typical step (``rbi``).
    jitter : float
        The emission time's error per ping beyond the model [s] (``sbi``, ``pbi``).
    drift : float
        Δ's random-walk step per ping [s].
    crossing : float
        The array's crossing time [s] (:func:`crossing_time`): the step error of ``rbi`` steps.
    bounds : (float, float), optional
        ``rbi``: the interval's (min, max) [s]; a step between successive heard rows shorter than ``min`` by more
        than the crossing time is refused (set such rows aside first:
        :func:`~sblsim.models.tracking.strays.stray_rows`); a row heard by nobody is no ping and counts as no interval.
    sequence : ndarray, optional
        ``pbi``: the intervals [s] in the tag's order, repeating
        (:func:`~sblsim.models.tracking.burst_sequence.align_sequence`), aligned on the heard rows' steps.
    source : str
        ``given`` or ``inferred`` (kept in the schedule).

    Returns
    -------
    PingSchedule

    Raises
    ------
    ModelError
        An unknown type, a bad interval, a ``pbi`` without a sequence, steps that break the given bounds, or a
        stable interval given that the steps contradict (:func:`check_stable`).
    """
    if kind not in PING_TYPES:
        raise ModelError(f"ping type: {kind!r}; allowed: {', '.join(PING_TYPES)}")
    if not (np.isfinite(interval) and interval > 0):
        raise ModelError(f"burst interval: {interval} s; allowed: a positive number of seconds")
    d = first_arrival_steps(toa)
    zeros = np.zeros_like(d)
    if kind == "sbi" and source == "given":
        check_stable(toa, crossing)
    if kind == "sbi":
        n = _stable_counts(toa, d, interval)
        count, offset, te, dr = n, zeros, jitter * np.sqrt(n), drift * np.sqrt(n)
    elif kind == "rbi":
        if bounds is not None:
            low, high = bounds
            if not 0 < low <= high:
                raise ModelError(f"burst interval: {low}:{high} s; allowed: 0 < min <= max")
            _check_shortest(toa, low, crossing)
        count, offset, te, dr = zeros, d.copy(), np.full_like(d, crossing), np.full_like(d, drift)
    else:
        if sequence is None or not len(sequence):
            raise ModelError("ping type pbi: no burst sequence; allowed: --burst-sequence FILE (the intervals [s])")
        # aligned on the heard rows' steps: a row heard by nobody is no ping (its time unknown), the step across it
        # shared by row as first_arrival_steps shares it
        first = first_arrivals(toa)
        heard = np.flatnonzero(np.isfinite(first))
        durations, aligned = align_sequence(np.diff(first[heard]), np.asarray(sequence, float), crossing)
        offset = _row_steps(first[heard[0]] + np.r_[0.0, np.cumsum(durations)], heard, len(first))
        matched = np.zeros(len(d), bool)
        single = np.diff(heard) == 1  # a heard row's step to the next heard row, none between
        matched[heard[:-1][single]] = aligned[single]
        count = zeros
        te = np.where(matched, np.maximum(jitter, MIN_STEP_SIGMA), crossing)
        dr = np.full_like(d, drift)
    steps = count * interval + offset
    typical = float(np.median(steps)) if len(steps) else interval
    gaps = tuple(int(k) for k in np.flatnonzero(steps > max(GAP_FACTOR * typical, GAP_MIN_S)))
    return PingSchedule(kind, float(interval), count, offset, te, dr, bounds, gaps, source)


def _stable_counts(toa: np.ndarray, d: np.ndarray, interval: float) -> np.ndarray:
    """A stable interval's pings elapsed per row step (m − 1,): between two heard rows, the whole number of
    ``interval`` [s] their first arrivals are apart (at least 1), shared evenly by the row steps between them (a row
    heard by nobody between, a missed ping or a row set aside, splits the count, not adds to it); before the first
    heard row and after the last, each row step's own (``d`` [s], :func:`first_arrival_steps`)."""
    n = np.maximum(np.round(d / interval), 1.0)
    first = first_arrivals(toa)
    heard = np.flatnonzero(np.isfinite(first))
    rows = np.diff(heard)
    whole = np.maximum(np.round(np.diff(first[heard]) / interval), 1.0)
    for a, r, w in zip(heard[:-1][rows > 1], rows[rows > 1], whole[rows > 1]):
        n[a:a + r] = w / r
    return n


def _check_shortest(toa: np.ndarray, low: float, crossing: float) -> None:
    """Refuse rows whose first arrivals come sooner than a random interval's min ``low`` [s] allows, less the
    crossing time [s], after the previous heard row. A row heard by nobody is no ping (its time is unknown): it
    neither counts as an interval nor is checked. A caller that sets strays aside first
    (:func:`~sblsim.models.tracking.strays.stray_rows`) leaves none.

    Raises
    ------
    ModelError
        One line naming the rows and their step.
    """
    first = first_arrivals(toa)
    heard = np.flatnonzero(np.isfinite(first))
    span = np.diff(first[heard])
    short = np.flatnonzero(span < low - crossing)
    if not len(short):
        return
    k = int(short[0])
    a, b = int(heard[k]) + 1, int(heard[k + 1]) + 1
    raise ModelError(f"burst interval: rows {a} and {b} are {span[k]:.3f} s apart by their first arrivals, below "
                     f"the random interval's min {low:g} s; allowed: the tag's --burst-interval MIN:MAX, and no row "
                     "closer to the previous one (set aside first: stray_rows)")


__all__ = ["GAP_FACTOR", "GAP_MIN_S", "MIN_STEP_SIGMA", "PING_TYPES", "SBI_CROSSINGS", "SBI_DIVISORS", "SBI_SHARE",
           "PingSchedule", "build_schedule", "check_stable", "crossing_time", "first_arrival_steps", "first_arrivals"]

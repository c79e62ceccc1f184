"""A season's clocks fitted in windows: the cost linear in the season's length and a fit's memory that of one window.

The clock model (:mod:`sblsim.models.sync.clocks`) couples a receiver's knots to its neighbours' only (the drift
prior's second differences, the emissions shared at one instant): in time order its normal equations are block
tridiagonal, and an arrival's information on a knot decays within a few bins of it. So a season is fitted
(:func:`fit_in_windows`) in **windows** of a whole number of bins, each fitted on its own
(:mod:`sblsim.models.sync.season`: :func:`~sblsim.models.sync.breaks.fit_with_breaks`, the reweighting, the
rejections, the breaks found, the noise scales) with the arrivals of an **overlap** either side, and each window's
clocks kept over its own span alone:

* each emission belongs to the window that holds its first arrival (its arrivals are never split between two
  windows); a window's fit sees the emissions within the overlap of its span (:func:`season_windows`);
* the knots kept are those on the window's own span, its edges included; at an edge two windows share, the two
  estimates (each with the overlap's data on its far side) are averaged, weighted by their inverse variances, so a
  clock's offset is continuous from one window to the next and its drift runs on across the edge (the bins either
  side fitted with the same arrivals of the overlap);
* a clock segment (:mod:`sblsim.models.sync.breaks`) that runs on past a window's edge is joined with the next
  window's segment of the same receiver and clock part that starts before it: a break is found by whichever window
  holds it, in its span or in its overlap (a break at a window's edge is inside both windows' fits), and kept from
  the window whose span holds its instant;
* bins no window's knots reach (a receiver out of the water for a window) are bridged by linear interpolation, the
  clock's ends extended with their end bins' drifts, as the drift prior bridges them in one fit;
* a window the reference receiver no longer hears (recovered: its clock gone) is fitted against another receiver's
  clock, and put on the reference's by that receiver's offset **carried** from the last window that synchronised it
  (the line through its offsets there carried on from the edge): the time base runs on as the reference's clock
  would, where no arrival sees it (the emissions' times absorb any common change of all clocks; one fit extends it
  by its drift prior alone).

Each arrival's residual, weight and rejection are its own emission's window's; each clock's noise scale the
arrivals-weighted root mean square of its windows' scales; an estimated slowness each window's own (the water
changes over a season), the fit's the windows' as a random effect (:func:`season_slowness`: where the windows
disagree beyond their sigmas, each one a draw of the season's water, their spread said). The overlap's length is
the choice that makes the windows' clocks the whole fit's: at :data:`OVERLAP_HOURS` and hourly bins the two agree
within a tenth of the offsets' sigma on a simulated fortnight (the tests). Units: seconds [s] throughout, times
from the caller's origin.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from sblsim.models.declarations import ModelError
from sblsim.models.sync.clock_fit import ClockFit

#: The windows' default length [days] and the overlap each side [h].
WINDOW_DAYS = 7.0
OVERLAP_HOURS = 12.0


@dataclass
class Windows:
    """A season cut into windows: ``edges`` (W+1,) [s] the windows' own spans' edges (a whole number of bins apart;
    the first window open before ``edges[0]``, the last after ``edges[-1]``) and ``overlap`` [s] each side."""

    edges: np.ndarray
    overlap: float

    def __len__(self) -> int:
        return len(self.edges) - 1

    def span(self, i: int) -> tuple[float, float]:
        """[s] window ``i``'s own span (±inf at the season's ends)."""
        return (-np.inf if i == 0 else float(self.edges[i]),
                np.inf if i == len(self) - 1 else float(self.edges[i + 1]))


def season_windows(time: np.ndarray, bin_width: float, window: float, overlap: float) -> Windows | None:
    """The windows of ``window`` [s] (rounded to whole bins of ``bin_width`` [s]) over the arrivals' ``time`` (n,)
    [s], each with ``overlap`` [s] either side; None where the span is within one window and its overlaps (one fit).

    Raises
    ------
    ModelError
        A window shorter than a bin or an overlap shorter than a bin.
    """
    if not window >= bin_width or not overlap >= bin_width:
        raise ModelError(f"sync: windows of {window / 86400:g} days with {overlap / 3600:g} h of overlap; allowed: "
                         f"each at least a bin ({bin_width / 3600:g} h)")
    time = np.asarray(time, float)
    if not len(time):
        return None
    start = np.floor(time.min() / bin_width) * bin_width
    step = max(1, int(round(window / bin_width))) * bin_width
    span = float(time.max() - start)
    if span <= step + 2 * overlap:
        return None
    count = max(2, int(round(span / step)))  # the last window up to half a window longer, none a sliver
    return Windows(start + step * np.arange(count + 1), float(overlap))


@dataclass
class _Piece:
    """A window's clock row kept over the window's own span."""

    window: int
    row: int
    key: tuple[int, int]  # the receiver and the clock part
    span: tuple[float, float]  # the row's own span in its window's fit (±inf open)
    start: float  # where it begins within the window's span
    open_start: bool
    open_end: bool


def fit_in_windows(fit_one: Callable[[np.ndarray], ClockFit], windows: Windows, receiver: np.ndarray,
                   time: np.ndarray, emission: np.ndarray, n_rows: int, reference: int, arrivals: bool = True
                   ) -> ClockFit:
    """The clocks of a season fitted window by window and joined (the module docstring).

    Parameters
    ----------
    fit_one : callable
        ``fit_one(rows)``: the clocks fitted to the arrivals ``rows`` (m,) int (indices into the season's arrays, in
        their order), with their rows numbered as the season's (a receiver's row its index; a later clock segment's
        after them), e.g. :func:`~sblsim.models.sync.breaks.fit_with_breaks` on those arrivals.
    windows : Windows
        :func:`season_windows`.
    receiver : numpy.ndarray
        (n,) int, each arrival's clock row before any break (its receiver, or the row ``fit_one`` is given for it).
    time : numpy.ndarray
        (n,) [s] each arrival on its receiver's clock.
    emission : numpy.ndarray
        (n,) int >= 0, each arrival's emission.
    n_rows : int
        The season's clock rows before any break (the receivers).
    reference : int
        The receiver whose clock is the season's time base (its offsets 0). A window ``fit_one`` fits against
        another receiver's clock (the reference's recovered) is put on it by that receiver's offset carried from the
        last earlier window that synchronised it (the line through its offsets there).
    arrivals : bool
        False: the clocks alone (a refit whose arrivals' residuals nobody reads, e.g. a sync tag's leave-one-out):
        each window's per-arrival arrays let go as soon as it is fitted, and the season's fit's ``residual``,
        ``standardised``, ``kept`` and ``emission_time`` empty, ``clock`` None; its clocks, scales, slowness and
        breaks are the same, so a refit's memory is one window's whatever the season's length.

    Returns
    -------
    ClockFit
        The season's clocks on the bins of all windows (rows: a receiver's first segment at its index, later
        segments after them; without a break in any window one row per receiver, as one fit gives them).

    Raises
    ------
    ModelError
        As ``fit_one``, the window's span named; the first window not against ``reference``; a later one against a
        receiver no earlier window synchronised.
    """
    time = np.asarray(time, float)
    emission = np.asarray(emission, np.int64)
    first = np.full(int(emission.max(initial=-1)) + 1, np.inf)
    np.minimum.at(first, emission, time)
    instant = first[emission]  # each arrival's emission's first arrival: the window it belongs to
    fits: list[tuple[int, np.ndarray, ClockFit]] = []
    for i in range(len(windows)):
        lo, hi = windows.span(i)
        rows = np.flatnonzero((instant >= lo - windows.overlap) & (instant < hi + windows.overlap))
        if not len(rows):
            continue
        try:
            fit = fit_one(rows)
        except ModelError as exc:
            raise ModelError(f"{exc} (in the window from {max(lo, instant.min()):.0f} s to {min(hi, instant.max()):.0f}"
                             " s of the clocks' time base: fitted in windows, each window needs its own sync-tag "
                             "emissions heard by two receivers)") from None
        if not arrivals:  # (its rows' arrays not held while the next windows are fitted)
            fit = _clocks_only(fit)
        if not fits and _reference(fit) != reference:
            raise ModelError(f"sync: the reference receiver ({reference}) ties no other receiver in the season's first "
                             "window; allowed: a reference receiver in the water from the start (--reference)")
        fits.append((i, rows if arrivals else None, _carried(fit, fits, reference, lo) if fits else fit))
    if not fits:
        raise ModelError("sync: no sync-tag arrival in any window; nothing to synchronise")
    return _joined(fits, windows, np.asarray(receiver, np.int64), instant, emission, n_rows, arrivals)


def _no_arrivals() -> dict:
    """A fit's per-arrival fields, empty (:func:`fit_in_windows` ``arrivals=False``)."""
    return {"emission_time": np.empty(0), "residual": np.empty(0), "standardised": np.empty(0),
            "kept": np.empty(0, bool), "clock": None}


def _clocks_only(fit: ClockFit) -> ClockFit:
    """A window's fit without its per-arrival arrays (:func:`fit_in_windows` ``arrivals=False``)."""
    return replace(fit, distance=None, **_no_arrivals())


def _reference(fit: ClockFit) -> int:
    """The receiver a window's clocks are against: its clock row held at 0 with no sigma (-1: none)."""
    zero = np.flatnonzero((fit.knots == 0).all(axis=1) & (fit.knot_sigma == 0).all(axis=1))
    if not len(zero):
        return -1
    return int(zero[0] if fit.site is None else fit.site[zero[0]])


def _carried(fit: ClockFit, earlier: list, reference: int, start: float) -> ClockFit:
    """A window's clocks put against the season's ``reference`` receiver where the window's are against another's
    (the season's reference recovered, its clock gone: :mod:`sblsim.models.sync.season`): every clock's offsets
    plus that receiver's own offset on the season's reference, carried from the last earlier window that
    synchronised it (the line through its knots there up to ``start`` [s], this window's own span's start, carried on
    from its value at ``start``; its sigma there added in quadrature), the emissions' times and the breaks' instants
    on the reference's clock less it."""
    here = _reference(fit)
    if here == reference or here < 0:
        return fit
    for _, _, last in reversed(earlier):
        site = np.arange(len(last.knots)) if last.site is None else last.site
        rows = [r for r in np.flatnonzero(site == here) if np.isfinite(last.knots[r]).all()]
        if rows:
            break
    else:
        raise ModelError(f"sync: in a window the reference receiver does not hear, receiver {here} is no clock an "
                         "earlier window synchronised; nothing carries the time base across")
    row = rows[-1]
    width = last.edges[1] - last.edges[0]
    before = last.edges <= start + 1e-6  # its knots up to this window's own span: their line carried on
    slope = np.polyfit(last.edges[before], last.knots[row, before], 1)[0] if before.sum() >= 2 else 0.0
    value = float(np.interp(start, last.edges, last.knots[row]))

    def offset(t):  # [s] the window's reference receiver's offset on the season's reference, carried
        return value + slope * (np.asarray(t, float) - start)

    sigma = float(np.interp(start, last.edges, np.nan_to_num(last.knot_sigma[row])))
    # a clock's offset o' on the window's reference at its own time r is read by that reference at r - o': on the
    # season's reference it is o' + offset(r - o') = o' (1 - slope) + offset(r)
    knots = fit.knots * (1.0 - slope) + offset(fit.edges)[None, :]
    breaks = None if fit.breaks is None else [replace(b, time=b.time - float(offset(b.time))) for b in fit.breaks]
    return replace(fit, knots=knots, knot_sigma=np.sqrt(fit.knot_sigma ** 2 + sigma ** 2),
                   drift=np.diff(knots, axis=1) / width, emission_time=fit.emission_time - offset(fit.emission_time),
                   breaks=breaks)


def _pieces(fits, windows: Windows) -> list[_Piece]:
    """Every window's synchronised clock rows that reach into its own span."""
    out = []
    for i, _, fit in fits:
        lo, hi = windows.span(i)
        n = len(fit.knots)
        site = np.arange(n) if fit.site is None else fit.site
        part = np.ones(n, np.int64) if fit.part is None else fit.part
        span = np.tile([-np.inf, np.inf], (n, 1)) if fit.span is None else fit.span
        for r in range(n):
            if not np.isfinite(fit.knots[r]).any() or max(span[r, 0], lo) > min(span[r, 1], hi):
                continue
            out.append(_Piece(i, r, (int(site[r]), int(part[r])), (float(span[r, 0]), float(span[r, 1])),
                              float(max(span[r, 0], lo)), bool(span[r, 0] <= lo), bool(span[r, 1] >= hi)))
    return out


def _chains(pieces: list[_Piece]) -> list[list[_Piece]]:
    """The pieces joined into the season's clock rows: a row running on past its window's end with the next piece
    of its receiver and part that began before its window's start."""
    chains: list[list[_Piece]] = []
    for key in sorted({p.key for p in pieces}):
        mine = sorted((p for p in pieces if p.key == key), key=lambda p: (p.window, p.start))
        for p in mine:
            last = next((c for c in reversed(chains) if c[-1].key == key), None)
            if last is not None and last[-1].open_end and p.open_start and last[-1].window < p.window:
                last.append(p)
            else:
                chains.append([p])
    return chains


def _filled(values: np.ndarray, extend: bool) -> np.ndarray:
    """A row's values with its gaps linearly interpolated and, ``extend``, its ends extended with the end bins'
    slopes (else held)."""
    k = np.arange(len(values))
    ok = np.isfinite(values)
    if ok.all() or not ok.any():
        return values
    out = np.interp(k, k[ok], values[ok])
    a, b = np.flatnonzero(ok)[[0, -1]]
    if extend and b - a >= 1:
        mean = (values[b] - values[a]) / (b - a)
        out[:a] = values[a] + (values[a + 1] - values[a] if ok[a + 1] else mean) * (k[:a] - a)
        out[b + 1:] = values[b] + (values[b] - values[b - 1] if ok[b - 1] else mean) * (k[b + 1:] - b)
    return out


def _joined(fits, windows: Windows, receiver: np.ndarray, instant: np.ndarray, emission: np.ndarray, n_rows: int,
            arrivals: bool = True) -> ClockFit:
    """The windows' fits joined into the season's (:func:`fit_in_windows`; ``arrivals`` False: no arrival's
    arrays)."""
    width = float(fits[0][2].edges[1] - fits[0][2].edges[0])
    low = min(float(f.edges[0]) for _, _, f in fits)
    n_bins = int(round((max(float(f.edges[-1]) for _, _, f in fits) - low) / width))
    edges = low + width * np.arange(n_bins + 1)
    chains = _chains(_pieces(fits, windows))
    # a receiver's first clock segment at its index (as one fit numbers them), later segments after the receivers
    first_of = {}
    for c, chain in enumerate(chains):
        site, part = chain[0].key
        if part == 1 and site not in first_of:
            first_of[site] = c
    order = [first_of.get(j) for j in range(n_rows)] + [c for c in range(len(chains)) if c not in first_of.values()]
    n_out = len(order)
    knots = np.full((n_out, n_bins + 1), np.nan)
    knot_sigma, weight = knots.copy(), np.zeros((n_out, n_bins + 1))
    drift_sigma = np.full((n_out, n_bins), np.nan)
    counts = np.zeros((n_out, n_bins), np.int64)
    site = np.arange(n_out)
    part = np.ones(n_out, np.int64)
    span = np.tile([-np.inf, np.inf], (n_out, 1))
    scale2, scale_n = np.zeros(n_out), np.zeros(n_out)
    where: dict[tuple[int, int], int] = {}
    by_window = {i: fit for i, _, fit in fits}
    for out, c in enumerate(order):
        if c is None:
            continue
        chain = chains[c]
        site[out], part[out] = chain[0].key
        span[out] = chain[0].span[0], chain[-1].span[1]
        for p in chain:
            where[(p.window, p.row)] = out
            fit = by_window[p.window]
            lo, hi = windows.span(p.window)
            k0 = int(round((float(fit.edges[0]) - low) / width))
            own = np.flatnonzero((fit.edges >= lo - 1e-6) & (fit.edges <= hi + 1e-6))
            value, sigma = fit.knots[p.row, own], fit.knot_sigma[p.row, own]
            w = np.where(np.isfinite(sigma) & (sigma > 0), 1.0 / np.where(sigma > 0, sigma, 1.0) ** 2, 1.0)
            g = k0 + own
            known = np.isfinite(knots[out, g])
            total = weight[out, g] + w
            knots[out, g] = np.where(known, (knots[out, g] * weight[out, g] + value * w) / total, value)
            knot_sigma[out, g] = np.where(known, np.fmin(knot_sigma[out, g], sigma), sigma)
            weight[out, g] = total
            bins = own[:-1][np.isin(own[:-1] + 1, own)]  # the window's bins with both edges in its own span
            drift_sigma[out, k0 + bins] = fit.drift_sigma[p.row, bins]
            counts[out, k0 + bins] = fit.counts[p.row, bins]
            kept_here = max(int(fit.counts[p.row, bins].sum()), 1)
            scale2[out] += kept_here * fit.scale[p.row] ** 2
            scale_n[out] += kept_here
        knots[out] = _filled(knots[out], extend=True)
        knot_sigma[out] = _filled(knot_sigma[out], extend=False)
    scale = np.where(scale_n > 0, np.sqrt(scale2 / np.maximum(scale_n, 1)), np.nan)
    rows_of = _arrivals_joined(fits, windows, where, receiver, instant, emission) if arrivals else _no_arrivals()
    breaks = []
    for i, _, fit in fits:
        lo, hi = windows.span(i)
        for b in fit.breaks or []:
            instant_b = b.time if np.isfinite(b.time) else b.first
            if lo <= instant_b < hi:
                breaks.append(replace(b, before=_row_for(where, site, span, i, b, True),
                                      after=_row_for(where, site, span, i, b, False)))
    slowness, slowness_sigma, each = _slowness(fits)
    plain = len(order) == n_rows and not breaks and np.isinf(span).all()  # one row per receiver, as one fit's
    drift = np.diff(knots, axis=1) / width
    fit = ClockFit(edges, knots, knot_sigma, drift, drift_sigma, counts, rows_of["emission_time"], rows_of["residual"],
                   rows_of["standardised"], rows_of["kept"], scale, slowness, slowness_sigma,
                   max(f.iterations for _, _, f in fits), window_slowness=each)
    if plain:
        return fit
    return replace(fit, site=site, span=span, clock=rows_of["clock"], breaks=breaks,
                   part=part if (part > 1).any() else None)


def _arrivals_joined(fits, windows: Windows, where: dict, receiver: np.ndarray, instant: np.ndarray,
                     emission: np.ndarray) -> dict:
    """The season's per-arrival fields (:func:`_no_arrivals`' keys) from the windows' fits: each arrival's residual,
    standardised residual, kept flag and clock row (the season's row its window's row was joined into: ``where``)
    its emission's window's, and each emission's time its window's."""
    n = len(instant)
    residual, standardised, kept = np.full(n, np.nan), np.full(n, np.nan), np.zeros(n, bool)
    clock = np.full(n, -1, np.int64)
    emission_time = np.full(int(emission.max(initial=-1)) + 1, np.nan)
    for i, rows, fit in fits:
        lo, hi = windows.span(i)
        mine = (instant[rows] >= lo) & (instant[rows] < hi)
        at = rows[mine]
        residual[at], standardised[at], kept[at] = fit.residual[mine], fit.standardised[mine], fit.kept[mine]
        local = receiver[at] if fit.clock is None else fit.clock[mine]  # each arrival's row in its window
        lookup = np.full(len(fit.knots) + 1, -1, np.int64)  # (the last: a row set aside, -1)
        for (w, r), out in where.items():
            if w == i:
                lookup[r] = out
        clock[at] = lookup[np.where(local >= 0, local, -1)]
        owned = np.unique(emission[at])
        emission_time[owned] = fit.emission_time[owned]
    return {"emission_time": emission_time, "residual": residual, "standardised": standardised, "kept": kept,
            "clock": clock}


def _row_for(where: dict, site: np.ndarray, span: np.ndarray, i: int, b, before: bool) -> int:
    """The season's row of window ``i``'s break ``b``'s segment before it (``before``) or after it: the row its
    window's segment was joined into, else (that segment wholly in the next or the last window's span) the row of
    the same receiver that ends nearest its last arrival before the break (starts nearest its first after it)."""
    row = where.get((i, b.before if before else b.after))
    if row is not None:
        return row
    mine = np.flatnonzero(site == b.receiver)
    gap = np.abs(span[mine, 1] - b.last) if before else np.abs(span[mine, 0] - b.first)
    return int(mine[np.argmin(np.where(np.isfinite(gap), gap, np.inf))])


def _slowness(fits) -> tuple[float | None, float | None, np.ndarray | None]:
    """The windows' estimated slownesses [s/m] as one (:func:`season_slowness`: the mean, its sigma; the mean and
    None where a window gives no sigma) and each window's with its sigma, (W, 2) (NaN: none); None, None, None where
    given."""
    values = [(f.slowness, f.slowness_sigma) for _, _, f in fits if f.slowness is not None]
    if not values:
        return None, None, None
    each = np.array([(v, np.nan if e is None else e) for v, e in values], float)
    mean, spread, _ = windows_slowness(each)
    return mean, spread, each


def windows_slowness(each: np.ndarray) -> tuple[float, float | None, float | None]:
    """The season's slowness from its windows' (``each``: (W, 2) [s/m] each window's slowness and sigma, NaN where
    none): :func:`season_slowness`'s mean, sigma and spread τ; their plain mean and None, None where a window gives
    no sigma."""
    s, sigma = each[:, 0], each[:, 1]
    if not (np.isfinite(sigma) & (sigma > 0)).all():
        return float(s.mean()), None, None
    return season_slowness(s, sigma)


def season_slowness(values: np.ndarray, sigma: np.ndarray) -> tuple[float, float, float]:
    """A season's slowness from its windows' estimates: the water's changes over the season as a random effect.

    The windows' slownesses ``values`` (W,) [s/m] with their sigmas ``sigma`` (W,) [s/m] differ by more than their
    sigmas where the water changes from week to week; the between-windows variance τ² is DerSimonian and Laird's
    moment estimate, ``max(0, (Q − (W − 1)) / (Σw − Σw² / Σw))`` with ``w = 1 / σ²`` and ``Q`` the weighted squares
    about the inverse-variance mean, the season's slowness the mean weighted by ``1 / (σ² + τ²)`` and its sigma
    ``√(1 / Σ(1 / (σ² + τ²)))``: each window counts as one draw of the season's water, not by its own tiny sigma
    alone. τ is the windows' spread (the water at a moment is that far from the season's mean). Where the windows
    agree (τ² = 0) the inverse-variance mean and its sigma.

    Returns
    -------
    mean, sigma, tau : float
        [s/m] the season's slowness, its sigma, and the windows' spread τ.

    References
    ----------
    DerSimonian & Laird, "Meta-analysis in clinical trials", Controlled Clinical Trials 7(3), 177-188, 1986.
    """
    values, w = np.asarray(values, float), np.asarray(sigma, float) ** -2.0
    fixed = np.sum(w * values) / w.sum()
    q = float(np.sum(w * (values - fixed) ** 2))
    tau2 = max(0.0, (q - (len(values) - 1)) / (w.sum() - np.sum(w**2) / w.sum())) if len(values) > 1 else 0.0
    if tau2 == 0.0:
        return float(fixed), float(w.sum() ** -0.5), 0.0
    random = 1.0 / (1.0 / w + tau2)
    return float(np.sum(random * values) / random.sum()), float(random.sum() ** -0.5), float(np.sqrt(tau2))


__all__ = ["OVERLAP_HOURS", "WINDOW_DAYS", "Windows", "fit_in_windows", "season_slowness", "season_windows",
           "windows_slowness"]

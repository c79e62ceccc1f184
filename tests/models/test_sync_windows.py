"""A season's clocks fitted in windows (:mod:`sblsim.models.sync.windows`, :mod:`sblsim.models.sync.season`) against
one fit of the whole season (:func:`~sblsim.models.sync.breaks.fit_with_breaks`) and the simulation's truth
(:func:`~sblsim.models.sync.simulate.simulate_sync`): a fortnight's offsets within a tenth of their sigma wherever
the two fits reject the same arrivals, a clock break at a window's edge found once, the sync tags' leave-one-out
refit in windows as in one fit, and the windows themselves."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.sync.breaks import fit_with_breaks
from sblsim.models.sync.clocks import fit_clocks
from sblsim.models.sync.emissions import connected, sync_emissions
from sblsim.models.sync.season import breaks_in_windows, clocks_in_windows
from sblsim.models.sync.simulate import simulate_sync
from sblsim.models.sync.windows import Windows, season_windows

#: The array, its span [days], the bins [s], the windows [days] and their overlap [h].
N, DAYS, WIDTH, WINDOW, OVERLAP = 6, 14.0, 3600.0, 3.0, 12.0


@lru_cache(maxsize=None)
def _season(jump_day: float | None = None, days: float = DAYS):
    """A simulated fortnight (or ``days``; 6 receivers, sync tags every 20 to 30 min, 3 % multipath echoes; receiver
    2's clock jumping +0.5 s at ``jump_day``), its clocks fitted once and in windows against receiver 0."""
    jump = None if jump_day is None else (2, jump_day * 86400.0, 0.5)
    sim = simulate_sync(n_receivers=N, hours=days * 24, seed=3, side=800.0, echo_share=0.03,
                        interval=(1200.0, 1800.0), jump=jump)
    origin = np.floor(sim.time.min())
    t = sim.time - origin
    emission, duplicate, single = sync_emissions(sim.tag, sim.receiver, t, np.full(N, 300.0))
    used = ~duplicate & ~single
    distance = np.linalg.norm(sim.positions[sim.tag] - sim.positions[sim.receiver], axis=1)
    slowness = np.full(len(t), 1 / sim.sound_speed)
    linked = connected(sim.receiver[used], emission[used], N, 0)
    args = (sim.receiver, emission, t, distance, slowness, used, linked, 0, WIDTH)
    whole = fit_with_breaks(*args, sim.tag)
    windows = season_windows(t[used], WIDTH, WINDOW * 86400, OVERLAP * 3600)
    windowed = breaks_in_windows(windows, *args, sim.tag)
    return sim, origin, t, used, args, windows, whole, windowed


def _offsets(fit, sim, t, pick):
    """[s] each picked arrival's offset on its clock row (NaN set aside at a break)."""
    rows = sim.receiver if fit.clock is None else fit.clock
    return np.where(rows[pick] >= 0, fit.offset(np.maximum(rows[pick], 0), t[pick]), np.nan)


def _truth(sim, t, origin, pick):
    """[s] each picked arrival's true offset against receiver 0's clock."""
    tau = sim.true_time(sim.receiver, sim.time, sim.after)
    return (sim.time - (tau + sim.offset0[0] + sim.drift[0] * tau))[pick]


@pytest.mark.slow
def test_a_fortnight_in_windows_as_one_fit():
    """5 windows of 3 days with 12 h overlaps: the same bins, one clock row per receiver; all but a few arrivals at
    the rejection threshold (0.3 % at most; 21 of 26,075 here) rejected alike; the offsets within a tenth of one fit's
    sigma in RMS over all arrivals and at every arrival more than 5 bins from one rejected otherwise (such a one moves
    the knots about it by up to half a sigma: two answers of one robust fit); as close to the truth as one fit
    (within 2 %)."""
    sim, origin, t, used, _, windows, whole, windowed = _season()
    assert len(windows) == 5 and windowed.site is None and np.array_equal(windowed.edges, whole.edges)
    differ = used & (whole.kept != windowed.kept)
    assert differ.sum() <= 0.003 * used.sum()
    pick = used & (sim.receiver != 0)
    ratio = np.abs(_offsets(windowed, sim, t, pick) - _offsets(whole, sim, t, pick))
    k = np.clip(((t[pick] - whole.edges[0]) // WIDTH).astype(int), 0, len(whole.edges) - 2)
    ratio /= np.minimum(whole.knot_sigma[sim.receiver[pick], k], whole.knot_sigma[sim.receiver[pick], k + 1])
    near = np.zeros(pick.sum(), bool)
    for b in np.unique((t[differ] // WIDTH).astype(int)):
        near |= np.abs((t[pick] // WIDTH).astype(int) - b) <= 5
    assert (~near).mean() > 0.5 and ratio[~near].max() <= 0.1
    assert np.sqrt(np.mean(ratio ** 2)) <= 0.1
    truth = _truth(sim, t, origin, pick)
    rms = [np.sqrt(np.mean((_offsets(f, sim, t, pick) - truth) ** 2)) for f in (whole, windowed)]
    assert rms[1] <= 1.02 * rms[0]
    # a window's own knots hold from its span's start to its end: continuous across every edge
    inner = ((windows.edges[1:-1] - whole.edges[0]) / WIDTH).round().astype(int)
    assert np.isfinite(windowed.knots[1:, inner]).all() and np.isfinite(windowed.drift[1:]).all()


@pytest.mark.parametrize("day", [6.0, pytest.param(6.02, marks=pytest.mark.slow),
                                 pytest.param(5.97, marks=pytest.mark.slow)])
def test_a_break_at_a_windows_edge_found_once(day):
    """Over 7 days, receiver 2's clock jumping +0.5 s at a window's edge (day 6, the second window's end; 30 min
    after it, 45 min before it), inside both windows' fits: one break found, at receiver 2, its size within 0.5 ms, its
    instant one fit's (within its stated interval), the arrivals on their segments as one fit puts them, the offsets
    as close to the truth as one fit's (within 5 %)."""
    sim, origin, t, used, _, windows, whole, windowed = _season(day, 7.0)
    assert windows.edges[2] == pytest.approx(6 * 86400.0 + windows.edges[0], abs=86400)
    (b,) = windowed.breaks
    (w,) = whole.breaks
    assert b.receiver == 2 and abs(b.size - 0.5) < 0.5e-3 and abs(b.time - w.time) <= b.time_within + w.time_within
    assert windowed.site is not None and (windowed.site == 2).sum() == 2
    on = used & (whole.clock >= 0) & (windowed.clock >= 0)
    assert np.array_equal(windowed.site[windowed.clock[on]], whole.site[whole.clock[on]])
    later = on & (sim.receiver == 2)
    assert np.array_equal(windowed.clock[later] == b.after, whole.clock[later] == w.after)
    pick = on & (sim.receiver != 0)
    truth = _truth(sim, t, origin, pick)
    rms = [np.sqrt(np.mean((_offsets(f, sim, t, pick) - truth) ** 2)) for f in (whole, windowed)]
    assert rms[1] <= 1.05 * rms[0]


@pytest.mark.slow
def test_a_sync_tags_leave_one_out_in_windows_as_in_one_fit():
    """Sync tag 3 left out, the clocks refitted with the season's rejections and scales in the windows and once:
    the offsets within a tenth of their sigma (no reweighting: the same arrivals in both)."""
    sim, origin, t, used, args, windows, whole, _ = _season()
    receiver, emission, time, distance, slowness, _, linked, reference, width = args
    without = used & (sim.tag != 3)
    once = fit_clocks(receiver, emission, time, distance, slowness, without, linked, reference, width,
                      keep=whole.kept, scale=whole.scale)
    windowed = clocks_in_windows(windows, receiver, emission, time, distance, slowness, without, linked, reference,
                                 width, whole.kept, whole.scale)
    pick = without & (receiver != 0)
    k = np.clip(((t[pick] - once.edges[0]) // WIDTH).astype(int), 0, len(once.edges) - 2)
    sigma = once.knot_sigma[receiver[pick], k]
    moved = windowed.offset(receiver[pick], t[pick]) - once.offset(receiver[pick], t[pick])
    assert np.all(np.abs(moved) <= 0.1 * sigma)


def test_the_windows_of_a_season():
    """Whole bins from the first arrival's bin; one fit (None) where the span is within a window and its overlaps;
    the last window up to half a window longer, never a sliver; each window's span open at the season's ends; a
    window or an overlap shorter than a bin refused."""
    day = 86400.0
    assert season_windows(np.array([10.0, 7 * day]), WIDTH, 7 * day, 12 * 3600.0) is None
    w = season_windows(np.array([1800.0, 15.2 * day]), WIDTH, 7 * day, 12 * 3600.0)
    assert isinstance(w, Windows) and len(w) == 2 and w.edges[0] == 0.0 and np.allclose(np.diff(w.edges), 7 * day)
    assert w.span(0) == (-np.inf, 7 * day) and w.span(1) == (7 * day, np.inf)
    w = season_windows(np.array([0.0, 16.5 * day]), WIDTH, 7 * day, 12 * 3600.0)
    assert len(w) == 2
    w = season_windows(np.array([0.0, 17.6 * day]), WIDTH, 7 * day, 12 * 3600.0)
    assert len(w) == 3
    for window, overlap in ((1800.0, 12 * 3600.0), (day, 60.0)):
        with pytest.raises(ModelError, match="at least a bin"):
            season_windows(np.array([0.0, 30 * day]), WIDTH, window, overlap)


@pytest.mark.slow
def test_the_time_base_carried_past_the_reference_receivers_recovery():
    """Receiver 0 (the reference) and its sync tag recovered at day 5 of 10, windows of 3 days: the last window,
    which it never hears, fitted against another receiver and carried onto receiver 0's time base. What the arrivals
    determine, each clock against receiver 1's, is as good as one fit's (within 5 % RMS after the recovery); the
    time base itself, which no arrival sees (the emissions' times absorb a change common to all clocks), within
    0.2 s of receiver 0's clock carried on (one fit's drift prior alone: seconds here)."""
    sim = simulate_sync(n_receivers=N, hours=10 * 24, seed=3, side=800.0, echo_share=0.03,
                        interval=(1200.0, 1800.0))
    tau = sim.true_time(sim.receiver, sim.time)
    on = ~(((sim.receiver == 0) | (sim.tag == 0)) & (tau > 5 * 86400.0))
    receiver, tag, logged = sim.receiver[on], sim.tag[on], sim.time[on]
    origin = np.floor(logged.min())
    t = logged - origin
    emission, duplicate, single = sync_emissions(tag, receiver, t, np.full(N, 300.0))
    used = ~duplicate & ~single
    distance = np.linalg.norm(sim.positions[tag] - sim.positions[receiver], axis=1)
    args = (receiver, emission, t, distance, np.full(len(t), 1 / sim.sound_speed), used,
            connected(receiver[used], emission[used], N, 0), 0, WIDTH)
    windows = season_windows(t[used], WIDTH, 3 * 86400, OVERLAP * 3600)
    fits = {"one": fit_with_breaks(*args, tag), "windows": breaks_in_windows(windows, *args, tag)}
    late = used & (receiver >= 2) & (sim.true_time(receiver, logged) > 6.5 * 86400)
    truth = sim.true_time(receiver[late], logged[late])
    r1 = sim.reading(np.full(late.sum(), 1), truth) - origin  # receiver 1's clock at the same instants
    error, base = {}, {}
    for name, fit in fits.items():
        relative = fit.offset(receiver[late], t[late]) - fit.offset(np.full(late.sum(), 1), r1)
        error[name] = np.sqrt(np.mean((relative - (t[late] - r1)) ** 2))
        base[name] = np.abs(fit.offset(receiver[late], t[late]) - sim.offset(receiver[late], logged[late], 0)).max()
    assert error["windows"] <= 1.05 * error["one"] and error["one"] < 1e-4
    assert base["windows"] < 0.2


@pytest.mark.parametrize("jump_day", [None, pytest.param(6.0, marks=pytest.mark.slow)])
def test_a_refit_for_its_clocks_alone_holds_no_arrivals_and_the_same_clocks(jump_day):
    """A sync tag's leave-one-out refit asked for its clocks alone (``arrivals=False``, as ``sync_tags.csv``'s fits
    are made) holds no arrival's array (a season's of them), and its clocks, sigmas, scales, sound speed and breaks
    are those of the refit that keeps them, bit for bit; with receiver 2's clock broken too (its rows the season
    fit's clock rows)."""
    sim, origin, t, used, args, windows, whole, windowed = _season(jump_day, days=9.0)
    receiver, emission, time, distance, slowness, _, linked, reference, width = args
    rows = receiver if windowed.clock is None else windowed.clock
    n_rows = len(windowed.knots)
    without = used & (sim.tag != 3) & (rows >= 0)
    still = connected(rows[without], emission[without], n_rows, reference)
    steady = None if windowed.site is None else windowed.site == reference
    kept, alone = (clocks_in_windows(windows, rows, emission, time, distance, slowness, without, still, reference,
                                     width, windowed.kept, windowed.scale, steady, arrivals=a) for a in (True, False))
    assert len(kept.residual) == len(t) and np.isfinite(kept.residual[without]).any()
    for values in (alone.residual, alone.standardised, alone.kept, alone.emission_time):
        assert values.size == 0
    assert alone.clock is None
    for name in ("edges", "knots", "knot_sigma", "drift", "drift_sigma", "counts", "scale"):
        assert np.array_equal(getattr(kept, name), getattr(alone, name), equal_nan=name != "counts"), name
    assert kept.slowness == alone.slowness
    assert [b.time for b in kept.breaks or []] == [b.time for b in alone.breaks or []]
    picked = without & (rows != reference)
    assert np.array_equal(kept.offset(rows[picked], t[picked]), alone.offset(rows[picked], t[picked]))


def test_a_season_s_slowness_from_windows_that_disagree_is_the_water_s_at_any_moment():
    """:func:`~sblsim.models.sync.windows.season_slowness` against statsmodels' DerSimonian-Laird random-effects
    combination (its mean, τ² and the mean's standard error): windows whose slownesses differ by far more than their
    sigmas (a season's water warming) give a sigma of their spread over √W, not the inverse-variance mean's, and τ
    near their spread; windows that agree (Q below its degrees of freedom) give the inverse-variance mean and its
    sigma exactly; one window its own."""
    from statsmodels.stats.meta_analysis import combine_effects

    from sblsim.models.sync.windows import season_slowness

    rng = np.random.default_rng(3)
    speeds = 1485.0 + 15.0 * np.sin(np.linspace(0.0, 2 * np.pi, 13))  # [m/s] a quarter's weeks
    values, sigma = 1.0 / speeds, rng.uniform(0.02, 0.06, 13) / speeds**2
    mean, spread, tau = season_slowness(values, sigma)
    reference = combine_effects(values, sigma**2, method_re="dl")
    assert mean == pytest.approx(reference.mean_effect_re, rel=1e-12)
    assert tau == pytest.approx(np.sqrt(reference.tau2), rel=1e-9)
    assert spread == pytest.approx(reference.sd_eff_w_re, rel=1e-9)
    c2 = 1485.0**2  # [m/s per s/m] slowness to speed
    assert tau * c2 == pytest.approx(np.std(speeds, ddof=1), rel=0.05)
    assert spread * c2 > 0.8 * np.std(speeds) / np.sqrt(13) and spread > 20 * sigma.max()
    w = sigma**-2.0
    agreeing = np.sum(w * values) / w.sum() + np.array([1.0, -1.0, 0.5, -0.5, 0.0]) * 0.3 * sigma[:5]
    mean, spread, tau = season_slowness(agreeing, sigma[:5])
    fixed = np.sum(w[:5] * agreeing) / w[:5].sum()
    assert tau == 0.0 and mean == pytest.approx(fixed, rel=1e-15) and spread == pytest.approx(w[:5].sum() ** -0.5)
    assert season_slowness(values[:1], sigma[:1]) == pytest.approx((values[0], sigma[0], 0.0))

"""A still tag's consider term of the receivers' clock offsets (issue 87, item 4): each receiver's offset from the
synchronisation is uncertain by its own sigma, a bias common to all that receiver's arrivals which pooling the pings
does not average. Checked: the term against the pooled fix's central differences; simulated still tags with such
clock errors consistent with it (NEES) and far from it without; ``clock_sigma_s`` carried from a synchronisation's
``offsets.csv`` through the matrix's ``receivers.csv`` into the tracker, whose reported covariance grows by the
central differences' share."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking.stationary import stationary_fix
from sblsim.models.tracking.still_tag import stationary_consider
from sblsim.orchestrator.readers.receivers_file import read_receivers
from sblsim.orchestrator.sync.clocks import read_clocks
from sblsim.orchestrator.sync.matrix_files import write_matrix
from sblsim.orchestrator.sync.toa import ToaOutcome
from sblsim.orchestrator.tracks.track import track

RECEIVERS = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0]])
C, SIGMA = 1480.0, 1e-4
#: Each receiver's clock offset's sigma [s] (0.3 ms: 0.44 m of range, where 200 pings pool the noise to ~1 cm).
CLOCK = np.array([3e-4, 2e-4, 4e-4, 3e-4, 1e-4, 3e-4])


def still_tag(seed: int, clock_errors: np.ndarray | None = None, m: int = 200):
    """A still tag's times of arrival (m, 6) [s] and its position: each receiver's arrivals shifted by its
    ``clock_errors`` [s] (the synchronisation's offset error), 40 % of arrivals not heard."""
    rng = np.random.default_rng(seed)
    p = np.array([120.0, 60.0]) + 30.0 * rng.normal(size=2)
    emissions = np.cumsum(rng.uniform(20.0, 40.0, m))
    toa = emissions[:, None] + np.linalg.norm(p - RECEIVERS, axis=1)[None] / C + SIGMA * rng.normal(size=(m, 6))
    if clock_errors is not None:
        toa += clock_errors[None, :]
    toa[rng.random(toa.shape) > 0.6] = np.nan
    return toa, p


def pooled(toa: np.ndarray):
    fixes = tt.fix_pings(toa, RECEIVERS, C, SIGMA)[0]
    return stationary_fix(toa, RECEIVERS, C, SIGMA, np.nanmedian(fixes, axis=0))


def central_clock_covariance(toa: np.ndarray, clock: np.ndarray, h: float = 2e-6) -> np.ndarray:
    """Σ_i σ_i² d_i d_iᵀ with d_i the pooled position's central difference in receiver i's arrivals shifted by
    ±h [s] (the fix solved again each time)."""
    start = pooled(toa).position
    out = np.zeros((2, 2))
    for i in range(len(RECEIVERS)):
        plus, minus = toa.copy(), toa.copy()
        plus[:, i] += h
        minus[:, i] -= h
        d = (stationary_fix(plus, RECEIVERS, C, SIGMA, start).position
             - stationary_fix(minus, RECEIVERS, C, SIGMA, start).position) / (2 * h)
        out += clock[i] ** 2 * np.outer(d, d)
    return out


def test_the_clock_term_is_the_central_differences_of_the_pooled_fix():
    """The consider covariance of the clocks alone (no survey, no speed error) against Σ σ_i² d_i d_iᵀ of central
    differences; None where no clock sigma (or only zeros) is known."""
    toa, _ = still_tag(4, m=60)
    fix = pooled(toa)
    term = stationary_consider(toa, RECEIVERS, C, fix, None, None, SIGMA, CLOCK)
    np.testing.assert_allclose(term, central_clock_covariance(toa, CLOCK), rtol=0.03)
    assert stationary_consider(toa, RECEIVERS, C, fix, None, None, SIGMA, None) is None
    assert stationary_consider(toa, RECEIVERS, C, fix, None, None, SIGMA, np.zeros(6)) is None
    # a receiver whose clock sigma is not known (NaN) adds nothing
    part = CLOCK.copy()
    part[2] = np.nan
    known = CLOCK.copy()
    known[2] = 0.0
    np.testing.assert_allclose(stationary_consider(toa, RECEIVERS, C, fix, None, None, SIGMA, part),
                               central_clock_covariance(toa, known), rtol=0.03)


def nees_over(seeds: int) -> tuple[float, float]:
    """The mean 2-D NEES of the pooled position over ``seeds`` still tags (200 pings each, every receiver's offset
    off by N(0, CLOCK_i)): with its own covariance alone, and with the clocks' consider term added."""
    alone, considered = [], []
    for seed in range(seeds):
        errors = CLOCK * np.random.default_rng(500 + seed).normal(size=len(CLOCK))
        toa, p = still_tag(seed, errors)
        fix = pooled(toa)
        e = fix.position - p
        alone.append(e @ np.linalg.solve(fix.covariance, e))
        full = fix.covariance + stationary_consider(toa, RECEIVERS, C, fix, None, None, SIGMA, CLOCK)
        considered.append(e @ np.linalg.solve(full, e))
    return float(np.mean(alone)), float(np.mean(considered))


@pytest.mark.slow
def test_still_tags_with_clock_errors_are_consistent_with_the_term_over_20_seeds():
    """The pooled covariance alone is far too small (2-D NEES ≫ 2); with the clocks' consider term the mean NEES of
    20 seeds lies where the mean of 20 χ²(2) lies with probability 0.998 ([1, 3.5]: Gamma(20, 0.1))."""
    alone, considered = nees_over(20)
    assert alone > 50, alone
    assert 1.0 <= considered <= 3.5, considered


@pytest.mark.slow
def test_still_tags_with_clock_errors_are_consistent_with_the_term_over_100_seeds():
    """Over 100 seeds (the mean's standard deviation 0.2 about 2) the mean NEES with the term within [1.5, 4.5],
    without it above 100."""
    alone, considered = nees_over(100)
    assert alone > 100, alone
    assert 1.5 <= considered <= 4.5, considered


def test_offsets_clock_sigma_reaches_the_matrix(tmp_path):
    """``offsets.csv``'s ``clock_sigma_s`` (one per receiver) is read into the clocks, written into a matrix's
    ``receivers.csv`` and read back by the tracker's reader; a value differing between a receiver's rows, or
    outside [0, 1] s, is refused in one line naming the column."""
    rows = []
    for name, noise, clock in (("A", 2e-4, 0.0), ("B", 3e-4, 1.5e-4)):
        for k in range(2):
            rows.append({"receiver": name, "bin": k, "start": 1e9 + 3600 * k, "end": 1e9 + 3600 * (k + 1),
                         "offset_start_s": 0.1 * k, "offset_end_s": 0.1 * (k + 1), "toa_sigma_s": noise,
                         "clock_sigma_s": clock})
    sync = tmp_path / "sync"
    sync.mkdir()
    pd.DataFrame(rows).to_csv(sync / "offsets.csv", index=False)
    clocks = read_clocks(sync)
    assert clocks.receivers == ["A", "B"]
    np.testing.assert_array_equal(clocks.clock_sigma, [0.0, 1.5e-4])
    outcome = ToaOutcome(np.zeros((3, 2)), ["B", "A"], np.array([[0.0, 0.0], [10.0, 0.0]]), pd.DataFrame(), {},
                         1e9, toa_sigma=np.array([3e-4, 2e-4]), clock_sigma=clocks.clock_sigma[[1, 0]])
    _, written = write_matrix(outcome, tmp_path)
    np.testing.assert_allclose(read_receivers(written).clock_sigma, [1.5e-4, 0.0])
    assert clocks.knot_sigma is None and clocks.averaged_sigma([0, 1], np.zeros((3, 2))) is None
    for bad, column in ((("clock_sigma_s", 1, 2e-4), "differs between its rows"), (("clock_sigma_s", 0, -1e-3),
                                                                                    "clock_sigma_s")):
        table = pd.DataFrame(rows)
        table.loc[bad[1], bad[0]] = bad[2]
        table.to_csv(sync / "offsets.csv", index=False)
        with pytest.raises(ModelError, match=column) as err:
            read_clocks(sync)
        assert "clock_sigma_s" in str(err.value) and "\n" not in str(err.value)


def test_the_offsets_sigmas_give_each_tags_averaged_clock_term(tmp_path):
    """``offsets.csv``'s offsets' and drifts' sigmas (B's edges 1, 2 and 1.5 × 10⁻⁴ s, its drifts' such that the
    edges are uncorrelated) are read into the clocks; a tag heard by B at both bins' middles has B's clock error
    averaged over them, ``√(Σ aₖ² σₖ²)`` with a = (¼, ½, ¼) (written out), written into the matrix's
    ``receivers.csv`` as ``clock_mean_sigma_s`` beside ``clock_sigma_s`` and read back; a negative sigma in either
    file is refused in one line naming its column."""
    sigma_b = [1e-4, 2e-4, 1.5e-4]
    rows = []
    for name, knots in (("A", [0.0, 0.0, 0.0]), ("B", sigma_b)):
        for k in range(2):
            drift = np.hypot(knots[k], knots[k + 1]) / 3600.0  # uncorrelated edges
            rows.append({"receiver": name, "bin": k, "start": 1e9 + 3600 * k, "end": 1e9 + 3600 * (k + 1),
                         "offset_start_s": 0.0, "offset_end_s": 0.0, "offset_start_sigma_s": knots[k],
                         "offset_end_sigma_s": knots[k + 1], "drift": 0.0, "drift_sigma": drift,
                         "toa_sigma_s": 2e-4, "clock_sigma_s": 1.6e-4 if name == "B" else 0.0})
    sync = tmp_path / "sync"
    sync.mkdir()
    pd.DataFrame(rows).to_csv(sync / "offsets.csv", index=False)
    clocks = read_clocks(sync)
    np.testing.assert_allclose(clocks.knot_sigma[1], sigma_b)
    times = np.array([[1e9 + 1800.0, np.nan], [1e9 + 5400.0, 1e9 + 5400.0]])  # B's column first, then A's
    mean = clocks.averaged_sigma([1, 0], times)
    expected = np.sqrt((0.25 * sigma_b[0]) ** 2 + (0.5 * sigma_b[1]) ** 2 + (0.25 * sigma_b[2]) ** 2)
    np.testing.assert_allclose(mean, [expected, 0.0], rtol=1e-9)
    outcome = ToaOutcome(np.zeros((2, 2)), ["B", "A"], np.array([[0.0, 0.0], [10.0, 0.0]]), pd.DataFrame(), {},
                         1e9, clock_sigma=clocks.clock_sigma[[1, 0]], clock_mean=mean)
    _, written = write_matrix(outcome, tmp_path)
    back = read_receivers(written)
    np.testing.assert_allclose(back.clock_mean, [expected, 0.0], rtol=1e-5)
    np.testing.assert_allclose(back.clock_sigma, [1.6e-4, 0.0])
    table = pd.DataFrame(rows)
    table.loc[1, "offset_start_sigma_s"] = -1e-4
    table.to_csv(sync / "offsets.csv", index=False)
    with pytest.raises(ModelError, match="offset_start_sigma_s") as err:
        read_clocks(sync)
    assert "\n" not in str(err.value)
    text = written.read_text().replace(f"{expected:.6g}", "-0.001")
    written.write_text(text)
    with pytest.raises(ModelError, match="clock_mean_sigma_s") as err:
        read_receivers(written)
    assert "\n" not in str(err.value)


def test_the_tracker_adds_the_clocks_term_of_the_receivers_file(tmp_path):
    """A still tag tracked with ``motion="stationary"`` from a matrix whose ``receivers.csv`` has ``clock_sigma_s``:
    its reported variances exceed those of the same matrix without the column by the central differences' clock
    covariance, and the summary names the term."""
    toa, _ = still_tag(7, CLOCK * np.random.default_rng(7).normal(size=6), m=80)
    start = np.nanmin(toa)
    outcome = ToaOutcome(toa - start, [f"R{k}" for k in range(6)], RECEIVERS, pd.DataFrame(), {}, 0.0)
    plain = tmp_path / "plain"
    plain.mkdir()
    write_matrix(outcome, plain)
    clocked = tmp_path / "clocked"
    clocked.mkdir()
    write_matrix(ToaOutcome(**(vars(outcome) | {"clock_sigma": CLOCK})), clocked)
    runs = [track(f / "toa.txt", f / "receivers.csv", sound_speed=C, toa_sigma=SIGMA, motion="stationary")
            for f in (plain, clocked)]
    assert runs[0].summary["track"] == runs[1].summary["track"] == "stationary"
    assert runs[1].summary["motion"]["consider_terms"] == ["clocks"]
    assert runs[0].summary["motion"]["consider_terms"] == []
    expected = central_clock_covariance(toa - start, CLOCK)
    grown = [(r.track[["sigma_x", "sigma_y"]].to_numpy() ** 2)[0] for r in runs]
    np.testing.assert_allclose(grown[1] - grown[0], np.diag(expected), rtol=0.05)
    # the error averaged over the tag's arrivals (clock_mean_sigma_s), half of one bin's: the place's term a quarter
    averaged = tmp_path / "averaged"
    averaged.mkdir()
    write_matrix(ToaOutcome(**(vars(outcome) | {"clock_sigma": CLOCK, "clock_mean": CLOCK / 2})), averaged)
    halved = track(averaged / "toa.txt", averaged / "receivers.csv", sound_speed=C, toa_sigma=SIGMA,
                   motion="stationary")
    np.testing.assert_allclose((halved.track[["sigma_x", "sigma_y"]].to_numpy() ** 2)[0] - grown[0],
                               np.diag(expected) / 4, rtol=0.05)

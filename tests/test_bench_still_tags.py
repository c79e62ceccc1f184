"""The still tags' benchmark (``bench_still_tags.py``): its records made as asked (the interval, the pings, the
receivers, a reflection at H2 in episodes), checked against the files it writes read back here, and a bad argument
is one line, exit 2."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))
import bench_still_tags as bench  # noqa: E402


def _read(toa: Path, receivers: Path) -> tuple[np.ndarray, pd.DataFrame]:
    return pd.read_csv(toa, sep=" ", na_values="NA").to_numpy(float), pd.read_csv(receivers)


def test_a_record_is_made_as_asked(tmp_path):
    """A sync tag's interval, 300 pings, the first five receivers: the files hold those receivers, the pings' first
    arrivals spaced as the interval says (to the path's few metres), about 80 % of the arrivals heard."""
    how = bench.Record((540.0, 660.0), 300, 5, 0.0)
    toa, receivers, places = bench.record(tmp_path, 3, how=how)
    times, table = _read(toa, receivers)
    assert times.shape == (300, 5) and list(table["name"]) == [f"H{k}" for k in range(1, 6)]
    assert np.allclose(table[["x_m", "y_m"]].to_numpy(), bench.RECEIVERS[:5]) and places.shape == (300, 2)
    first = np.nanmin(times, axis=1)
    gaps = np.diff(first)
    assert 540.0 - 1.0 < np.median(gaps) < 660.0 + 1.0 and gaps.min() > 540.0 - 2.0 - 1.0
    assert np.isfinite(times).mean() == pytest.approx(0.8, abs=0.05)


def test_a_reflection_lengthens_h2s_path_alone_in_episodes(tmp_path):
    """The same seed with and without a reflection: the other receivers' times the same to the nanosecond, H2's
    later by 8 to 15 m of path in runs of consecutive pings, about the share asked of the record."""
    plain = _read(*bench.record(tmp_path, 5, how=bench.Record(pings=2000))[:2])[0]
    (tmp_path / "r").mkdir()
    how = bench.Record(pings=2000, reflection=0.3)
    reflected = _read(*bench.record(tmp_path / "r", 5, how=how)[:2])[0]
    others = [k for k in range(plain.shape[1]) if k != 1]
    assert np.array_equal(np.isnan(plain), np.isnan(reflected))
    assert np.allclose(plain[:, others], reflected[:, others], atol=2e-9, equal_nan=True)
    late = (reflected[:, 1] - plain[:, 1]) * 1480.0
    heard = np.isfinite(late)
    on = heard & (late > 1.0)
    assert ((late[on] > 8.0 * 0.99) & (late[on] < 15.0 * 1.01)).all()
    assert np.abs(late[heard & ~on]).max() < 1e-6
    share = on.sum() / heard.sum()
    assert 0.15 < share < 0.6, share
    runs = np.diff(np.flatnonzero(np.diff(np.r_[False, on[heard], False].astype(int))))[::2]
    assert np.median(runs) > 5, runs  # episodes of hours (a ping every two minutes), not single pings


def test_no_reflection_draws_nothing_and_the_default_is_the_whole_array(tmp_path):
    """No reflection: no ping's path lengthened; the default record: 720 pings at all 8 receivers."""
    on, excess = bench._reflected(np.random.default_rng(0), np.arange(100.0), 0.0)
    assert not on.any() and not excess.any()
    times, table = _read(*bench.record(tmp_path, 0)[:2])
    assert times.shape == (bench.PINGS, len(bench.RECEIVERS)) and len(table) == len(bench.RECEIVERS)


def test_the_canal_site_spreads_its_receivers_along_two_legs_and_moves_the_tag_along_it(tmp_path):
    """``--site canal``: six receivers 200 m apart along the canal's path (its two 500 m legs at a right angle),
    alternate banks 10 m apart; the record's receivers file holds them, and a moved tag's second place is 20 m
    north (along the second leg), its first on that leg."""
    receivers = bench.canal(6)
    on_first = np.abs(receivers[:, 1]) <= 5.0  # the first leg along y = 0, the second along x = 500
    along = np.where(on_first, receivers[:, 0], 500.0 + receivers[:, 1])
    np.testing.assert_allclose(along, np.arange(6) * 200.0, atol=1e-9)
    first, second = receivers[on_first], receivers[~on_first]
    assert np.allclose(np.abs(first[:, 1]), 5.0) and np.allclose(np.abs(second[:, 0] - 500.0), 5.0)
    how = bench.Record(pings=100, receivers=6, site="canal")
    toa, table_path, places = bench.record(tmp_path, 1, move=how.layout()[2], how=how)
    _, table = _read(toa, table_path)
    assert np.allclose(table[["x_m", "y_m"]].to_numpy(), receivers)
    assert np.allclose(places[0], bench.CANAL_TAG) and np.allclose(places[-1] - places[0], [0.0, 20.0])
    assert abs(places[0][0] - 500.0) < 5.0


@pytest.mark.parametrize("args, message", [(["--receivers", "3"], "--receivers: 3; allowed: 4 to 8"),
                                           (["--reflection", "1"], "--reflection: 1; allowed: 0 <= SHARE < 1"),
                                           (["--interval", "60", "30"], "--interval: 60 30; allowed: 0 < LO <= HI"),
                                           (["--pings", "10"], "--pings: 10; allowed: 40 or more"),
                                           (["--site", "lake"], "--site: invalid choice: 'lake'")])
def test_a_bad_argument_is_one_line_and_exit_2(args, message):
    run = subprocess.run([sys.executable, str(BENCHMARKS / "bench_still_tags.py"), *args], capture_output=True,
                         text=True, timeout=120)
    err = run.stderr.strip().splitlines()
    assert run.returncode == 2 and message in err[-1], run.stderr


def test_a_drift_moves_the_tag_from_the_middle_ping_and_rows_are_matched_to_their_pings(tmp_path):
    """``drift``: the tag still to the middle ping's predecessor, then along the move's direction by the speed a ping
    (the middle ping the first moved); :func:`pings` gives each row its ping from the row's time (a row a few
    milliseconds off the emission, some pings without a row), as the record's own times say."""
    from types import SimpleNamespace

    how = bench.Record(pings=100, receivers=6, site="canal")
    places = bench.record(tmp_path, 2, drift=0.5, how=how)[2]
    steps = np.linalg.norm(np.diff(places, axis=0), axis=1)
    assert np.allclose(places[:50], bench.CANAL_TAG) and np.allclose(steps[49:], 0.5) and not steps[:49].any()
    assert np.allclose((places[-1] - places[49]) / np.linalg.norm(places[-1] - places[49]), [0.0, 1.0])
    t = np.cumsum(np.random.default_rng(2).uniform(*how.interval, how.pings))
    kept = np.setdiff1d(np.arange(how.pings), [0, 17, 18, 99])
    track = pd.DataFrame({"time": t[kept] + np.random.default_rng(0).uniform(-0.005, 0.005, len(kept))})
    assert np.array_equal(bench.pings(SimpleNamespace(track=track), 2, how), kept)

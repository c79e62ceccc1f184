"""The tracker's medium and motion beyond one constant speed and a moving tag (orchestrator/tracks/track.py,
models/tracking/sound_speed.py): a measured sound-speed series, the fallback where the pings cannot determine the
speed, and a stationary tag pooled into one position."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import sblsim
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.tracking import sound_speed as ss
from sblsim.orchestrator.tracks.variants import write_toa

DATA = Path(__file__).resolve().parents[2] / "data" / "lake-hald"
RECEIVERS = np.array([[0.0, 0.0], [200.0, 0.0], [200.0, 150.0], [0.0, 150.0], [100.0, 75.0], [60.0, 140.0]])
NAMES = [f"R{k + 1}" for k in range(len(RECEIVERS))]


def _receivers(tmp_path: Path) -> Path:
    path = tmp_path / "receivers.csv"
    rows = "\n".join(f"{n},{x:g},{y:g}" for n, (x, y) in zip(NAMES, RECEIVERS))
    path.write_text("name,x_m,y_m\n" + rows + "\n")
    return path


def _truth(tmp_path: Path, emissions: np.ndarray, positions: np.ndarray) -> Path:
    path = tmp_path / "truth.txt"
    np.savetxt(path, np.column_stack([positions, emissions]), header="x y t", comments="")
    return path


def _error(result) -> np.ndarray:
    e = result.errors
    return e.loc[e["estimator"] == result.score["estimator"], "error_2d_m"].to_numpy()


def test_rescaled_arrivals_give_each_ping_its_own_range_at_the_reference_speed():
    """At exact emission times the rescaled travel times times the reference speed are the ranges (computed here
    from the positions); the speed is the series' at each emission, held beyond its ends and flagged there."""
    rng = np.random.default_rng(3)
    emissions = np.arange(10) * 30.0
    points = rng.uniform(0, 150, (10, 2))
    ranges = np.linalg.norm(points[:, None] - RECEIVERS[None], axis=2)
    series = np.array([[0.0, 1440.0], [200.0, 1460.0]])
    speeds = np.interp(emissions, series[:, 0], series[:, 1])
    toa = emissions[:, None] + ranges / speeds[:, None]
    toa[2, 1] = np.nan
    scaled, found, outside = ss.rescale_to_reference(toa, emissions, series, 1450.0)
    heard = np.isfinite(toa)
    assert np.allclose(((scaled - emissions[:, None]) * 1450.0)[heard], ranges[heard], atol=1e-6)
    assert np.isnan(scaled[2, 1]) and np.allclose(found, speeds)
    assert outside.tolist() == [t > 200.0 for t in emissions]


def test_emission_estimates_take_the_fix_and_else_the_median_delay():
    """A ping without a fix: its first arrival less the median delay the fixed pings show."""
    toa = np.array([[1.10, 1.20], [2.15, 2.30], [3.12, 3.40], [np.nan, np.nan]])
    fixed = np.array([1.0, 2.0, np.nan, np.nan])
    out = ss.emission_estimates(toa, fixed)
    assert out[:2].tolist() == [1.0, 2.0] and out[2] == pytest.approx(3.12 - np.median([0.10, 0.15]))
    assert np.isnan(out[3])


def _warming(tmp_path: Path, low: float, high: float, seed: int = 5):
    """400 pings of a simulated tag in water whose speed goes from ``low`` to ``high`` [m/s] over the record: the
    times of arrival, the series and the truth written to ``tmp_path``; returns the files and the speeds."""
    s = tt.TrackerSettings(sound_speed=1455.0, sigma_toa=1e-4, interval=2.0, acceleration_psd=1e-3)
    _, truth, emissions = tt.simulate_pings(RECEIVERS, 400, s, np.random.default_rng(seed), speed=0.1,
                                            detection=0.9)
    rng = np.random.default_rng(seed + 1)
    series = np.column_stack([np.linspace(emissions[0] - 10, emissions[-1] + 10, 50), np.linspace(low, high, 50)])
    speeds = np.interp(emissions, series[:, 0], series[:, 1])
    ranges = np.linalg.norm(truth[:, None] - RECEIVERS[None], axis=2)
    toa = emissions[:, None] + ranges / speeds[:, None] + 1e-4 * rng.normal(size=ranges.shape)
    toa[rng.random(toa.shape) > 0.9] = np.nan
    write_toa(tmp_path / "toa.txt", toa, NAMES)
    speed_file = tmp_path / "speed.csv"
    speed_file.write_text("time_s,sound_speed_m_s\n" + "\n".join(f"{t:.6f},{c:.6f}" for t, c in series) + "\n")
    return {"receivers": _receivers(tmp_path), "truth": _truth(tmp_path, emissions, truth)}, speed_file, speeds


@pytest.mark.slow
def test_a_measured_series_tracks_a_tag_in_water_that_warms(tmp_path):
    """The water warms from 1,440 to 1,470 m/s over the record: with the series the track is as good as the same
    tag's in water of one speed given exactly (RMS within 5 %); with one speed given (the series' median) it is
    worse by at least twice."""
    (tmp_path / "still").mkdir()
    files, _, _ = _warming(tmp_path / "still", 1455.0, 1455.0)
    still = sblsim.replay_toa(tmp_path / "still" / "toa.txt", sound_speed=1455.0, **files)
    files, speed_file, speeds = _warming(tmp_path, 1440.0, 1470.0)
    measured = sblsim.replay_toa(tmp_path / "toa.txt", sound_speed_file=speed_file, **files)
    one = sblsim.replay_toa(tmp_path / "toa.txt", sound_speed=1455.0, **files)
    summary = measured.summary["sound_speed"]
    assert summary["source"] == "measured series" and summary["pings_outside_series"] == 0
    assert summary["range_m_s"][0] == pytest.approx(speeds.min(), abs=0.05)
    rms = [float(np.sqrt(np.nanmean(_error(r) ** 2))) for r in (still, measured, one)]
    assert rms[1] <= 1.05 * rms[0] + 0.01 and rms[2] >= 2 * rms[1], rms


@pytest.mark.slow
def test_where_the_pings_cannot_give_the_speed_the_fallback_is_stated(tmp_path, capsys):
    """Two pings cannot calibrate the speed: TEOS-10's for fresh water at 20 °C (within 0.5 m/s of pure water's
    1,482.35 m/s, Marczak, J. Acoust. Soc. Am. 102, 2776, 1997) is taken with --temperature and --salinity, the
    default 1,500 m/s without, and a warning says so in one line."""
    from sblsim.orchestrator.cli import main

    lines = (DATA / "toa.txt").read_text().splitlines()
    toa = tmp_path / "toa.txt"
    toa.write_text("\n".join([lines[0], lines[100], lines[101]]) + "\n")
    base = ["replay", str(toa), "--format", "toa", "--receivers", str(DATA / "hydrophones.csv")]
    assert main(base + ["--temperature", "20", "--salinity", "0", "--out", str(tmp_path / "t")]) == 0
    speed = json.loads((tmp_path / "t" / "summary.json").read_text())["sound_speed"]
    assert speed["source"] == "fallback" and abs(speed["sound_speed_m_s"] - 1482.35) <= 0.5, speed
    warning = [line for line in capsys.readouterr().err.splitlines() if "sound speed" in line]
    assert len(warning) == 1 and "do not determine the sound speed" in warning[0] and "TEOS-10" in warning[0]
    assert main(base + ["--out", str(tmp_path / "d")]) == 0
    speed = json.loads((tmp_path / "d" / "summary.json").read_text())["sound_speed"]
    assert speed["sound_speed_m_s"] == ss.DEFAULT_SOUND_SPEED and "1500 m/s" in capsys.readouterr().err


def test_the_fallback_has_a_spread_and_a_weak_calibration_is_combined_with_it():
    """The fallback's standard deviation: without a temperature the spread of TEOS-10's surface speeds over the
    temperatures and salinities allowed as a uniform's, its extremes at the range's corners (computed with gsw
    directly, and no grid point outside them); with 20 °C and practical salinity 0, TEOS-10's change over 1 °C and 1
    in salinity in quadrature. Two estimates combined: the mean and standard deviation of their normalised product,
    integrated numerically on a grid."""
    import gsw

    def speed(t, s):  # practical salinity s as the Reference Salinity (no position given)
        sa = gsw.SR_from_SP(s)
        return gsw.sound_speed(sa, gsw.CT_from_t(sa, t, 0.0), 0.0)

    c, sigma, words = ss.fallback_prior()
    (t0, t1), (s0, s1) = ss.TEMPERATURE_RANGE, ss.SALINITY_RANGE
    low, high = speed(t0, s0), speed(t1, s1)
    grid = speed(*np.meshgrid(np.linspace(t0, t1, 31), np.linspace(s0, s1, 31)))
    assert c == ss.DEFAULT_SOUND_SPEED and grid.min() >= low - 1e-9 and grid.max() <= high + 1e-9
    assert sigma == pytest.approx((high - low) / np.sqrt(12.0), rel=1e-9) and "1500" in words
    c, sigma, _ = ss.fallback_prior(20.0, 0.0)
    expected = np.hypot((speed(21.0, 0.0) - speed(19.0, 0.0)) / 2, speed(20.0, 1.0) - speed(20.0, 0.0))
    assert abs(c - 1482.35) <= 0.5 and sigma == pytest.approx(expected, rel=1e-9)
    x = np.linspace(1300.0, 1600.0, 600001)
    density = np.exp(-0.5 * ((x - 1417.7) / 5.6) ** 2 - 0.5 * ((x - 1500.0) / 51.4) ** 2)
    mean = np.sum(x * density) / np.sum(density)
    sd = np.sqrt(np.sum((x - mean) ** 2 * density) / np.sum(density))
    assert ss.combine_speeds(1417.7, 5.6, 1500.0, 51.4) == pytest.approx((mean, sd), rel=1e-7)


def test_a_stationary_tag_is_one_position_within_its_covariance(tmp_path):
    """A tag that does not move (speed 0, no process noise), 300 pings: one position for every row, within 3.5 of
    its own sigmas of the truth (χ²(2) at 0.998), and closer than the single-ping fixes' median error."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1.5e-4, interval=5.0, acceleration_psd=1e-12)
    rng = np.random.default_rng(8)
    toa, truth, emissions = tt.simulate_pings(RECEIVERS, 300, s, rng, start=np.array([120.0, 40.0]), speed=0.0,
                                              detection=0.7)
    write_toa(tmp_path / "toa.txt", toa, NAMES)
    result = sblsim.replay_toa(tmp_path / "toa.txt", receivers=_receivers(tmp_path), sound_speed=1480.0,
                               truth=_truth(tmp_path, emissions, truth), motion="stationary")
    track = result.track
    assert result.score["estimator"] == "stationary" and track[["x", "y"]].nunique().max() == 1
    cov = np.diag([track["sigma_x"].iloc[0] ** 2, track["sigma_y"].iloc[0] ** 2])
    e = track[["x", "y"]].to_numpy()[0] - [120.0, 40.0]
    assert e @ np.linalg.inv(cov) @ e <= 12.4, (e, cov)
    fixes = result.errors.loc[result.errors["estimator"] == "fix", "error_2d_m"]
    assert np.hypot(*e) < np.nanmedian(fixes)
    assert result.summary["motion"]["model"] == "stationary" and (track["quality"] != "flagged").mean() > 0.95
    motion = result.summary["motion"]
    assert not motion["moved"] and motion["moved_test"]["trusted_fixes"] >= 100, motion


@pytest.mark.slow
def test_a_moving_tag_tracked_as_stationary_is_said_and_flagged(tmp_path, capsys):
    """A tag moving at 0.3 m/s through the array tracked with --motion stationary: its trusted fixes lie in order in
    time (the summary's ratio recomputed here from the fixes of four receivers or more: the median distance of
    successive ones over their median distance from their median, far below √2, the ratio of fixes in no order), the
    summary says it moved, one warning line, and every row flagged: never one confident position written as ok."""
    from sblsim.models.tracking.fix import fix_pings
    from sblsim.orchestrator.cli import main

    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1.5e-4, interval=5.0, acceleration_psd=1e-3)
    toa, truth, emissions = tt.simulate_pings(RECEIVERS, 200, s, np.random.default_rng(9), start=np.array([60.0, 60.0]),
                                              speed=0.3, detection=0.8)
    write_toa(tmp_path / "toa.txt", toa, NAMES)
    out = tmp_path / "o"
    assert main(["replay", str(tmp_path / "toa.txt"), "--format", "toa", "--receivers", str(_receivers(tmp_path)),
                 "--sound-speed", "1480", "--motion", "stationary", "--out", str(out)]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "the tag moved" in line]
    summary = json.loads((out / "summary.json").read_text())
    track = np.genfromtxt(out / "track.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert len(said) == 1 and summary["motion"]["moved"], (said, summary["motion"])
    assert (track["quality"] == "flagged").all()
    fx, fe, _, fu, _ = fix_pings(toa, RECEIVERS, 1480.0, 1.5e-4)
    p = fx[np.isfinite(fe) & (fu.sum(axis=1) >= 4)]
    ratio = np.median(np.hypot(*np.diff(p, axis=0).T)) / np.median(np.hypot(*(p - np.median(p, axis=0)).T))
    assert ratio < 0.3 and summary["motion"]["moved_test"]["successive_ratio"] < 0.3, (ratio, summary["motion"])


@pytest.mark.parametrize("options,message", [
    (["--temperature", "10"], "--salinity: needed with --temperature"),
    (["--sound-speed", "1417", "--sound-speed-file", "x.csv"], "--sound-speed-file: not with --sound-speed"),
    (["--sound-speed", "1417", "--temperature", "10", "--salinity", "0"], "--temperature: only where"),
    (["--temperature", "80", "--salinity", "0"], "--temperature: 80"),
    (["--motion", "stationary", "--acceleration-psd", "0.01"], "--acceleration-psd: not with --motion stationary"),
    (["--sound-speed-file", "speed.csv"], "line 3 column sound_speed_m_s: 2000 m/s is not allowed"),
])
def test_bad_medium_options_are_refused_in_one_line(tmp_path, capsys, monkeypatch, options, message):
    """Each bad combination or value: one line naming it, exit 2, nothing written."""
    from sblsim.orchestrator.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "speed.csv").write_text("time_s,sound_speed_m_s\n0,1417\n10,2000\n")
    code = main(["replay", str(DATA / "toa.txt"), "--format", "toa", "--receivers", str(DATA / "hydrophones.csv"),
                 "--out", str(tmp_path / "o"), *options])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_a_series_off_the_records_time_base_is_refused_and_a_short_one_warned(tmp_path, capsys):
    """A series in seconds since 1970 (YAPS's and ``sblsim sync``'s ``epo, ss`` columns) against a record on its own
    time base: refused in one line without the record's stated origin (``--time-origin``), and with an origin a day
    off it overlaps no ping (refused, naming both spans); nothing written either way. A series that ends half way
    through the record: the pings after it counted on the console (one warning line) and in summary.json, their
    count the simulated pings emitted after the series' last time."""
    from sblsim.orchestrator.cli import main

    files, speed_file, _ = _warming(tmp_path, 1450.0, 1460.0)
    series = np.loadtxt(speed_file, delimiter=",", skiprows=1)
    base = ["replay", str(tmp_path / "toa.txt"), "--format", "toa", "--receivers", str(files["receivers"])]
    epoch = tmp_path / "epoch.csv"
    epoch.write_text("epo,ss\n" + "".join(f"{t + 1.6e9:.3f},{c:.3f}\n" for t, c in series))
    assert main(base + ["--sound-speed-file", str(epoch), "--out", str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "its times are absolute" in err[0] and "--time-origin" in err[0], err
    assert main(base + ["--sound-speed-file", str(epoch), "--time-origin", "1599913600", "--out",
                        str(tmp_path / "e")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "do not overlap the pings' first arrivals" in err[0] and "[86390," in err[0], err
    assert not (tmp_path / "e").exists()
    half = tmp_path / "half.csv"
    kept = series[: len(series) // 2]
    half.write_text("time_s,sound_speed_m_s\n" + "".join(f"{t:.6f},{c:.6f}\n" for t, c in kept))
    assert main(base + ["--sound-speed-file", str(half), "--out", str(tmp_path / "h")]) == 0
    summary = json.loads((tmp_path / "h" / "summary.json").read_text())
    emitted = np.loadtxt(files["truth"], skiprows=1)[:, 2]  # the simulated emission times
    after = int((emitted > kept[-1, 0]).sum())
    assert summary["sound_speed"]["pings_outside_series"] == after and after > 100, after
    warning = [line for line in capsys.readouterr().err.splitlines() if "sound-speed series" in line]
    assert len(warning) == 1 and f"{after} of {summary['pings']} pings" in warning[0], warning

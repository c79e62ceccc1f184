"""The water the replay takes (orchestrator/readers/water.py, speed.py, depth.py): a temperature series made the sound
speed by TEOS-10 (against gsw called here and the file parsed here by pandas), a calibration the stated water cannot
have replaced by the water's own speed and said in one line, the depth of a tag among receivers in one plane held and
said, within the water column where its depth is given; and their refusals, one line each."""

from __future__ import annotations

import json
from pathlib import Path

import gsw
import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.readers.water import read_temperature_series

#: 8 receivers over 150 x 120 m; in a 2 m bay 1.1-1.8 m deep (one plane).
FLAT = np.array([[0.0, 0.0], [150.0, 0.0], [150.0, 120.0], [0.0, 120.0], [75.0, 60.0], [40.0, 110.0],
                 [110.0, 15.0], [20.0, 60.0]])
DEPTHS = np.array([1.1, 1.8, 1.3, 1.5, 1.2, 1.7, 1.4, 1.6])
NAMES = [f"R{k + 1}" for k in range(len(FLAT))]


def _teos10(t, sp, z=0.0):
    """TEOS-10 by hand, no position known: the Reference Salinity, the pressure at 45° N."""
    sa, p = gsw.SR_from_SP(sp), gsw.p_from_z(-np.asarray(z, float), 45.0)
    return gsw.sound_speed(sa, gsw.CT_from_t(sa, t, p), p)


def _pings(folder: Path, speed, planar: bool = False, m: int = 40, seed: int = 3) -> np.ndarray:
    """A tag crossing the array at 0.4 m/s, a ping every 2 s, 0.1 ms of timing noise, its speed of sound at each
    emission ``speed(t)`` [m/s]; 1 m deep among the bay's receivers (``planar``) or in 2-D. Writes ``toa.csv``,
    ``receivers.csv``, ``truth.csv``; returns the emission times [s]."""
    rng = np.random.default_rng(seed)
    t = 10.0 + 2.0 * np.arange(m)
    xy = np.array([30.0, 25.0]) + np.cumsum(0.8 * np.column_stack([np.cos(0.6 + 0.01 * np.arange(m)),
                                                                   np.sin(0.6 + 0.01 * np.arange(m))]), axis=0)
    receivers = np.column_stack([FLAT, -DEPTHS]) if planar else FLAT
    tag = np.column_stack([xy, np.full(m, -1.0)]) if planar else xy
    ranges = np.linalg.norm(tag[:, None] - receivers[None], axis=2)
    toa = t[:, None] + ranges / speed(t)[:, None] + 1e-4 * rng.normal(size=ranges.shape)
    pd.DataFrame(toa, columns=NAMES).to_csv(folder / "toa.csv", index=False, float_format="%.9f")
    table = {"name": NAMES, "x_m": FLAT[:, 0], "y_m": FLAT[:, 1]} | ({"z_m": -DEPTHS} if planar else {})
    pd.DataFrame(table).to_csv(folder / "receivers.csv", index=False)
    pd.DataFrame({"x": xy[:, 0], "y": xy[:, 1], "t": t}).to_csv(folder / "truth.csv", index=False)
    return t


def test_a_temperature_file_reads_as_pandas_reads_it(tmp_path):
    origin = pd.Timestamp("2024-06-01T12:00:00Z")
    times = origin + pd.to_timedelta([0.0, 60.5, 121.0], unit="s")
    iso = tmp_path / "iso.csv"
    pd.DataFrame({"Date and Time (UTC)": times.strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
                  "Temperature (°C)": [28.5, 29.25, 30.0]}).to_csv(iso, index=False)
    back = pd.read_csv(iso)
    seconds = (pd.to_datetime(back.iloc[:, 0], utc=True) - origin).dt.total_seconds().to_numpy()
    series = read_temperature_series(iso, origin.timestamp())
    assert np.allclose(series, np.column_stack([seconds, back.iloc[:, 1]]), atol=1e-6)
    epoch = tmp_path / "epo.csv"
    pd.DataFrame({"epo": origin.timestamp() + seconds, "temperature_c": back.iloc[:, 1]}).to_csv(epoch, index=False)
    assert np.allclose(read_temperature_series(epoch, origin.timestamp()), series, atol=1e-6)
    base = tmp_path / "base.csv"
    pd.DataFrame({"time_s": seconds, "temp": back.iloc[:, 1]}).to_csv(base, index=False)
    assert np.allclose(read_temperature_series(base), series)


@pytest.mark.parametrize("text,message", [
    ("time_s,temperature_c\n0,20\n10,abc\n", "line 3 column temperature_c: 'abc' is not allowed; allowed: a finite"),
    ("time_s,temperature_c\n0,20\n10,55\n", "column temperature_c: '55' is not allowed; allowed: a finite number in "
                                            "[-2, 40] °C"),
    ("time_s,temperature_c\n0,20\n0,21\n", "line 3 column time_s: the time does not increase"),
    ("time_utc,temperature_c\n2024-06-01T12:00:00Z,20\n", "its times are absolute"),
    ("time_utc,temperature_c\n2024-06-31T12:00:00Z,20\n", "a date and time that exists"),
    ("time_s,salinity\n0,20\n", "the header needs a time"),
    ("time_s,temperature_c\n", "holds a header and no rows"),
])
def test_a_bad_temperature_file_is_refused_in_one_line(tmp_path, text, message):
    path = tmp_path / "t.csv"
    path.write_text(text)
    with pytest.raises(ModelError) as error:
        read_temperature_series(path)
    assert message in str(error.value) and "\n" not in str(error.value) and "temperature file" in str(error.value)


def test_a_temperature_series_is_the_speed_teos10_gives(tmp_path):
    """Water warming from 28 to 31 °C at practical salinity 35 (a logger every 10 s, ISO 8601 times in UTC): the pings'
    own speeds from gsw here; the replay takes the series' median over the pings within 0.5 m/s of gsw's, its range
    within 0.5 m/s of gsw's, and the track close to the truth."""
    warming = np.linspace(0.0, 100.0, 11), np.linspace(28.0, 31.0, 11)
    t = _pings(tmp_path, lambda t: _teos10(np.interp(t, *warming), 35.0))
    origin = pd.Timestamp("2024-06-01T12:00:00Z")
    pd.DataFrame({"time_utc": (origin + pd.to_timedelta(warming[0], unit="s")).strftime("%Y-%m-%dT%H:%M:%SZ"),
                  "temperature_c": warming[1]}).to_csv(tmp_path / "temperature.csv", index=False)
    result = sblsim.replay_toa(tmp_path / "toa.csv", receivers=tmp_path / "receivers.csv", truth=tmp_path / "truth.csv",
                               temperature_file=tmp_path / "temperature.csv", salinity=35.0, smooth=False,
                               time_origin=origin.isoformat(), acceleration_psd=1e-3)
    speed = result.summary["sound_speed"]
    at_pings = _teos10(np.interp(t, *warming), 35.0)
    assert speed["source"] == "temperature series (TEOS-10)"
    assert abs(speed["sound_speed_m_s"] - np.median(at_pings)) <= 0.5, speed
    assert np.allclose(speed["range_m_s"], [at_pings.min(), at_pings.max()], atol=0.5), speed
    assert result.score["rms_m"] < 0.25, result.score  # the EKF's, 0.1 ms of timing noise (0.15 m)


def test_a_calibration_the_stated_water_cannot_have_is_replaced_and_said(tmp_path, capsys):
    """Pings at 1,500 m/s with the water stated as 30 °C and salinity 35 (TEOS-10: 1,545 m/s): the calibration
    (1,500) is outside the water's speeds, one warning line says so, and the water's own speed (gsw here) is taken
    (a calibration inside the water's speeds is kept: tests/models/test_tracking_water.py)."""
    _pings(tmp_path, lambda t: np.full(len(t), 1500.0))
    common = ["replay", str(tmp_path / "toa.csv"), "--format", "toa", "--receivers", str(tmp_path / "receivers.csv"),
              "--acceleration-psd", "0.001"]
    assert main([*common, "--temperature", "30", "--salinity", "35", "--out", str(tmp_path / "o")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "stated water" in line]
    assert len(said) == 1 and said[0].startswith("sblsim: warning: ") and "outside" in said[0], said
    speed = json.loads((tmp_path / "o" / "summary.json").read_text())["sound_speed"]
    assert speed["source"] == "fallback (the calibration is outside the stated water's speeds)"
    assert speed["sound_speed_m_s"] == pytest.approx(_teos10(30.0, 35.0), abs=1e-6)
    assert abs(speed["calibrated_m_s"] - 1500.0) < 2.0 and not speed["plausible_m_s"][0] <= 1500.0


@pytest.mark.slow
def test_a_tag_among_receivers_in_one_plane_is_held_at_a_stated_depth(tmp_path, capsys):
    """The bay: no depth given, one warning line says the depth is held at the receivers' mean depth (read here with
    pandas) with their span as σ and asks for the water's depth; every row there, none surer; with --water-depth 2,
    at mid-water (1 ± 2/√12 m) and every row inside the water column."""
    _pings(tmp_path, lambda t: np.full(len(t), 1545.0), planar=True, m=30)
    common = ["replay", str(tmp_path / "toa.csv"), "--format", "toa", "--receivers", str(tmp_path / "receivers.csv"),
              "--truth", str(tmp_path / "truth.csv"), "--smooth", "--sound-speed", "1545", "--acceleration-psd",
              "0.001"]
    assert main([*common, "--out", str(tmp_path / "plane")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "depth" in line]
    assert len(said) == 1 and "one plane" in said[0] and "--water-depth" in said[0], said
    depth = json.loads((tmp_path / "plane" / "summary.json").read_text())["depth"]
    z = pd.read_csv(tmp_path / "receivers.csv")["z_m"]
    assert depth["basis"] == "plane" and depth["depth_m"] == pytest.approx(-z.mean())
    assert depth["sigma_m"] == pytest.approx(z.max() - z.min())
    track = pd.read_csv(tmp_path / "plane" / "track.csv")
    assert (abs(track["z"] + depth["depth_m"]) < depth["sigma_m"]).all() and (track["sigma_z"] >= depth["sigma_m"]
                                                                              - 1e-9).all()
    assert main([*common, "--water-depth", "2", "--out", str(tmp_path / "water")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "depth" in line]
    assert len(said) == 1 and "mid-water" in said[0], said
    depth = json.loads((tmp_path / "water" / "summary.json").read_text())["depth"]
    assert (depth["depth_m"], depth["sigma_m"], depth["water_depth_m"]) == pytest.approx((1.0, 2 / np.sqrt(12), 2.0))
    track = pd.read_csv(tmp_path / "water" / "track.csv")
    assert ((track["z"] <= 0.0) & (track["z"] >= -2.0)).all()
    assert json.loads((tmp_path / "water" / "score.json").read_text())["rms_m"] < 0.1


@pytest.mark.parametrize("planar,options,message", [
    (False, ["--water-depth", "10"], "water_depth: 10 m needs the receivers' depths"),
    (True, ["--water-depth", "1.5"], "water_depth: 1.5 m is above receiver 'R2' at 1.8 m"),
    (True, ["--water-depth", "0"], "--water-depth: 0.0 is outside the allowed range (0, 11000] m"),
    (True, ["--water-depth", "2", "--tag-depth", "3"], "tag_depth: 3 m is outside the water column [0, 2] m"),
    (False, ["--temperature-file", "t.csv"], "--salinity: needed with --temperature-file"),
    (False, ["--temperature-file", "t.csv", "--salinity", "35", "--sound-speed", "1500"],
     "--temperature-file: not with --sound-speed"),
    (False, ["--temperature-file", "t.csv", "--salinity", "35", "--temperature", "20"],
     "--temperature-file: not with --temperature"),
    (False, ["--temperature", "20", "--salinity", "50"], "--salinity: 50.0 is outside the allowed range [0, 42]"),
    (False, ["--temperature-file", "t.csv", "--salinity", "35", "--time-origin", "2024-06-01T00:00:00Z"],
     "temperature file: 't.csv' line 2 column time_utc: '2024-06-01 25:00' is not allowed"),
])
def test_bad_water_options_are_refused_in_one_line(tmp_path, capsys, monkeypatch, planar, options, message):
    monkeypatch.chdir(tmp_path)
    _pings(tmp_path, lambda t: np.full(len(t), 1500.0), planar=planar, m=12)
    (tmp_path / "t.csv").write_text("time_utc,temperature_c\n2024-06-01 25:00,20\n")
    code = main(["replay", "toa.csv", "--format", "toa", "--receivers", "receivers.csv", "--out", "o", *options])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], (options, err)
    assert not (tmp_path / "o").exists()

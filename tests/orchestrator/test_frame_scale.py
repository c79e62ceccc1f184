"""Frames by their distortion (issue 98 item 3): a metric frame is taken only where its scale over the array is within
0.1 % of 1 (orchestrator/io/frames.py), checked against the projections' closed forms (Snyder 1987): Web Mercator's
point scale is sec φ, a transverse Mercator's k0 (1 + A²/2 + …) with A the longitude's offset from the central
meridian times cos φ."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.frames import MAX_SCALE_ERROR, frame_for, scale_range

BOATS = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


@pytest.mark.parametrize("lat", [0.0, 30.0, 56.3, 60.4, 75.0])
def test_web_mercators_scale_is_the_secant_of_the_latitude(lat):
    lats = np.array([lat, lat + 0.01])
    low, high = scale_range("EPSG:3857", lats, np.array([8.6, 8.62]))
    assert np.isclose(low, 1 / np.cos(np.radians(lat)), rtol=1e-6)
    assert np.isclose(high, 1 / np.cos(np.radians(lat + 0.01)), rtol=1e-6)


@pytest.mark.parametrize("lon", [3.0, 5.33, 8.9])
def test_a_utm_zones_scale_follows_the_transverse_mercator_series(lon):
    lat = 60.38  # UTM 32N's central meridian is 9° E
    a = np.cos(np.radians(lat)) * np.radians(lon - 9.0)
    expected = 0.9996 * (1 + a ** 2 / 2)  # Snyder eq. 8-11 to second order (the ellipsoid's term below 1e-6 here)
    low, high = scale_range("EPSG:32632", np.array([lat]), np.array([lon]))
    assert np.isclose(low, expected, rtol=2e-5) and np.isclose(high, low, rtol=1e-9)


def test_a_frame_that_distorts_the_array_is_refused_naming_its_scale():
    lat, lon = np.array([60.38, 60.40]), np.array([5.32, 5.36])
    assert frame_for(lat, lon, "EPSG:32631").crs == "EPSG:32631"  # scale 0.9998: taken
    for crs, scale in (("EPSG:3857", 1 / np.cos(np.radians(60.38))), ("EPSG:25833", None)):
        with pytest.raises(ModelError) as refused:
            frame_for(lat, lon, crs)
        line = str(refused.value)
        assert "\n" not in line and crs in line and "EPSG:32631" in line
        low, _ = scale_range(crs, lat, lon)
        assert abs(low - 1) > MAX_SCALE_ERROR and f"{low:.6g}" in line
        if scale is not None:
            assert f"{scale:.4g}" in line or f"{low:.4g}" in line


@pytest.mark.slow
def test_the_study_refuses_web_mercator_before_any_work(tmp_path):
    done = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", "track", str(BOATS / "detections.csv"),
                           "--receivers", str(BOATS / "deployments.csv"), "--frame", "EPSG:3857",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr[-1000:]
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "EPSG:3857" in lines[0] and "scales distances by" in lines[0]
    assert not (tmp_path / "out").exists()



def _sheet(tmp_path, rows, columns):
    import pandas as pd

    path = tmp_path / "deployments.csv"
    pd.DataFrame(rows, columns=columns).to_csv(path, index=False, float_format="%.10f")
    return path


def test_a_given_frame_is_judged_over_the_deployments_used(tmp_path):
    """A network's sheet spans zones; the frame given fits the study's own deployments: taken. Used where it does
    not fit: refused naming its scale (in_water's restriction, as the study and the sync take it)."""
    from sblsim.orchestrator.readers.deployments import read_deployments

    rows = [("1", 60.38, 5.33), ("2", 60.39, 5.34), ("3", 44.5, -82.5)]  # Norway, and a receiver on the Great Lakes
    sheet = read_deployments(_sheet(tmp_path, rows, ["serial", "lat", "lon"]), frame="EPSG:32631")
    kept = sheet.restricted(np.array([True, True, False]))
    assert kept.frame.crs == "EPSG:32631" and len(kept.table) == 2
    with pytest.raises(ModelError, match="EPSG:32631.*scales distances by"):
        sheet.restricted(np.array([True, False, True]))


def test_positions_in_a_distorting_crs_are_taken_to_the_arrays_utm_zone(tmp_path):
    """x, y given in ETRS89 / UTM 33N for an array at 5.3° E (scale 1.0031 there): projected to UTM 31N (pyproj's
    own transformation the reference), said in a note; in UTM 31N itself, kept as given."""
    from pyproj import Transformer

    from sblsim.orchestrator.readers.deployments import read_deployments

    lat, lon = np.array([60.38, 60.39]), np.array([5.33, 5.35])
    x33, y33 = Transformer.from_crs("EPSG:4326", "EPSG:25833", always_xy=True).transform(lon, lat)
    path = _sheet(tmp_path, list(zip(["1", "2"], x33, y33)), ["serial", "x_m", "y_m"])
    taken = read_deployments(path, crs="EPSG:25833")
    x31, y31 = Transformer.from_crs("EPSG:4326", "EPSG:32631", always_xy=True).transform(lon, lat)
    assert taken.frame.crs == "EPSG:32631"
    assert np.allclose(taken.table["x"], x31, atol=1e-3) and np.allclose(taken.table["y"], y31, atol=1e-3)
    assert any("EPSG:25833" in n and "EPSG:32631" in n for n in taken.notes)
    path = _sheet(tmp_path, list(zip(["1", "2"], x31, y31)), ["serial", "x_m", "y_m"])
    kept = read_deployments(path, crs="EPSG:32631")
    assert kept.frame.crs == "EPSG:32631" and np.allclose(kept.table["x"], x31, atol=1e-6)
    assert not any("scales distances" in n for n in kept.notes)

"""Survey B (GNATSS NCL1, day 208) read into the calibration log: geodesy, pairing by identity, the
straight-ray check of the reading, hostile files."""

from __future__ import annotations

import calendar
import os
import random
import shutil

import numpy as np
import pandas as pd
import pymap3d
import pytest

from sblsim.models.calibration import StraightRay, solve
from sblsim.models.errors import ModelError
from sblsim.orchestrator.io import tables
from sblsim.orchestrator.surveys import gnatss
from sblsim.orchestrator.surveys.gnatss import (
    community_editing,
    read_gnatss,
    read_ncl1,
    straight_ray_residuals,
)
from sblsim.orchestrator.surveys.gnatss_site import read_site
from sblsim.orchestrator.surveys.local_frame import ecef_to_enu, enu_rotation, geodetic_to_enu
from sblsim.orchestrator.surveys.log import LOG_COLUMNS, check_frame

PXP, POS, SITE = gnatss.ncl1_paths()
#: GNATSS's own harmonic means of the CTD for NCL1 (tests/data/config.yaml, sv_mean) [m/s].
GNATSS_SV_MEAN = {"NCL1-1": 1481.551, "NCL1-2": 1481.521, "NCL1-3": 1481.509}
TURNAROUND = {"NCL1-1": 0.20, "NCL1-2": 0.32, "NCL1-3": 0.44}


@pytest.fixture(scope="module")
def survey():
    return read_ncl1()


@pytest.fixture(scope="module")
def raw():
    """The two files parsed independently of the reader (numpy / plain Python)."""
    pings = [line.split() for line in PXP.read_text().splitlines() if line.strip()]
    pos = np.loadtxt(POS)
    return pings, pos


# --------------------------------------------------------------------------- geodesy

def test_geodesy_round_trip_enu_geodetic_enu_within_a_millimetre():
    """pymap3d's own round trip at the NCL1 origin: ENU -> geodetic -> ENU and ENU -> ECEF -> ENU."""
    rng = np.random.default_rng(208)
    enu = rng.uniform([-3000, -3000, -1500], [3000, 3000, 50], size=(200, 3))
    lat0, lon0, h0 = 45.3023, -124.9656, 0.0
    lat, lon, h = pymap3d.enu2geodetic(enu[:, 0], enu[:, 1], enu[:, 2], lat0, lon0, h0)
    back = geodetic_to_enu(lat, lon, h, lat0, lon0, h0)
    assert np.max(np.abs(back - enu)) < 1e-3
    x, y, z = pymap3d.enu2ecef(enu[:, 0], enu[:, 1], enu[:, 2], lat0, lon0, h0)
    assert np.max(np.abs(ecef_to_enu(np.column_stack([x, y, z]), lat0, lon0, h0) - enu)) < 1e-3


def test_geodesy_published_points_iogp_guidance_note_7_2():
    """IOGP Geomatics Guidance Note 7-2 (EPSG dataset) worked examples on WGS 84.

    Method 9602 (geographic/geocentric): 53°48'33.820"N, 2°07'46.380"E, h = 73.0 m is
    X = 3771793.968, Y = 140253.342, Z = 5124304.349 m. Method 9836 (geocentric/topocentric): with the
    origin X0 = 3652755.3058, Y0 = 319574.6799, Z0 = 5201547.3536 m (55°N, 5°E), that point is
    U (east) = -189013.869, V (north) = -128642.040, W (up) = -4220.171 m.
    """
    lat = 53 + 48 / 60 + 33.820 / 3600
    lon = 2 + 7 / 60 + 46.380 / 3600
    xyz = np.array(pymap3d.geodetic2ecef(lat, lon, 73.0))
    np.testing.assert_allclose(xyz, [3771793.968, 140253.342, 5124304.349], atol=1e-3)
    lat0, lon0, h0 = pymap3d.ecef2geodetic(3652755.3058, 319574.6799, 5201547.3536)
    assert lat0 == pytest.approx(55.0, abs=1e-9) and lon0 == pytest.approx(5.0, abs=1e-9)
    enu = ecef_to_enu(np.array([[3771793.968, 140253.342, 5124304.349]]), lat0, lon0, h0)[0]
    np.testing.assert_allclose(enu, [-189013.869, -128642.040, -4220.171], atol=1e-3)


def test_enu_rotation_is_the_rotation_of_the_enu_conversion():
    """R is orthonormal and turns a small ECEF offset into the difference of two ENU conversions."""
    lat0, lon0 = 45.3023, -124.9656
    rotation = enu_rotation(lat0, lon0)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0, abs=1e-12)
    base = np.array(pymap3d.geodetic2ecef(lat0, lon0, -27.0))
    offset = np.array([3.0, -2.0, 1.5])
    delta = ecef_to_enu(np.vstack([base + offset, base]), lat0, lon0, 0.0)
    np.testing.assert_allclose(rotation @ offset, delta[0] - delta[1], atol=1e-6)
    # up at the origin is the ellipsoid normal: (cos φ cos λ, cos φ sin λ, sin φ) in ECEF
    phi, lam = np.radians(lat0), np.radians(lon0)
    np.testing.assert_allclose(rotation[2], [np.cos(phi) * np.cos(lam), np.cos(phi) * np.sin(lam), np.sin(phi)],
                               atol=1e-12)


# --------------------------------------------------------------------------- the reading

def test_log_columns_times_and_travel_times_against_the_raw_files(survey, raw):
    log, site = survey
    pings, pos = raw
    assert tuple(log.columns) == LOG_COLUMNS
    assert log["ping"].dtype == np.int64 and (log[[c for c in LOG_COLUMNS if "sigma" in c]] > 0).all().all()
    # every non-zero travel time is one row, and no other row
    expected = sum(1 for p in pings for us in p[2:5] if int(us) != 0)
    assert len(log) == expected
    # the first ping: 27-JUL-22 17:37:45.00 UTC, POSIX from the calendar; J2000 = POSIX - 946728000
    posix = calendar.timegm((2022, 7, 27, 17, 37, 45, 0, 0, 0))
    first = log[log["ping"] == 0].set_index("transponder")
    assert (first["t_tx_s"] == posix).all()
    assert posix - 946728000 == pos[0, 0]
    for k, tid in enumerate(("NCL1-1", "NCL1-2", "NCL1-3")):
        us = int(pings[0][2 + k])
        assert first.loc[tid, "t_rx_s"] - posix == pytest.approx(us * 1e-6, abs=1e-6)
        assert first.loc[tid, "twtt_s"] == pytest.approx(us * 1e-6 - TURNAROUND[tid], abs=1e-12)
        # the reply's position is the POS line at transmit + TWTT (turnaround included)
        line = pos[np.argmin(np.abs(pos[:, 0] - (pos[0, 0] + us * 1e-6)))]
        e, n, u = pymap3d.ecef2enu(*line[1:4], site.lat_deg, site.lon_deg, site.height_m)
        np.testing.assert_allclose(first.loc[tid, ["rx_e_m", "rx_n_m", "rx_u_m"]].to_numpy(float), [e, n, u],
                                   atol=1e-6)


def test_sigmas_keep_the_covariance_trace(survey, raw):
    """A rotation keeps the trace: σe² + σn² + σu² of each position equals xx + yy + zz of its POS line."""
    log, _ = survey
    _, pos = raw
    trace = {round(t * 1e6): xx + yy + zz for t, xx, yy, zz in zip(pos[:, 0], pos[:, 4], pos[:, 8], pos[:, 12])}
    for prefix, time in (("tx", "t_tx_s"), ("rx", "t_rx_s")):
        keys = np.round((log[time].to_numpy() - 946728000) * 1e6).astype(np.int64)
        got = sum(log[f"{prefix}_sigma_{a}_m"] ** 2 for a in "enu").to_numpy()
        np.testing.assert_allclose(got, [trace[k] for k in keys], rtol=1e-9)


def test_site_transponders_and_harmonic_means(survey):
    """A-priori positions from lat/lon/(orthometric height + geoid undulation); harmonic means of the CTD
    from 4 m to each depth agree with GNATSS's own (its config.yaml) within 5 mm/s."""
    _, site = survey
    lat = [45.302064471, 45.295207747, 45.309643593]
    lon = [-124.978181346, -124.958752845, -124.959348875]
    height = [-1176.5866, -1146.5881, -1133.7305]
    for k, t in enumerate(site.transponders):
        x = np.array(pymap3d.geodetic2ecef(lat[k], lon[k], height[k] - 26.59))
        e, n, u = pymap3d.ecef2enu(*x, 45.3023, -124.9656, 0.0)
        assert (t.e_m, t.n_m, t.u_m) == pytest.approx((e, n, u), abs=1e-6)
        assert t.sound_speed_mps == pytest.approx(GNATSS_SV_MEAN[t.id], abs=5e-3)
    assert site.as_dict()["transponders"][2]["turnaround_s"] == 0.44


# --------------------------------------------------------------------------- pairing by identity

def _shuffled(path, tmp_path, seed):
    lines = path.read_text().splitlines(keepends=True)
    random.Random(seed).shuffle(lines)
    out = tmp_path / path.name
    out.write_text("".join(lines))
    return out


def test_shuffled_files_give_the_same_log(survey, tmp_path):
    log, site = survey
    shuffled, _ = read_gnatss(_shuffled(PXP, tmp_path, 1), _shuffled(POS, tmp_path, 2), site)
    pd.testing.assert_frame_equal(shuffled, log)


def test_replies_are_paired_by_column_identity_not_arrival(survey, raw, tmp_path):
    """Swap the travel-time columns of NCL1-1 and NCL1-3 in pxp_tt and their columns in the site: the same log.
    Replies arrive out of transponder order in most pings, so arrival order could not pair them."""
    log, _ = survey
    pings, _ = raw
    arrivals = [[int(us) - 1e6 * TURNAROUND[t] for us, t in zip(p[2:5], TURNAROUND)] for p in pings]
    out_of_order = sum(1 for p, a in zip(pings, arrivals)
                       if all(int(us) for us in p[2:5]) and list(np.argsort([int(us) for us in p[2:5]])) != [0, 1, 2])
    assert out_of_order > 0 and len(arrivals) == len(pings)
    swapped = tmp_path / "pxp_tt"
    swapped.write_text("".join(f"{p[0]} {p[1]} {p[4]} {p[3]} {p[2]} {' '.join(p[5:])}\n" for p in pings))
    site_text = SITE.read_text().replace("column = 1", "column = @").replace("column = 3", "column = 1") \
        .replace("column = @", "column = 3")
    (tmp_path / "site.toml").write_text(site_text)
    again, _ = read_gnatss(swapped, POS, tmp_path / "site.toml")
    pd.testing.assert_frame_equal(again.sort_values(["ping", "transponder"]).reset_index(drop=True),
                                  log.sort_values(["ping", "transponder"]).reset_index(drop=True))


# --------------------------------------------------------------------------- the straight-ray check

def _edited_pings_independently(raw) -> int:
    """The community editing from the raw files: all three replies, sqrt(trace C) <= 5 cm at transmit and
    at each reply, transmit point within 150 m of the array centre."""
    pings, pos = raw
    by_time = {round(t * 1e6): row for t, row in zip(pos[:, 0], pos)}
    kept = 0
    for p in pings:
        us = [int(v) for v in p[2:5]]
        if 0 in us:
            continue
        t = calendar.timegm((2000 + int(p[0][7:9]), 7, int(p[0][:2]), int(p[1][:2]), int(p[1][3:5]), 0, 0, 0, 0))
        key = round((t + float(p[1][6:]) - 946728000) * 1e6)
        rows = [by_time[key]] + [by_time[key + v] for v in us]
        if max(np.sqrt(r[4] + r[8] + r[12]) for r in rows) > 0.05:
            continue
        e, n, _ = pymap3d.ecef2enu(*rows[0][1:4], 45.3023, -124.9656, 0.0)
        kept += np.hypot(e, n) <= 150.0
    return kept


def test_community_editing_matches_an_independent_count(survey, raw):
    log, site = survey
    edited = community_editing(log, site)
    assert edited["ping"].nunique() == _edited_pings_independently(raw)
    assert (edited.groupby("ping")["transponder"].nunique() == 3).all()
    assert np.hypot(edited["tx_e_m"], edited["tx_n_m"]).max() <= 150.0


#: Bounds of the straight-ray check on the edited pings [s]. At the a-priori positions the residuals carry
#: each transponder's own offset (its a-priori position error seen along its mean line of sight; measured
#: 173 us RMS, mean -129 us); about each transponder's mean they scatter by 28-45 us (the sound speed's
#: change over the day, which one harmonic mean cannot follow, and the GNSS noise). After the rigid shift the
#: RMS was 42.7 us (6.3 cm of two-way path). A reading error is far larger: a reply paired with another
#: transponder is off by a turnaround step (0.12 s) plus the slant difference, the reply's position taken at
#: transmit by up to ~2 m of path (ms), a wrong ECEF/ENU axis by kilometres.
APRIORI_RMS_BOUND, SHIFTED_RMS_BOUND = 300e-6, 60e-6


def test_straight_ray_residuals_after_editing_and_the_rigid_shift(survey):
    log, site = survey
    edited = community_editing(log, site)
    before = straight_ray_residuals(edited, site)
    assert np.sqrt(np.mean(before ** 2)) < APRIORI_RMS_BOUND
    for tid in edited["transponder"].unique():  # the scatter about each transponder's own offset
        assert np.std(before[(edited["transponder"] == tid).to_numpy()]) < SHIFTED_RMS_BOUND
    # the calibration solver: one rigid shift, each transponder at its harmonic mean, no outlier rule
    c0 = 1481.5
    speeds = np.array([t.sound_speed_mps for t in site.transponders])
    ids = [t.id for t in site.transponders]
    replies = check_frame(edited[list(LOG_COLUMNS)].copy(), [""] * len(edited), "ncl1").replies(ids)
    apriori = np.array([[t.e_m, t.n_m, t.u_m] for t in site.transponders])
    fit = solve(replies, apriori, c0, rigid=True, outlier_factor=None, legs=StraightRay(c0 / speeds))
    shift = fit.offset[0]
    np.testing.assert_allclose(fit.offset, np.tile(shift, (3, 1)), atol=1e-15)
    order = check_frame(edited[list(LOG_COLUMNS)].copy(), [""] * len(edited), "ncl1").frame
    after = straight_ray_residuals(order, site, shift)
    # the solver's TWTT residuals are this independent straight-ray model's at the solved shift
    np.testing.assert_allclose(fit.residual_s, after, atol=1e-12)
    assert np.sqrt(np.mean(after ** 2)) < SHIFTED_RMS_BOUND
    # the weighted least-squares solution: the residuals are W-orthogonal to the Jacobian's columns
    step = 1e-3
    jac = np.column_stack([(straight_ray_residuals(order, site, shift - step * d)
                            - straight_ray_residuals(order, site, shift + step * d)) / (2 * step)
                           for d in np.eye(3)])
    w = fit.weight
    assert np.max(np.abs(jac.T @ (w * after))) < 1e-9 * np.linalg.norm(jac) * np.linalg.norm(w * after) * len(after)
    # an unweighted fit is not the solution (the weights matter): its normal equations are not met
    assert np.max(np.abs(jac.T @ after)) > 1e-6 * np.linalg.norm(jac) * np.linalg.norm(after)
    # its sigma from the same Jacobian and weights, scaled by the variance of unit weight
    factor = np.sum(w * after ** 2) / (len(after) - 3)
    sigma = np.sqrt(np.diag(factor * np.linalg.inv(jac.T @ (w[:, None] * jac))))
    np.testing.assert_allclose(fit.sigma[0], sigma, rtol=1e-4)
    assert np.all(fit.sigma[0] < 0.02) and np.linalg.norm(shift) < 1.0
    assert fit.used.all() and len(fit.used) == 3 * edited["ping"].nunique()


def test_the_check_fails_when_replies_are_paired_wrongly(survey, tmp_path):
    """The check can fail: the site's columns 1 and 2 swapped without the data puts the residuals far
    above the bound (each reply paired with another transponder)."""
    log, _ = survey
    text = SITE.read_text().replace("column = 1", "column = @").replace("column = 2", "column = 1") \
        .replace("column = @", "column = 2")
    (tmp_path / "site.toml").write_text(text)
    wrong_log, wrong_site = read_gnatss(PXP, POS, tmp_path / "site.toml")
    edited = community_editing(wrong_log, wrong_site)
    assert np.sqrt(np.mean(straight_ray_residuals(edited, wrong_site) ** 2)) > 100 * APRIORI_RMS_BOUND


# --------------------------------------------------------------------------- hostile files

def _copy(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    for path in (PXP, POS, SITE):
        shutil.copy(path, folder / path.name)
    return folder / PXP.name, folder / POS.name, folder / SITE.name


def _main(capsys, pxp, pos, site, out):
    status = gnatss.main(["--pxp-tt", str(pxp), "--posfilter", str(pos), "--site", str(site), "--out", str(out)])
    err = capsys.readouterr().err
    return status, err


def test_main_writes_the_log(tmp_path, capsys, survey):
    pxp, pos, site = _copy(tmp_path)
    out = tmp_path / "log.csv"
    status, err = _main(capsys, pxp, pos, site, out)
    assert status == 0 and err == ""
    back = pd.read_csv(out, comment="#", dtype={"transponder": str})
    pd.testing.assert_frame_equal(back, survey[0], check_exact=False, rtol=1e-15, atol=0)


@pytest.mark.parametrize("target, line, column, bad", [
    ("pxp", 7, 4, "23x79346"),
    ("pos", 11, 5, "0.76E-03.1"),
    ("pos", 20, 3, "nan"),
    ("pxp", 3, 1, "27-JUX-22"),
])
def test_a_bad_number_names_file_line_and_column(tmp_path, capsys, target, line, column, bad):
    pxp, pos, site = _copy(tmp_path)
    path = pxp if target == "pxp" else pos
    lines = path.read_text().splitlines(keepends=True)
    fields = lines[line - 1].split()
    fields[column - 1] = bad
    lines[line - 1] = " ".join(fields) + "\n"
    path.write_text("".join(lines))
    out = tmp_path / "log.csv"
    status, err = _main(capsys, pxp, pos, site, out)
    assert status == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert path.name in err and f"line {line}" in err and f"column {column}" in err
    assert not out.exists() and not list(tmp_path.glob(".log.csv*"))


def test_truncated_files_are_refused(tmp_path, capsys):
    pxp, pos, site = _copy(tmp_path)
    data = pos.read_bytes()
    cut = data.index(b"\n", len(data) // 2) + 40
    pos.write_bytes(data[:cut])  # mid-line: the last line has too few fields
    out = tmp_path / "log.csv"
    status, err = _main(capsys, pxp, pos, site, out)
    assert status == 2 and "fields" in err and "truncated" in err and not out.exists()
    lines = data.decode().splitlines(keepends=True)
    pos.write_text("".join(lines[:len(lines) // 2]))  # at a line end: pings without positions
    status, err = _main(capsys, pxp, pos, site, out)
    assert status == 2 and "no position at" in err and "pxp_tt line" in err and not out.exists()


def test_oversize_and_odd_files_are_refused(tmp_path, capsys, monkeypatch):
    pxp, pos, site = _copy(tmp_path)
    out = tmp_path / "log.csv"
    monkeypatch.setattr(tables, "MAX_LOG_BYTES", 100_000)  # pxp_tt (92 kB) passes, the 1.4 MB file does not
    status, err = _main(capsys, pxp, pos, site, out)
    assert status == 2 and "POS_FREED_TRANS_TWTT" in err and "MiB" in err and not out.exists()
    monkeypatch.undo()
    status, err = _main(capsys, pxp, tmp_path, site, out)
    assert status == 2 and "is a directory" in err
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    status, err = _main(capsys, fifo, pos, site, out)
    assert status == 2 and "not a regular file" in err and not out.exists()


def test_conflicting_positions_and_duplicate_pings_are_refused(tmp_path, capsys):
    pxp, pos, site = _copy(tmp_path)
    out = tmp_path / "log.csv"
    lines = pos.read_text().splitlines(keepends=True)
    fields = lines[1].split()
    fields[1] = f"{float(fields[1]) + 5:.3f}"
    pos.write_text("".join(lines) + " ".join(fields) + "\n")
    status, err = _main(capsys, pxp, pos, site, out)
    assert status == 2 and "two different positions at one time" in err and "lines 2 and 5905" in err
    shutil.copy(POS, pos)
    text = pxp.read_text().splitlines(keepends=True)
    pxp.write_text("".join(text + text[:1]))
    status, err = _main(capsys, pxp, pos, site, out)
    assert status == 2 and "lines 1 and 1477 are two pings at one time" in err and not out.exists()


@pytest.mark.parametrize("old, new, message", [
    ("column = 3", "column = 2", "site.transponders: the columns must be 1 ... 3, each once"),
    ("turnaround_s = 0.44", "turnaround_s = -1", "site.transponders[2].turnaround_s: -1 is outside the allowed "
                                                 "range [0, 10]"),
    ("lat_deg = 45.3023", "lat_deg = 95.3", "site.origin.lat_deg: 95.3 is outside the allowed range [-90, 90]"),
    ('id = "NCL1-2"', 'id = "NCL1-1"', "site.transponders: every id must be different"),
])
def test_bad_site_values_name_the_key_and_range(tmp_path, old, new, message):
    text = SITE.read_text()
    assert old in text
    (tmp_path / "site.toml").write_text(text.replace(old, new, 1))
    with pytest.raises(ModelError) as info:
        read_site(tmp_path / "site.toml")
    assert message in str(info.value)


def test_a_reply_shorter_than_its_turnaround_is_refused(tmp_path, capsys):
    pxp, pos, site = _copy(tmp_path)
    lines = pxp.read_text().splitlines(keepends=True)
    fields = lines[0].split()
    fields[4] = "400000"  # NCL1-3 turns around in 0.44 s
    lines[0] = " ".join(fields) + "\n"
    pxp.write_text("".join(lines))
    status, err = _main(capsys, pxp, pos, site, tmp_path / "log.csv")
    assert status == 2 and "line 1: column 5" in err and "turnaround 0.44 s" in err

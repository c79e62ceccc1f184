"""``--format garpos``: GARPOS's observation CSV, site-parameter file and profile, written here from a known geometry
(the attitude's rotation against scipy's), the paths GARPOS's files name never read, hostile files refused."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from sblsim.orchestrator.cli import main
from sblsim.orchestrator.surveys.calibrate import calibrate, load_survey
from sblsim.orchestrator.surveys.garpos import read_garpos

STATIONS = {"M11": (-47.0, 408.6, -1345.0), "M12": (486.6, 48.1, -1354.3), "M13": (-26.4, -506.1, -1335.8),
            "M14": (-538.1, -22.7, -1330.5)}
CENTRE = (0.5, -0.3, 0.2)
ATD = np.array([1.5547, -1.2690, 23.7295])  # forward, rightward, downward
C = 1500.0


def _enu_offset(heading, pitch, roll):
    """GARPOS's corr_attitude written with scipy: Rz(heading) Ry(pitch) Rx(roll) on (forward, right, down) in
    North-East-Down, then East-North-Up."""
    ned = Rotation.from_euler("ZYX", [heading, pitch, roll], degrees=True).apply(ATD)
    return np.array([ned[1], ned[0], -ned[2]])


def _write(folder, n=320, shift=(0.08, -0.05, 0.03), rng=None, extra_rows=()):
    """GARPOS's three files of a known survey (straight rays at C through a constant profile)."""
    rng = rng or np.random.default_rng(0)
    folder.mkdir()
    ids = list(STATIONS)
    truth = {k: np.array(v) + np.array(CENTRE) + np.array(shift) for k, v in STATIONS.items()}
    lines = [",SET,LN,MT,TT,ResiTT,TakeOff,gamma,flag,ST,ant_e0,ant_n0,ant_u0,head0,pitch0,roll0,RT,ant_e1,ant_n1,"
             "ant_u1,head1,pitch1,roll1"]
    transducers = []
    for i in range(n):
        mt = ids[i % 4]
        st = 30000.0 + 13.0 * i
        # the values as the file holds them (5 and 3 decimals)
        a0 = np.round([900 * math.sin(i / 25) + 100, 900 * math.cos(i / 31), 14.5 + 0.3 * rng.normal()], 5)
        att0 = np.round([(37.0 * i) % 360, rng.normal(0, 1.5), rng.normal(0, 2.5)], 3)
        p0 = a0 + _enu_offset(*att0)
        leg = np.linalg.norm(p0 - truth[mt]) / C
        rt = st + 2 * leg + 1.0
        a1 = np.round(a0 + np.array([1.2, -0.4, 0.05]), 5)
        att1 = np.round(att0 + np.array([0.4, -0.3, 0.6]), 3)
        p1 = a1 + _enu_offset(*att1)
        tt = leg + np.linalg.norm(p1 - truth[mt]) / C + 5e-7 * rng.normal()
        lines.append(f"{i},S01,L01,{mt},{tt:.7f},0.0,0.0,0.0,False,{st:.6f},{a0[0]:.5f},{a0[1]:.5f},{a0[2]:.5f},"
                     f"{att0[0]:.3f},{att0[1]:.3f},{att0[2]:.3f},{rt:.6f},{a1[0]:.5f},{a1[1]:.5f},{a1[2]:.5f},"
                     f"{att1[0]:.3f},{att1[1]:.3f},{att1[2]:.3f}")
        transducers.append((p0, p1))
    lines += list(extra_rows)
    (folder / "obs.csv").write_text("# cfgfile = /etc/passwd\n" + "\n".join(lines) + "\n")
    (folder / "svp.csv").write_text("depth,speed\n" + "\n".join(f"{z:.1f},{C:.3f}" for z in range(0, 1600, 100))
                                    + "\n")
    model = "\n".join(f" {k}_dPos = {v[0]:.4f} {v[1]:.4f} {v[2]:.4f} 3.0010 3.0010 3.0010 0 0 0"
                      for k, v in STATIONS.items())
    (folder / "initcfg.ini").write_text(f"""[Obs-parameter]
 Site_name   = TEST
 Campaign    = 0101.ship
 Date(UTC)   = 2019-03-15
 SoundSpeed  = /nonexistent/svp.csv

[Data-file]
 datacsv     = /etc/shadow

[Site-parameter]
 Latitude0   =  34.96166667
 Longitude0  = 139.26333333
 Height0     =  43.00
 Stations    = {' '.join(ids)}

[Model-parameter]
{model}
 dCentPos    = {CENTRE[0]} {CENTRE[1]} {CENTRE[2]} 0 0 0 0 0 0
 ATDoffset   = {ATD[0]} {ATD[1]} {ATD[2]} 0 0 0 0 0 0
""")
    return truth, np.array(transducers)


def _args(folder, *extra):
    return ["calibrate", str(folder / "obs.csv"), "--format", "garpos", "--initcfg", str(folder / "initcfg.ini"),
            "--svp", str(folder / "svp.csv"), *extra]


def test_the_reader_turns_the_offset_by_the_attitude_as_scipy_does(tmp_path):
    truth, transducers = _write(tmp_path / "g", extra_rows=[
        "900,S01,L01,M11,2.2,0,0,0,True,40000.0,0,0,14,0,0,0,40003.3,0,0,14,0,0,0",
        "901,S01,L01,M00,2.2,0,0,0,False,40010.0,0,0,14,0,0,0,40013.3,0,0,14,0,0,0"])
    site = read_garpos(tmp_path / "g" / "obs.csv", tmp_path / "g" / "initcfg.ini", tmp_path / "g" / "svp.csv")
    f = site.log.frame.sort_values("t_tx_s")
    np.testing.assert_allclose(f[["tx_e_m", "tx_n_m", "tx_u_m"]].to_numpy(), transducers[:, 0], atol=2e-5)
    np.testing.assert_allclose(f[["rx_e_m", "rx_n_m", "rx_u_m"]].to_numpy(), transducers[:, 1], atol=2e-5)
    assert site.left_out == {"flagged": 1, "unknown_transponder": 1}
    assert site.ids == list(STATIONS) and site.name == "TEST.0101.ship"
    np.testing.assert_allclose(site.apriori, np.array(list(STATIONS.values())) + CENTRE)
    # times: seconds of the survey's day, UTC
    assert f["t_tx_s"].iloc[0] == pytest.approx(1552608000.0 + 30000.0)
    assert site.origin == {"lat_deg": 34.96166667, "lon_deg": 139.26333333, "height_m": 43.0}


@pytest.mark.slow
def test_a_garpos_survey_is_solved_by_the_command(tmp_path, capsys):
    truth, _ = _write(tmp_path / "g")
    out = tmp_path / "out"
    assert main(_args(tmp_path / "g", "--out", str(out), "--set", "solver.perturbation=garpos",
                      "--set", "solver.knot_interval=1200", "--set", "solver.mu_t=60")) == 0
    s = json.loads((out / "solution.json").read_text())
    assert s["format"] == "garpos" and s["solver"]["propagation"] == "ray" and s["abic"] is not None
    for t in s["transponders"]:
        want = truth[t["id"]] - (np.array(STATIONS[t["id"]]) + CENTRE)
        assert (t["e_m"], t["n_m"], t["u_m"]) == pytest.approx(tuple(want), abs=0.01)
    assert (out / "ntd.csv").is_file()
    survey = load_survey(str(tmp_path / "g" / "obs.csv"), "garpos", ["solver.propagation=straight"],
                         str(tmp_path / "g" / "initcfg.ini"), str(tmp_path / "g" / "svp.csv"))
    assert survey.solver["propagation"] == "straight"
    assert np.allclose(calibrate(survey).segments[0][3].offset[0], truth["M11"] - survey.apriori[0], atol=0.01)


@pytest.mark.parametrize("edit, message", [
    (lambda d: (d / "obs.csv").write_text((d / "obs.csv").read_text().replace(",False,30013", ",Maybe,30013")),
     "line 4: flag: 'Maybe' is not True or False"),
    (lambda d: (d / "obs.csv").write_text((d / "obs.csv").read_text().replace(",TT,", ",T2,")),
     "lacks the column TT"),
    (lambda d: (d / "initcfg.ini").write_text((d / "initcfg.ini").read_text().replace(" ATDoffset", " ATD")),
     "[Model-parameter] ATDoffset is missing"),
    (lambda d: (d / "initcfg.ini").write_text((d / "initcfg.ini").read_text().replace("2019-03-15", "15/03/19")),
     "Date(UTC): '15/03/19' is not a date YYYY-MM-DD"),
    (lambda d: (d / "svp.csv").write_text("depth,speed\n0,1500\n100,2500\n"), "speed: 2500 is outside"),
])
def test_hostile_garpos_files_are_refused_in_one_line(tmp_path, capsys, edit, message):
    _write(tmp_path / "g", n=40)
    edit(tmp_path / "g")
    assert main(_args(tmp_path / "g", "--out", str(tmp_path / "out"))) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "out").exists()


def test_garpos_needs_its_three_files_and_only_garpos_takes_them(tmp_path, capsys):
    _write(tmp_path / "g", n=40)
    assert main(["calibrate", str(tmp_path / "g" / "obs.csv"), "--format", "garpos"]) == 2
    assert "--initcfg FILE" in capsys.readouterr().err
    assert main(["calibrate", str(tmp_path / "g" / "obs.csv"), "--initcfg", str(tmp_path / "g" / "initcfg.ini")]) == 2
    assert "go with --format garpos" in capsys.readouterr().err

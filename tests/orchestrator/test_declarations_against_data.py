"""What a user declares, checked against the data at the first command that sees both (issue 88, item 3): receivers'
positions in kilometres or degrees (``sync``, ``toa``, a design's water), a stable burst interval on a random tag
(``toa``, ``replay``), a tag depth the arrivals refute, two tags under one id, and ``[site.area]`` in an LBL design;
each refused in one line with exit status 2 and nothing written, on simulated cases with a known truth."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import sblsim
from sblsim.models.errors import ConfigError, ModelError
from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.sync.simulate import simulate_sync
from sblsim.models.tracking import schedule as ps
from sblsim.models.tracking.depth import check_given_depth
from sblsim.models.tracking.twins import two_places
from sblsim.orchestrator.cli import main
from tests.helpers import problem_with

#: The simulated files' epoch [s since 1970 UTC].
EPOCH = 1_700_000_000
#: A number in a message.
NUMBER = r"(-?[0-9.]+(?:e[+-]?[0-9]+)?)"


def _refused(capsys, args: list[str], out: Path) -> str:
    """Run the command line: exit status 2, one line on stderr, nothing written at ``out``; the line."""
    code = main(args)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and not out.exists(), (code, err)
    return err[0]


@pytest.fixture(scope="module")
def array(tmp_path_factory):
    """Six receivers over 400 m with their sync tags, 3 h of detections (YAPS table), the table in metres, in
    kilometres and in degrees (about 56.4° N), and a synchronisation made with the table in metres."""
    folder = tmp_path_factory.mktemp("array")
    sim = simulate_sync(n_receivers=6, hours=3.0, seed=5, side=400.0, noise=0.15e-3)
    t = sim.time + EPOCH
    epo = np.floor(t).astype(np.int64)
    table = pd.DataFrame({"epo": epo, "frac": [f"{v:.7f}" for v in np.clip(t - epo, 0, 0.9999999)],
                          "tag": [f"S{i}" for i in sim.tag], "serial": [f"R{j}" for j in sim.receiver]})
    table.iloc[np.lexsort((table["frac"].astype(float), table["epo"]))].to_csv(folder / "detections.csv", index=False)
    receivers = pd.DataFrame({"serial": [f"R{j}" for j in range(6)], "sync_tag": [f"S{j}" for j in range(6)],
                              "x_m": sim.positions[:, 0], "y_m": sim.positions[:, 1]})
    receivers.to_csv(folder / "m.csv", index=False)
    receivers.assign(x_m=sim.positions[:, 0] / 1e3, y_m=sim.positions[:, 1] / 1e3).to_csv(folder / "km.csv",
                                                                                           index=False)
    receivers.assign(x_m=9.3 + sim.positions[:, 0] / 61_500.0, y_m=56.4 + sim.positions[:, 1] / 111_195.0).to_csv(
        folder / "deg.csv", index=False)
    result = sblsim.sync(folder / "detections.csv", receivers=folder / "m.csv", sound_speed=sim.sound_speed)
    (folder / "sync").mkdir()  # the file sblsim toa reads of a synchronisation (the figures not drawn: fast)
    result.offsets.to_csv(folder / "sync" / "offsets.csv", index=False, float_format="%.12g")
    return folder, sim


@pytest.mark.parametrize("unit, factor", [("km", 1e3), ("deg", None)])
def test_sync_refuses_receivers_in_kilometres_or_degrees(array, capsys, unit, factor):
    """The table's distances against the sync tags' clock-free double differences: the factor the message gives is
    the one the table was divided by (within 5 %), the unit named, the file named."""
    folder, sim = array
    out = folder / f"sync_{unit}"
    line = _refused(capsys, ["sync", str(folder / "detections.csv"), "--receivers", str(folder / f"{unit}.csv"),
                             "--sound-speed", str(sim.sound_speed), "--out", str(out)], out)
    assert f"{unit}.csv" in line and "lat, lon columns" in line, line
    found = float(re.search(rf"put the receivers {NUMBER} times as far apart", line).group(1))
    if factor is not None:
        assert abs(found / factor - 1) < 0.05 and "look like kilometres" in line, line
    else:  # a degree of latitude is 111 km, of longitude at 56.4° N 61.5 km
        assert 5e4 < found < 1.3e5 and "look like degrees" in line, line


def test_toa_refuses_receivers_too_small_for_the_tags_arrivals(array, capsys):
    """The metre table makes the matrix; the same synchronisation with the table in kilometres is refused: the
    arrivals spread over far more than sound crosses 0.4 "m"."""
    folder, _ = array
    common = ["toa", str(folder / "detections.csv"), "--sync", str(folder / "sync"), "--tag", "S1"]
    assert main([*common, "--receivers", str(folder / "m.csv"), "--out", str(folder / "toa_m")]) == 0
    capsys.readouterr()
    line = _refused(capsys, [*common, "--receivers", str(folder / "km.csv"), "--out", str(folder / "toa_km")],
                    folder / "toa_km")
    assert "km.csv" in line and "look like kilometres" in line, line


def test_toa_refuses_a_stable_interval_on_a_random_tag(array, capsys):
    """Sync tag S1 pings at U(540, 660) s: ``--ping-type sbi`` is refused, the range the message gives within the
    simulated one (the first arrivals' steps differ from the emissions' by under sound's crossing, 0.4 s)."""
    folder, _ = array
    out = folder / "toa_sbi"
    line = _refused(capsys, ["toa", str(folder / "detections.csv"), "--receivers", str(folder / "m.csv"), "--sync",
                             str(folder / "sync"), "--tag", "S1", "--ping-type", "sbi", "--out", str(out)], out)
    low, high = map(float, re.search(rf"are {NUMBER} to {NUMBER} s apart", line).groups())
    assert line.startswith("sblsim: error: ping type sbi") and "rbi" in line, line
    assert 539.5 < low < high < 660.5 and high - low > 40, line


#: Six receivers over 400 × 300 m.
FLAT = np.array([[0, 0], [400, 0], [400, 300], [0, 300], [200, 150], [100, 250]], float)


def test_a_stable_interval_is_refused_where_the_steps_are_random_and_kept_where_pings_are_missed():
    """The check alone: a tag at U(20, 40) s is refused; a stable tag heard at a third of its pings (most steps
    several intervals) and one with every ping are not."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1.5e-4, interval=30.0, acceleration_psd=1e-4)
    crossing = ps.crossing_time(FLAT, 1480.0)
    rng = np.random.default_rng(5)
    for kind, heard, refused in (("rbi", 1.0, True), ("sbi", 1.0, False), ("sbi", 0.35, False)):
        toa, _, _ = tt.simulate_pings(FLAT, 300, s, np.random.default_rng(2), detection=0.8, ping_type=kind,
                                      burst_interval=(20.0, 40.0), speed=0.1)
        toa = toa[np.isfinite(toa).any(axis=1) & (rng.random(len(toa)) < heard)]  # pings nobody heard left out
        if refused:
            with pytest.raises(ModelError, match="ping type sbi: the pings' first arrivals are"):
                ps.check_stable(toa, crossing)
        else:
            ps.check_stable(toa, crossing)
            steps = np.diff(ps.first_arrivals(toa))
            assert heard == 1.0 or np.mean(steps > 45.0) > 0.5  # most steps of the sparse tag are multiples


def test_replay_refuses_a_stable_interval_on_a_random_tag(tmp_path, capsys):
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1.5e-4, interval=30.0, acceleration_psd=1e-4)
    toa, _, _ = tt.simulate_pings(FLAT, 60, s, np.random.default_rng(2), detection=0.8, ping_type="rbi",
                                  burst_interval=(20.0, 40.0), speed=0.1)
    names = [f"R{k}" for k in range(len(FLAT))]
    pd.DataFrame(toa, columns=names).to_csv(tmp_path / "toa.csv", index=False, na_rep="NA", float_format="%.9f")
    pd.DataFrame({"name": names, "x_m": FLAT[:, 0], "y_m": FLAT[:, 1]}).to_csv(tmp_path / "r.csv", index=False)
    line = _refused(capsys, ["replay", str(tmp_path / "toa.csv"), "--format", "toa", "--receivers",
                             str(tmp_path / "r.csv"), "--sound-speed", "1480", "--ping-type", "sbi", "--out",
                             str(tmp_path / "o")], tmp_path / "o")
    assert "--burst-interval 20:40" in line, line


#: Eight receivers 2-20 m deep over 200 × 150 m.
DEEP = np.array([[0.0, 0.0, -2.0], [200.0, 0.0, -15.0], [200.0, 150.0, -4.0], [0.0, 150.0, -20.0],
                 [100.0, 75.0, -8.0], [60.0, 140.0, -3.0], [140.0, 20.0, -12.0], [30.0, 80.0, -6.0]])


def _deep_tag(n: int = 60):
    """A tag circling the array's middle between 7 and 13 m deep: its times of arrival and truth."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1.5e-4, interval=2.0, acceleration_psd=1e-3)

    def path(t):
        a = 2 * np.pi * np.asarray(t) / 240.0
        return np.column_stack([100 + 50 * np.cos(a), 75 + 40 * np.sin(a), -10 - 3 * np.sin(3 * a)])

    toa, truth, _ = tt.simulate_pings(DEEP, n, s, np.random.default_rng(1), detection=0.8, path=path)
    return toa, truth


@pytest.mark.slow
def test_a_tag_depth_the_arrivals_refute_is_refused(tmp_path, capsys):
    """``--tag-depth 60`` for a tag 7-13 m deep: one line naming the depth given, and the depths the free fixes
    show, overlapping the truth's; the check alone keeps the tag's mean depth and its deepest."""
    toa, truth = _deep_tag()
    names = [f"R{k}" for k in range(len(DEEP))]
    pd.DataFrame(toa, columns=names).to_csv(tmp_path / "toa.csv", index=False, na_rep="NA", float_format="%.9f")
    pd.DataFrame({"name": names, "x_m": DEEP[:, 0], "y_m": DEEP[:, 1], "z_m": DEEP[:, 2]}).to_csv(
        tmp_path / "r.csv", index=False)
    line = _refused(capsys, ["replay", str(tmp_path / "toa.csv"), "--format", "toa", "--receivers",
                             str(tmp_path / "r.csv"), "--sound-speed", "1480", "--tag-depth", "60", "--out",
                             str(tmp_path / "o")], tmp_path / "o")
    low, high = map(float, re.search(rf"put the tag at {NUMBER} to {NUMBER} m", line).groups())
    assert "tag_depth: 60 m given" in line and low < -truth[:, 2].max() and high > -truth[:, 2].min(), line
    fx, _, fc, used, _ = tt.fix_pings(toa, DEEP, 1480.0, 1.5e-4)
    for given in (-truth[:, 2].mean(), -truth[:, 2].min()):
        check_given_depth(given, 0.3, fx, fc, used.sum(axis=1), DEEP)
    with pytest.raises(ModelError, match="tag_depth: 30 m given"):
        check_given_depth(30.0, 0.3, fx, fc, used.sum(axis=1), DEEP)


#: Eight receivers over 600 × 400 m, and two places 400 m apart.
WIDE = np.array([[0, 0], [600, 0], [600, 400], [0, 400], [300, 200], [150, 300], [450, 100], [300, 0]], float)
PLACES = ((100.0, 200.0), (500.0, 200.0))


def _interleaved(count: int) -> pd.DataFrame:
    """``count`` tags (one per place of :data:`PLACES`) at U(20, 40) s, each 30 m round its place, one matrix."""
    s = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=1.5e-4, interval=30.0, acceleration_psd=1e-4)
    rows = []
    for k, (cx, cy) in enumerate(PLACES[:count]):
        def path(t, cx=cx, cy=cy):
            a = 2 * np.pi * np.asarray(t) / 3600.0
            return np.column_stack([cx + 30 * np.cos(a), cy + 30 * np.sin(a)])

        toa, _, _ = tt.simulate_pings(WIDE, 120, s, np.random.default_rng(10 + k), detection=0.8, ping_type="rbi",
                                      burst_interval=(20.0, 40.0), path=path, first_emission=5.0 * k)
        rows.append(pd.DataFrame(toa).assign(first=np.nanmin(toa, axis=1)))
    frame = pd.concat(rows).sort_values("first").drop(columns="first")
    return frame[frame.notna().any(axis=1)]


def test_two_tags_under_one_id_are_refused_naming_both_places(tmp_path, capsys):
    names = [f"R{k}" for k in range(len(WIDE))]
    _interleaved(2).set_axis(names, axis=1).to_csv(tmp_path / "4555.csv", index=False, na_rep="NA",
                                                   float_format="%.9f")
    pd.DataFrame({"name": names, "x_m": WIDE[:, 0], "y_m": WIDE[:, 1]}).to_csv(tmp_path / "r.csv", index=False)
    line = _refused(capsys, ["replay", str(tmp_path / "4555.csv"), "--format", "toa", "--receivers",
                             str(tmp_path / "r.csv"), "--sound-speed", "1480", "--out", str(tmp_path / "o")],
                    tmp_path / "o")
    assert "transmitter 4555: looks like two tags" in line, line
    found = np.array([float(v) for v in re.findall(rf"\({NUMBER}, {NUMBER}\) m", line)[0] +
                      re.findall(rf"\({NUMBER}, {NUMBER}\) m", line)[1]]).reshape(2, 2)
    truth = np.array(PLACES)
    error = min(np.abs(found - truth).max(), np.abs(found[::-1] - truth).max())
    assert error < 35.0, (found, line)  # each within the circle's radius (30 m) of its place
    # one tag alone: its fixes neither jump nor split
    one = _interleaved(1).to_numpy()
    fx, fe, fc, _, _ = tt.fix_pings(one, WIDE, 1480.0, 1.5e-4)
    ok = np.isfinite(fe)
    assert two_places(fx[ok], fe[ok], fc[ok]) is None


#: A pond of 300 m (the telemetry design tests' L-shaped lake), in metres, kilometres and degrees.
POND = {
    "design": {"name": "pond"},
    "site.area": {"polygon": "0 0; 0 300; 150 300; 150 150; 300 150; 300 0"},
    "detection": {"range_50_m": 350.0, "slope": 0.02},
    "work_area": {"shape": "site", "points": 8},
    "prescription": {"drms_m": 2.0, "coverage_pct": 90.0},
    "candidates": {"systems": ["ilbl"], "receivers": [4, 5]},
    "search": {"generations": 2, "seed": 3},
    "monte_carlo": {"replicates": 10, "path": False},
}


@pytest.mark.parametrize("polygon, unit", [
    ("0 0; 0 0.3; 0.15 0.3; 0.15 0.15; 0.3 0.15; 0.3 0", "kilometres"),
    ("56.400 9.300; 56.400 9.305; 56.4015 9.305; 56.4015 9.3025; 56.403 9.3025; 56.403 9.300", "degrees"),
])
def test_a_design_water_in_kilometres_or_degrees_is_refused(polygon, unit):
    with pytest.raises(ConfigError, match=rf"^site.area.polygon: the water is .* m across.* looks like {unit}"):
        sblsim.design(None, **problem_with(POND, **{"site.area": {"polygon": polygon}}))


def test_an_lbl_design_refuses_the_water_of_a_telemetry_array():
    with pytest.raises(ConfigError, match=r"^site.area.polygon: no effect in a design of lbl"):
        sblsim.design(None, scenario="lbl-field", work_area={"radius_m": 500.0}, candidates={"systems": ["lbl"]},
                      **{"site.area": {"polygon": "0 0; 0 300; 300 300; 300 0"}})

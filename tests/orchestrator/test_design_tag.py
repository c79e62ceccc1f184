"""A telemetry design's tag (``[tag]``: the ping type and burst interval as the tracker names them, a pseudo-random
tag's sequence file, the power class) and the site's SNR model as the detection curve: the confirmation's pings
follow the tag, its walk is tracked for every ping type, bad keys are refused in one line, and a design on the SNR
curve runs."""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest

import sblsim
from sblsim.models.acoustics import sonar
from sblsim.models.errors import ConfigError
from sblsim.orchestrator.design.problem import check_problem, read_problem
from tests.helpers import problem_with
from tests.orchestrator.test_design_telemetry import SMALL  # the small L-shaped lake, a logistic curve

#: A pseudo-random tag's intervals [s] (a maker's table: not a uniform draw, repeated in turn).
SEQUENCE = [31.7, 22.4, 38.9, 27.0, 35.3, 20.8, 29.6, 24.1]


def _problem(**changes):
    return problem_with(SMALL, **changes)


def _toml(problem: dict) -> str:
    """The problem as a DESIGN.toml (``site.area`` as ``[site.area]``)."""
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list):
            return "[" + ", ".join(value(x) for x in v) + "]"
        return repr(v)
    return "".join(f"[{section}]\n" + "".join(f"{k} = {value(v)}\n" for k, v in keys.items()) + "\n"
                   for section, keys in problem.items())


def _resolved(tmp_path, **tag):
    from sblsim.orchestrator.design.telemetry import resolve

    (tmp_path / "seq.csv").write_text("interval_s\n" + "".join(f"{v}\n" for v in SEQUENCE))
    (tmp_path / "pond.toml").write_text(_toml(_problem(tag=tag)))
    return resolve(check_problem(read_problem(tmp_path / "pond.toml")))


def test_the_confirmations_pings_follow_the_tag(tmp_path):
    """The simulated tag's emissions step as its ping type says: a stable 25 s (within the tracker's jitter and
    drift), a random U(20, 40) s by default, a pseudo-random tag's sequence read from a file next to the design
    file (named relative to it), in its order."""
    from sblsim.orchestrator.design.telemetry_confirm import simulated_pings

    steps = {}
    for name, tag in (("sbi", {"ping_type": "sbi", "burst_interval_s": [25.0]}), ("rbi", {}),
                      ("pbi", {"ping_type": "pbi", "burst_sequence": "seq.csv"})):
        problem = _resolved(tmp_path, **tag)
        receivers = problem.sites[:5]
        _, _, emissions = simulated_pings(problem, receivers, 40, np.random.default_rng(1),
                                          start=problem.points[0])
        steps[name] = np.diff(emissions)
    np.testing.assert_allclose(steps["sbi"], 25.0, atol=0.05)
    assert 20.0 <= steps["rbi"].min() and steps["rbi"].max() <= 40.0 and np.ptp(steps["rbi"]) > 10.0
    np.testing.assert_allclose(steps["pbi"], np.resize(SEQUENCE, 39), atol=0.01)
    assert problem.tag.burst_interval == (min(SEQUENCE), max(SEQUENCE))


@pytest.mark.parametrize("tag, message", [
    ({"burst_interval_s": [40.0, 20.0]}, r"^tag.burst_interval_s: \[40, 20\] s, the shortest above the longest"),
    ({"burst_interval_s": [0.0, 20.0]}, r"^tag.burst_interval_s\[0\]: .*0.1"),
    ({"burst_interval_s": [-5.0, 20.0]}, r"^tag.burst_interval_s\[0\]: .*0.1"),
    ({"burst_interval_s": [30.0]}, r"^tag.burst_interval_s: \[30\] s for rbi"),
    ({"ping_type": "sbi"}, r"^tag.burst_interval_s: \[\] s for sbi"),
    ({"ping_type": "sbi", "burst_interval_s": [20.0, 40.0]}, r"^tag.burst_interval_s: \[20, 40\] s for sbi"),
    ({"ping_type": "pbi"}, "^tag.burst_sequence: missing for pbi"),
    ({"ping_type": "pbi", "burst_interval_s": [20.0, 40.0], "burst_sequence": "s.csv"},
     r"^tag.burst_interval_s: \[20, 40\] s for pbi"),
    ({"burst_sequence": "s.csv"}, "^tag.burst_sequence: given for rbi"),
    ({"ping_type": "xbi"}, "^tag.ping_type: .*sbi, rbi, pbi"),
    ({"source_level_db": 150.0}, "^tag.source_level_db: 150 dB with a range test's curve"),
])
def test_a_bad_tag_is_refused_in_one_line(tag, message):
    with pytest.raises(ConfigError, match=message) as error:
        check_problem(_problem(tag=tag))
    assert "\n" not in str(error.value)


def test_a_bad_burst_interval_exits_2_in_one_line_and_writes_nothing(tmp_path, capsys):
    from sblsim.orchestrator.cli import main

    for k, interval in enumerate(([40.0, 20.0], [0.0, 30.0])):
        (tmp_path / f"bad{k}.toml").write_text(_toml(_problem(tag={"burst_interval_s": interval})))
        status = main(["design", str(tmp_path / f"bad{k}.toml"), "--out", str(tmp_path / "out")])
        assert status == 2 and not (tmp_path / "out").exists()
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and "tag.burst_interval_s" in err, err


def test_a_bad_sequence_file_is_refused_in_one_line(tmp_path):
    (tmp_path / "seq.csv").write_text("interval_s\n30\nthirty\n")
    (tmp_path / "pond.toml").write_text(_toml(_problem(tag={"ping_type": "pbi", "burst_sequence": "seq.csv"})))
    with pytest.raises(ConfigError, match="^tag.burst_sequence: burst sequence: .*line 3") as error:
        sblsim.design(tmp_path / "pond.toml")
    assert "\n" not in str(error.value)


@pytest.mark.parametrize("section, key, value", [
    ("tag", "ping_type", "sbi"), ("tag", "burst_interval_s", [20.0, 30.0]), ("tag", "source_level_db", 150.0),
    ("detection", "frequency_hz", 180000.0), ("detection", "salinity", 0.0),
])
def test_the_tag_and_the_snr_model_are_refused_for_the_other_systems(section, key, value):
    raw = read_problem("lbl-field-2km")
    raw.setdefault(section, {})[key] = value
    with pytest.raises(ConfigError, match=f"^{section}.{key}: .* apply to an ilbl design only") as error:
        check_problem(raw)
    assert "\n" not in str(error.value)


def _walk_tracked(ping_type: str, **tag):
    """300 pings of a tag circling inside 6 receivers (each heard with probability 0.8), tracked by the design's
    tracking (the replay's pipeline) with the tag's ping type."""
    from sblsim.models.tracking.ekf import TrackerSettings
    from sblsim.models.tracking.simulate import simulate_pings
    from sblsim.orchestrator.design.telemetry_tracking import track_path

    receivers = np.array([[0.0, 0.0], [300.0, 0.0], [300.0, 250.0], [0.0, 250.0], [150.0, 120.0], [90.0, 230.0]])
    settings = TrackerSettings(sound_speed=1480.0, sigma_toa=1.5e-4, acceleration_psd=1e-4,
                               interval=tag.get("interval", 2.0))

    def circle(t):  # 80 m round the array's middle in an hour (0.14 m/s)
        a = 2.0 * np.pi * np.asarray(t) / 3600.0
        return np.column_stack([150.0 + 80.0 * np.cos(a), 125.0 + 80.0 * np.sin(a)])

    sequence = tag.get("sequence")
    interval = (tag["interval"], tag["interval"]) if ping_type == "sbi" else (20.0, 40.0)
    toa, positions, emissions = simulate_pings(receivers, 300, settings, np.random.default_rng(3), detection=0.8,
                                               ping_type=ping_type, burst_interval=interval, burst_sequence=sequence,
                                               path=circle)
    return track_path(receivers, toa, positions, emissions, 1480.0, 1.5e-4, interval, ping_type=ping_type,
                      burst_sequence=sequence)


@pytest.mark.parametrize("ping_type, tag", [
    ("sbi", {"interval": 30.0}), ("pbi", {"sequence": np.array(SEQUENCE)}), ("rbi", {}),
])
def test_the_walk_of_every_ping_type_is_tracked_within_its_bound(ping_type, tag):
    """As the random burst interval's walk (tests/orchestrator/test_design_telemetry.py): a stable and a
    pseudo-random tag's 300 pings tracked, every ping from the first fix on positioned, the track consistent with
    its covariance (mean 2-D NEES in [1, 4]) and its RMS within 1.5 times the tracker's smoothing bound."""
    row = _walk_tracked(ping_type, **tag)
    assert row["tracked_pings"] >= 295, row
    assert 1.0 <= row["tracked_nees"] <= 4.0 and row["tracked_ratio"] <= 1.5, row
    assert 0.0 < row["tracked_rms_m"] < 1.0, row


@pytest.mark.slow
def test_a_design_with_a_stable_tag_records_it_and_tracks_its_walk(tmp_path):
    """A whole design with an sbi tag (25 s) and the path: design.json records the tag, the walk's 250 pings are
    tracked within the tracker's band (NEES in [1.5, 4.5], as the rbi design's test)."""
    sblsim.design(None, **_problem(tag={"ping_type": "sbi", "burst_interval_s": [25.0, 25.0]},
                                   monte_carlo={"path": True}), out=tmp_path / "d")
    document = json.loads((tmp_path / "d" / "design.json").read_text())
    assert document["tag"]["ping_type"] == "sbi" and document["tag"]["burst_interval_s"] == [25.0, 25.0]
    (path,) = document["designs"][0]["path"]
    assert path["pings"] == 250 and 0 < path["tracked_pings"] <= 250
    assert 1.5 <= path["tracked_nees"] <= 4.5 and path["tracked_ratio"] <= 3.0, path


@pytest.mark.slow
def test_a_design_on_the_sites_snr_model_runs(tmp_path):
    """No range test: the tag's power class (136 dB re 1 uPa at 1 m, a quiet 69 kHz tag: Bowles, Denes & Shane
    2010 measured 129-137 dB for one maker's) in the sea. The design's curve is the SNR model's, its 50 % distance
    the sonar module's detection range (within 1 %), and the design meets with every receiver in the water."""
    problem = _problem(detection={"range_50_m": 0.0, "slope": 0.0}, tag={"source_level_db": 136.0})
    start = time.process_time()
    result = sblsim.design(None, **problem, out=tmp_path / "d")
    seconds = time.process_time() - start
    document = json.loads((tmp_path / "d" / "design.json").read_text())
    assert document["tag"]["source_level_db"] == 136.0
    assert document["tag"]["detection_curve"].startswith("SNR model: SL 136 dB, 69 kHz")
    from sblsim.orchestrator.design.telemetry import resolve

    curve = resolve(check_problem(problem)).curve
    expected = sonar.detection_range(69000.0, 5000.0, 136.0, 0.0, 12.0, 2.5, 0.5, 10.0, 35.0, 0.0)
    assert curve.range_at(0.5) == pytest.approx(expected, rel=0.01) and 300.0 < expected < 500.0
    best = result.designs[0]
    assert best["meets"], best["fails"]
    receivers = np.array(best["receivers_m"])
    assert ((receivers >= 0.0) & (receivers <= 300.0)).all()
    assert not ((receivers[:, 0] > 150.0) & (receivers[:, 1] > 150.0)).any()  # not in the L's missing quarter
    assert math.isfinite(seconds)

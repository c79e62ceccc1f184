"""Configuration: built-in scenarios, ``--set`` overrides, validation messages, ties and TOML round trip."""

from __future__ import annotations

import math
import tomllib

import pytest

from sblsim.models import COMPONENTS, RECEIVER_MODELS
from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cosim.config import (
    BUILTIN_SCENARIOS,
    MIN_SIGMA,
    RECEIVER_KEYS,
    SECTIONS,
    load_config,
    parse_override,
    section_variables,
    to_toml,
)


def declared_parameters(section: str, receiver: str = "ekf") -> set[str]:
    """Parameter names a section must hold, computed from the declarations (the receiver's section: of the
    ``receiver`` model, plus the orchestrator's receiver keys)."""
    if section in COMPONENTS:
        seed = {"seed", "scenario_key", "cell", "replicate"}
        model = RECEIVER_MODELS[receiver] if section == "receiver" else COMPONENTS[section]
        declared = model.variables()
        extra = {v.name for v in RECEIVER_KEYS} if section == "receiver" else set()
        return ({v.name for v in declared if v.causality == "parameter" and v.scope != "fmu"} - seed) | extra
    return {v.name for v in section_variables(section)}


# --------------------------------------------------------------------------- built-in scenarios

def raw_trajectory(name: str) -> str:
    """The trajectory a built-in scenario file names (the harbour runs the square)."""
    from importlib import resources

    raw = tomllib.loads((resources.files("sblsim.orchestrator") / "scenarios" / f"{name}.toml").read_text())
    return raw["target"]["trajectory"]


@pytest.mark.parametrize("name", BUILTIN_SCENARIOS)
def test_builtin_scenario_resolves(name):
    cfg = load_config(name)
    assert list(cfg) == list(SECTIONS)
    for section in SECTIONS:
        assert set(cfg[section]) == declared_parameters(section, cfg["simulation"]["receiver"]), section
    assert cfg["run"]["scenario"] == name
    assert cfg["target"]["trajectory"] == raw_trajectory(name)
    assert cfg["simulation"]["duration"] >= cfg["simulation"]["sampling_time"]
    # the scenario file's own values are applied (read independently with tomllib)
    from importlib import resources

    raw = tomllib.loads((resources.files("sblsim.orchestrator") / "scenarios" / f"{name}.toml").read_text())
    for section, table in raw.items():
        for key, value in table.items():
            assert cfg[section][key] == value, f"{section}.{key}"


def test_seed_argument_sets_run_seed():
    assert load_config("semicircle", seed=1234)["run"]["seed"] == 1234
    assert load_config("semicircle")["run"]["seed"] == 0


def test_builtin_name_not_shadowed_by_directory_in_cwd(tmp_path, monkeypatch):
    """A directory called like a scenario in the working directory (e.g. ``--out semicircle`` of an
    earlier run) must not hide the built-in scenario."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "semicircle").mkdir()
    cfg = load_config("semicircle")
    assert cfg["run"]["scenario"] == "semicircle"
    assert cfg["target"]["radius"] == 15.0


# --------------------------------------------------------------------------- invalid input

def _error(source="semicircle", overrides=(), seed=None) -> str:
    with pytest.raises(ModelError) as info:
        load_config(source, list(overrides), seed)
    message = str(info.value)
    assert "\n" not in message
    return message


def test_unknown_scenario():
    message = _error("nosuch")
    assert message.startswith("scenario:")
    assert "'nosuch'" in message
    for name in BUILTIN_SCENARIOS:
        assert name in message


def test_missing_config_file(tmp_path):
    message = _error(str(tmp_path / "absent.toml"))
    assert message.startswith("config:") and "absent.toml" in message


def test_invalid_toml_file(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[platform\nbaseline = \n")
    message = _error(str(path))
    assert message.startswith("config:") and "not valid TOML" in message


def test_unknown_set_key():
    message = _error(overrides=["platform.nokey=1"])
    assert message.startswith("platform.nokey:")
    assert "unknown key" in message
    assert "baseline" in message  # the known keys are listed


def test_unknown_section():
    message = _error(overrides=["sonar.gain=1"])
    assert message.startswith("sonar:")
    assert "unknown section" in message
    for section in SECTIONS:
        assert section in message


def test_unknown_section_in_file(tmp_path):
    path = tmp_path / "cfg.toml"
    path.write_text("[sonar]\ngain = 1\n")
    assert _error(str(path)).startswith("sonar:")


def test_unknown_key_in_file(tmp_path):
    path = tmp_path / "cfg.toml"
    path.write_text("[platform]\nbasline = 3.0\n")
    message = _error(str(path))
    assert message.startswith("platform.basline:")


@pytest.mark.parametrize("item", ["platform.baseline", "platform", "=3", "a.b.c=1"])
def test_malformed_set_item(item):
    with pytest.raises(ModelError, match="--set"):
        parse_override(item)


@pytest.mark.parametrize("override, field, allowed", [
    ("acoustics.sigma_range=-1", "acoustics.sigma_range", "[0, 1000] m"),
    ("platform.baseline=0", "platform.baseline", "(0, 1000] m"),
    ("platform.baseline=-2.5", "platform.baseline", "(0, 1000] m"),
    ("acoustics.loss_pct=101", "acoustics.loss_pct", "[0, 100] %"),
    ("acoustics.loss_pct=-1", "acoustics.loss_pct", "[0, 100] %"),
    ("target.depth_sigma=-0.1", "target.depth_sigma", "[0, 1000] m"),
    ("receiver.sigma_range=0", "receiver.sigma_range", "[0.001, 1000] m"),
    ("platform.beaufort=9", "platform.beaufort", "[0, 8]"),
    ("target.speed=0", "target.speed", "(0, 10] m/s"),
    ("simulation.sampling_time=0", "simulation.sampling_time", "[0.001, 60] s"),
])
def test_out_of_range_value_names_field_and_range(override, field, allowed):
    message = _error(overrides=[override])
    assert message.startswith(field + ":")
    assert allowed in message


def test_non_numeric_value():
    message = _error(overrides=["platform.baseline=three"])
    assert message.startswith("platform.baseline:") and "(0, 1000] m" in message


def test_bad_choice():
    message = _error(overrides=["target.trajectory=zigzag"])
    assert message.startswith("target.trajectory:")
    for choice in ("semicircle", "spiral", "random", "square", "file"):
        assert choice in message


def test_seed_out_of_range():
    assert _error(seed=-1).startswith("run.seed:")


def test_duration_shorter_than_sampling_time():
    message = _error(overrides=["simulation.duration=0.05"])
    assert message.startswith("simulation.duration:")


# --------------------------------------------------------------------------- ties

def test_receiver_sigma_range_follows_acoustics():
    cfg = load_config("semicircle", ["acoustics.sigma_range=0.37"])
    assert cfg["receiver"]["sigma_range"] == 0.37


def test_receiver_sigma_range_floored_when_acoustics_noise_is_zero():
    cfg = load_config("semicircle", ["acoustics.sigma_range=0"])
    assert cfg["acoustics"]["sigma_range"] == 0.0
    assert cfg["receiver"]["sigma_range"] == MIN_SIGMA


def test_explicit_receiver_sigma_range_kept():
    cfg = load_config("semicircle", ["acoustics.sigma_range=0.37", "receiver.sigma_range=0.5"])
    assert cfg["acoustics"]["sigma_range"] == 0.37
    assert cfg["receiver"]["sigma_range"] == 0.5
    cfg = load_config("semicircle", ["receiver.sigma_range=0.5", "acoustics.sigma_range=0.37"])
    assert cfg["receiver"]["sigma_range"] == 0.5


def test_receiver_sigma_depth_follows_target():
    assert load_config("semicircle", ["target.depth_sigma=0.2"])["receiver"]["sigma_depth"] == 0.2
    assert load_config("semicircle", ["target.depth_sigma=0.2", "receiver.sigma_depth=0.05"]
                       )["receiver"]["sigma_depth"] == 0.05


@pytest.mark.parametrize("radius, speed, depth", [(15.0, 0.5, 5.0), (8.0, 0.25, 3.0), (40.0, 1.5, 12.0)])
def test_semicircle_start_state_and_duration(radius, speed, depth):
    cfg = load_config("semicircle", [f"target.radius={radius}", f"target.speed={speed}", f"target.depth={depth}"])
    rx = cfg["receiver"]
    # the semicircle of radius r starts at (0, -r, depth), heading North at the swimming speed
    assert rx["x0_x"] == pytest.approx(0.0, abs=1e-9)
    assert rx["x0_y"] == pytest.approx(-radius, rel=1e-12)
    assert rx["x0_z"] == pytest.approx(depth, rel=1e-12)
    assert rx["x0_vx"] == pytest.approx(speed, rel=1e-12)
    assert rx["x0_vy"] == pytest.approx(0.0, abs=1e-9)
    assert rx["x0_vz"] == 0.0
    assert cfg["simulation"]["duration"] == pytest.approx(math.pi * radius / speed, rel=1e-12)


def test_explicit_initial_state_and_duration_kept():
    cfg = load_config("semicircle", ["receiver.x0_x=2.5", "receiver.x0_vy=-0.1", "simulation.duration=12"])
    assert cfg["receiver"]["x0_x"] == 2.5
    assert cfg["receiver"]["x0_vy"] == -0.1
    assert cfg["receiver"]["x0_y"] == pytest.approx(-cfg["target"]["radius"])  # the others still tied
    assert cfg["simulation"]["duration"] == 12.0


def test_square_start_and_duration():
    cfg = load_config("square", ["target.square_side=6", "target.speed=0.5"])
    rx = cfg["receiver"]
    # SW corner (-s/2, -s/2), heading North
    assert (rx["x0_x"], rx["x0_y"], rx["x0_z"]) == pytest.approx((-3.0, -3.0, cfg["target"]["depth"]))
    assert (rx["x0_vx"], rx["x0_vy"]) == pytest.approx((0.5, 0.0))
    assert cfg["simulation"]["duration"] == pytest.approx(4 * 6 / 0.5)


def test_file_trajectory_start_and_duration(tmp_path):
    path = tmp_path / "track.csv"
    path.write_text("time,N,E,D\n0,1,2,3\n10,6,2,3\n30,6,12,4\n")
    cfg = load_config("semicircle", ["target.trajectory=file", f"target.trajectory_file={path}"])
    rx = cfg["receiver"]
    assert (rx["x0_x"], rx["x0_y"], rx["x0_z"]) == (1.0, 2.0, 3.0)
    assert (rx["x0_vx"], rx["x0_vy"], rx["x0_vz"]) == pytest.approx((0.5, 0.0, 0.0))
    assert cfg["simulation"]["duration"] == 30.0


# --------------------------------------------------------------------------- round trip

@pytest.mark.parametrize("name, overrides", [
    ("semicircle", []),
    ("semicircle", ["acoustics.sigma_range=0.37", "receiver.x0_x=1.25", "platform.gps_model=gauss-markov"]),
    ("spiral", []),
    ("random", ["acoustics.loss_pct=12.5"]),
    ("square", []),
    ("harbour", []),
])
def test_to_toml_round_trip(tmp_path, name, overrides):
    cfg = load_config(name, overrides, seed=42)
    path = tmp_path / "config.toml"
    path.write_text(to_toml(cfg))
    again = load_config(path)
    assert again == cfg
    # types survive too (ints stay ints, floats stay floats)
    for section in cfg:
        for key, value in cfg[section].items():
            assert type(again[section][key]) is type(value), f"{section}.{key}"
    # and the text is plain TOML holding every section
    assert set(tomllib.loads(path.read_text())) == set(SECTIONS)


def test_duration_limits_say_what_fits(monkeypatch):
    """The longest run is what fits in the memory available here; a duration is a whole number of T."""
    from sblsim.orchestrator.cosim import limits

    monkeypatch.setattr(limits, "available_memory", lambda: 2**30)
    most = limits.max_steps()
    assert most == int(0.75 * 2**30 // limits.bytes_per_step())
    assert load_config("semicircle", [f"simulation.duration={most // 10}"])["simulation"]["duration"] == most // 10
    with pytest.raises(ModelError, match=rf"^simulation\.duration: {most // 10 + 1} s at T = 0\.1 s is "
                                          rf"{10 * (most // 10 + 1)} steps; at most {most} steps fit"):
        load_config("semicircle", [f"simulation.duration={most // 10 + 1}"])
    with pytest.raises(ModelError, match=r"give 4\.8 or 5\.1 s$"):
        load_config("semicircle", ["simulation.duration=5", "simulation.sampling_time=0.3"])
    # 0 is one pass, cut to whole sampling times (documented)
    assert load_config("semicircle", ["simulation.sampling_time=0.3"])["simulation"]["duration"] > 0


SHORT_RUN = "simulation.duration=15"  # 150 steps


@pytest.mark.slow
def test_a_saved_configuration_runs_and_compares_with_any_receiver(tmp_path, capsys):
    """A run's config.toml holds every key of its receiver (the ekf's): another receiver drops the keys it does not
    have, said in one note line, and runs as the scenario with that receiver does."""
    import json

    import pandas as pd

    from sblsim.orchestrator.cli import main

    assert main(["run", "semicircle", "--set", SHORT_RUN, "--out", str(tmp_path / "x")]) == 0
    saved = tmp_path / "x" / "config.toml"
    capsys.readouterr()
    assert main(["run", str(saved), "--set", "simulation.receiver=lsq", "--out", str(tmp_path / "lsq")]) == 0
    err = capsys.readouterr().err
    lsq_only = {v.name for v in section_variables("receiver", "lsq")}
    dropped = [k for k in tomllib.loads(saved.read_text())["receiver"] if k not in lsq_only]
    assert "gate_max_rejections" in dropped
    assert err.splitlines() == [f"note: {saved}'s {', '.join(f'receiver.{k}' for k in dropped)} are not keys of the "
                                "lsq receiver: not used"], err
    assert main(["run", "semicircle", "--set", SHORT_RUN, "--set", "receiver=lsq", "--out", str(tmp_path / "d")]) == 0
    mine, direct = (json.loads((tmp_path / d / "summary.json").read_text()) for d in ("lsq", "d"))
    assert mine.pop("wall_time") >= 0 and direct.pop("wall_time") >= 0
    assert mine == direct  # the scenario's own lsq run, every number

    capsys.readouterr()
    assert main(["compare", str(saved), "--receivers", "ekf,lsq,ukf", "--replicates", "2",
                 "--out", str(tmp_path / "c")]) == 0
    assert capsys.readouterr().err.count("note: ") == 1  # lsq's, once
    assert main(["compare", "semicircle", "--set", SHORT_RUN, "--receivers", "ekf,lsq", "--replicates", "2",
                 "--out", str(tmp_path / "c2")]) == 0
    keep = ["runs", "rms_e_tot", "mean_e_tot", "nees", "pcrb_rms"]
    mine, direct = (pd.read_csv(tmp_path / c / "compare.csv").set_index("receiver") for c in ("c", "c2"))
    pd.testing.assert_frame_equal(mine.loc[["ekf", "lsq"], keep], direct.loc[["ekf", "lsq"], keep])


def test_a_receiver_key_the_files_own_receiver_lacks_is_still_refused(tmp_path, capsys):
    """Only the keys of the file's own receiver are dropped for another one: a key its own receiver does not have
    either is refused, as is another receiver's key given on the command line."""
    import sblsim
    from sblsim.orchestrator.cli import main

    (tmp_path / "receiver.toml").write_text('[simulation]\nreceiver = "ekf"\n[receiver]\nalpha = 0.5\n')
    for argv in ([], ["--set", "receiver=ekf"], ["--set", "receiver=lsq"]):
        assert main(["run", str(tmp_path / "receiver.toml"), "--out", str(tmp_path / "o"), *argv]) == 2
        err = capsys.readouterr().err
        assert err.startswith("sblsim: error: receiver.alpha: not a parameter of the ") and err.count("\n") == 1, err
    with pytest.raises(sblsim.ConfigError, match="^receiver.q_horizontal: not a parameter of the lsq receiver"):
        sblsim.load(sblsim.load("semicircle"), set={"receiver": "lsq", "receiver.q_horizontal": 5.0})
    # a configuration given to the API: the same rule, silently
    assert sblsim.load(sblsim.load("semicircle"), set={"receiver": "lsq"}) == sblsim.load("semicircle",
                                                                                          set={"receiver": "lsq"})
    assert capsys.readouterr().err == ""
    assert not (tmp_path / "o").exists()

"""Swappable receivers: the least-squares receiver, and a user's FMU built outside the package."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import ConfigError, load_config
from sblsim.orchestrator.cosim.run import run

USER_SCRIPT = Path(__file__).parents[1] / "data" / "user_receiver.py"
SHORT = ["simulation.duration=20"]


def build_user_fmu(script: Path, dest: Path) -> Path:
    from pythonfmu import FmuBuilder

    return Path(FmuBuilder.build_FMU(script, dest=dest))


@pytest.fixture(scope="module")
def user_fmu(tmp_path_factory):
    return build_user_fmu(USER_SCRIPT, tmp_path_factory.mktemp("user"))


def test_lsq_receiver_runs_the_same_on_both_engines(fmu_dir):
    cfg = load_config("semicircle", ["receiver=lsq", "acoustics.loss_pct=20", *SHORT], seed=2)
    assert cfg["simulation"]["receiver"] == "lsq"
    local, fmu = run(cfg).timeseries, run(cfg, "fmu", fmu_dir=fmu_dir).timeseries
    for col in ("est_x", "est_y", "est_z", "est_vx", "nis", "pos_std"):
        np.testing.assert_allclose(fmu[col], local[col], rtol=0, atol=1e-9, equal_nan=True)
    # it is the instrumentation fix of every slot with a fresh range, with no filter: not the EKF's estimate
    valid = local["instr_valid"].to_numpy()
    assert valid[-100:].all()
    fresh = valid & local["packet_valid"].to_numpy()
    assert 0 < fresh.sum() < valid.sum()  # some slots lost their packet: the estimate stayed there
    np.testing.assert_array_equal(local.loc[fresh, "est_x"], local.loc[fresh, "instr_x"])
    ekf = run(load_config("semicircle", ["acoustics.loss_pct=20", *SHORT], seed=2)).timeseries
    assert np.abs(ekf["est_x"] - local["est_x"]).max() > 1e-3


@pytest.mark.slow
def test_cli_set_receiver_lsq(tmp_path, capsys):
    assert main(["run", "semicircle", "--set", "receiver=lsq", "--set", "simulation.duration=5",
                 "--out", str(tmp_path / "r")]) == 0
    assert "receiver lsq" in capsys.readouterr().out


def test_a_users_receiver_fmu_is_swapped_in(user_fmu):
    cfg = load_config("semicircle", [f"receiver=fmu:{user_fmu}", *SHORT], seed=1)
    ts = run(cfg).timeseries
    # the user's algorithm, checked from what it was fed: depth straight from the sensor, and the
    # horizontal point on the circle of radius sqrt(r² − Δz²) around the transmitting beacon
    np.testing.assert_array_equal(ts["est_z"].iloc[1:], ts["depth"].iloc[1:])
    fresh = (ts["packet_valid"] & (ts["packet_seq"].diff() != 0)).to_numpy().copy()
    fresh[0] = False
    rows = ts[fresh]
    horizontal = np.hypot(rows["est_x"] - rows["beacon_x"], rows["est_y"] - rows["beacon_y"])
    expected = np.sqrt(np.maximum(rows["range"] ** 2 - (rows["depth"] - rows["beacon_z"]) ** 2, 0))
    assert len(rows) > 150
    np.testing.assert_allclose(horizontal, expected, rtol=0, atol=1e-9)
    ekf = run(load_config("semicircle", SHORT, seed=1)).timeseries
    assert np.abs(ekf["est_x"] - ts["est_x"]).max() > 0.1


def test_a_users_receiver_without_the_lanes_is_refused_where_packets_arrive_two_in_a_step(user_fmu, tmp_path,
                                                                                         capsys):
    """The user's FMU has no inputs for the later lanes of a delivery: it runs on lane 1 alone (above); where slots
    are shorter than the travel time (T = 0.01 s on the semicircle: packets arrive two in a step) it would lose the
    packets on the later lanes, so the run is refused in one line, with nothing written."""
    sets = [f"receiver=fmu:{user_fmu}", "simulation.sampling_time=0.01", "simulation.duration=5"]
    with pytest.raises(ModelError, match="no inputs for the later lanes of a delivery"):
        run(load_config("semicircle", sets, seed=1))
    out = tmp_path / "r"
    assert main(["run", "semicircle", *[a for s_ in sets for a in ("--set", s_)], "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "shorter simulation.sampling_time" in err
    assert not out.exists()
    # the built-in receivers take every lane of the same run
    assert run(load_config("semicircle", sets[1:], seed=1)).metrics["updates"].iloc[0] > 450


def test_a_mismatching_fmu_is_rejected_naming_every_variable(tmp_path, capsys):
    text = USER_SCRIPT.read_text()
    bad = (text.replace('("est_x", "Real", "m")', '("est_x", "Real", "cm")')
               .replace(', ("depth", "Real", "m"), ("rx_time"', ', ("rx_time"')
               .replace('("nis", "Real", "1")', '("nis", "Integer", "")')
               .replace("class UserReceiver", "class BadReceiver"))
    assert bad.count("BadReceiver") == 1 and '"cm"' in bad
    script = tmp_path / "bad_receiver.py"
    script.write_text(bad)
    fmu = build_user_fmu(script, tmp_path)
    with pytest.raises(ModelError) as info:
        load_cfg = load_config("semicircle", [f"receiver=fmu:{fmu}", *SHORT])
        run(load_cfg)
    message = str(info.value)
    assert "does not match the receiver interface" in message
    assert "missing input 'depth'" in message
    assert "'est_x' has unit 'cm', expected 'm'" in message
    assert "'nis' has type 'Integer', expected 'Real'" in message
    assert "\n" not in message
    assert main(["run", "semicircle", "--set", f"receiver=fmu:{fmu}", "--out", str(tmp_path / "out")]) == 2
    assert "missing input 'depth'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_bad_receiver_values_are_refused(tmp_path):
    allowed = "one of ekf, ekf-seq, ukf, lsq, model:PATH.py or fmu:PATH"
    with pytest.raises(ConfigError, match=f"simulation.receiver: 'kalman' is not allowed; {allowed}"):
        load_config("semicircle", ["receiver=kalman"])
    with pytest.raises(ConfigError, match="simulation.receiver: no FMU file at"):
        load_config("semicircle", [f"receiver=fmu:{tmp_path / 'none.fmu'}"])
    with pytest.raises(ModelError, match="simulation.master: .newton. is not allowed"):
        load_config("semicircle", ["master=newton"])


def test_a_users_receiver_travels_in_the_ssp_package(user_fmu, fmu_dir, tmp_path):
    from sblsim.orchestrator.cosim.ssp import export_ssp
    from sblsim.orchestrator.cosim.ssp_read import read_ssp

    cfg = load_config("semicircle", [f"receiver=fmu:{user_fmu}", *SHORT], seed=3)
    path = export_ssp(cfg, tmp_path / "user.ssp", fmu_dir)
    system = read_ssp(path)
    receiver = system.config["simulation"]["receiver"]
    assert receiver.startswith("fmu:") and receiver.endswith("UserReceiver.fmu")
    assert system.fmu_files["receiver"].read_bytes() == user_fmu.read_bytes()
    # the user's FMU declares no parameters: its parameter set is empty, sblsim's keys keep their values
    assert {k: v for k, v in system.config.items() if k != "simulation"} == \
        {k: v for k, v in cfg.items() if k != "simulation"}


@pytest.mark.parametrize("receiver, key", [("lsq", "q_horizontal"), ("ekf", "alpha"), ("ekf", "beacon_arm"),
                                           ("ukf", "no_such_key")])
def test_a_key_the_chosen_receiver_does_not_declare_stops_with_one_line(receiver, key, tmp_path, capsys):
    with pytest.raises(ConfigError) as info:
        load_config("semicircle", [f"receiver={receiver}", f"receiver.{key}=0.5"])
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"receiver.{key}: not a parameter of the {receiver} receiver")
    from sblsim.models import RECEIVER_MODELS

    declared = [v.name for v in RECEIVER_MODELS[receiver].config_parameters() if v.causality == "parameter"]
    assert all(name in message for name in ("sigma_range", "x0_x")) and "seed" not in message
    assert set(message.split("its keys: ")[1].split(", ")) <= set(declared) | {"latency"}  # the orchestrator's
    # the command line says the same, exits 2 and writes nothing
    code = main(["run", "semicircle", "--set", f"receiver={receiver}", "--set", f"receiver.{key}=0.5",
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.strip() == f"sblsim: error: {message}" and not (tmp_path / "out").exists()


def test_the_same_key_in_a_file_is_checked_against_the_receiver_the_file_chooses(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[simulation]\nreceiver = "ukf"\n[receiver]\nalpha = 0.5\nq_horizontal = 0.02\n')
    cfg = load_config(str(path))
    assert cfg["receiver"]["alpha"] == 0.5 and cfg["receiver"]["q_horizontal"] == 0.02
    path.write_text('[simulation]\nreceiver = "ekf"\n[receiver]\nalpha = 0.5\n')
    with pytest.raises(ConfigError, match="receiver.alpha: not a parameter of the ekf receiver"):
        load_config(str(path))


def test_a_users_fmu_that_fails_in_a_run_stops_with_one_line(tmp_path, capsys):
    """Its doStep reports an error after 2 s: the run stops with one line naming the FMU, nothing written."""
    script = tmp_path / "FailingReceiver.py"
    text = USER_SCRIPT.read_text().replace("class UserReceiver(Fmi2Slave):", "class FailingReceiver(Fmi2Slave):")
    script.write_text(text
                      .replace("    def do_step(self, current_time, step_size):\n",
                               "    def do_step(self, current_time, step_size):\n"
                               "        if current_time > 2.0:\n            return False\n"))
    fmu = build_user_fmu(script, tmp_path)
    code = main(["run", "semicircle", "--set", f"receiver=fmu:{fmu}", *[a for s in SHORT for a in ("--set", s)],
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "FailingReceiver.fmu" in err and "fmi2DoStep" in err, err
    assert "Traceback" not in err and not (tmp_path / "out").exists()

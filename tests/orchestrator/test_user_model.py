"""docs/extending.md's worked example: a receiver written as one Python file (docs/examples/constant_position.py).

It runs on the local engine and on the fmu engine (its FMU built on demand)
with the same numbers, builds as an FMU with ``sblsim fmus build --model``
that runs as ``fmu:PATH``, and its estimate equals an independent numpy
replay of the filter its docstring describes. Bad model files stop with one
line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import ConfigError, load_config, receiver_label
from sblsim.orchestrator.cosim.run import run

EXAMPLE = Path(__file__).parents[2] / "docs" / "examples" / "constant_position.py"
OVERRIDES = ["simulation.duration=30", "acoustics.loss_pct=20", f"receiver=model:{EXAMPLE}",
             "receiver.q_position=0.02"]
COLUMNS = ["est_x", "est_y", "est_z", "cov_xx", "cov_xy", "cov_zz", "nis", "instr_x", "pos_std"]


@pytest.fixture(scope="module")
def local():
    cfg = load_config("semicircle", OVERRIDES, seed=3)
    return cfg, run(cfg, "local", replicates=[0, 1])


def test_the_example_runs_on_both_engines_with_the_same_numbers(local, fmu_dir):
    cfg, result = local
    assert receiver_label(cfg) == "constant-position" and cfg["receiver"]["q_position"] == 0.02
    via_fmu = run(cfg, "fmu", replicates=[0, 1], fmu_dir=fmu_dir)
    np.testing.assert_allclose(via_fmu.timeseries[COLUMNS].to_numpy(), result.timeseries[COLUMNS].to_numpy(),
                               rtol=0, atol=1e-9)
    assert result.metrics["nees_mean"].notna().all()


def test_the_example_builds_as_an_fmu_that_runs_as_a_users_fmu(local, tmp_path, capsys):
    cfg, result = local
    assert main(["fmus", "build", "--model", str(EXAMPLE), "--out", str(tmp_path)]) == 0
    fmu = tmp_path / "sblsim_receiver_constant_position.fmu"
    assert fmu.is_file() and str(fmu) in capsys.readouterr().out
    as_fmu = load_config("semicircle", [*OVERRIDES[:2], f"receiver=fmu:{fmu}", "receiver.q_position=0.02"], seed=3)
    again = run(as_fmu, "local", replicates=[0, 1])  # the FMU stands in for the receiver on the local engine
    np.testing.assert_allclose(again.timeseries[COLUMNS].to_numpy(), result.timeseries[COLUMNS].to_numpy(),
                               rtol=0, atol=1e-9)


def test_the_example_is_the_filter_its_docstring_describes(local):
    """Replay: position random walk, velocity 0, depth then the fresh range at each slot (numpy)."""
    cfg, result = local
    rc = cfg["receiver"]
    T = cfg["simulation"]["sampling_time"]
    for _, ts in result.timeseries.groupby("replicate"):
        x = np.array([rc["x0_x"], rc["x0_y"], rc["x0_z"]])
        P = np.eye(3) * rc["p0_position"] ** 2
        last, est, fixed = 0, [], False
        for row in ts.itertuples():  # the step from row.time − T to row.time
            P = P + np.eye(3) * rc["q_position"] * T
            if row.packet_seq != last and row.time >= row.rx_time - 1e-9:
                last = row.packet_seq
                updates = [(row.depth, lambda x: (x[2], np.array([0.0, 0.0, 1.0])), rc["sigma_depth"] ** 2)]
                if row.packet_valid and 1 <= row.beacon_id <= 4:
                    fixed = True  # its first update with a received packet: an estimate from here on
                    b = np.array([row.beacon_x, row.beacon_y, row.beacon_z])
                    updates.append((row.range, lambda x, b=b: (np.linalg.norm(x - b), (x - b) / np.linalg.norm(x - b)),
                                    rc["sigma_range"] ** 2))
                for z, measure, var in updates:
                    h, H = measure(x)
                    K = P @ H / (H @ P @ H + var)
                    x = x + K * (z - h)
                    A = np.eye(3) - np.outer(K, H)
                    P = A @ P @ A.T + np.outer(K, K) * var
            est.append(x.copy() if fixed else np.full(3, np.nan))  # before the first fix: no estimate
        np.testing.assert_allclose(ts[["est_x", "est_y", "est_z"]].to_numpy(), np.array(est), rtol=0, atol=1e-9)
        velocity = ts[["est_vx", "est_vy", "est_vz"]].to_numpy()
        np.testing.assert_array_equal(velocity[np.isfinite(np.array(est)).all(axis=1)], 0.0)


@pytest.mark.parametrize("text, message", [
    ("x = 1\n", "defines 0 model classes (none); it must define exactly one receiver"),
    ("import no_such_module\n", "cannot import"),
    ("from sblsim.models.receiver import PaperEKF\nclass A(PaperEKF):\n    name = 'receiver'\n",
     "must be 'receiver_' + letters, digits or '_', and not a built-in's"),
    ("from sblsim.models.target import Target\nclass A(Target):\n    name = 'receiver_target'\n",
     "does not match the receiver interface: missing input 'packet_seq'"),
])
def test_a_bad_model_file_stops_with_one_line(text, message, tmp_path, capsys):
    path = tmp_path / "mine.py"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config("semicircle", [f"receiver=model:{path}"])
    assert message in str(info.value) and "\n" not in str(info.value)
    assert main(["run", "semicircle", "--set", f"receiver=model:{path}", "--out", str(tmp_path / "o")]) == 2
    assert message in capsys.readouterr().err and not (tmp_path / "o").exists()

"""``sblsim budget``: the error budget adds up, a lone source carries everything, a source the system does not
have contributes nothing, the linear case follows the Fisher information, common random numbers pay, and the
command line writes its files or stops with one line."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from sblsim.models.platform.geometry import lever_arms
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run
from sblsim.orchestrator.montecarlo.budget import (
    DEFAULT_REPLICATES,
    NO_EFFECT,
    OFF,
    ON,
    budget,
    configurations,
    planned,
)
from sblsim.orchestrator.montecarlo.error_sources import SOURCES, switched_off

SHORT = "simulation.duration=20"


def contribution(b, name: str) -> float:
    return float(b.table.loc[b.table["source"] == name, "contribution"].iloc[0])


def status(b, name: str) -> str:
    return str(b.table.loc[b.table["source"] == name, "status"].iloc[0])


def test_every_switch_names_a_key_of_the_configuration():
    cfg = load_config("semicircle")
    for name, (description, overrides) in SOURCES.items():
        assert description and overrides, name
        for item in overrides:
            section, key = item.split("=", 1)[0].split(".")
            assert key in cfg[section], (name, item)
    assert SOURCES["latency"][1] == ("receiver.latency=0",)  # every receiver has the key


def test_switching_a_source_off_keeps_the_receiver():
    """The ties would retune R (σ_r = 0 is floored at 1 mm); a budget keeps the configured receiver."""
    cfg = load_config("semicircle", ["simulation.receiver=ekf-seq"])
    off = switched_off(cfg, SOURCES["range_noise"][1])
    assert off["acoustics"]["sigma_range"] == 0.0
    assert off["receiver"] == cfg["receiver"] and off["receiver"]["sigma_range"] == 0.1
    assert load_config("semicircle", ["simulation.receiver=ekf-seq", "acoustics.sigma_range=0"])[
        "receiver"]["sigma_range"] == 0.001  # what the ties would have made of it
    gps_off = switched_off(cfg, SOURCES["gps"][1])
    assert gps_off["platform"]["gps_sigma"] == 0.0 and gps_off["receiver"]["beacon_gps_sigma"] == 0.1
    sound = switched_off(load_config("harbour"), SOURCES["sound_speed"][1])
    assert sound["acoustics"]["sound_speed_profile"] == "constant"
    assert sound["acoustics"]["sound_speed_true"] == sound["acoustics"]["sound_speed_assumed"]


def test_a_source_already_zero_leaves_the_configuration_and_its_runs_unchanged():
    cfg = load_config("semicircle", [SHORT])
    assert cfg["platform"]["imu_bias_deg"] == 0.0 and cfg["acoustics"]["loss_pct"] == 0.0
    for name in ("imu_bias", "packet_loss", "sound_speed", "survey", "multipath"):
        off = switched_off(cfg, SOURCES[name][1])
        assert off == cfg and off is not cfg, name
    off = switched_off(cfg, SOURCES["packet_loss"][1])
    a, b = run(cfg, replicates=range(3)).metrics, run(off, replicates=range(3)).metrics
    pd.testing.assert_frame_equal(a, b)


def test_the_budget_adds_up_to_the_total():
    """(a) floor + Σ contributions + remainder = total, to rounding."""
    cfg = load_config("semicircle", [SHORT, "acoustics.loss_pct=10", "acoustics.outlier_pct=5",
                                     "platform.imu_bias_deg=0.5", "acoustics.clock_drift_ppm=10",
                                     "acoustics.sound_speed_true=1510", "platform.installation_sigma=0.05"])
    b = budget(cfg, 20)
    on = b.table[b.table["status"] == ON]
    assert set(on["source"]) == {"gps", "imu_noise", "imu_bias", "waves", "range_noise", "sound_speed",
                                 "clock_drift", "multipath", "packet_loss", "depth_sensor", "installation"}
    total = b.floor + math.fsum(b.table["contribution"]) + b.remainder
    assert total == pytest.approx(b.total, rel=1e-12, abs=0)
    assert (b.table["share"] * b.total).to_numpy() == pytest.approx(b.table["contribution"].to_numpy(), rel=1e-12)
    assert (b.table.loc[b.table["status"] != ON, "contribution"] == 0).all()
    assert b.runs == 20 * (2 + len(on) + 1)  # all on, all off, each source on, usbl_angle (no effect)
    assert b.runs == 20 * planned(cfg)
    assert b.diverged == 0


@pytest.mark.slow
def test_a_lone_source_carries_the_whole_error_above_the_floor():
    """(b) Every source off but the range noise: it is total − floor, exactly; the remainder is 0."""
    items = [SHORT] + [o for name, (_, overrides) in SOURCES.items() if name not in ("range_noise", "sound_speed")
                       for o in overrides]
    cfg = load_config("semicircle", items)
    b = budget(cfg, 10)
    assert contribution(b, "range_noise") == b.total - b.floor
    # the floor: what is left with every source off, the paper's EKF taking a range as of the step it is used at,
    # up to a step after the diver's position it refers to (0.015 m here; 0.005 m when ranges were used at
    # their transmission)
    assert b.total > 3 * b.floor > 0
    assert b.remainder == 0.0
    others = b.table[b.table["source"] != "range_noise"]
    assert (others["contribution"] == 0.0).all() and (others["status"] == OFF).all()
    assert b.first() == ["range_noise"]


def test_a_source_the_system_does_not_have_contributes_nothing():
    """(c) The survey error of LBL transponders, given to an SBL: it runs, and every run is unchanged."""
    cfg = load_config("semicircle", [SHORT, "platform.system=sbl", "platform.survey_sigma=0.5"])
    b = budget(cfg, 10)
    assert status(b, "survey") == NO_EFFECT and contribution(b, "survey") == 0.0
    assert not np.any(b.differences["survey"])
    assert status(b, "gps") == ON


@pytest.mark.slow
def test_a_static_diver_with_range_and_depth_noise_follows_the_fisher_information():
    """(d) The linear case in closed form.

    A static diver at p (a waypoint table holding one point), the platform level at the origin (Beaufort 0,
    no GPS or IMU error: the beacons at their lever arms b_i), the ``lsq`` receiver, only range noise σ_r and
    depth noise σ_d on. Each fix is the weighted least-squares solution of the held ranges (one per beacon)
    and the depth, weights W = diag(1/σ_r², …, 1/σ_d²) (``receiver.sigma_range``, ``sigma_depth``, tied to
    the true ones). Linearized at p, with H = [H_r; H_d] (rows u_i = (p − b_i)/‖p − b_i‖ and e_zᵀ) and
    J = HᵀWH, the fix error is J⁻¹HᵀWε, so its covariance is J⁻¹ (Σ_k H_kᵀW_k cov(ε_k) W_k H_k) J⁻¹: each
    independent noise adds its own term, and its contribution to the position MSE (3-D) is
    ``trace(J⁻¹ H_rᵀ W_r H_r J⁻¹)`` for the ranges and ``trace(J⁻¹ H_dᵀ W_d H_d J⁻¹)`` for the depth
    (the receiver's W is kept when a source is off). Every step's fix uses ranges with independent noises,
    fresh or held, so the time average over a run has the same expectation. The first slots (fewer than
    three beacons heard) differ, a few steps of 600: within the tolerance of four standard errors.
    """
    sr, sd = 0.1, 0.05
    p = np.array([10.0, 5.0, 20.0])
    point = f"{p[0]} {p[1]} {p[2]}"
    cfg = load_config("semicircle", [
        "target.trajectory=file", f"target.waypoints=0 {point}; 1000 {point}", "simulation.duration=60",
        "simulation.receiver=lsq", "platform.gps_sigma=0", "platform.imu_sigma_deg=0", "platform.beaufort=0",
        f"acoustics.sigma_range={sr}", f"target.depth_sigma={sd}"])
    assert (cfg["receiver"]["sigma_range"], cfg["receiver"]["sigma_depth"]) == (sr, sd)
    b = budget(cfg, 200)
    assert set(b.table.loc[b.table["status"] == ON, "source"]) == {"range_noise", "depth_sensor"}
    arms = lever_arms(cfg["platform"])
    H_r = (p - arms) / np.linalg.norm(p - arms, axis=1)[:, None]
    H_d = np.array([[0.0, 0.0, 1.0]])
    J_inv = np.linalg.inv(H_r.T @ H_r / sr**2 + H_d.T @ H_d / sd**2)
    expected = {"range_noise": np.trace(J_inv @ H_r.T @ H_r @ J_inv) / sr**2,
                "depth_sensor": np.trace(J_inv @ H_d.T @ H_d @ J_inv) / sd**2}
    for name, value in expected.items():
        row = b.table[b.table["source"] == name].iloc[0]
        assert abs(row["contribution"] - value) < 4.0 * row["se"], (name, row["contribution"], row["se"], value)
    assert b.floor < 1e-12  # perfect ranges of a static diver: the fix is exact
    assert abs(b.remainder) < 4.0 * b.remainder_se + 1e-12


def test_common_random_numbers_make_a_difference_far_more_precise():
    """(e) The depth sensor's contribution from paired runs (the same replicates) and from independent ones
    (replicates N … 2N − 1 for the switched-off arm): the standard error of the paired difference is some 800
    times smaller here (a source this small changes each run's MSE by little; for the two largest, GPS and
    range noise, whose contribution varies from run to run as much as the total does, the gain is only about
    1.4 times)."""
    n = 50
    cfg = load_config("semicircle", [SHORT])
    off = switched_off(cfg, SOURCES["depth_sensor"][1])
    on = run(cfg, replicates=range(n)).metrics["e_tot_rms"].to_numpy() ** 2
    paired = run(off, replicates=range(n)).metrics["e_tot_rms"].to_numpy() ** 2
    independent = run(off, replicates=range(n, 2 * n)).metrics["e_tot_rms"].to_numpy() ** 2
    se_crn = np.std(on - paired, ddof=1) / math.sqrt(n)
    se_independent = math.sqrt((np.var(on, ddof=1) + np.var(independent, ddof=1)) / n)
    assert np.mean(on - paired) > 2 * se_crn  # the paired difference is significant
    assert abs(np.mean(on) - np.mean(independent)) < 4 * se_independent  # the independent one is not
    assert se_independent > 5 * se_crn, se_independent / se_crn


def test_a_compared_system_starts_from_its_defaults_and_a_set_wins():
    lbl, usbl = (cfg for _, cfg in configurations("semicircle", compare=("platform.system", ["lbl", "usbl"])))
    assert (lbl["platform"]["layout"], lbl["platform"]["beacons"], lbl["platform"]["baseline"]) == ("circle", 4, 50)
    assert usbl["platform"]["usbl_angle_sigma_deg"] == 0.5
    (_, sbl), = configurations("semicircle", compare=("platform.system", ["sbl"]))  # its own: as configured
    assert sbl.config == configurations("semicircle")[0][1].config
    (label, cfg), = configurations("semicircle", ["platform.baseline=20"], compare=("platform.system", ["lbl"]))
    assert label == "platform.system = lbl" and cfg["platform"]["baseline"] == 20
    (_, cfg), = configurations("semicircle", receiver="ukf")
    assert cfg["simulation"]["receiver"] == "ukf"


# --------------------------------------------------------------------------- the command line

def test_the_command_writes_the_budget(tmp_path, capsys):
    """(f) budget.csv, budget.md, budget.png and config.toml; one printed line per source, largest first."""
    out = tmp_path / "b"
    assert main(["budget", "semicircle", "--set", "simulation.duration=10", "--replicates", "4", "--out",
                 str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    for name in ("budget.csv", "budget.md", "budget.png", "config.toml"):
        assert (out / name).is_file(), name
    table = pd.read_csv(out / "budget.csv")
    assert list(table.columns) == ["source", "description", "status", "contribution", "se", "share", "rms"]
    assert list(table["source"])[-3:] == ["floor", "remainder", "total"]
    assert set(table["source"]) >= set(SOURCES)
    assert load_config(str(out / "config.toml"))["simulation"]["duration"] == 10
    lines = [line for line in printed if line.split(":")[0].strip() in SOURCES]
    assert len(lines) == len(SOURCES)
    on = table[table["status"] == ON]
    assert [line.split(":")[0].strip() for line in lines[:len(on)]] == list(on["source"])
    assert list(on["contribution"]) == sorted(on["contribution"], reverse=True)
    assert "| source |" in (out / "budget.md").read_text() and "first" in (out / "budget.md").read_text()
    assert main(["budget", "semicircle", "--replicates", "4", "--out", str(out)]) == 2  # an earlier budget is kept
    assert "--force" in capsys.readouterr().err


@pytest.mark.slow
def test_the_command_compares_budgets(tmp_path, capsys):
    out = tmp_path / "c"
    assert main(["budget", "semicircle", "--set", "simulation.duration=10", "--replicates", "3", "--compare",
                 "platform.system=sbl,usbl", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "platform.system = sbl:" in printed and "platform.system = usbl:" in printed
    table = pd.read_csv(out / "budget.csv")
    assert list(table.columns)[0] == "platform.system" and set(table["platform.system"]) == {"sbl", "usbl"}
    usbl = table[table["platform.system"] == "usbl"].set_index("source")
    assert usbl.loc["usbl_angle", "status"] == ON
    assert (out / "config_sbl.toml").is_file() and (out / "config_usbl.toml").is_file()
    assert "| source | sbl | usbl |" in (out / "budget.md").read_text()


@pytest.mark.parametrize("compare, needle", [("platform.system=sbl,xbl", "platform.system"),
                                             ("acoustics.sigma=0.1,1", "acoustics.sigma"),
                                             ("platform.baseline=1,-3", "platform.baseline"),
                                             ("baseline=1,3", "--compare")])
def test_a_bad_comparison_is_one_line(tmp_path, capsys, compare, needle):
    out = tmp_path / "bad"
    assert main(["budget", "semicircle", "--compare", compare, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.splitlines() == [err.strip()] and err.startswith("sblsim: error:") and needle in err
    assert not out.exists()


def test_the_help_states_the_default_replicates(capsys):
    with pytest.raises(SystemExit):
        main(["budget", "--help"])
    assert f"(default {DEFAULT_REPLICATES})" in " ".join(capsys.readouterr().out.split())

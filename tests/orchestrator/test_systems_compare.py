"""The positioning systems side by side: ``sblsim compare --systems`` and ``sblsim map --compare platform.system``."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from sblsim.models.platform.geometry import lever_arms
from sblsim.models.systems import SYSTEMS
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.run import run_batch, with_replicates
from sblsim.orchestrator.cosim.systems import system_overrides
from sblsim.orchestrator.maps import accuracy_map, make_maps, plot

#: The LBL defaults of compare, set by hand as a user would.
LBL_BY_HAND = ["platform.system=lbl", "platform.layout=circle", "platform.beacons=4", "platform.baseline=50"]


def test_the_defaults_table_names_every_system_and_the_documented_values():
    assert tuple(SYSTEMS) == ("sbl", "lbl", "usbl", "ilbl")
    assert set(SYSTEMS["sbl"].compare_defaults) == {"platform.layout=cross", "platform.baseline=3"}
    assert set(LBL_BY_HAND[1:]) == set(SYSTEMS["lbl"].compare_defaults)
    assert "platform.usbl_angle_sigma_deg=0.5" in SYSTEMS["usbl"].compare_defaults
    # the inverted LBL: LBL's field, its hydrophones tracked by a receiver with the emission epoch as a state
    assert set(SYSTEMS["ilbl"].compare_defaults) == {*LBL_BY_HAND[1:], "simulation.receiver=ekf-seq"}


@pytest.mark.parametrize("scenario", ["semicircle", "spiral", "random", "square", "harbour", "random-walk"])
def test_the_built_in_divers_are_above_the_default_seafloor(scenario):
    cfg = load_config(scenario, system_overrides("lbl"))
    assert cfg["target"]["depth"] < cfg["platform"]["seafloor_depth"]


def test_the_scenarios_own_system_keeps_the_scenarios_platform():
    """At the lbl-field site the LBL keeps its 250 m circle and the SBL starts from the paper's cross; on the
    harbour (an SBL scenario of 1 m arms) the SBL keeps its 1 m."""
    from sblsim.orchestrator.cosim.config import scenario_system

    own = scenario_system("lbl-field")
    assert own == "lbl"
    lbl = load_config("lbl-field", system_overrides("lbl", own=own))["platform"]
    sbl = load_config("lbl-field", system_overrides("sbl", own=own))["platform"]
    assert (lbl["layout"], lbl["baseline"]) == ("circle", 250.0)
    assert (sbl["system"], sbl["layout"], sbl["baseline"]) == ("sbl", "cross", 3.0)
    harbour = load_config("harbour", system_overrides("sbl", own=scenario_system("harbour")))["platform"]
    assert harbour["baseline"] == 1.0


def test_the_users_set_wins_over_the_system_defaults():
    cfg = load_config("semicircle", system_overrides("lbl", ["platform.baseline=30"]))
    assert cfg["platform"]["system"] == "lbl" and cfg["platform"]["layout"] == "circle"
    assert cfg["platform"]["baseline"] == 30
    assert load_config("semicircle", system_overrides("sbl"))["platform"] == load_config("semicircle")["platform"]


def test_every_system_runs_on_the_same_diver_path():
    """The target draws its own random numbers: the random path is the same whatever the system."""
    paths = []
    for system in SYSTEMS:
        cfg = load_config("random", system_overrides(system, ["simulation.duration=20"]), seed=5)
        ts = run_batch(with_replicates(cfg, range(2))).timeseries
        paths.append(ts[["replicate", "true_x", "true_y", "true_z"]].to_numpy())
    np.testing.assert_array_equal(paths[0], paths[1])
    np.testing.assert_array_equal(paths[0], paths[2])


@pytest.mark.slow
def test_compare_systems_writes_one_row_per_system_and_the_lbl_row_is_a_plain_run(tmp_path, capsys):
    """The lbl row of ``compare --systems`` is the run a user gets with the LBL defaults set by hand (same seed,
    replicate 0); the sbl row the scenario's own run; the USBL row's PCRB is the USBL bound of its runs."""
    base = ["--set", "simulation.duration=20"]
    out = tmp_path / "cmp"
    code = main(["compare", "semicircle", "--systems", "sbl,lbl,usbl", "--receivers", "ekf-seq", "--replicates", "1",
                 "--seed", "3", *base, "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    assert "per system and receiver, seed 3" in printed.splitlines()[0]
    assert "lbl: 4 transponders on a 50 m circle" in printed
    table = pd.read_csv(out / "compare.csv")
    assert table.columns[0] == "system" and table["system"].tolist() == ["sbl", "lbl", "usbl"]
    assert table["receiver"].tolist() == ["ekf-seq"] * 3
    assert "| lbl | ekf-seq |" in (out / "compare.md").read_text() and (out / "compare.png").stat().st_size > 10_000
    for system, by_hand in (("lbl", LBL_BY_HAND), ("sbl", []), ("usbl", ["platform.system=usbl"])):
        run_out = tmp_path / system
        args = [a for o in [*by_hand, "receiver=ekf-seq"] for a in ("--set", o)]
        assert main(["run", "semicircle", *args, *base, "--seed", "3", "--out", str(run_out)]) == 0
        summary = json.loads((run_out / "summary.json").read_text())
        row = table[table["system"] == system].iloc[0]
        assert row.rms_e_tot == pytest.approx(summary["e_tot_rms"], rel=1e-12)
        assert row.mean_e_tot == pytest.approx(summary["e_tot_mean"], rel=1e-12)
        assert row.nees == pytest.approx(summary["nees_mean"], rel=1e-12)
        assert row.pcrb_rms == pytest.approx(summary["pcrb_rms"], rel=1e-12)
    usbl = table[table["system"] == "usbl"].iloc[0]
    assert usbl.ratio_to_pcrb == pytest.approx(usbl.rms_e_tot / usbl.pcrb_rms, rel=1e-12)


@pytest.mark.parametrize("args, message", [
    (["--systems", "sbl,xbl"], "--systems: 'xbl' is not one of sbl, lbl, usbl"),
    (["--systems", "sbl,sbl"], "--systems: 'sbl,sbl' names a system twice"),
    (["--systems", "sbl,lbl", "--set", "platform.system=usbl"], "the system is set by --systems, not by --set"),
    (["--systems", "lbl", "--set", "target.depth=60"],
     "platform.seafloor_depth: 50 m is not below the diver (60 m, target.depth)"),
])
def test_compare_systems_refuses_bad_input_with_one_line(args, message, tmp_path, capsys):
    code = main(["compare", "semicircle", *args, "--out", str(tmp_path / "c")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and message in err and not (tmp_path / "c").exists()


@pytest.mark.parametrize("n", [4, 6, 8])
def test_the_lbl_map_at_the_centre_of_the_circle_is_the_closed_form(n):
    """N ≥ 3 transponders equally spaced on a circle of radius R on the seafloor at depth D, the diver at depth z
    above the centre, Δz = D − z, range variance σ² = σ_r² + σ_survey² (no attitude term for LBL).

    Range i's unit vector is ``g_i = (R cos θ_i, R sin θ_i, Δz) / sqrt(R² + Δz²)`` (up to sign), so
    ``J = Σ g_i g_iᵀ / σ² + e_z e_zᵀ / σ_d²``. For N ≥ 3 equally spaced angles ``Σ cos² θ_i = Σ sin² θ_i = N/2``
    and ``Σ cos θ_i = Σ sin θ_i = Σ cos θ_i sin θ_i = 0``: the horizontal block is
    ``(N/σ²) · (R² / (R² + Δz²)) / 2 · I`` and its cross terms with z vanish, so the depth sensor fixes z
    without changing it. Each horizontal axis has variance ``2σ²(R² + Δz²) / (N R²)``, and the horizontal
    DRMS is ``sqrt(2 · 2σ²(R² + Δz²) / (N R²))`` (the SBL closed form ``2σ / (√N sin α)`` with
    ``sin α = R / sqrt(R² + Δz²)``). The test checks this derivation with numpy's sums and inverse, and the map
    against it."""
    sigma_r, survey, radius, seafloor, z, sigma_d = 0.2, 0.1, 40.0, 60.0, 5.0, 0.001
    cfg = load_config("semicircle", system_overrides("lbl", [
        f"platform.beacons={n}", f"platform.baseline={radius}", f"platform.seafloor_depth={seafloor}",
        f"acoustics.sigma_range={sigma_r}", f"platform.survey_sigma={survey}", f"target.depth_sigma={sigma_d}",
        f"target.depth={z}"]))
    sigma2, dz = sigma_r ** 2 + survey ** 2, seafloor - z
    closed = math.sqrt(2 * 2 * sigma2 * (radius ** 2 + dz ** 2) / (n * radius ** 2))
    # the derivation, numerically
    transponders = lever_arms(cfg["platform"])
    assert transponders.shape == (n, 3) and np.allclose(np.hypot(transponders[:, 0], transponders[:, 1]), radius)
    g = (np.array([0.0, 0.0, z]) - transponders) / np.linalg.norm(np.array([0.0, 0.0, z]) - transponders, axis=1,
                                                                   keepdims=True)
    J = g.T @ g / sigma2 + np.diag([0.0, 0.0, 1.0 / sigma_d ** 2])
    assert J[0, 0] == pytest.approx(n / sigma2 * radius ** 2 / (radius ** 2 + dz ** 2) / 2, rel=1e-12)
    assert abs(J[0, 2]) < 1e-9 * J[0, 0] and abs(J[0, 1]) < 1e-9 * J[0, 0]
    assert math.sqrt(np.trace(np.linalg.inv(J)[:2, :2])) == pytest.approx(closed, rel=1e-12)
    # the map
    drms = accuracy_map(cfg, np.array([0.0]), np.array([0.0]))[0, 0]
    assert drms == pytest.approx(closed, rel=1e-9)


def _usbl_closed_form(rho: float, dz: float, sigma_range: float, gps: float, attitude_deg: float,
                      angle_deg: float, arm: float) -> float:
    """Horizontal DRMS of one USBL packet at horizontal distance ρ, depth difference Δz, the depth known, a level
    array (axis down) measuring the direction cosines across its axis with the std σ_u each.

    Frame at the diver: n along the line of sight, t across it (horizontal), v across it in its vertical plane.
    With ``r = sqrt(ρ² + Δz²)`` and the elevation ε (``sin ε = Δz / r``), a direction cosine across the plane moves
    the azimuth by σ_u / cos ε (t: ``ρ σ_u / cos ε = r σ_u``), one in the plane moves the elevation by
    σ_u / sin ε (v: ``r σ_u / sin ε``); an attitude error σ_θ per Euler angle turns the direction by σ_θ in each
    of t and v (roll and yaw share t as sin ε and cos ε); the transceiver's position error
    ``σ_b² = σ_GPS² + (σ_θ a)²`` per axis (a the lever arm) adds to each. So the fix has the independent errors
    ``σ_r² + σ_b²`` along n, ``r² (σ_u² + σ_θ²) + σ_b²`` along t and ``r² (σ_u² / sin² ε + σ_θ²) + σ_b²`` along v.
    With the depth known (σ_d → 0) the variance along the horizontal of the plane is
    ``1 / (cos² ε / var_n + sin² ε / var_v)`` and ``DRMS² = var_t + that``. Far away at a shallow angle the range
    and the depth fix the distance and the across term dominates: ``DRMS ≈ r √(σ_u² + σ_θ²)``, linear in it.
    """
    r = math.hypot(rho, dz)
    su, st = math.radians(angle_deg), math.radians(attitude_deg)
    b2 = gps ** 2 + (st * arm) ** 2
    cos_e, sin_e = rho / r, dz / r
    var_n = sigma_range ** 2 + b2
    var_t = r ** 2 * (su ** 2 + st ** 2) + b2
    var_v = r ** 2 * (su ** 2 / sin_e ** 2 + st ** 2) + b2
    along = 1.0 / (cos_e ** 2 / var_n + sin_e ** 2 / var_v)
    return math.sqrt(var_t + along)


def test_the_usbl_map_grows_linearly_far_from_the_transceiver_as_distance_times_the_angle_noise():
    """A transceiver 1 m deep, the diver at 5 m: the map is the closed form of the direction-cosine packet with the
    depth everywhere, and far off (ρ ≥ 100 m, within 2.3° of the horizontal) the DRMS is the slant range times the
    angle noise and the attitude error combined, √(σ_u² + σ_θ²) (1 %): twice the distance, twice the DRMS."""
    sigma_range, gps, attitude, angle = 0.1, 0.1, 1.0, 0.5
    cfg = load_config("semicircle", system_overrides("usbl", [
        "platform.transducer_depth=1", "target.depth=5", f"acoustics.sigma_range={sigma_range}",
        f"platform.gps_sigma={gps}", f"platform.imu_sigma_deg={attitude}", f"platform.usbl_angle_sigma_deg={angle}",
        "target.depth_sigma=0.001"]))
    distances = np.array([10.0, 20.0, 100.0, 200.0, 400.0])
    east = accuracy_map(cfg, distances, np.array([0.0]))[0]
    north = accuracy_map(cfg, np.array([0.0]), distances)[:, 0]
    np.testing.assert_allclose(east, north, rtol=1e-9)  # the map is round
    closed = [_usbl_closed_form(rho, 4.0, sigma_range, gps, attitude, angle, 1.0) for rho in distances]
    np.testing.assert_allclose(east, closed, rtol=1e-3)
    sigma_a = math.hypot(math.radians(angle), math.radians(attitude))
    np.testing.assert_allclose(east[2:], np.hypot(distances[2:], 4.0) * sigma_a, rtol=0.01)
    assert east[3] / east[2] == pytest.approx(2.0, rel=0.01) and east[4] / east[3] == pytest.approx(2.0, rel=0.01)


@pytest.mark.slow
def test_map_compare_platform_system_draws_each_system_from_its_defaults(tmp_path, capsys):
    out = tmp_path / "map"
    code = main(["map", "semicircle", "--extent", "20", "--step", "2", "--compare", "platform.system=sbl,lbl,usbl",
                 "--out", str(out)])
    assert code == 0, capsys.readouterr().err
    assert "platform.system = lbl: horizontal DRMS" in capsys.readouterr().out
    frame = pd.read_csv(out / "map.csv")
    assert frame["platform.system"].unique().tolist() == ["sbl", "lbl", "usbl"] and len(frame) == 3 * 21 * 21
    assert (out / "map.png").stat().st_size > 20_000
    lbl = frame[frame["platform.system"] == "lbl"]["drms"].to_numpy()
    by_hand = load_config("semicircle", LBL_BY_HAND)
    east = np.arange(-20.0, 20.5, 2.0)
    np.testing.assert_allclose(lbl, accuracy_map(by_hand, east, east).ravel(), rtol=1e-12)
    labels, configs, east, north, maps = make_maps("semicircle", extent=20, step=2,
                                                   compare=("platform.system", ["sbl", "lbl", "usbl"]))
    assert [c["platform"]["system"] for c in configs] == ["sbl", "lbl", "usbl"]
    assert configs[1]["platform"]["baseline"] == 50 and configs[0]["platform"]["baseline"] == 3
    fig = plot(labels, configs, east, north, maps, [0.5, 1])
    panels = [ax for ax in fig.axes if ax.get_title()]
    assert len(panels) == 3 and len(fig.axes) == 4  # three maps and the colour bar
    assert "transponders off the map" in panels[1].get_title() and "one transceiver" in panels[2].get_title()

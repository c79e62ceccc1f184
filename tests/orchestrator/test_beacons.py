"""Any number of beacons: the circle layout, the key ``platform.beacons``, the FMUs built per number of beacons
(on the fmu engine, in a plain C host, in libcosim from the SSP), the accuracy map and the PCRB."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.fmus.build import beacons_dir, build_all, fmu_path
from sblsim.models import COMPONENTS
from sblsim.models.platform.geometry import platform_offsets
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import run
from sblsim.orchestrator.cosim.ssp import export_ssp
from sblsim.orchestrator.cosim.ssp_read import read_ssp
from sblsim.orchestrator.maps import accuracy_map
from tests.fmus_tests.test_fmi_semantics import finite_but_the_estimate_before_a_fix
from tests.helpers import share_compiled_objects
from tests.orchestrator.test_systems import SNR_CASES

FIVE = "12 0 1; 3 9 1.5; -8 6 1; -7 -7 2; 4 -11 1"
#: id -> (overrides, number of beacons)
LAYOUTS = {f"circle{n}": (["platform.layout=circle", f"platform.beacons={n}"], n) for n in (3, 4, 6, 8)}
LAYOUTS["custom5"] = (["platform.layout=custom", f'platform.beacon_offsets="{FIVE}"'], 5)


@pytest.fixture(scope="module")
def beacon_fmus(tmp_path_factory) -> Path:
    """The four components' FMUs for 3, 4, 5 and 8 beacons (``build_all``) and every FMU for 6 beacons
    (``sblsim fmus build --beacons 6``), each number in its own folder."""
    directory = tmp_path_factory.mktemp("beacon_fmus")
    for n in (3, 4, 5, 8):
        build_all(directory, names=list(COMPONENTS), n_beacons=n)
    assert main(["fmus", "build", "--beacons", "6", "--out", str(directory)]) == 0
    assert fmu_path(directory / "beacons6", "platform").is_file()
    return directory


def assert_same_frames(a: pd.DataFrame, b: pd.DataFrame, atol: float = 1e-9) -> None:
    assert a.shape == b.shape and list(a.columns) == list(b.columns)
    for column in a.columns:
        x, y = a[column].to_numpy(dtype=float), b[column].to_numpy(dtype=float)
        assert np.array_equal(np.isnan(x), np.isnan(y)), f"{column}: NaN positions differ"
        diff = np.abs(x[~np.isnan(x)] - y[~np.isnan(y)])
        assert diff.size == 0 or diff.max() <= atol, f"{column}: max difference {diff.max()}"


def test_the_circle_puts_n_beacons_at_the_baseline_from_north():
    cfg = load_config("semicircle", ["platform.layout=circle", "platform.beacons=6", "platform.baseline=2"])
    offsets = platform_offsets(cfg["platform"])
    assert make_plan(cfg).n_beacons == 6 and offsets.shape == (6, 3)
    angles = np.arctan2(offsets[:, 1], offsets[:, 0])
    np.testing.assert_allclose(np.unwrap(angles), 2 * np.pi * np.arange(6) / 6, atol=1e-15)
    np.testing.assert_allclose(np.hypot(offsets[:, 0], offsets[:, 1]), 2.0, rtol=1e-15)
    assert np.all(offsets[:, 2] == cfg["platform"]["transducer_depth"])


def test_a_circle_of_four_is_the_cross_to_the_bit():
    cross = run(load_config("semicircle", ["simulation.duration=6"], seed=4)).timeseries
    circle = run(load_config("semicircle", ["simulation.duration=6", "platform.layout=circle"], seed=4)).timeseries
    pd.testing.assert_frame_equal(cross, circle, check_exact=True)


def test_a_custom_layout_fills_the_beacon_count():
    cfg = load_config("semicircle", LAYOUTS["custom5"][0])
    assert cfg["platform"]["beacons"] == 5
    again = load_config("semicircle", LAYOUTS["custom5"][0] + ["platform.beacons=5"])
    assert again["platform"] == cfg["platform"]


@pytest.mark.slow
@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_both_engines_give_the_same_numbers_for_any_number_of_beacons(beacon_fmus, layout):
    overrides, n = LAYOUTS[layout]
    cfg = load_config("semicircle", overrides + ["simulation.duration=6", "acoustics.loss_pct=10"], seed=7)
    assert make_plan(cfg).n_beacons == n
    local = run(cfg, "local").timeseries
    fmu = run(cfg, "fmu", fmu_dir=beacon_fmus).timeseries
    assert sorted(set(local["beacon_id"]) - {0}) == list(range(1, n + 1))  # 0: the first step, nothing arrived
    assert_same_frames(local, fmu)


@pytest.mark.slow
def test_the_fmu_engine_builds_the_fmus_it_needs_out_of_the_box(beacon_fmus, tmp_path):
    """``sblsim run --engine fmu`` with 6 beacons and no FMUs built for 6: they are built into the cache (an empty
    one, given the objects the module's FMUs for 6 beacons compiled)."""
    assert share_compiled_objects(tmp_path / "cache") > 0
    env = {**os.environ, "SBLSIM_CACHE_DIR": str(tmp_path / "cache"), "SBLSIM_FMU_DIR": str(tmp_path / "none")}
    args = ["run", "semicircle", "--engine", "fmu", "--set", "platform.layout=circle", "--set", "platform.beacons=6",
            "--set", "simulation.duration=3", "--seed", "5", "--out", str(tmp_path / "out")]
    done = subprocess.run([sys.executable, "-m", "sblsim.orchestrator.cli", *args], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert list((tmp_path / "cache" / "fmus").glob("*/sblsim_platform.fmu"))
    overrides = ["platform.layout=circle", "platform.beacons=6", "simulation.duration=3"]
    local = run(load_config("semicircle", overrides, seed=5)).timeseries
    fmu = pd.read_parquet(tmp_path / "out" / "timeseries.parquet")
    np.testing.assert_allclose(fmu[["est_x", "est_y", "est_z"]].to_numpy(), local[["est_x", "est_y", "est_z"]],
                               rtol=0, atol=1e-9)


def c_host_runs(c_host: Path, directory: Path, tmp_path: Path):
    """Each component's FMU of ``directory`` run for 30 steps of 0.1 s in the plain C host (no Python, an empty
    environment): yields the component, its model description and its Real outputs (30, m), checked finite but a
    receiver's estimate, which without a packet is never defined (NaN throughout, printed as nan or -nan)."""
    import zipfile

    from fmpy import read_model_description

    for name in COMPONENTS:
        fmu, folder = fmu_path(directory, name), tmp_path / name
        with zipfile.ZipFile(fmu) as archive:
            archive.extractall(folder)
        md = read_model_description(str(fmu))
        outputs = [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
        binary = folder / "binaries" / "linux64" / f"{md.coSimulation.modelIdentifier}.so"
        proc = subprocess.run([str(c_host), str(binary), md.guid, f"file://{folder}/resources", "30", "0.1", ""],
                              input="\n".join(map(str, outputs)), capture_output=True, text=True, env={}, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        rows = np.array([[float(x) for x in line.split()[2:]] for line in proc.stdout.splitlines()
                         if line.startswith("a")])
        assert rows.shape == (30, len(outputs))
        names = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
        estimated = finite_but_the_estimate_before_a_fix(names, rows)
        assert not (name == "receiver" and estimated.any())
        yield name, md, rows


@pytest.mark.slow
def test_six_beacon_fmus_run_in_a_plain_c_host_with_an_empty_environment(beacon_fmus, c_host, tmp_path):
    for name, md, rows in c_host_runs(c_host, beacons_dir(beacon_fmus, 6), tmp_path):
        if name == "platform":  # six beacons 60° apart (whatever the waves' yaw; their tilt is a few degrees)
            names = [v.name for v in md.modelVariables if v.causality == "output" and v.type == "Real"]
            assert sum(n.endswith("_true_x") for n in names) == 6
            first, sixth = (rows[0, [names.index(f"beacon{i}_true_{a}") for a in "xy"]] for i in (1, 6))
            turn = math.degrees(math.atan2(sixth[1], sixth[0]) - math.atan2(first[1], first[0]))
            assert (turn + 180.0) % 360.0 - 180.0 == pytest.approx(-60.0, abs=2.0)


@pytest.mark.slow
def test_six_beacon_ssp_runs_in_libcosim_like_the_jacobi_master(beacon_fmus, tmp_path):
    pytest.importorskip("libcosimpy")
    cfg = load_config("semicircle", LAYOUTS["circle6"][0] + ["simulation.duration=10"], seed=12)
    ssp = export_ssp(cfg, tmp_path / "six.ssp", beacon_fmus)
    back = read_ssp(ssp)
    assert back.config["platform"]["layout"] == "circle" and back.config["platform"]["beacons"] == 6
    hosts = Path(__file__).with_name("ssp_hosts.py")
    out = tmp_path / "libcosim.npz"
    done = subprocess.run([sys.executable, str(hosts), "libcosim", str(ssp), str(out)], capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    data = dict(np.load(out))
    jacobi = run({**cfg, "simulation": {**cfg["simulation"], "master": "jacobi"}}, "fmu",
                 fmu_dir=beacon_fmus).timeseries
    assert len(data["time"]) == len(jacobi) == 100
    np.testing.assert_allclose(np.column_stack([data[f"est_{a}"] for a in "xyz"]),
                               jacobi[["est_x", "est_y", "est_z"]].to_numpy(), rtol=0, atol=1e-9)


def _map_at(cfg: dict, points: np.ndarray) -> np.ndarray:
    """The accuracy map at (East, North) points [m]."""
    return np.array([accuracy_map(cfg, np.array([e]), np.array([n]))[0, 0] for e, n in points])


def test_the_map_of_a_circle_of_six_is_symmetric_under_a_rotation_by_60_degrees():
    cfg = load_config("semicircle", LAYOUTS["circle6"][0] + ["platform.baseline=3"])
    rng = np.random.default_rng(1)
    points = rng.uniform(-25.0, 25.0, (12, 2))
    c, s = math.cos(math.pi / 3), math.sin(math.pi / 3)
    rotated = points @ np.array([[c, -s], [s, c]]).T
    here, there = _map_at(cfg, points), _map_at(cfg, rotated)
    np.testing.assert_allclose(there, here, rtol=1e-9)
    # and a rotation by 30° is not a symmetry of six beacons
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    assert np.abs(_map_at(cfg, points @ np.array([[c, -s], [s, c]]).T) / here - 1).max() > 1e-4


@pytest.mark.parametrize("n", [3, 4, 6, 8])
def test_the_map_at_the_centre_is_the_closed_form(n):
    """Below the centre of N equally spaced beacons: horizontal DRMS 2σ/(√N sin α), α the lines of sight's angle
    with the vertical (the depth sensor fixes z; the cross terms vanish for N ≥ 3)."""
    sigma, baseline, h, depth = 0.3, 2.0, 1.0, 9.0
    cfg = load_config("semicircle", ["platform.layout=circle", f"platform.beacons={n}", f"platform.baseline={baseline}",
                                     f"platform.transducer_depth={h}", f"acoustics.sigma_range={sigma}",
                                     "platform.gps_sigma=0", "platform.imu_sigma_deg=0", "target.depth_sigma=0.001",
                                     f"target.depth={depth}"])
    alpha = math.atan2(baseline, depth - h)
    drms = accuracy_map(cfg, np.array([0.0]), np.array([0.0]))[0, 0]
    assert drms == pytest.approx(2 * sigma / (math.sqrt(n) * math.sin(alpha)), rel=1e-9)


@pytest.mark.slow  # 1.6 s, but each count a library of its own: 20-30 s of compiling each on a fresh machine
def test_the_pcrb_of_a_run_takes_n_beacons():
    """The bound of a run follows the beacons of its layout: finite, and not the same for 3 and 8 beacons."""
    base = ["platform.layout=circle", "simulation.duration=20"]
    rms = {n: run(load_config("semicircle", base + [f"platform.beacons={n}"], seed=2)).metrics["pcrb_rms"][0]
           for n in (3, 8)}
    assert np.isfinite(rms[3]) and np.isfinite(rms[8]) and rms[3] > 0 and rms[8] > 0 and rms[3] != rms[8]


@pytest.fixture(scope="module")
def usbl_fmus(tmp_path_factory) -> Path:
    """The four components' FMUs of the USBL interface (one transceiver), in the folder ``usbl``."""
    directory = tmp_path_factory.mktemp("usbl_fmus")
    build_all(directory, names=list(COMPONENTS), n_beacons=1)
    assert beacons_dir(directory, 1) == directory / "usbl"
    return directory


def _libcosim_against_jacobi(cfg: dict, fmu_dir: Path, tmp_path: Path, channel: tuple[str, ...] = ()) -> pd.DataFrame:
    """The configuration's SSP stepped by libcosim gives the fmu engine's Jacobi numbers (≤ 1e-9): the estimate
    [m] and each Real output of the channel named in ``channel`` at every step. The Jacobi run's time series."""
    pytest.importorskip("libcosimpy")
    ssp = export_ssp(cfg, tmp_path / "system.ssp", fmu_dir)
    assert read_ssp(ssp).config["platform"]["system"] == cfg["platform"]["system"]
    out = tmp_path / "libcosim.npz"
    done = subprocess.run([sys.executable, str(Path(__file__).with_name("ssp_hosts.py")), "libcosim", str(ssp),
                           str(out), *(f"acoustics.{name}" for name in channel)], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    data = dict(np.load(out))
    jacobi = run({**cfg, "simulation": {**cfg["simulation"], "master": "jacobi"}}, "fmu", fmu_dir=fmu_dir).timeseries
    assert len(data["time"]) == len(jacobi)
    np.testing.assert_allclose(np.column_stack([data[f"est_{a}"] for a in "xyz"]),
                               jacobi[["est_x", "est_y", "est_z"]].to_numpy(), rtol=0, atol=1e-9)
    for name in channel:
        np.testing.assert_allclose(data[f"acoustics.{name}"], jacobi[name].to_numpy(dtype=float), rtol=0, atol=1e-9,
                                   err_msg=name)
    return jacobi


@pytest.mark.slow
def test_a_six_transponder_lbl_ssp_runs_in_libcosim_like_the_jacobi_master(beacon_fmus, tmp_path):
    cfg = load_config("semicircle", LAYOUTS["circle6"][0] + ["platform.system=lbl", "platform.baseline=40",
                                                             "platform.survey_sigma=0.2", "acoustics.ranging=twtt",
                                                             "simulation.duration=5"], seed=3)
    _libcosim_against_jacobi(cfg, beacon_fmus, tmp_path)


@pytest.mark.slow
def test_a_usbl_ssp_runs_in_libcosim_like_the_jacobi_master(usbl_fmus, tmp_path):
    cfg = load_config("semicircle", ["platform.system=usbl", "platform.usbl_misalignment_deg=1",
                                     "simulation.duration=5"], seed=3)
    _libcosim_against_jacobi(cfg, usbl_fmus, tmp_path)


@pytest.mark.slow
def test_usbl_fmus_run_in_a_plain_c_host_with_an_empty_environment(usbl_fmus, c_host, tmp_path):
    """Each USBL FMU in the plain C host (no Python, empty environment): 30 finite steps; the channel declares
    the direction of arrival and the attitudes it reads, the platform one transceiver."""
    for name, md, _rows in c_host_runs(c_host, beacons_dir(usbl_fmus, 1), tmp_path):
        names = {v.name: v.causality for v in md.modelVariables}
        if name == "acoustics":
            assert names["azimuth"] == names["elevation"] == "output" and names["array_roll"] == "input"
        if name == "platform":
            assert "beacon1_true_x" in names and "beacon2_true_x" not in names


def test_fmus_build_refuses_beacons_with_the_usbl_system(capsys):
    assert main(["fmus", "build", "--system", "usbl", "--beacons", "6", "--out", "unused"]) != 0
    assert "--beacons: 6 with --system usbl" in capsys.readouterr().err


@pytest.mark.slow
def test_a_ray_ssp_with_a_profile_receiver_runs_in_libcosim_like_the_jacobi_master(fmu_dir, tmp_path):
    """Eigenrays through Munk's profile (the channel's eigenray table and its exact solve) and a receiver ranging
    with that profile, stepped by libcosim from the SSP: the fmu engine's Jacobi numbers."""
    cfg = load_config("semicircle", ["acoustics.propagation=ray", "acoustics.sound_speed_profile=munk",
                                     "receiver.sound_speed_profile=acoustics", "simulation.duration=5"], seed=4)
    _libcosim_against_jacobi(cfg, fmu_dir, tmp_path)
    back = read_ssp(tmp_path / "system.ssp").config  # the package the host ran is the ray run's
    assert back["acoustics"]["propagation"] == "ray" and back["receiver"]["sound_speed_profile"] != "assumed"


@pytest.mark.slow
@pytest.mark.parametrize("case", SNR_CASES)
def test_an_snr_ssp_runs_in_libcosim_like_the_jacobi_master(request, fmu_dir, tmp_path, case):
    """Detection by signal-to-noise on each system (:data:`~tests.orchestrator.test_systems.SNR_CASES`), stepped by
    libcosim from the SSP ``sblsim ssp export`` writes: the fmu engine's Jacobi numbers, the estimate and the
    channel's SNR, detection probability, range and travel time at every step; the package carries the site."""
    scenario, overrides = SNR_CASES[case]
    cfg = load_config(scenario, overrides, seed=9)
    fmus = request.getfixturevalue("usbl_fmus") if cfg["platform"]["system"] == "usbl" else fmu_dir
    jacobi = _libcosim_against_jacobi(cfg, fmus, tmp_path, ("snr", "detection_probability", "range", "travel_time"))
    back = read_ssp(tmp_path / "system.ssp").config
    for key in ("detection", "propagation", "source_level", "fluctuation", "water_depth", "bottom"):
        assert back["acoustics"][key] == cfg["acoustics"][key], key
    assert back["platform"]["beaufort"] == cfg["platform"]["beaufort"]
    assert not jacobi["packet_valid"].astype(bool).all() and (jacobi["arrival"] > 1).any()  # lost and reflected

"""A receiver that ranges with its own sound-speed profile (``receiver.sound_speed_profile``).

* The travel time → slant range conversion (:func:`sblsim.models.acoustics.ray_inversion.slant_range`) inverts a linear
  gradient's closed-form travel time, ``τ = arccosh(1 + g² R² / (2 c₁ c₂)) / |g|`` (the circular arc between two
  points; Jensen et al. ch. 3), to the geometric range, and the eigenray travel times of the deep NCL1 cast to
  below 1 cm at about 1 km slant range, where the single assumed speed is metres off.
* ``acoustics`` (the true profile) gives the receiver the channel's table; bad values are refused in one line
  (exit status 2, nothing written); the default computes nothing new (the pinned reference results,
  tests/orchestrator/test_reference.py, hold that).
* At a 1000 m LBL site (transponders on the seafloor, eigenrays through the Munk profile) ekf-seq on the random
  walk with the single assumed speed is biased far beyond its bound, and with the true profile reaches its PCRB
  with a mean NEES in [1.5, 4.5].
* The budget names the profile error, off for a receiver of the single assumed speed.
* The embeddable C of ``sblsim codegen receiver``, fed a recorded run of a profile receiver, reproduces its
  estimates.
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from sblsim.models import MODELS, RECEIVERS
from sblsim.models.acoustics.ray_inversion import ray_bending, slant_range
from sblsim.models.acoustics.rays import eigenray_families, first_arrival, profile_arrays
from sblsim.models.acoustics.sound_speed import PROFILE, profile_table
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import run, run_batch, with_replicates
from sblsim.orchestrator.montecarlo.budget import OFF, ON, budget
from sblsim.orchestrator.montecarlo.error_sources import SOURCES

#: The 1000 m site: four transponders on the seafloor on an 800 m circle, two-way ranging, eigenrays through the
#: Munk profile; the random walk near the surface (slant ranges about 1.3 km), 50 s at a 0.5 s sampling time.
SITE = ["simulation.receiver=ekf-seq", "platform.system=lbl", "platform.seafloor_depth=1000", "platform.layout=circle",
        "platform.baseline=800", "acoustics.ranging=twtt", "simulation.sampling_time=0.5", "simulation.duration=50",
        "acoustics.propagation=ray", "acoustics.sound_speed_profile=munk"]


@pytest.mark.slow
def test_the_conversion_inverts_a_linear_gradients_closed_form():
    c0, g = 1480.0, 0.05  # [m/s], [1/s]: c = c0 + g z
    nodes, speeds = profile_arrays([[0.0, c0], [5000.0, c0 + g * 5000.0]])
    rng = np.random.default_rng(4)
    for _ in range(30):
        zs, zr, x = rng.uniform(0, 1500), rng.uniform(0, 1500), rng.uniform(0, 2000)
        c1, c2 = c0 + g * zs, c0 + g * zr
        r = np.hypot(x, zr - zs)
        tau = np.arccosh(1.0 + g * g * r * r / (2.0 * c1 * c2)) / g
        rho, valid = slant_range(zs, zr, tau, 1500.0 * tau, nodes, speeds)
        assert float(valid) == 1.0
        assert float(rho) == pytest.approx(r, abs=1e-6), (zs, zr, x)


@pytest.mark.slow
def test_the_true_profile_removes_the_sound_speed_error_of_a_deep_cast():
    """Travel times of the direct eigenray through the NCL1 cast (1220 m) at about 1 km slant range, 20 random
    geometries (each conversion costs a ray inversion, about 0.1 s): the conversion gives the geometric range to
    below 1 cm (from 5 % off), the single assumed speed metres off."""
    nodes, speeds = profile_arrays(profile_table("ctd:NCL1", "", 15.0, 35.0))
    rng = np.random.default_rng(7)
    worst, straight = 0.0, 0.0
    for _ in range(20):
        zs, zr = rng.uniform(900.0, 1200.0), rng.uniform(0.0, 50.0)
        x = rng.uniform(0.0, 700.0)
        tau, _, _, kind = first_arrival(1.0, zs, zr, x, 0.0, 1500.0, nodes, speeds)
        assert float(kind) == 1.0
        r = np.hypot(x, zr - zs)
        for start in (1500.0 * float(tau), 1.05 * 1500.0 * float(tau), 0.95 * 1500.0 * float(tau)):
            rho, valid = slant_range(zs, zr, tau, start, nodes, speeds)
            worst = max(worst, abs(float(rho) - r))
        straight = max(straight, abs(1500.0 * float(tau) - r))
    assert worst < 0.01
    assert straight > 5.0


def test_the_bending_is_a_linear_gradients_arc():
    """c = c0 + g z: the ray between two points is the circle centred where c would vanish; the bending the
    receiver turns a direction by (from the slant range and the two depths) is the chord's elevation minus that
    circle's grazing angle at the transceiver."""
    c0, g = 1480.0, 0.05
    nodes, speeds = profile_arrays([[0.0, c0], [5000.0, c0 + g * 5000.0]])
    zc = -c0 / g
    rng = np.random.default_rng(11)
    for _ in range(30):
        zt, zr, x = rng.uniform(0, 50), rng.uniform(0, 1500), rng.uniform(1, 1500)
        a, b = zt - zc, zr - zc
        xc = (x * x + b * b - a * a) / (2 * x)
        grazing = np.sign(xc) * abs(np.pi / 2 - np.arctan2(a, -xc))  # positive down while it descends
        bending, valid = (float(v) for v in ray_bending(zt, zr, np.hypot(x, zr - zt), nodes, speeds))
        assert valid == 1.0
        assert bending == pytest.approx(np.arctan2(zr - zt, x) - grazing, abs=1e-9), (zt, zr, x)
        assert abs(bending) > 1e-6 or x < 5  # the ray bends: the measured angle is not the chord's


@pytest.mark.slow
def test_the_bending_turns_a_deep_casts_eigenrays_to_the_chord():
    """The direct eigenray from a transceiver near the surface to a diver 50-1200 m deep through the NCL1 cast
    (solved by the eigenray families, another solver): its launch angle plus the bending is the chord's elevation
    within 1e-9 rad, where the launch angle is up to a degree off it."""
    nodes, speeds = profile_arrays(profile_table("ctd:NCL1", "", 15.0, 35.0))
    solve = eigenray_families()
    rng = np.random.default_rng(5)
    worst, bent = 0.0, 0.0
    for _ in range(30):
        zt, zr, x = rng.uniform(0, 10), rng.uniform(50, 1200), rng.uniform(1, 1000)
        tau, launch, _arrival, valid = (np.asarray(v).ravel() for v in solve(zt, zr, x, 0.0, nodes, speeds))
        assert valid[0]
        bending = float(ray_bending(zt, zr, np.hypot(x, zr - zt), nodes, speeds)[0])
        worst = max(worst, abs(launch[0] + bending - np.arctan2(zr - zt, x)))
        bent = max(bent, abs(launch[0] - np.arctan2(zr - zt, x)))
    assert worst < 1e-9 and bent > np.radians(0.5)


def test_the_usbl_elevation_is_the_eigenrays_in_ray_mode():
    """Without angle and attitude noise the USBL's measured elevation is the grazing angle of the reply's eigenray
    at the transceiver (−arrival_angle), not the chord's: through Munk 300 m deep and 200 m off they differ."""
    quiet = ["platform.system=usbl", "platform.usbl_angle_sigma_deg=0", "platform.imu_sigma_deg=0",
             "target.depth=300", "target.radius=200", "simulation.sampling_time=0.5", "simulation.duration=20"]
    for propagation in ("ray", "straight"):
        cfg = load_config("random-walk", quiet + [f"acoustics.propagation={propagation}",
                                                  "acoustics.sound_speed_profile=munk"], seed=3)
        ts = run(cfg, "local", replicates=[0]).timeseries
        got = ts[ts["packet_valid"] > 0]
        assert len(got) > 20
        np.testing.assert_allclose(got["elevation"], -got["arrival_angle"], rtol=0, atol=1e-9)
        bend = (got["launch_angle"] - got["arrival_angle"]).abs()
        assert (bend.min() > 1e-3) if propagation == "ray" else (bend.max() == 0.0)


def test_acoustics_gives_the_receiver_the_channels_table():
    plan = make_plan(load_config("random-walk", ["acoustics.sound_speed_profile=ctd:NCL1",
                                                 "receiver.sound_speed_profile=acoustics",
                                                 "acoustics.sound_speed_assumed=1490"]))
    params = plan.component_parameters("receiver")
    assert params["sound_speed_model"] == "profile" and params["sound_speed_assumed"] == 1490.0
    np.testing.assert_array_equal(PROFILE.rows(params, "sound_speed_rows"),
                                  PROFILE.rows(plan.component_parameters("acoustics"), "sound_speed_rows"))
    munk = make_plan(load_config("random-walk", ["receiver.sound_speed_profile=munk"]))
    assert munk.component_parameters("receiver")["sound_speed_rows"] == 256
    default = make_plan(load_config("random-walk")).component_parameters("receiver")
    assert default["sound_speed_model"] == "assumed" and default["sound_speed_rows"] == 0
    # a constant channel: one row at its true speed
    const = make_plan(load_config("random-walk", ["receiver.sound_speed_profile=acoustics",
                                                  "acoustics.sound_speed_true=1510"]))
    np.testing.assert_array_equal(PROFILE.rows(const.component_parameters("receiver"), "sound_speed_rows"),
                                  [[0.0, 1510.0]])


@pytest.mark.parametrize("value, message", [
    ("ctd:NOPE", "receiver.sound_speed_profile: unknown cast 'NOPE'"),
    ("constant", "receiver.sound_speed_profile: 'constant' is not a receiver's profile; one of assumed,"),
    ("no-such-cast.csv", ("receiver.sound_speed_profile: no such file '", "no-such-cast.csv'; use assumed,")),
    ("table", "receiver.sound_speed_table: sound_speed_profile = table needs rows"),
])
def test_a_bad_profile_is_refused_in_one_line(value, message, tmp_path, capsys):
    out = tmp_path / "out"
    code = main(["run", "random-walk", "--set", "simulation.duration=1", "--set",
                 f"receiver.sound_speed_profile={value}", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and not out.exists()
    needles = message if isinstance(message, tuple) else (message,)  # a relative path is made absolute
    assert len(err.splitlines()) == 1 and all(needle in err for needle in needles), err


@pytest.mark.slow
def test_a_profile_receiver_reaches_its_pcrb_at_a_1000_m_site_where_the_assumed_speed_is_biased():
    """With the single assumed speed ekf-seq is tens of metres off (NEES in the thousands); with the true profile
    its NEES is in [1.5, 4.5] and its RMS error that of the same receiver in isovelocity water at the assumed
    speed (no sound-speed error at all: the straight line at 1500 m/s), within 10 %: the PCRB's ratio of this
    receiver at this geometry (about 1.47 over 12 replicates of 50 s, its own: 1.46 without any sound-speed error,
    over the steps with an estimate; 1.55 and 1.54 over 100 s; 1.2-1.3 when the steps before the first fix counted,
    reporting the truth under the prior's bound). Measured at 50 s: NEES 3.0 (7,600 with the single assumed speed),
    the RMS error 0.7 % above the isovelocity run's."""
    def metrics(*more):
        cfg = load_config("random-walk", [*SITE, *more], seed=1)
        return run_batch(with_replicates(cfg, range(12)), "local", timeseries=False).metrics

    def rms(m):
        return float(np.sqrt(np.mean(m["e_tot_rms"] ** 2)))

    straight, aware = metrics(), metrics("receiver.sound_speed_profile=acoustics")
    isovelocity = metrics("acoustics.propagation=straight", "acoustics.sound_speed_profile=constant")
    np.testing.assert_array_equal(straight["pcrb_rms"], aware["pcrb_rms"])  # the same bound
    pcrb = float(np.sqrt(np.mean(aware["pcrb_rms"] ** 2)))
    assert rms(straight) > 10.0 * pcrb and float(straight["nees_mean"].mean()) > 100.0
    nees = float(aware["nees_mean"].mean())
    assert 1.5 <= nees <= 4.5, nees
    assert rms(aware) == pytest.approx(rms(isovelocity), rel=0.10), (rms(aware), rms(isovelocity))
    assert rms(aware) <= 1.75 * pcrb, (rms(aware), pcrb)


@pytest.mark.slow
def test_the_budget_names_the_profile_error():
    assert "profile error" in SOURCES["profile_error"][0]
    short = ["simulation.duration=10"]
    plain = budget(load_config("random-walk", short), 2)  # the single assumed speed: off (its switch is no change)
    assert plain.table.set_index("source").loc["profile_error", "status"] == OFF
    wrong = load_config("random-walk", [*SITE, "simulation.duration=10", "acoustics.sound_speed_profile=ctd:NCL1",
                                        "receiver.sound_speed_profile=munk"])
    b = budget(wrong, 4)
    row = b.table.set_index("source").loc["profile_error"]
    assert row["status"] == ON and row["contribution"] > 10.0 * row["se"] > 0  # seen 15 standard errors (29 over 20 s)
    right = load_config("random-walk", [*short, "receiver.sound_speed_profile=acoustics"])
    off = budget(right, 2)
    assert off.table.set_index("source").loc["profile_error", "status"] == OFF


@pytest.mark.slow
def test_the_embedded_receiver_with_a_profile_reproduces_the_recorded_estimate(tmp_path):
    from sblsim.fmus.compiler import find_compiler
    from sblsim.fmus.embedded import write_receiver

    cfg = load_config("random-walk", [*SITE[1:], "simulation.duration=20", "receiver.sound_speed_profile=acoustics",
                                      "simulation.receiver=ekf-seq"], seed=2)
    series = run(cfg).timeseries
    model = MODELS[RECEIVERS["ekf-seq"]]
    plan = make_plan(cfg)
    n = plan.n_beacons
    params = plan.component_parameters("receiver")
    declared = {v.name: v for v in model.fmu_parameters_declared(n)}
    args = []
    for k, v in params.items():
        if k in declared:
            v = declared[k].choices.index(v) if declared[k].choices is not None else v
            args.append(f"{k}={float(v)!r}")
    out = tmp_path / "receiver_c"
    write_receiver("ekf-seq", out, n)
    exe = out / "receiver"
    cc = find_compiler("system")
    subprocess.run([*cc.command, "-O2", "-std=c99", "-ffp-contract=off", "-Wall", "-Werror",
                    *map(str, sorted(out.glob("*.c"))), "-lm", "-o", str(exe)], check=True, capture_output=True)
    T = cfg["simulation"]["sampling_time"]
    inputs = [v.name for v in model.inputs(n)]
    lines = [" ".join(repr(float(x)) for x in [k * T, T, *(getattr(row, n, 0.0) for n in inputs)])
             for k, row in enumerate(series.itertuples(index=False))]
    done = subprocess.run([str(exe), *args], input="\n".join(lines) + "\n", capture_output=True, text=True, env={},
                          timeout=300)
    assert done.returncode == 0, done.stderr
    printed = np.array([[float(x) for x in line.split()] for line in done.stdout.splitlines()])
    np.testing.assert_allclose(printed[:, 1:], series[["est_x", "est_y", "est_z"]].to_numpy(), rtol=0, atol=1e-9)
    # the profile did something: the same run with the single assumed speed estimates elsewhere
    plain = run(load_config("random-walk", [*SITE[1:], "simulation.duration=20", "simulation.receiver=ekf-seq"],
                            seed=2)).timeseries
    # (over the steps where both have an estimate: neither has one before its first fix)
    assert np.nanmax(np.abs(plain["est_x"].to_numpy() - series["est_x"].to_numpy())) > 1.0

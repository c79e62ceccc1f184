"""Tests of the target: trajectories, trajectory files and the sampled depth sensor.

References are independent: circle/square geometry worked by hand, the spiral's
arc length integrated as an ODE by scipy, finite differences of positions for
speeds, np.interp for file paths, a numpy rebuild of the random path and of the
depth noise from the Philox reference streams (``sblsim.models.philox.uniforms`` /
``normals``), and chi-square / Fisher-z intervals for the noise statistics.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.integrate import solve_ivp

from sblsim.models.declarations import ModelError
from sblsim.models.philox import normals, uniforms
from sblsim.models.table_text import parse_table
from sblsim.models.target import Target, natural_duration, start_state
from sblsim.models.target.core import MAX_WAYPOINTS, WAYPOINTS
from sblsim.models.target.trajectories import OPEN_DURATION, read_trajectory_file
from tests.helpers import Core

CONF = 0.999
COMPONENT = 2  # the target's component index in the seed tree
DEPTH_NOISE, RANDOM_PATH = 0, 1  # stream purposes (sblsim.models.philox docstring, "Randomness")


def run(params, times, replicates=(0,)):
    """Positions and velocities (len(times), B, 3) and depth readings (len(times), B) at the host times."""
    core = Core(Target, params, replicates=list(replicates)).initialize(times[0])
    pos, vel, dep = [], [], []
    for k, t in enumerate(times):
        if k > 0:
            core.step(times[k - 1], t - times[k - 1])
        o = core.outputs
        pos.append(np.column_stack([o["pos_x"], o["pos_y"], o["pos_z"]]))
        vel.append(np.column_stack([o["vel_x"], o["vel_y"], o["vel_z"]]))
        dep.append(o["depth_measured"])
    return np.array(pos), np.array(vel), np.array(dep)


def fd_speed(pos, times):
    return np.linalg.norm(np.diff(pos, axis=0), axis=-1) / np.diff(times)[:, None]


# ----------------------------------------------------------------------------
# Semicircle
# ----------------------------------------------------------------------------

def test_semicircle_geometry_speed_and_duration():
    r, v, depth = 12.0, 0.8, 4.0
    params = dict(trajectory="semicircle", radius=r, speed=v, depth=depth, depth_sigma=0.0)
    duration = natural_duration(params)
    assert duration == pytest.approx(math.pi * r / v, rel=1e-15)
    times = np.linspace(0.0, duration, 401)
    pos, vel, dep = run(params, times)
    np.testing.assert_allclose(np.linalg.norm(pos[:, 0, :2], axis=1), r, rtol=1e-12)
    np.testing.assert_allclose(pos[:, 0, 2], depth)
    np.testing.assert_array_equal(dep[:, 0], depth)       # depth_sigma = 0: the reading is the depth
    # from (0, -r) through (r, 0) to (0, r)
    np.testing.assert_allclose(pos[0, 0], [0.0, -r, depth], atol=1e-12)
    np.testing.assert_allclose(pos[200, 0], [r, 0.0, depth], atol=1e-9)
    np.testing.assert_allclose(pos[-1, 0], [0.0, r, depth], atol=1e-9)
    # angle grows linearly: θ(t) = -π/2 + v t / r
    theta = np.arctan2(pos[:, 0, 1], pos[:, 0, 0])
    np.testing.assert_allclose(theta, -0.5 * np.pi + v * times / r, atol=1e-12)
    # speed: chord / dt = 2 r sin(v dt / 2r) / dt
    dt = times[1] - times[0]
    np.testing.assert_allclose(fd_speed(pos[:, 0], times), 2 * r * np.sin(v * dt / (2 * r)) / dt, rtol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(vel[:-1, 0], axis=1), v, rtol=1e-12)
    # velocity output equals the central difference of positions
    central = (pos[2:, 0] - pos[:-2, 0]) / (2 * dt)
    np.testing.assert_allclose(vel[1:-1, 0], central, atol=v * (v * dt / r) ** 2)
    # tangent to the circle
    np.testing.assert_allclose(np.sum(vel[:-1, 0, :2] * pos[:-1, 0, :2], axis=1), 0.0, atol=1e-12)


def test_semicircle_holds_end_point_after_duration():
    r, v = 5.0, 0.5
    params = dict(trajectory="semicircle", radius=r, speed=v, depth=3.0, depth_sigma=0.0)
    d = math.pi * r / v
    pos, vel, _ = run(params, np.array([0.0, d + 1.0, d + 20.0]))
    np.testing.assert_allclose(pos[1:, 0], [[0.0, r, 3.0]] * 2, atol=1e-12)
    np.testing.assert_array_equal(vel[1:, 0], 0.0)


# ----------------------------------------------------------------------------
# Spiral
# ----------------------------------------------------------------------------

def spiral_reference(times, r0, pitch, v):
    """Position and velocity on ρ = ρ0 + kθ at speed v: dθ/dt = v / sqrt(ρ² + k²), integrated by scipy."""
    k = pitch / (2 * np.pi)
    sol = solve_ivp(lambda t, th: v / np.sqrt((r0 + k * th) ** 2 + k * k), (times[0], times[-1]), [0.0],
                    t_eval=times, rtol=1e-12, atol=1e-12, method="DOP853")
    th = sol.y[0]
    rho = r0 + k * th
    pos = np.column_stack([rho * np.cos(th), rho * np.sin(th)])
    tangent = np.column_stack([k * np.cos(th) - rho * np.sin(th), k * np.sin(th) + rho * np.cos(th)])
    return pos, v * tangent / np.linalg.norm(tangent, axis=1)[:, None]


@pytest.mark.parametrize("r0", [0.0, 2.0])
def test_spiral_follows_the_arc_length_ode(r0):
    pitch, v = 5.0, 0.6
    params = dict(trajectory="spiral", spiral_start_radius=r0, spiral_pitch=pitch, speed=v, depth=6.0,
                  depth_sigma=0.0)
    times = np.linspace(0.0, OPEN_DURATION, 401)
    pos, vel, _ = run(params, times)
    ref_pos, ref_vel = spiral_reference(times, r0, pitch, v)
    np.testing.assert_allclose(pos[:, 0, :2], ref_pos, atol=1e-8)
    np.testing.assert_allclose(vel[:, 0, :2], ref_vel, atol=1e-8)
    np.testing.assert_array_equal(pos[:, 0, 2], 6.0)
    np.testing.assert_array_equal(vel[:, 0, 2], 0.0)


def test_spiral_radius_grows_and_speed_is_constant():
    r0, pitch, v = 2.0, 5.0, 0.6
    params = dict(trajectory="spiral", spiral_start_radius=r0, spiral_pitch=pitch, speed=v, depth=6.0,
                  depth_sigma=0.0)
    assert natural_duration(params) == OPEN_DURATION
    times = np.linspace(0.0, OPEN_DURATION, 2001)   # dt = 0.05 s
    pos, vel, _ = run(params, times)
    rho = np.linalg.norm(pos[:, 0, :2], axis=1)
    assert rho[0] == pytest.approx(r0, abs=1e-9)
    assert np.all(np.diff(rho) > 0)
    # Archimedean: ρ = ρ0 + (pitch / 2π) θ with the unwrapped polar angle
    theta = np.unwrap(np.arctan2(pos[:, 0, 1], pos[:, 0, 0]))
    np.testing.assert_allclose(rho, r0 + pitch / (2 * np.pi) * (theta - theta[0]), atol=1e-6)
    # constant speed along the path
    np.testing.assert_allclose(fd_speed(pos[:, 0], times), v, rtol=2e-3)
    np.testing.assert_allclose(np.linalg.norm(vel[:, 0], axis=1), v, rtol=1e-12)
    # total length swum = v t
    length = np.sum(np.linalg.norm(np.diff(pos[:, 0], axis=0), axis=1))
    assert length == pytest.approx(v * OPEN_DURATION, rel=1e-4)
    # velocity output equals the central difference of positions
    dt = times[1] - times[0]
    np.testing.assert_allclose(vel[1:-1, 0], (pos[2:, 0] - pos[:-2, 0]) / (2 * dt), atol=2e-3 * v)


# ----------------------------------------------------------------------------
# Square
# ----------------------------------------------------------------------------

def test_square_corners_and_duration():
    s, v, depth = 10.0, 0.5, 2.0
    params = dict(trajectory="square", square_side=s, speed=v, depth=depth, depth_sigma=0.0)
    leg = s / v
    assert natural_duration(params) == pytest.approx(4 * leg)
    h = s / 2
    corners = np.array([[-h, -h], [h, -h], [h, h], [-h, h], [-h, -h]])
    pos, vel, _ = run(params, leg * np.arange(5.0))
    np.testing.assert_allclose(pos[:, 0, :2], corners, atol=1e-12)
    np.testing.assert_allclose(pos[:, 0, 2], depth)
    # mid-leg: halfway between corners, moving N, E, S, W at speed v
    pos, vel, _ = run(params, leg * (np.arange(4.0) + 0.5))
    np.testing.assert_allclose(pos[:, 0, :2], 0.5 * (corners[:-1] + corners[1:]), atol=1e-12)
    np.testing.assert_allclose(vel[:, 0], [[v, 0, 0], [0, v, 0], [-v, 0, 0], [0, -v, 0]], atol=1e-12)
    # after the lap: holds the start corner
    pos, vel, _ = run(params, np.array([0.0, 4 * leg + 3.0]))
    np.testing.assert_allclose(pos[1, 0, :2], [-h, -h])
    np.testing.assert_array_equal(vel[1, 0], 0.0)


# ----------------------------------------------------------------------------
# Random path
# ----------------------------------------------------------------------------

RANDOM = dict(trajectory="random", radius=10.0, max_radius=14.0, speed=1.0, turn_interval=4.0, depth=5.0,
              depth_sigma=0.0, seed=31, scenario_key=2, cell=5)


def random_legs(q, replicate, n_legs):
    """Starts and unit directions (n_legs, 2) of the random path, rebuilt from the reference uniforms.

    Leg j: heading 2π u₀; if that leg would end outside the disc of radius
    max_radius, the bearing to the centre plus (2π/3)(u₁ − ½) instead.
    """
    keys = (q["seed"], q["scenario_key"], q["cell"], replicate)
    leg = q["speed"] * q["turn_interval"]
    start = np.array([q["radius"], 0.0])
    starts, dirs = [], []
    for j in range(n_legs):
        u = uniforms(*keys, COMPONENT, RANDOM_PATH, j, 2)
        heading = 2 * np.pi * u[0]
        if np.linalg.norm(start + leg * np.array([np.cos(heading), np.sin(heading)])) > q["max_radius"]:
            heading = math.atan2(-start[1], -start[0]) + (2 * np.pi / 3) * (u[1] - 0.5)
        d = np.array([np.cos(heading), np.sin(heading)])
        starts.append(start)
        dirs.append(d)
        start = start + leg * d
    return np.array(starts), np.array(dirs)


def random_reference(q, replicate, t0, times):
    """Positions (len(times), 3) and velocities of the rebuilt random path; turns at t0 + j T."""
    T, v = q["turn_interval"], q["speed"]
    j = np.floor((np.asarray(times) - t0) / T + 1e-9).astype(int)
    starts, dirs = random_legs(q, replicate, int(j.max()) + 1)
    pos = starts[j] + v * (times - t0 - j * T)[:, None] * dirs[j]
    depth = np.full((len(times), 1), q["depth"])
    return np.hstack([pos, depth]), np.hstack([v * dirs[j], np.zeros_like(depth)])


@pytest.mark.parametrize("t0,h", [(0.0, 0.5), (3.0, 0.7), (3.0, 9.0)])
def test_random_path_matches_the_rebuilt_legs(t0, h):
    """Positions and velocities against the numpy rebuild, from t0 (turns at t0 + j T), with host steps
    shorter than a leg and steps spanning two turns."""
    replicates = [0, 3, 11]
    times = t0 + h * np.arange(int(200.0 / h) + 1)
    pos, vel, _ = run(RANDOM, times, replicates=replicates)
    for b, r in enumerate(replicates):
        ref_pos, ref_vel = random_reference(RANDOM, r, t0, times)
        np.testing.assert_allclose(pos[:, b], ref_pos, atol=1e-9, err_msg=f"replicate {r}")
        np.testing.assert_allclose(vel[:, b], ref_vel, atol=1e-12, err_msg=f"replicate {r}")


def test_random_path_state_blocks_and_turn_instants():
    core = Core(Target, RANDOM, replicates=[0, 1]).initialize(0.0)
    T = RANDOM["turn_interval"]
    for j in range(1, 6):
        core.step((j - 1) * T, T)  # ends exactly on turn j
        np.testing.assert_array_equal(core.state["leg"][:, 0], [j, j])
        for b in range(2):
            starts, dirs = random_legs(RANDOM, b, j + 1)
            np.testing.assert_allclose(core.state["start"][b], starts[j], atol=1e-12)
            np.testing.assert_allclose(core.state["direction"][b], dirs[j], atol=1e-15)
            # at a turn instant the diver is at the start of the new leg
            np.testing.assert_allclose([core.outputs["pos_x"][b], core.outputs["pos_y"][b]], starts[j], atol=1e-12)


def test_random_path_stays_in_disc_with_constant_speed_legs():
    """Properties of the compiled path itself, read at the turn instants (its waypoints)."""
    B, T, leg = 30, RANDOM["turn_interval"], RANDOM["speed"] * RANDOM["turn_interval"]
    times = np.arange(0.0, 1000.0 + T / 2, T)          # 250 legs
    pos, vel, _ = run(RANDOM, times, replicates=range(B))
    pts = np.transpose(pos, (1, 0, 2))                  # (B, legs + 1, 3)
    np.testing.assert_allclose(pts[:, 0], np.tile([RANDOM["radius"], 0.0, RANDOM["depth"]], (B, 1)))
    # every leg has length v * interval
    np.testing.assert_allclose(np.linalg.norm(np.diff(pts, axis=1), axis=-1), leg, rtol=1e-12)
    # never farther than max_radius + one leg
    radius = np.linalg.norm(pts[:, :, :2], axis=-1)
    assert radius.max() <= RANDOM["max_radius"] + leg + 1e-9
    # a leg either ends inside the disc, or heads within ±60° of the bearing to the centre
    start, step = pts[:, :-1, :2], np.diff(pts[:, :, :2], axis=1)
    cosang = np.sum(-start * step, axis=-1) / (np.linalg.norm(start, axis=-1) * leg)
    inside = np.linalg.norm(start + step, axis=-1) <= RANDOM["max_radius"] + 1e-9
    assert np.all(inside | (cosang >= math.cos(math.radians(60.0)) - 1e-9))
    # a leg takes its uniform heading 2π u₀ unless that leg would leave the disc; then it heads home (±60°)
    keys = (RANDOM["seed"], RANDOM["scenario_key"], RANDOM["cell"])
    u0 = np.array([[uniforms(*keys, b, COMPONENT, RANDOM_PATH, j, 2)[0] for j in range(start.shape[1])]
                   for b in range(B)])
    free = np.stack([np.cos(2 * np.pi * u0), np.sin(2 * np.pi * u0)], axis=-1)
    homed = np.linalg.norm(step / leg - free, axis=-1) > 1e-9
    leaves = np.linalg.norm(start + leg * free, axis=-1) > RANDOM["max_radius"]
    np.testing.assert_array_equal(homed, leaves)
    assert np.all(cosang[homed] >= math.cos(math.radians(60.0)) - 1e-9)
    assert homed.mean() > 0.05  # the homing rule was exercised
    # the walk does reach the edge of the disc (unconstrained, 250 legs would wander ~60 m away)
    assert radius.max() > RANDOM["max_radius"] - 0.5 * leg
    assert np.mean(radius > RANDOM["max_radius"] - leg) > 0.05
    # speed v on legs; finite differences inside a leg agree
    times = np.arange(0.0, 80.0, 0.5) + 0.25
    pos, vel, _ = run(RANDOM, times, replicates=range(B))
    np.testing.assert_allclose(np.linalg.norm(vel, axis=-1), RANDOM["speed"], rtol=1e-12)
    same_leg = np.floor(times[1:] / T) == np.floor(times[:-1] / T)
    np.testing.assert_allclose(fd_speed(pos, times)[same_leg], RANDOM["speed"], rtol=1e-9)


def test_random_first_heading_is_uniform():
    """Inside a large disc the first heading is 2π u₀: uniform on [0, 2π) (KS test), and exactly the stream."""
    q = dict(RANDOM, max_radius=1000.0)
    B = 2000
    core = Core(Target, q, replicates=range(B)).initialize(0.0)
    headings = np.mod(np.arctan2(core.outputs["vel_y"], core.outputs["vel_x"]), 2 * np.pi)
    assert stats.kstest(headings / (2 * np.pi), "uniform").pvalue > 1 - CONF
    for r in (0, 7, 1999):
        u0 = uniforms(q["seed"], q["scenario_key"], q["cell"], r, COMPONENT, RANDOM_PATH, 0, 2)[0]
        assert headings[r] == pytest.approx(2 * np.pi * u0, abs=1e-12)


def test_random_path_replicates_differ_and_are_reproducible():
    times = np.array([0.0, 10.0, 30.0, 50.0])
    pos_batch, _, _ = run(RANDOM, times, replicates=range(6))
    pos_alone, _, _ = run(RANDOM, times, replicates=[4])
    np.testing.assert_array_equal(pos_alone[:, 0], pos_batch[:, 4])
    pos_again, _, _ = run(RANDOM, times, replicates=[4])
    np.testing.assert_array_equal(pos_again, pos_alone)
    # all replicates start at (r, 0) and then differ
    np.testing.assert_array_equal(pos_batch[0], np.tile([10.0, 0.0, 5.0], (6, 1)))
    at50 = pos_batch[-1]
    dists = np.linalg.norm(at50[:, None, :] - at50[None, :, :], axis=-1)
    assert np.all(dists[~np.eye(6, dtype=bool)] > 1e-6)
    # another seed gives another path
    pos_other, _, _ = run(dict(RANDOM, seed=32), times, replicates=[4])
    assert np.linalg.norm(pos_other[-1, 0] - pos_alone[-1, 0]) > 1e-6
    # start_state is the deterministic start; the random first heading is reported as zero velocity
    p0, v0 = start_state(RANDOM)
    np.testing.assert_array_equal(p0, [10.0, 0.0, 5.0])
    np.testing.assert_array_equal(v0, 0.0)


# ----------------------------------------------------------------------------
# Trajectory file
# ----------------------------------------------------------------------------

TRACK = np.array([
    [0.0, 0.0, 0.0, 2.0],
    [10.0, 5.0, 0.0, 3.0],
    [15.0, 5.0, 4.0, 3.0],
    [30.0, -1.0, 4.0, 1.5],
])


def write_track(path, rows, header="time,N,E,D"):
    lines = ([header] if header else []) + [",".join(repr(float(x)) for x in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _track_reference(times):
    pos = np.column_stack([np.interp(times, TRACK[:, 0], TRACK[:, k]) for k in (1, 2, 3)])
    slopes = np.diff(TRACK[:, 1:], axis=0) / np.diff(TRACK[:, 0])[:, None]
    seg = np.clip(np.searchsorted(TRACK[:, 0], times, side="right") - 1, 0, len(TRACK) - 2)
    inside = (times >= TRACK[0, 0]) & (times < TRACK[-1, 0])
    return pos, np.where(inside[:, None], slopes[seg], 0.0), slopes


@pytest.mark.parametrize("source", ["header", "no header", "waypoints text"])
def test_trajectory_file_linear_interpolation(tmp_path, source):
    if source == "waypoints text":
        params = dict(trajectory="file", waypoints="; ".join(" ".join(repr(float(x)) for x in r) for r in TRACK))
    else:
        f = write_track(tmp_path / "track.csv", TRACK, "time,N,E,D" if source == "header" else None)
        params = dict(trajectory="file", trajectory_file=str(f))
    params["depth_sigma"] = 0.0
    assert natural_duration(params) == 30.0
    times = np.array([0.0, 2.5, 9.9, 10.0, 12.0, 14.5, 22.0, 29.0, 30.0, 35.0])
    pos, vel, _ = run(params, times)
    ref_pos, ref_vel, slopes = _track_reference(times)
    np.testing.assert_allclose(pos[:, 0], ref_pos, atol=1e-12)
    # velocity = slope of the current segment (at a waypoint, the one starting there; zero once it ends)
    np.testing.assert_allclose(vel[:, 0], ref_vel, atol=1e-12)
    p0, v0 = start_state(params)
    np.testing.assert_allclose(p0, TRACK[0, 1:])
    np.testing.assert_allclose(v0, slopes[0])


def test_trajectory_file_holds_before_the_first_waypoint(tmp_path):
    rows = TRACK + [5.0, 0.0, 0.0, 0.0]  # the track starts at t = 5 s
    f = write_track(tmp_path / "late.csv", rows)
    times = np.array([0.0, 2.0, 5.0, 7.5, 40.0])
    pos, vel, _ = run(dict(trajectory="file", trajectory_file=str(f), depth_sigma=0.0), times)
    ref = np.column_stack([np.interp(times, rows[:, 0], rows[:, k]) for k in (1, 2, 3)])
    np.testing.assert_allclose(pos[:, 0], ref, atol=1e-12)
    np.testing.assert_array_equal(vel[:2, 0], 0.0)
    np.testing.assert_array_equal(vel[-1, 0], 0.0)


def test_waypoint_table_round_trips_through_fmu_parameters(tmp_path):
    f = write_track(tmp_path / "track.csv", TRACK)
    values = Target.fmu_parameters(dict(trajectory="file", trajectory_file=str(f)))
    assert values["waypoint_rows"] == len(TRACK)
    np.testing.assert_array_equal([values[f"waypoint_north[{k + 1}]"] for k in range(len(TRACK))], TRACK[:, 1])
    index = next(v for v in Target.fmu_parameters_declared() if v.name == "trajectory").choices.index("file")
    config = Target.config_values(dict(values, trajectory=index))  # as an FMU holds it: the choice's index
    assert config["trajectory"] == "file"
    np.testing.assert_array_equal(parse_table(config["waypoints"], WAYPOINTS, "w"), TRACK)


@pytest.mark.parametrize("first_row,label", [
    ("0,1e1,0,5", "unsigned exponent"),
    ("0,1E-3,0,5", "upper-case exponent"),
])
def test_trajectory_file_without_header_keeps_first_row_in_scientific_notation(tmp_path, first_row, label):
    """A headerless file whose first row uses exponent notation is all data (no row lost)."""
    f = tmp_path / "sci.csv"
    f.write_text(first_row + "\n10,20,0,5\n20,30,0,5\n")
    w = read_trajectory_file(f, WAYPOINTS)
    first = [float(x) for x in first_row.split(",")]
    np.testing.assert_array_equal(w[:, 0], [0.0, 10.0, 20.0], err_msg=label)
    np.testing.assert_array_equal(w[0], first, err_msg=label)


def test_trajectory_file_comment_lines_keep_every_data_row(tmp_path):
    """'#' comment lines (before the header and between rows) are skipped; no data row is lost."""
    f = tmp_path / "commented.csv"
    f.write_text("# diver track, NED metres\ntime,N,E,D\n0,10,0,5\n# pause\n10,20,0,5\n20,30,0,5\n")
    w = read_trajectory_file(f, WAYPOINTS)
    np.testing.assert_array_equal(w, [[0, 10, 0, 5], [10, 20, 0, 5], [20, 30, 0, 5]])
    g = tmp_path / "commented_no_header.csv"
    g.write_text("# track\n0,10,0,5\n10,20,0,5\n")
    np.testing.assert_array_equal(read_trajectory_file(g, WAYPOINTS), [[0, 10, 0, 5], [10, 20, 0, 5]])


@pytest.mark.parametrize("content,where", [
    ("time,N,E,D\n0,0,0\n10,1,1\n", r"line 2 has 3 columns"),                     # 3 columns
    ("time,N,E\n0,0,0\n10,1,1\n", r"line 1 \(3 fields, no number\) is neither numbers nor a header"),  # 3 names
    ("a,b,c,d\n0,0,0,5\n10,1,1,5\n", r"line 1 \(4 fields, no number\) is neither numbers nor a header"),  # names
    ("0,0,0\n10,1,1\n", r"line 1 has 3 columns"),                                 # 3 columns, no header
    ("time,N,E,D\n0,0,0,1\n10,abc,0,1\n", r"line 3, column waypoint_north: 'abc' is not a number"),
    ("time,N,E,D\n0,0,0,1\n10,1,0,-1\n", r"line 3, column waypoint_down: -1 is outside the allowed range \[0, "),
    ("time,N,E,D\n0,0,0,1\n10,nan,0,1\n", r"line 3, column waypoint_north: nan is not finite"),
    ("time,N,E,D\n0,0,0,1\n10,1,inf,1\n", r"line 3, column waypoint_east: inf is not finite"),
    ("time,N,E,1\n0,0,0,1\n10,1,0,1\n", r"line 1, column waypoint_time: 'time' is not a number"),  # not a header
    ("time,N,E,D\n0,0,0,1\n10,1,0,1\n5,2,0,1\n", r"line 4, column waypoint_time: must be greater than the line before"),
    ("time,N,E,D\n0,0,0,1\n0,1,0,1\n", r"line 3, column waypoint_time: must be greater than the line before"),
    ("time,N,E,D\n0,0,0,1\n", r"at least 2 rows"),                               # one row
    ("", r"at least 2 rows"),                                                     # empty file
    ("# only a comment\ntime,N,E,D\n", r"at least 2 rows"),
])
def test_trajectory_file_malformed_raises_model_error(tmp_path, content, where):
    f = tmp_path / "bad.csv"
    f.write_text(content)
    with pytest.raises(ModelError, match=r"^target\.trajectory_file: .*" + where):
        read_trajectory_file(f, WAYPOINTS)
    with pytest.raises(ModelError, match=r"^target\.trajectory_file: .*" + where):
        Core(Target, dict(trajectory="file", trajectory_file=str(f)))


def test_a_file_that_is_not_a_trajectory_is_not_echoed(tmp_path):
    """A path a configuration names may be any file (a password file): the error names it, not its text."""
    f = tmp_path / "shadow"
    f.write_text("root:$6$secrethash:19000:0:99999:7:::\nbin:*:19000:0:99999:7:::\n")
    with pytest.raises(ModelError) as error:
        read_trajectory_file(f, WAYPOINTS)
    assert "secrethash" not in str(error.value) and "99999" not in str(error.value)
    assert str(error.value).startswith(f"target.trajectory_file: {str(f)!r} line 1 (1 fields, no number)")


def test_trajectory_file_time_order_error_names_the_file_line(tmp_path):
    f = tmp_path / "bad.csv"
    f.write_text("time,N,E,D\n# comment\n0,0,0,1\n10,1,0,1\n5,2,0,1\n")
    with pytest.raises(ModelError, match=r"line 5"):
        read_trajectory_file(f, WAYPOINTS)


def test_trajectory_file_empty_path_is_not_called_a_directory():
    with pytest.raises(ModelError, match=r"no such file"):
        read_trajectory_file("", WAYPOINTS)


def test_trajectory_file_with_too_many_rows(tmp_path):
    rows = np.column_stack([np.arange(MAX_WAYPOINTS + 1.0), np.zeros((MAX_WAYPOINTS + 1, 2)),
                            np.ones(MAX_WAYPOINTS + 1)])
    with pytest.raises(ModelError, match=rf"^target\.trajectory_file: .* {MAX_WAYPOINTS + 1} rows; "
                                         rf"at most {MAX_WAYPOINTS}"):
        read_trajectory_file(write_track(tmp_path / "long.csv", rows), WAYPOINTS)
    ok = read_trajectory_file(write_track(tmp_path / "full.csv", rows[:-1]), WAYPOINTS)
    np.testing.assert_array_equal(ok, rows[:-1])
    # the full table runs: the last waypoint of 512 is reached
    pos, _, _ = run(dict(trajectory="file", trajectory_file=str(tmp_path / "full.csv"), depth_sigma=0.0),
                    np.array([0.0, 255.5, MAX_WAYPOINTS - 1.0]))
    np.testing.assert_allclose(pos[:, 0, 2], 1.0)


@pytest.mark.parametrize("name,message", [("does_not_exist.csv", "no such file"), ("", ""),
                                          (".", "is a directory")])
def test_trajectory_file_missing_raises_model_error(tmp_path, name, message):
    path = "" if not name else str(tmp_path / name)
    with pytest.raises(ModelError, match=rf"^target\.trajectory_file: .*{message}"):
        read_trajectory_file(path, WAYPOINTS)
    if path:
        with pytest.raises(ModelError, match=rf"^target\.trajectory_file: .*{message}"):
            Core(Target, dict(trajectory="file", trajectory_file=path))
    # neither a file nor waypoint text
    with pytest.raises(ModelError, match=r"^target\.trajectory_file: trajectory = file needs"):
        Core(Target, dict(trajectory="file"))


def test_waypoints_text_errors_name_row_and_column():
    with pytest.raises(ModelError, match=r"^target\.waypoints: row 2, column waypoint_north: 'x' is not a number"):
        Core(Target, dict(trajectory="file", waypoints="0 0 0 1; 10 x 0 1"))
    with pytest.raises(ModelError, match=r"^target\.waypoints: row 2, column waypoint_time: must be greater"):
        Core(Target, dict(trajectory="file", waypoints="0 0 0 1; 0 1 0 1"))


def test_natural_duration_of_every_trajectory(tmp_path):
    assert natural_duration(dict(trajectory="semicircle", radius=7.0, speed=0.35)) == pytest.approx(
        math.pi * 7.0 / 0.35, rel=1e-15)
    assert natural_duration(dict(trajectory="square", square_side=6.0, speed=0.4)) == pytest.approx(60.0, rel=1e-15)
    assert natural_duration(dict(trajectory="spiral")) == OPEN_DURATION
    assert natural_duration(dict(trajectory="random")) == OPEN_DURATION
    f = write_track(tmp_path / "t.csv", TRACK * [1.5, 1, 1, 1])
    assert natural_duration(dict(trajectory="file", trajectory_file=str(f))) == 45.0


# ----------------------------------------------------------------------------
# Depth sensor
# ----------------------------------------------------------------------------

def test_depth_sensor_noise_is_the_reference_stream_with_std_sigma():
    sigma, seed, B = 0.05, 12, 3000
    times = np.array([0.0, 1.0, 2.0])
    pos, _, dep = run(dict(trajectory="square", depth=7.0, depth_sigma=sigma, seed=seed, sample_period=1.0),
                      times, replicates=range(B))
    err = dep - pos[:, :, 2]
    # exact: draw k of the depth stream for sample k
    for k in range(3):
        for r in (0, 1, 2999):
            assert err[k, r] == pytest.approx(sigma * normals(seed, 0, 0, r, COMPONENT, DEPTH_NOISE, k, 1)[0],
                                              abs=1e-14)
    err = err.ravel()
    ss = float(np.sum(err**2))
    lo = math.sqrt(ss / stats.chi2.ppf(0.5 + CONF / 2, err.size))
    hi = math.sqrt(ss / stats.chi2.ppf(0.5 - CONF / 2, err.size))
    assert lo <= sigma <= hi, f"depth noise std {math.sqrt(ss / err.size)} vs {sigma}"
    assert abs(err.mean()) <= stats.norm.ppf(0.5 + CONF / 2) * sigma / math.sqrt(err.size)
    # independent from one reading to the next
    r = np.corrcoef(dep[0] - 7.0, dep[1] - 7.0)[0, 1]
    assert abs(math.atanh(r)) <= stats.norm.ppf(0.5 + CONF / 2) / math.sqrt(dep.shape[1] - 3)


@pytest.mark.parametrize("h", [0.3, 0.5, 2.2])
def test_depth_sensor_samples_and_holds(tmp_path, h):
    """T_s = 0.5 s, host steps h: the reading is z(t_k) + σ w_k at the last sample t_k = t0 + k T_s."""
    f = write_track(tmp_path / "track.csv", TRACK)
    sigma, T_s, t0 = 0.02, 0.5, 1.0
    params = dict(trajectory="file", trajectory_file=str(f), depth_sigma=sigma, sample_period=T_s, seed=3,
                  cell=1)
    times = t0 + h * np.arange(int(25.0 / h) + 1)
    _, _, dep = run(params, times, replicates=[0, 6])
    for b, r in enumerate((0, 6)):
        k = np.floor((times - t0) / T_s + 1e-9).astype(int)
        noise = np.array([normals(3, 0, 1, r, COMPONENT, DEPTH_NOISE, j, 1)[0] for j in k])
        ref = np.interp(t0 + k * T_s, TRACK[:, 0], TRACK[:, 3]) + sigma * noise
        np.testing.assert_allclose(dep[:, b], ref, atol=1e-13, err_msg=f"replicate {r}")

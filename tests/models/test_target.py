"""Tests of the target: trajectories, trajectory files and the depth sensor.

References are independent: circle/spiral/square geometry worked by hand,
finite differences of positions for speeds, np.interp for file paths, and a
chi-square interval for the depth-sensor noise.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from models.core import ModelError
from models.target import TargetCore, natural_duration, start_state
from models.target.trajectories import OPEN_DURATION, read_trajectory_file

CONF = 0.999


def run(params, times, replicates=(0,)):
    """Positions and velocities (len(times), B, 3) and depth readings (len(times), B) at the given times."""
    core = TargetCore(params, replicates=list(replicates))
    core.initialize(times[0])
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
    np.testing.assert_array_equal(dep[:, 0], pos[:, 0, 2])       # depth_sigma = 0
    # from (0, -r) through (r, 0) to (0, r)
    np.testing.assert_allclose(pos[0, 0], [0.0, -r, depth], atol=1e-12)
    np.testing.assert_allclose(pos[200, 0], [r, 0.0, depth], atol=1e-9)
    np.testing.assert_allclose(pos[-1, 0], [0.0, r, depth], atol=1e-9)
    # angle grows linearly: θ(t) = -π/2 + v t / r
    theta = np.arctan2(pos[:, 0, 1], pos[:, 0, 0])
    np.testing.assert_allclose(theta, -0.5 * np.pi + v * times / r, atol=1e-12)
    # speed: chord / dt approaches v (chord = 2 r sin(v dt / 2r))
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
              depth_sigma=0.0, seed=31)


def test_random_path_stays_in_disc_with_constant_speed_legs():
    core = TargetCore(RANDOM, replicates=range(30))
    core.initialize(0.0)
    pts = core.path.points                      # (B, legs + 1, 3)
    leg = RANDOM["speed"] * RANDOM["turn_interval"]
    np.testing.assert_allclose(pts[:, 0], np.tile([RANDOM["radius"], 0.0, RANDOM["depth"]], (30, 1)))
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
    # the walk does reach the edge of the disc (unconstrained, 250 legs would wander ~60 m away)
    assert radius.max() > RANDOM["max_radius"] - 0.5 * leg
    assert np.mean(radius > RANDOM["max_radius"] - leg) > 0.05
    # sampled by the core: speed v on legs (sample inside a leg), finite differences agree
    times = np.arange(0.0, 80.0, 0.5) + 0.25
    pos, vel, _ = run(RANDOM, times, replicates=range(30))
    np.testing.assert_allclose(np.linalg.norm(vel, axis=-1), RANDOM["speed"], rtol=1e-12)
    same_leg = np.floor(times[1:] / 4.0) == np.floor(times[:-1] / 4.0)
    np.testing.assert_allclose(fd_speed(pos, times)[same_leg], RANDOM["speed"], rtol=1e-9)


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
    # start_state is the deterministic start
    p0, v0 = start_state(RANDOM)
    np.testing.assert_array_equal(p0, [10.0, 0.0, 5.0])


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


@pytest.mark.parametrize("header", ["time,N,E,D", None])
def test_trajectory_file_linear_interpolation(tmp_path, header):
    f = write_track(tmp_path / "track.csv", TRACK, header)
    params = dict(trajectory="file", trajectory_file=str(f), depth_sigma=0.0)
    assert natural_duration(params) == 30.0
    times = np.array([0.0, 2.5, 9.9, 10.0, 12.0, 14.5, 22.0, 29.0, 30.0, 35.0])
    pos, vel, _ = run(params, times)
    ref = np.column_stack([np.interp(times, TRACK[:, 0], TRACK[:, k]) for k in (1, 2, 3)])
    np.testing.assert_allclose(pos[:, 0], ref, atol=1e-12)
    # velocity = slope of the current segment (zero once the file ends)
    slopes = np.diff(TRACK[:, 1:], axis=0) / np.diff(TRACK[:, 0])[:, None]
    seg = np.clip(np.searchsorted(TRACK[:, 0], times, side="right") - 1, 0, 2)
    expected = np.where((times < 30.0)[:, None], slopes[seg], 0.0)
    np.testing.assert_allclose(vel[:, 0], expected, atol=1e-12)
    p0, v0 = start_state(params)
    np.testing.assert_allclose(p0, TRACK[0, 1:])
    np.testing.assert_allclose(v0, slopes[0])


@pytest.mark.parametrize("first_row,label", [
    ("0,1e1,0,5", "unsigned exponent"),
    ("0,1E-3,0,5", "upper-case exponent"),
])
def test_trajectory_file_without_header_keeps_first_row_in_scientific_notation(tmp_path, first_row, label):
    """A headerless file whose first row uses exponent notation is all data (no row lost)."""
    f = tmp_path / "sci.csv"
    f.write_text(first_row + "\n10,20,0,5\n20,30,0,5\n")
    w = read_trajectory_file(f)
    first = [float(x) for x in first_row.split(",")]
    np.testing.assert_array_equal(w.times, [0.0, 10.0, 20.0], err_msg=label)
    np.testing.assert_allclose(w.points[0], first[1:], err_msg=label)


def test_trajectory_file_leading_comment_line_keeps_first_row(tmp_path):
    """'#' comments are accepted (comment='#'); a comment line must not eat the first data row."""
    f = tmp_path / "commented.csv"
    f.write_text("# diver track, NED metres\n0,10,0,5\n10,20,0,5\n20,30,0,5\n")
    w = read_trajectory_file(f)
    np.testing.assert_array_equal(w.times, [0.0, 10.0, 20.0])
    np.testing.assert_allclose(w.points[0], [10.0, 0.0, 5.0])


@pytest.mark.parametrize("content", [
    "time,N,E\n0,0,0\n10,1,1\n",                           # 3 columns
    "0,0,0\n10,1,1\n",                                     # 3 columns, no header
    "time,N,E,D\n0,0,0,1\n10,abc,0,1\n",                   # non-numeric
    "time,N,E,D\n0,0,0,1\n10,1,0,1\n5,2,0,1\n",            # decreasing time
    "time,N,E,D\n0,0,0,1\n0,1,0,1\n",                      # repeated time
    "time,N,E,D\n0,0,0,1\n",                               # one row
    "time,N,E,D\n0,0,0,1\n10,nan,0,1\n",                   # not finite
    "",                                                    # empty file
])
def test_trajectory_file_malformed_raises_model_error(tmp_path, content):
    f = tmp_path / "bad.csv"
    f.write_text(content)
    with pytest.raises(ModelError, match=r"target\.trajectory_file"):
        read_trajectory_file(f)
    with pytest.raises(ModelError, match=r"target\.trajectory_file"):
        TargetCore(dict(trajectory="file", trajectory_file=str(f)))


@pytest.mark.parametrize("name", ["does_not_exist.csv", ""])
def test_trajectory_file_missing_raises_model_error(tmp_path, name):
    path = str(tmp_path / name) if name else ""
    with pytest.raises(ModelError, match=r"target\.trajectory_file"):
        read_trajectory_file(path)
    with pytest.raises(ModelError, match=r"target\.trajectory_file"):
        TargetCore(dict(trajectory="file", trajectory_file=path))


# ----------------------------------------------------------------------------
# Depth sensor
# ----------------------------------------------------------------------------

def test_depth_sensor_noise_std():
    sigma = 0.05
    times = np.array([0.0, 1.0, 2.0])
    pos, _, dep = run(dict(trajectory="square", depth=7.0, depth_sigma=sigma, seed=12), times,
                      replicates=range(3000))
    err = (dep - pos[:, :, 2]).ravel()
    ss = float(np.sum(err**2))
    lo = math.sqrt(ss / stats.chi2.ppf(0.5 + CONF / 2, err.size))
    hi = math.sqrt(ss / stats.chi2.ppf(0.5 - CONF / 2, err.size))
    assert lo <= sigma <= hi, f"depth noise std {math.sqrt(ss / err.size)} vs {sigma}"
    assert abs(err.mean()) <= stats.norm.ppf(0.5 + CONF / 2) * sigma / math.sqrt(err.size)
    # independent from one reading to the next
    r = np.corrcoef(dep[0] - 7.0, dep[1] - 7.0)[0, 1]
    assert abs(math.atanh(r)) <= stats.norm.ppf(0.5 + CONF / 2) / math.sqrt(dep.shape[1] - 3)

"""Each proposed telemetry array confirmed by simulated tags (``sblsim design`` of an inverted LBL, step 4 of
:mod:`sblsim.orchestrator.design.telemetry`): tags at the work area's worst and median points ping
(:func:`~sblsim.models.tracking.simulate.simulate_pings`, the tag's ping type and intervals: ``[tag]``), each
receiver hears each ping
with the curve's probability at its distance, and each ping heard by enough receivers is fixed by least squares with
its emission time unknown (:func:`fixes`): the simulated yield and DRMS beside the predicted (:func:`static_check`);
with ``monte_carlo.path``, the same along an animal's correlated random walk through the work area
(:func:`path_check`), whose pings are also tracked as a recorded tag's are, against the tracker's smoothing bound
(:func:`~sblsim.orchestrator.design.telemetry_tracking.track_path`), and through clocks synchronised from the sync
tags (:func:`~sblsim.orchestrator.design.telemetry_tracking.track_synchronised`). With ``detection.multipath_pct``
a share of the heard arrivals is late by a reflection's excess path (:func:`multipath_delays`), which the prediction
leaves out: the rows show what it costs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from sblsim.models.design import area as areas
from sblsim.models.design import telemetry as tm
from sblsim.models.tracking.ekf import TrackerSettings
from sblsim.models.tracking.simulate import simulate_pings
from sblsim.orchestrator.design.telemetry import TelemetryProblem
from sblsim.orchestrator.design.telemetry_judgement import TelemetryDesign, fixed_pings, sync_hearing
from sblsim.orchestrator.design.telemetry_search import PINGS_PER_REPLICATE
from sblsim.orchestrator.design.telemetry_tracking import SYNC_STREAM, track_path, track_synchronised

#: The path's animal: its speed [m/s] and the standard deviation of its turn per ping [rad]; the positions of the
#: path at which the prediction is made.
WALK_SPEED, WALK_TURN, PATH_PREDICTED = 0.3, 0.5, 200
#: A simulated yield within this many percentage points of the predicted is confirmed.
YIELD_TOLERANCE_PP = 5.0
#: In 3-D, the walk's tag swims between the work area's shallowest and deepest depths as a sine of this period [s].
DEPTH_PERIOD = 3600.0
#: The stream of the multipath's draws (beside the design's seed and the receiver count), so that no other draw of
#: the confirmation moves with ``detection.multipath_pct``: the same pings, walk and detections, only some late.
MULTIPATH_STREAM = 0x3A7B
#: In 3-D a simulated ping's fix more than this above the surface [m] is discarded (a fish is below it; the margin
#: keeps a shallow tag's fixes whose depth errs upward).
SURFACE_MARGIN = 1.0


def checked_points(design: TelemetryDesign, problem: TelemetryProblem) -> list[tuple[str, int]]:
    """The work area's worst point (the largest finite DRMS of the fixed pings) and its median point."""
    drms = design.drms_fixed
    finite = np.flatnonzero(np.isfinite(drms) & (design.fixable > 0.0))
    if not len(finite):
        return []
    order = finite[np.argsort(drms[finite], kind="stable")]
    return [("worst", int(order[-1])), ("median", int(order[(len(order) - 1) // 2]))]


def fixes(receivers: np.ndarray, toa: np.ndarray, sound_speed: float, water: Any = None,
          iterations: int = 30, sigma_m: np.ndarray | None = None, depth: np.ndarray | None = None,
          depth_weight: float = 1.0) -> np.ndarray:
    """Each ping's position [m] from its times of arrival at the receivers that heard it (NaN: not heard), the
    emission unknown: least squares on ``‖p − r_i‖ + c t_e = c toa_i`` over the receivers that heard, by
    Gauss-Newton from several starts at once (the centroid of those receivers, each receiver, a 5 × 5 grid over the
    receivers' box grown by half, in 3-D at three depths over their depths grown by half), the solution of the
    least residual in the ``water`` kept (a tie, as the two exact solutions three receivers can give: the nearest
    that centroid); NaN where no start converges in the water (a fix on land, or in 3-D more than
    :data:`SURFACE_MARGIN` above the surface, is discarded). In 3-D (receivers (North, East, depth), depth positive
    down) a depth sensor's ``depth`` reading is one more row, ``depth_weight (depth − z)``.

    Parameters
    ----------
    receivers : ndarray, shape (n, dim)
        [m]; dim 2 or 3.
    toa : ndarray, shape (K, n)
        [s]; NaN where not heard.
    sound_speed : float
        [m/s].
    water : shapely Polygon, optional
    iterations : int, optional
    sigma_m : ndarray, broadcastable to (K, n), optional
        Each arrival's standard deviation [m] where it differs between receivers (a range-dependent noise,
        ``detection.range_k``): each residual weighted by the smallest over it (None: every arrival alike).
    depth : ndarray, shape (K,), optional
        3-D: the tag's depth reading per ping [m] (None: no sensor).
    depth_weight : float, optional
        The reading's weight against an arrival's of the smallest σ: that σ over the sensor's [1].

    Returns
    -------
    ndarray, shape (K, dim)
        [m].
    """
    toa = np.asarray(toa, float)
    receivers = np.asarray(receivers, float)
    dim = receivers.shape[1]
    heard = np.isfinite(toa)
    w = heard.astype(float)
    wr = w if sigma_m is None else w * np.min(sigma_m, axis=-1, keepdims=True) / np.broadcast_to(sigma_m, w.shape)
    count = np.maximum(w.sum(axis=1), 1.0)
    ranges = sound_speed * np.where(heard, toa - np.nanmin(np.where(heard, toa, np.inf), axis=1, keepdims=True),
                                    0.0)
    centre = (w @ receivers) / count[:, None]
    low, high = receivers.min(axis=0), receivers.max(axis=0)
    pad = 0.5 * (high - low) + 1.0
    axes = [np.linspace(low[k] - pad[k], high[k] + pad[k], 5) for k in range(2)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 2)
    if dim == 3:
        levels = np.linspace(max(low[2] - pad[2], 0.0), high[2] + pad[2], 3)
        grid = np.column_stack([np.repeat(grid, len(levels), axis=0), np.tile(levels, len(grid))])
    common = np.vstack([receivers + 1e-3, grid])
    starts = np.concatenate([centre[:, None], np.broadcast_to(common, (len(toa),) + common.shape)], axis=1)
    x = np.concatenate([starts, np.zeros(starts.shape[:2] + (1,))], axis=-1)  # (K, S, dim + 1)
    dist = np.linalg.norm(x[:, :, None, :dim] - receivers, axis=-1)
    x[..., dim] = np.sum(w[:, None] * (ranges[:, None] - dist), axis=-1) / count[:, None]
    read = None
    if depth is not None:
        read = np.asarray(depth, float)[:, None]
        wd = np.where(np.isfinite(read), depth_weight, 0.0)  # (K, 1)
        read = np.where(np.isfinite(read), read, 0.0)
        row = np.zeros(dim + 1)
        row[2] = 1.0

    def residuals(x: np.ndarray) -> np.ndarray:
        dist = np.linalg.norm(x[:, :, None, :dim] - receivers, axis=-1)
        r = wr[:, None] * (ranges[:, None] - (dist + x[..., dim:dim + 1]))
        return r if read is None else np.concatenate([r, (wd * (read - x[..., 2]))[..., None]], axis=-1)

    for _ in range(iterations):
        diff = x[:, :, None, :dim] - receivers  # (K, S, n, dim)
        dist = np.maximum(np.linalg.norm(diff, axis=-1), 1e-9)
        residual = wr[:, None] * (ranges[:, None] - (dist + x[..., dim:dim + 1]))
        J = np.concatenate([diff / dist[..., None], np.ones(dist.shape + (1,))], axis=-1) * wr[:, None, :, None]
        if read is not None:
            residual = np.concatenate([residual, (wd * (read - x[..., 2]))[..., None]], axis=-1)
            J = np.concatenate([J, np.broadcast_to(wd[:, :, None, None] * row, J.shape[:2] + (1, dim + 1))],
                               axis=2)
        A = np.einsum("ksni,ksnj->ksij", J, J) + 1e-9 * np.eye(dim + 1)
        step = np.linalg.solve(A, np.einsum("ksni,ksn->ksi", J, residual)[..., None])[..., 0]
        x = x + step
        if np.all(np.linalg.norm(step, axis=-1) < 1e-9):
            break
    cost = np.sum(residuals(x) ** 2, axis=-1)
    ok = np.isfinite(cost) & (np.linalg.norm(step, axis=-1) < 1e-4)
    if water is not None:
        ok &= areas.inside(water, np.where(np.isfinite(x[..., :2]), x[..., :2], 0.0))
    if dim == 3:
        ok &= x[..., 2] >= -SURFACE_MARGIN  # a fish is below the surface
    cost = np.where(ok, cost, np.inf)
    best = cost.min(axis=1, keepdims=True)
    tied = np.isfinite(cost) & (cost <= best + 1e-6 * count[:, None] + 1e-9 * best)
    near = np.where(tied, np.linalg.norm(x[..., :dim] - centre[:, None], axis=-1), np.inf)
    pick = np.argmin(near, axis=1)
    out = x[np.arange(len(x)), pick, :dim]
    return np.where(np.isfinite(best), out, np.nan)


def _readings(problem: TelemetryProblem, positions: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
    """The tag's depth sensor's readings at the pings' true positions (K, 3) [m] (σ ``detection.depth_sigma_m``);
    None without a sensor, or in a planar design (``rng`` not drawn from)."""
    if problem.depth_sigma is None:
        return None
    return positions[:, 2] + problem.depth_sigma * rng.standard_normal(len(positions))


def _fixed(problem: TelemetryProblem, receivers: np.ndarray, toa: np.ndarray, sigma: np.ndarray,
           readings: np.ndarray | None) -> np.ndarray:
    """:func:`fixes` of a design's pings (3-D: with the depth readings weighted by the smallest arrival's σ over
    the sensor's)."""
    weight = 1.0 if readings is None else float(np.min(sigma)) / problem.depth_sigma
    return fixes(receivers, toa, problem.sections["detection"]["sound_speed"], problem.water,
                 sigma_m=sigma if problem.sigma_per_m else None, depth=readings, depth_weight=weight)


def _errors(problem: TelemetryProblem, estimates: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """The fixes' errors (rows where a fix was made) on the prescription's axes (North, East; or all in 3-D with
    ``prescription.dimensions = "3d"``) [m]."""
    axes = 2 if problem.horizontal else truth.shape[1]
    return (estimates - truth)[np.isfinite(estimates).all(axis=1)][:, :axes]


def multipath_delays(shape: tuple[int, ...], pct: float, excess_m: float, sound_speed: float,
                     rng: np.random.Generator) -> np.ndarray:
    """Each arrival's lateness [s] by multipath: with probability ``pct`` / 100 a reflection, late by an excess path
    drawn from an exponential of mean ``excess_m`` over the sound speed, else 0. The channel's multipath
    (:mod:`sblsim.models.acoustics.core`, ``acoustics.outlier_pct`` and ``outlier_excess``, the fixed channel of
    Cario, Casavola, Gagliardi, Lupia, Severino, Sensors 21(3):762, 2021), drawn with one uniform u per arrival:
    a reflection where u < p, its excess ``−excess_m log(1 − u / p)`` (u / p is uniform given u < p). Nothing is
    drawn where ``pct`` is 0.

    Parameters
    ----------
    shape : tuple of int
        The arrivals' shape, (K, n).
    pct : float
        [%] the share of reflections, 0 to 100.
    excess_m : float
        [m] a reflection's mean excess path, > 0.
    sound_speed : float
        [m/s].
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape ``shape``
        [s], ≥ 0.

    Raises
    ------
    ValueError
        ``pct`` outside 0–100 or ``excess_m`` not positive.
    """
    if not 0.0 <= pct <= 100.0 or not excess_m > 0.0:
        raise ValueError(f"multipath_delays: pct {pct} (allowed 0 to 100), excess_m {excess_m} (allowed > 0)")
    if pct == 0.0:
        return np.zeros(shape)
    p = pct / 100.0
    u = rng.random(shape)
    late = u < p
    return np.where(late, -excess_m * np.log1p(-np.where(late, u, 0.0) / p), 0.0) / sound_speed


def _heard(problem: TelemetryProblem, toa: np.ndarray, d: np.ndarray, q: np.ndarray, rng: np.random.Generator,
           late: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Simulated times of arrival (K, n) [s] as the receivers hear them: the range-dependent law's noise added
    (``detection.range_k``), then each arrival kept with the curve's probability ``q`` at its distance ``d`` (both
    broadcastable to (K, n)), NaN where not heard, then each heard arrival made late by multipath
    (:func:`multipath_delays`, ``detection.multipath_pct`` and ``multipath_excess_m``, drawn from ``late``, else
    from ``rng`` after the others; nothing drawn at 0 %); and each arrival's σ [m] (``d``'s shape)."""
    detection = problem.sections["detection"]
    sigma = tm.range_sigma(d, problem.sigma_m, problem.sigma_per_m)
    toa = tm.range_noise(toa, d, problem.sigma_m, problem.sigma_per_m, detection["sound_speed"], rng)
    toa[rng.random(toa.shape) >= q] = np.nan  # the curve, receiver by receiver
    pct = detection.get("multipath_pct", 0.0)
    if pct > 0.0:  # the prediction (the Fisher information) leaves it out: the Monte Carlo shows what it costs
        toa = toa + multipath_delays(toa.shape, pct, detection["multipath_excess_m"], detection["sound_speed"],
                                     rng if late is None else late)
    return toa, sigma


def _counted(problem: TelemetryProblem, heard: np.ndarray, own: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pings (K,) heard by the receivers a fix needs, and those of them whose own pattern's DRMS ``own`` (K,)
    [m] is finite and within ``prescription.fix_gate_m`` (the fixes that count)."""
    enough = heard.sum(axis=1) >= problem.needed
    gate = problem.prescription["fix_gate_m"]
    return enough, enough & np.isfinite(own) & ((own <= gate) if gate > 0.0 else True)


def _simulated_fixes(problem: TelemetryProblem, design: TelemetryDesign, toa: np.ndarray, positions: np.ndarray,
                     sigma: np.ndarray, counted: np.ndarray, rng: np.random.Generator
                     ) -> tuple[np.ndarray, np.ndarray | None]:
    """The fixes that count (``counted`` (K,)) made (:func:`_fixed`, σ ``sigma`` broadcastable to (K, n), with the
    depth sensor's readings where it has one): their errors on the prescription's axes [m], and the readings of
    every ping (K,) (None without a sensor)."""
    k = np.flatnonzero(counted)
    readings = _readings(problem, positions, rng)
    estimates = _fixed(problem, design.receivers, toa[k], np.broadcast_to(sigma, toa.shape)[k],
                       None if readings is None else readings[k])
    return _errors(problem, estimates, positions[k]), readings


def static_check(design: TelemetryDesign, problem: TelemetryProblem, where: str, index: int,
                 rng: np.random.Generator, late: np.random.Generator | None = None) -> dict:
    """A tag at one point, pinging: its simulated yield and DRMS beside the predicted (module docstring, step 4);
    in 3-D at the point's depth, fixed in 3-D (with the depth sensor's readings where it has one); with
    ``detection.multipath_pct``, some arrivals late (drawn from ``late``: :func:`_heard`)."""
    mc = problem.sections["monte_carlo"]
    point = problem.points[index]
    pings = mc["replicates"] * PINGS_PER_REPLICATE
    toa, positions, emissions = simulated_pings(problem, design.receivers, pings, rng, start=point,
                                                path=lambda t: np.repeat(point[None], len(t), axis=0))
    d = np.linalg.norm(design.receivers - point, axis=1)
    q = problem.curve.probability(d)
    toa, sigma = _heard(problem, toa, d, q, rng, late)
    heard = np.isfinite(toa)
    own = tm.fix_drms(point[None], design.receivers, sigma[None], heard[:, None, :], problem.depth_sigma,
                      problem.horizontal)[:, 0]
    enough, counted = _counted(problem, heard, own)
    errors, _ = _simulated_fixes(problem, design, toa, positions, sigma[None], counted, rng)
    simulated = float(np.sqrt(np.mean(np.sum(errors**2, axis=1)))) if len(errors) else math.inf
    predicted = float(design.drms_fixed[index])
    ratio = simulated / predicted if math.isfinite(simulated) and predicted > 0.0 else math.nan
    predicted_yield, simulated_yield = float(design.positioning_yield[index]), float(np.mean(enough))
    predicted_fixed, simulated_fixed = float(design.fixable[index]), float(np.mean(counted))
    confirmed = bool(abs(ratio - 1.0) <= mc["tolerance_pct"] / 100.0 and
                     abs(simulated_yield - predicted_yield) <= YIELD_TOLERANCE_PP / 100.0)
    depth = {"depth_m": float(point[2])} if problem.three_d else {}
    return {"point": where, "north_m": float(point[0]), "east_m": float(point[1]), **depth,
            "predicted_drms_m": predicted, "simulated_drms_m": simulated, "ratio": ratio, "confirmed": confirmed,
            "pings": int(pings), "fixes": int(len(errors)), "predicted_yield": predicted_yield,
            "simulated_yield": simulated_yield, "predicted_fixed": predicted_fixed, "simulated_fixed": simulated_fixed}


def simulated_pings(problem: TelemetryProblem, receivers: np.ndarray, pings: int, rng: np.random.Generator,
                    **where: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The tag's ``pings`` as :func:`~sblsim.models.tracking.simulate.simulate_pings` makes them (every receiver
    hearing: the curve is applied after), with the problem's tag (``[tag]``: its ping type, burst interval or
    sequence; a stable interval's Δ as the simulator's ``interval``) and ``where`` (``start``, ``path``).

    Returns
    -------
    toa, positions, emissions
        As :func:`~sblsim.models.tracking.simulate.simulate_pings`: (K, n) [s], (K, dim) [m], (K,) [s].
    """
    detection, tag = problem.sections["detection"], problem.tag
    stable = {"interval": tag.burst_interval[0]} if tag.ping_type == "sbi" else {}
    settings = TrackerSettings(sound_speed=detection["sound_speed"], sigma_toa=detection["sigma_toa_s"], **stable)
    return simulate_pings(receivers, pings, settings, rng, detection=1.0, ping_type=tag.ping_type,
                          burst_interval=tag.burst_interval, burst_sequence=tag.burst_sequence, **where)


def walk_depth(problem: TelemetryProblem, times: np.ndarray) -> np.ndarray:
    """The walk's depth in 3-D at the emission ``times`` [s]: the work area's one depth, or between its shallowest
    and deepest as a sine of :data:`DEPTH_PERIOD` starting at their middle [m] (K,)."""
    depths = problem.sections["work_area"]["depths_m"]
    low, high = min(depths), max(depths)
    return 0.5 * (low + high) + 0.5 * (high - low) * np.sin(2.0 * math.pi * np.asarray(times, float) / DEPTH_PERIOD)


def walk(problem: TelemetryProblem, times: np.ndarray, rng: np.random.Generator, speed: float = WALK_SPEED,
         turn: float = WALK_TURN) -> np.ndarray:
    """A tagged animal's correlated random walk inside the work area (and the water) at the emission ``times``
    [s]: from the work area's point nearest its centroid, at ``speed`` [m/s], its heading turning by a normal of
    ``turn`` [rad] each ping; a step that would leave turns again (up to 50 draws, else the animal stays).

    Returns
    -------
    ndarray, shape (K, 2)
        (North, East) [m].
    """
    points = problem.points[:, :2]  # in 3-D: the horizontal walk (its depth :func:`walk_depth`'s)
    position = points[np.argmin(np.linalg.norm(points - points.mean(axis=0), axis=1))].copy()
    heading = rng.uniform(0.0, 2.0 * math.pi)
    out = np.empty((len(times), 2))
    steps = np.diff(np.asarray(times, float), prepend=float(times[0]))
    for k, dt in enumerate(steps):
        for _ in range(50):
            heading += rng.normal(0.0, turn)
            nxt = position + speed * dt * np.array([math.cos(heading), math.sin(heading)])
            if areas.inside(problem.work, nxt[None])[0] and areas.inside(problem.water, nxt[None])[0]:
                position = nxt
                break
            heading += rng.uniform(0.5, 1.5) * math.pi
        out[k] = position
    return out


def path_check(design: TelemetryDesign, problem: TelemetryProblem, rng: np.random.Generator,
               late: np.random.Generator | None = None) -> dict:
    """A tagged animal on a correlated random walk (:func:`walk`) through the work area, pinging as in
    :func:`static_check`: the simulated yield, share fixed and DRMS over the path beside the predicted at the
    path's positions (the RMS over the fixes that count of each ping position's predicted DRMS, weighted by its
    probability of a fix; :data:`PATH_PREDICTED` positions of the path, evenly spaced). In 3-D the walk's depth is
    :func:`walk_depth`'s, its pings fixed and tracked in 3-D (with the depth sensor's readings where it has one).
    With ``detection.multipath_pct`` some arrivals are late (drawn from ``late``: :func:`_heard`), for the fixes, the
    tracking and the tracking through synchronised clocks alike (the sync tags' own arrivals are not); the tracker is
    told their share and mean delay (``track_path``'s ``multipath``)."""
    mc, detection, tag = problem.sections["monte_carlo"], problem.sections["detection"], problem.tag
    pings = mc["replicates"] * PINGS_PER_REPLICATE
    walked = np.random.default_rng(rng.integers(2**63))

    def path(t: np.ndarray) -> np.ndarray:
        out = walk(problem, t, walked)
        return np.column_stack([out, walk_depth(problem, t)]) if problem.three_d else out

    toa, positions, emissions = simulated_pings(problem, design.receivers, pings, rng, path=path)
    d = np.linalg.norm(positions[:, None] - design.receivers[None], axis=-1)
    q = problem.curve.probability(d)
    toa, sigma = _heard(problem, toa, d, q, rng, late)
    heard = np.isfinite(toa)
    own = tm.fix_drms(positions, design.receivers, sigma, heard, problem.depth_sigma, problem.horizontal)
    enough, counted = _counted(problem, heard, own)
    # the tracker models the late arrivals it is given (their share and mean delay, as _heard draws them)
    pct = detection.get("multipath_pct", 0.0)
    multipath = (pct / 100.0, detection["multipath_excess_m"] / detection["sound_speed"]) if pct > 0.0 else None
    errors, readings = _simulated_fixes(problem, design, toa, positions, sigma, counted, rng)
    simulated = float(np.sqrt(np.mean(np.sum(errors**2, axis=1)))) if len(errors) else math.inf
    chosen = np.linspace(0, pings - 1, min(PATH_PREDICTED, pings)).astype(int)
    gate = problem.prescription["fix_gate_m"]
    rms, fixed = fixed_pings(positions[chosen], design.receivers, sigma[chosen], q[chosen], gate, rng,
                             needed=problem.needed, depth_sigma_m=problem.depth_sigma,
                             horizontal=problem.horizontal)
    ok = np.isfinite(rms) & (fixed > 0.0)
    predicted = float(np.sqrt(np.sum(fixed[ok] * rms[ok] ** 2) / np.sum(fixed[ok]))) if ok.any() else math.inf
    ratio = simulated / predicted if math.isfinite(simulated) and math.isfinite(predicted) else math.nan
    predicted_yield = float(np.mean(tm.positioning_yield(q[chosen], problem.needed)))
    simulated_yield = float(np.mean(enough))
    row = {"path": "correlated random walk", "pings": int(pings), "fixes": int(len(errors)),
           "length_m": float(np.sum(np.linalg.norm(np.diff(positions, axis=0), axis=1))),
           "predicted_drms_m": predicted, "simulated_drms_m": simulated, "ratio": ratio,
           "predicted_yield": predicted_yield, "simulated_yield": simulated_yield,
           "predicted_fixed": float(np.mean(fixed)), "simulated_fixed": float(np.mean(counted)),
           "confirmed": bool(abs(ratio - 1.0) <= mc["tolerance_pct"] / 100.0 and
                             abs(simulated_yield - predicted_yield) <= YIELD_TOLERANCE_PP / 100.0)
           } | track_path(design.receivers, toa, positions, emissions, detection["sound_speed"],
                          detection["sigma_toa_s"], tag.burst_interval, readings, problem.depth_sigma or 0.3,
                          ping_type=tag.ping_type, burst_sequence=tag.burst_sequence, multipath=multipath)
    if mc["sync_clocks"] and np.isfinite(toa).any():  # the same pings through clocks synchronised from sync tags
        clocks = np.random.default_rng([problem.sections["search"]["seed"], design.count, SYNC_STREAM])
        row |= track_synchronised(design.receivers, toa, positions, emissions,
                                  sync_hearing(design.receivers, problem.curve),
                                  detection["sound_speed"], detection["sigma_toa_s"], tag.burst_interval, clocks, row,
                                  readings, problem.depth_sigma or 0.3, ping_type=tag.ping_type,
                                  burst_sequence=tag.burst_sequence, multipath=multipath)
    return row


def confirm(design: TelemetryDesign, problem: TelemetryProblem) -> None:
    """A proposed design's Monte Carlo rows (:func:`static_check` at :func:`checked_points`) and, with
    ``monte_carlo.path``, its path's row (:func:`path_check`); the multipath drawn from a stream of its own
    (:data:`MULTIPATH_STREAM`)."""
    rng = np.random.default_rng([problem.sections["search"]["seed"], design.count, 1])
    late = np.random.default_rng([problem.sections["search"]["seed"], design.count, MULTIPATH_STREAM])
    design.monte_carlo = [static_check(design, problem, where, index, rng, late)
                          for where, index in checked_points(design, problem)]
    if problem.sections["monte_carlo"]["path"]:
        design.path = [path_check(design, problem, rng, late)]

__all__ = ["DEPTH_PERIOD", "MULTIPATH_STREAM", "PATH_PREDICTED", "SURFACE_MARGIN", "WALK_SPEED", "WALK_TURN",
           "YIELD_TOLERANCE_PP", "checked_points", "confirm", "fixes", "multipath_delays", "path_check",
           "simulated_pings", "static_check", "walk", "walk_depth"]

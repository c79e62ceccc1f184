"""The three positioning systems (SBL, LBL, USBL) in runs: the accuracy limit, two-way ranging, per-run errors and
the two engines.

* The bound (``pcrb_rms``; USBL: range, azimuth and elevation, :func:`sblsim.models.systems.usbl_bound.pcrb`) on
  ``random-walk``, a trajectory drawn from the receivers' motion model, with only white error sources: ``ekf-seq``
  reaches it and no receiver beats it beyond the sampling error.
* TWTT cancels a clock drift that ruins OWTT; the turnaround jitter enters the range as ``c σ / 2``.
* The errors drawn once per run (LBL survey, SBL installation, USBL mounting misalignment) are constant within a
  run and differ between runs.
* The local and fmu engines give the same numbers for every system, for 3 to 8 beacons, with TWTT, with eigenrays
  and with detection by signal-to-noise.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from sblsim.models.platform.geometry import platform_offsets
from sblsim.models.systems.usbl_bound import FIXED as USBL_FIXED
from sblsim.models.systems.usbl_bound import pcrb as usbl_pcrb
from sblsim.models.systems.usbl_bound import pcrb_inputs as usbl_pcrb_inputs
from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.connections import default_connections
from sblsim.orchestrator.cosim.engines import close_handles, make_handles
from sblsim.orchestrator.cosim.limits import step_count
from sblsim.orchestrator.cosim.master import simulate
from sblsim.orchestrator.cosim.metrics import slots
from sblsim.orchestrator.cosim.plan import make_plan
from sblsim.orchestrator.cosim.run import merge_params, run, run_batch, with_replicates
from tests.orchestrator.test_fmus import assert_same_frames

SYSTEMS = ("sbl", "lbl", "usbl")
RECEIVERS = ("ekf-seq", "ekf", "ukf", "lsq")
SPEED = 1500.0  # the scenarios' assumed and true sound speed [m/s]


def new_packets(ts):
    """The new, received packets of one replicate's time series (in time order), one row each, on every lane of a
    delivery (lane 1: the packet columns; lane m: ``lane<m>_*``, a packet_seq other than 0 and than the last one
    the lane held), with lane 1's column names."""
    frames = []
    for m in range(1, 9):
        prefix = "" if m == 1 else f"lane{m}_"
        if prefix + "packet_seq" not in ts:
            break
        seq = ts[prefix + "packet_seq"].to_numpy()
        held = pd.Series(np.where(seq > 0, seq, np.nan)).ffill().shift(1).fillna(0).to_numpy()
        new = (seq != held) & (seq > 0) & ts[prefix + "packet_valid"].to_numpy(bool)
        mine = [c for c in ts if (c.startswith(prefix) if m > 1 else not c.startswith("lane"))]
        frames.append(ts.loc[new, mine].rename(columns={c: c[len(prefix):] for c in mine}).assign(
            time=ts["time"].to_numpy()[new]))
    return pd.concat(frames).sort_values(["time", "rx_time"], kind="stable")


def both_engines(cfg, fmu_dir):
    """Replicates 0 and 1 of ``cfg`` on the local and the fmu engine: every time-series column and every metric
    equal to 1e-9 (:func:`assert_same_frames`); the local engine's result."""
    local = run(cfg, "local", replicates=[0, 1])
    fmu = run(cfg, "fmu", fmu_dir=fmu_dir, replicates=[0, 1])
    assert local.steps == fmu.steps
    assert_same_frames(local.timeseries, fmu.timeseries)
    assert_same_frames(local.metrics, fmu.metrics)
    return local


def every_output(cfg, replicates):
    """Every output of every component at each step (the master's record, ``component.variable`` -> (N, B)), of a
    batch of replicates on the local engine: what a run records before it keeps its time-series columns."""
    cfgs = with_replicates(cfg, replicates)
    n, sim = make_plan(cfg).n_beacons, cfg["simulation"]
    handles = make_handles("local", None, n, dict(make_plan(cfg).sources))
    try:
        for name, handle in handles.items():
            handle.setup(*merge_params(cfgs, name, handle.parameters))
        return simulate(handles, default_connections(n), {"receiver": sim["ekf_rate_ratio"]}, sim["sampling_time"],
                        step_count(sim["duration"], sim["sampling_time"]), algorithm=sim["master"])
    finally:
        close_handles(handles)


# --------------------------------------------------------------------------- the accuracy limit

#: White error sources only, none drawn per run: range noise, depth noise, the wave motion. The GPS and IMU errors
#: are off as well: a USBL packet's angles are taken from the broadcast transceiver position, and neither the GPS
#: error's shift of that origin nor the lever arm turned by the attitude error is in the bound (or in the receivers'
#: R); the SBL bound with them is the subject of test_accuracy.py.
WHITE = ["simulation.sampling_time=0.5", "simulation.duration=60", "platform.gps_sigma=0", "platform.imu_sigma_deg=0",
         "platform.survey_sigma=0", "platform.installation_sigma=0", "platform.usbl_misalignment_deg=0"]
RUNS = 200


@pytest.fixture(scope="module", params=SYSTEMS)
def bounded(request):
    """system -> receiver -> the metrics of 200 random-walk runs (the same paths and noises for every receiver)."""
    system = request.param
    metrics = {}
    for receiver in RECEIVERS:
        cfg = load_config("random-walk", WHITE + [f"platform.system={system}", f"receiver={receiver}"], seed=4)
        metrics[receiver] = run_batch(with_replicates(cfg, range(RUNS)), timeseries=False).metrics
    return system, metrics


def normalized(m):
    """Each run's mean squared error over its squared bound, ``q = e_tot_rms² / pcrb_rms²``, their mean and its
    standard error. The bound changes a lot from run to run (USBL: with the diver's angle off the vertical), the
    ratio much less: per run, an ideal filter's expected squared error is the bound of that path."""
    q = (m["e_tot_rms"] / m["pcrb_rms"]).to_numpy() ** 2
    return q.mean(), q.std(ddof=1) / math.sqrt(q.size)


def test_ekf_seq_reaches_the_bound_and_no_receiver_beats_it(bounded):
    """Over the steps with an estimate (from each receiver's first fix on: ``e_tot_rms`` and ``pcrb_rms`` alike),
    ekf-seq's error is what it reports, and it is at the bound or above, within √2 of it.

    * Consistent: its mean NEES within 10 % of 3 (the χ²₃ mean; over 200 runs of 120 steps its sampling error is
      under 2 %). Seen: SBL 3.03, LBL 3.08, USBL 3.05.
    * At the bound or above: sqrt(mean q) > 1 − 3 standard errors, and no receiver's mean q below 1 − 3 standard
      errors (the bound is a lower bound: a bound too large, e.g. the range-only bound of a USBL run, several times
      the range-direction one, fails here). Over 200 runs the standard error of the ratio is ≤ 0.025 (checked).
    * Within √2 of it: sqrt(mean q) < 1.3, below √2, the ratio of a bound that counted each packet's information
      twice. What ekf-seq reaches is its own covariance (the NEES above), and that is larger than the bound, with
      the same prior, Q and R parameters. Measured over the steps with an estimate: sqrt(mean q) SBL 1.106, LBL
      1.077, USBL 1.225 (± 0.016, 0.019, 0.009); its reported pos_std over the bound (100 runs) 1.08, 1.05, 1.19
      from the first packet on (USBL step 1: 0.215 m against 0.171 m), a steady gap, not a start-up transient. The
      EKF takes H and R at its estimate, the bound at the true path; whether that explains the USBL 19 % is not
      known (an open question: docs/model.md). Before the estimate of step 0 was left out (NaN: no estimate before
      the first fix) it counted the prior's first step, where error and bound are both the prior's (its bound² more
      than the other 119 steps' together), and the ratio read 1.02-1.04.

    Other receivers (seen, sqrt(mean q)): ukf within 0.005 of ekf-seq, ekf 1.66 (LBL) to 2.35 (USBL), lsq 2.7
    (USBL) to 6.1 (SBL)."""
    system, metrics = bounded
    m = metrics["ekf-seq"]
    assert not m["diverged"].any() and (m["pcrb_rms"] > 0).all()
    q, se = normalized(m)
    ratio, se_ratio = math.sqrt(q), se / (2 * math.sqrt(q))
    assert se_ratio < 0.025, f"{system}: standard error {se_ratio:.3f} of the ratio: too few runs for the tolerance"
    nees = float(m["nees_mean"].mean())
    assert abs(nees / 3.0 - 1.0) < 0.1, f"{system}: ekf-seq mean NEES {nees:.3f}, not its error"
    assert 1.0 - 3.0 * se_ratio < ratio < 1.3, f"{system}: ekf-seq RMS / PCRB = {ratio:.3f} ± {se_ratio:.3f}"
    for receiver, m in metrics.items():
        if receiver != "lsq":  # the bound of the path over the same steps: the Kalman receivers' first fix is the same
            np.testing.assert_array_equal(m["pcrb_rms"], metrics["ekf-seq"]["pcrb_rms"])
        q, se = normalized(m)
        assert q > 1.0 - 3.0 * se, f"{system}: {receiver} beats the bound: mean q = {q:.3f} ± {se:.3f}"


@pytest.mark.parametrize("system", SYSTEMS)
def test_every_receiver_has_the_bound_of_the_path_and_its_rms_over_its_own_estimates(system):
    """The per-step bound is the path's, the same for every receiver; ``pcrb_rms`` is its RMS over the steps the
    receiver has an estimate at (those ``e_tot_rms`` averages: none before its first fix), so ``lsq``, whose first
    fix needs a whole set of ranges (SBL, LBL), averages it over fewer steps than the Kalman receivers."""
    runs = {}
    for receiver in RECEIVERS:
        cfg = load_config("random-walk", WHITE + [f"platform.system={system}", f"receiver={receiver}",
                                                  "simulation.duration=20"], seed=4)
        runs[receiver] = run(cfg, replicates=[0, 1, 2])
    for receiver, result in runs.items():
        ts, n = result.timeseries, result.steps
        bound = ts["pcrb"].to_numpy().reshape(3, n).T
        np.testing.assert_array_equal(bound, runs["ekf-seq"].timeseries["pcrb"].to_numpy().reshape(3, n).T)
        estimated = np.isfinite(ts["est_x"].to_numpy().reshape(3, n).T)
        assert not estimated[0].any() and estimated[-1].all(), receiver  # from the first fix on
        np.testing.assert_allclose(result.metrics["pcrb_rms"],
                                   np.sqrt(np.sum(np.where(estimated, bound**2, 0.0), axis=0) / estimated.sum(axis=0)),
                                   rtol=1e-13, err_msg=receiver)
        every_step = np.sqrt(np.mean(bound**2, axis=0))  # the prior's first steps: a larger RMS
        assert np.all(result.metrics["pcrb_rms"] < every_step), receiver
    if system != "usbl":
        first = {r: np.isfinite(x.timeseries["est_x"].to_numpy().reshape(3, -1).T).argmax(axis=0)
                 for r, x in runs.items()}
        assert np.all(first["lsq"] > first["ekf-seq"])
        assert np.all(runs["lsq"].metrics["pcrb_rms"] != runs["ekf-seq"].metrics["pcrb_rms"])


def test_a_usbl_run_reports_the_usbl_bound_of_its_own_packets():
    """The per-step ``pcrb`` of a USBL run is the range-direction bound (casadi) of the recorded packets (their
    transceiver and attitude) at the recorded true positions, ``pcrb_rms`` its RMS, the same whatever the batch;
    far below the range-only bound of the same packets."""
    from sblsim.models.bound import pcrb, pcrb_inputs

    cfg = load_config("random-walk", ["platform.system=usbl", "simulation.duration=20", "acoustics.loss_pct=20"],
                      seed=2)
    result = run(cfg, replicates=[0, 1])
    ts = result.timeseries
    n = result.steps
    column = {c: ts[c].to_numpy().reshape(2, n).T for c in ("true_x", "true_y", "true_z", "packet_seq",
                                                           "packet_valid", "beacon_id", "beacon_x", "beacon_y",
                                                           "beacon_z", "pcrb", "doa_roll", "doa_pitch", "doa_yaw")}
    slot, fresh = slots(column["packet_seq"], column["packet_valid"].astype(bool) & (column["beacon_id"] == 1))
    assert (slot & ~fresh).sum() > 10  # lost packets: depth-only slots
    truth = np.stack([column[f"true_{a}"] for a in "xyz"], -1)
    transceiver = np.stack([column[f"beacon_{a}"] for a in "xyz"], -1)
    attitude = np.stack([column[f"doa_{a}"] for a in ("roll", "pitch", "yaw")], -1)
    p = make_plan(cfg).bound
    fixed = {k: p[k] for k in USBL_FIXED[1:]}  # after dt
    # the transceiver position's error per axis: the GPS error and the lever arm turned by the attitude error
    platform = cfg["platform"]
    assert fixed["position_variance"] == pytest.approx(
        platform["gps_sigma"] ** 2 + (math.radians(platform["imu_sigma_deg"]) * platform["transducer_depth"]) ** 2,
        rel=1e-12)
    bound = usbl_pcrb(*usbl_pcrb_inputs(truth, slot, fresh, transceiver, attitude, dt=0.1, **fixed))
    np.testing.assert_array_equal(column["pcrb"], bound)
    estimated = np.isfinite(ts["est_x"].to_numpy().reshape(2, n).T)  # pcrb_rms: over the steps with an estimate
    assert not estimated.all() and estimated[-1].all()  # none before the first fix
    np.testing.assert_allclose(result.metrics["pcrb_rms"],
                               np.sqrt(np.sum(np.where(estimated, bound**2, 0.0), axis=0) / estimated.sum(axis=0)),
                               rtol=1e-14)
    kept = {k: fixed[k] for k in ("q_horizontal", "q_vertical", "p0_position", "p0_velocity", "attitude_variance",
                                  "depth_variance")}
    range_only = pcrb(*pcrb_inputs(truth, slot, fresh, transceiver, np.zeros_like(truth), dt=0.1,
                                   noise_variance=p["noise_variance"], **kept))
    assert np.all(np.sqrt(np.mean(range_only**2, axis=0)) > 3 * result.metrics["pcrb_rms"])
    alone = run(cfg, replicates=[1])  # a run's bound whatever batch it is part of
    np.testing.assert_array_equal(alone.timeseries["pcrb"], column["pcrb"][:, 1])
    assert alone.metrics["pcrb_rms"][0] == result.metrics["pcrb_rms"][1]


# --------------------------------------------------------------------------- two-way ranging

@pytest.mark.parametrize("system", SYSTEMS)
def test_twtt_cancels_a_clock_drift_that_ruins_owtt(system):
    """100 ppm of clock drift. OWTT: the range grows by ``c δ (t_k − t0 + τ)`` (0.45 m after 30 s) and e_tot_mean
    by a factor ≥ 5 in every run (seen 7.7-16). TWTT: the drift acts on the round trip Δt only, ``c δ Δt / 2`` (about
    5 mm for SBL, 9 mm for LBL's 50 m deep transponders: the 0.05 s turnaround counts), each range exactly that
    longer, and e_tot_mean within 2 cm and 3 % of the run without drift (seen ≤ 6 mm, 1.7 %). USBL has TWTT only.
    The OWTT runs are those of a receiver without the clock's states (``receiver.clock_states = false``); with them
    (the default under a drift) the error is at least halved in every run."""
    base = ["simulation.duration=30", f"platform.system={system}", "receiver=ekf-seq", "receiver.clock_states=false"]
    for ranging in ("owtt", "twtt") if system != "usbl" else ("twtt",):
        runs = [run(load_config("random-walk", base + [f"acoustics.ranging={ranging}",
                                                       f"acoustics.clock_drift_ppm={ppm}"], seed=3),
                    replicates=range(4)) for ppm in (0, 100)]
        steady, drift = (r.metrics["e_tot_mean"].to_numpy() for r in runs)
        ts0, ts1 = runs[0].timeseries, runs[1].timeseries
        valid = ts0["packet_valid"].to_numpy(bool)
        longer = (ts1["range"] - ts0["range"]).to_numpy()[valid]
        if ranging == "owtt":
            elapsed = (ts0["tx_time"] + ts0["travel_time"]).to_numpy()[valid]
            np.testing.assert_allclose(longer, SPEED * 1e-4 * elapsed, rtol=1e-9, atol=1e-9)
            assert np.all(drift > 5.0 * steady), (system, drift / steady)
            states = run(load_config("random-walk", [*base[:-1], "acoustics.ranging=owtt",
                                                     "acoustics.clock_drift_ppm=100"], seed=3), replicates=range(4))
            assert np.all(states.metrics["e_tot_mean"].to_numpy() < 0.5 * drift), (system, states.metrics, drift)
        else:
            trip = ts0["travel_time"].to_numpy()[valid]  # TWTT: the round trip, turnaround included
            np.testing.assert_allclose(longer, SPEED * 1e-4 * trip / 2.0, rtol=1e-9, atol=1e-10)
            assert 0.05 < trip.min() and trip.max() < 0.2
            np.testing.assert_allclose(drift, steady, rtol=0.03, atol=0.0)
            assert np.abs(drift - steady).max() < 0.02


@pytest.mark.parametrize("system", SYSTEMS)
def test_turnaround_jitter_enters_the_range_as_c_sigma_over_two(system):
    """TWTT with a 1 ms turnaround jitter and every other error off (range noise 1 µm): over 600 packets,
    ``range − range_true`` has std 1500 · 1e-3 / 2 = 0.75 m, inside the 99.9 % χ² interval of the sample std
    (± about 7 %), and mean 0 within 4 standard errors (0.12 m); without the jitter it is below 1e-5 m."""
    base = ["simulation.duration=60", f"platform.system={system}", "acoustics.ranging=twtt",
            "acoustics.sigma_range=1e-6", "platform.gps_sigma=0", "platform.imu_sigma_deg=0", "target.depth_sigma=0"]
    sigma = SPEED * 1e-3 / 2.0
    ts = new_packets(run(load_config("random-walk", base + ["acoustics.turnaround_sigma=1e-3"], seed=3)).timeseries)
    error = (ts["range"] - ts["range_true"]).to_numpy()
    n = error.size
    assert 595 <= n < 600  # one packet per slot of 60 s, but the last slots' replies arrive after the end
    low, high = (sigma * math.sqrt(chi2.ppf(p, n - 1) / (n - 1)) for p in (0.0005, 0.9995))
    assert low < error.std(ddof=1) < high, (error.std(ddof=1), low, high)
    assert abs(error.mean()) < 4.0 * sigma / math.sqrt(n)
    ts = new_packets(run(load_config("random-walk", base, seed=3)).timeseries)
    assert np.abs(ts["range"] - ts["range_true"]).max() < 1e-5


# --------------------------------------------------------------------------- errors drawn once per run

def test_lbl_survey_error_is_constant_within_a_run_and_differs_between_runs():
    """The position a packet of transponder 1 carries minus its true position (the seafloor point of the layout;
    the platform's own output too) is the same at every packet of a run, nonzero, and another in each replicate."""
    sigma = 0.5
    cfg = load_config("random-walk", ["platform.system=lbl", f"platform.survey_sigma={sigma}",
                                      "simulation.duration=10"], seed=5)
    true = platform_offsets(cfg["platform"])[0]
    assert true[2] == cfg["platform"]["seafloor_depth"]
    result = run(cfg, replicates=range(4))
    surveys = []
    for rep, ts in result.timeseries.groupby("replicate"):
        packets = new_packets(ts.sort_values("time"))
        first = packets[packets["beacon_id"] == 1]
        assert len(first) == 25
        offset = first[["beacon_x", "beacon_y", "beacon_z"]].to_numpy() - true
        assert np.all(offset == offset[0]), rep
        surveys.append(offset[0])
    surveys = np.array(surveys)
    assert np.all(np.abs(surveys) > 1e-6) and np.all(np.abs(surveys) < 5 * sigma)
    assert len({tuple(s) for s in surveys}) == 4
    outputs = every_output(cfg, range(4))
    for k, a in enumerate("xyz"):
        np.testing.assert_array_equal(outputs[f"platform.beacon1_true_{a}"], true[k])
        np.testing.assert_allclose(outputs[f"platform.beacon1_{a}"] - true[k], np.broadcast_to(surveys[:, k], (100, 4)),
                                   rtol=0, atol=1e-12)


def test_sbl_installation_error_is_constant_within_a_run_and_differs_between_runs():
    """In a Beaufort 4 sea with exact GPS and IMU, the true beacon i is the broadcast one plus R δ_i (R the platform's
    attitude): ``Rᵀ (b_i − b̃_i)`` is the same at every step of a run, nonzero, and another in each replicate."""
    sigma = 0.05
    cfg = load_config("random-walk", [f"platform.installation_sigma={sigma}", "platform.gps_sigma=0",
                                      "platform.imu_sigma_deg=0", "platform.beaufort=4", "simulation.duration=5"],
                      seed=5)
    out = every_output(cfg, range(3))
    attitude = np.stack([out[f"platform.{a}"] for a in ("yaw", "pitch", "roll")], -1)  # (N, B, 3)
    assert np.ptp(attitude[..., 2]) > 0.01  # the platform rolls
    for i in range(1, 5):
        true = np.stack([out[f"platform.beacon{i}_true_{a}"] for a in "xyz"], -1)
        sent = np.stack([out[f"platform.beacon{i}_{a}"] for a in "xyz"], -1)
        delta = np.array([[Rotation.from_euler("ZYX", attitude[k, b]).as_matrix().T @ (true[k, b] - sent[k, b])
                           for b in range(3)] for k in range(attitude.shape[0])])
        np.testing.assert_allclose(delta, np.broadcast_to(delta[0], delta.shape), rtol=0, atol=1e-12)
        assert np.all(np.abs(delta[0]) > 1e-6) and np.all(np.abs(delta[0]) < 5 * sigma)
        assert len({tuple(d) for d in delta[0]}) == 3, i


def test_usbl_misalignment_is_constant_within_a_run_and_differs_between_runs():
    """``array_* − roll/pitch/yaw`` (the array's true attitude less the platform's) is the mounting misalignment:
    the same at every step of a run, another in each replicate, 0 without it."""
    sigma = 2.0
    cfg = load_config("random-walk", ["platform.system=usbl", f"platform.usbl_misalignment_deg={sigma}",
                                      "simulation.duration=10"], seed=5)
    ts = run(cfg, replicates=range(4)).timeseries
    angles = ("roll", "pitch", "yaw")
    misalignment = []
    for rep, series in ts.groupby("replicate"):
        mu = np.stack([series[f"array_{a}"] - series[a] for a in angles], -1)
        np.testing.assert_allclose(mu, np.broadcast_to(mu[0], mu.shape), rtol=0, atol=1e-12, err_msg=str(rep))
        misalignment.append(mu[0])
    misalignment = np.array(misalignment)
    assert np.all(np.abs(misalignment) > 1e-8) and np.all(np.abs(misalignment) < math.radians(5 * sigma))
    assert len({tuple(m) for m in misalignment}) == 4
    assert np.ptp(ts["roll"]) > 0.01  # the platform moves; the difference does not
    aligned = run(load_config("random-walk", ["platform.system=usbl", "simulation.duration=10"], seed=5)).timeseries
    for a in angles:
        np.testing.assert_array_equal(aligned[f"array_{a}"], aligned[a])


# --------------------------------------------------------------------------- the two engines

#: id -> overrides: SBL and LBL on a circle of N beacons with TWTT (and LBL with OWTT), USBL (one transceiver)
ENGINE_CASES = {
    **{f"{system}-circle{n}-twtt": [f"platform.system={system}", "platform.layout=circle", f"platform.beacons={n}",
                                    "acoustics.ranging=twtt", "acoustics.turnaround_sigma=1e-4"]
       for system in ("sbl", "lbl") for n in (3, 4, 6, 8)},
    "lbl-cross-owtt": ["platform.system=lbl", "platform.survey_sigma=0.2"],
    "usbl-ekf": ["platform.system=usbl", "platform.usbl_misalignment_deg=1", "acoustics.turnaround_sigma=1e-4"],
    "usbl-ekf-seq": ["platform.system=usbl", "receiver=ekf-seq", "acoustics.outlier_pct=10"],
    # the inverted LBL: the pinger's jitter and drift, a ping's arrivals on the lanes of a delivery
    "ilbl-ekf-seq": ["platform.system=ilbl", "platform.layout=circle", "receiver=ekf-seq",
                     "acoustics.ping_jitter=0.02", "acoustics.clock_drift_ppm=20"],
    "ilbl-ukf-circle6": ["platform.system=ilbl", "platform.layout=circle", "platform.beacons=6", "receiver=ukf",
                         "acoustics.ping_jitter=0.01", "acoustics.outlier_pct=10", "acoustics.ping_interval=0.7"],
}


@pytest.mark.slow
@pytest.mark.parametrize("overrides", ENGINE_CASES.values(), ids=ENGINE_CASES.keys())
def test_engines_agree_for_every_system(fmu_dir, overrides):
    """5 s with 10 % loss through both engines: every time-series column (est_x … and the bound) and every metric
    equal to 1e-9. The FMUs for 4 beacons are the suite's; other numbers (and USBL's one transceiver) are built into
    the cache once."""
    cfg = load_config("random-walk", overrides + ["simulation.duration=5", "acoustics.loss_pct=10"], seed=9)
    local = both_engines(cfg, fmu_dir)
    assert local.steps == 50
    assert not local.timeseries["packet_valid"].all()


#: id -> overrides: eigenrays through the Munk profile (``acoustics.propagation = "ray"``) for every system, and
#: with a water depth (the surface- and bottom-reflected eigenrays solved too)
RAY = ["acoustics.propagation=ray", "acoustics.sound_speed_profile=munk"]
RAY_CASES = {
    "sbl-ray": ["platform.system=sbl", *RAY],
    "lbl-ray": ["platform.system=lbl", *RAY],
    "usbl-ray": ["platform.system=usbl", *RAY],
    "sbl-ray-water-depth": ["platform.system=sbl", *RAY, "acoustics.water_depth=8"],
    "lbl-ray-water-depth": ["platform.system=lbl", *RAY, "acoustics.water_depth=50"],
    # a receiver that ranges with its own profile (the true one): its slot event of the eigenray conversion
    "lbl-ray-receiver-profile": ["platform.system=lbl", *RAY, "receiver.sound_speed_profile=acoustics"],
    "usbl-ray-receiver-profile": ["platform.system=usbl", *RAY, "receiver.sound_speed_profile=munk",
                                  "simulation.receiver=ekf-seq"],
    "ilbl-ray-water-depth": ["platform.system=ilbl", *RAY, "acoustics.water_depth=50", "simulation.receiver=ukf",
                             "acoustics.ping_jitter=0.01"],
}


@pytest.mark.slow
@pytest.mark.parametrize("overrides", RAY_CASES.values(), ids=RAY_CASES.keys())
def test_engines_agree_with_eigenrays(fmu_dir, overrides):
    """``ray`` through both engines: every time-series column (travel time, launch and arrival angles, the path)
    and every metric equal to 1e-9; the rays bend (a straight chord leaves and arrives at one angle)."""
    cfg = load_config("random-walk", overrides + ["simulation.duration=5", "acoustics.loss_pct=10"], seed=9)
    local = both_engines(cfg, fmu_dir)
    assert local.steps == 50
    received = local.timeseries[local.timeseries["arrival"] > 0]
    assert len(received) > 20
    assert (received["launch_angle"] - received["arrival_angle"]).abs().min() > 1e-6  # refracted, not the chord


#: id -> (scenario, overrides): detection by signal-to-noise (``acoustics.detection = "snr"``) on each system, at
#: a source level and fluctuation of the received level that lose some packets and range some on a surface- or
#: bottom-reflected eigenray: SBL one-way on the semicircle in 40 m of calm water, the LBL field (two-way) and the
#: deep USBL site, shortened
SNR_CASES = {
    "sbl-owtt-snr": ("semicircle", ["acoustics.propagation=ray", "acoustics.detection=snr",
                                    "acoustics.water_depth=40", "platform.beaufort=0", "acoustics.source_level=105",
                                    "acoustics.fluctuation=15", "simulation.duration=10"]),
    "lbl-field-twtt-snr": ("lbl-field", ["acoustics.source_level=145", "acoustics.fluctuation=10",
                                         "simulation.duration=90"]),
    "usbl-deep-snr": ("usbl-deep", ["acoustics.source_level=160", "acoustics.fluctuation=10",
                                    "simulation.duration=400"]),
}


@pytest.mark.slow
@pytest.mark.parametrize(("scenario", "overrides"), SNR_CASES.values(), ids=SNR_CASES.keys())
def test_engines_agree_with_detection_by_snr(fmu_dir, scenario, overrides):
    """``snr`` through both engines: every time-series column (the SNR and detection probability of each
    packet's arrival, the range, the estimate) and every metric (``detected_pct``) equal to 1e-9; the runs take
    each branch of what is heard: nothing (lost), the direct arrival, a reflected one (its range received)."""
    cfg = load_config(scenario, overrides, seed=9)
    assert cfg["acoustics"]["detection"] == "snr"
    result = both_engines(cfg, fmu_dir)
    ts = result.timeseries
    sent = ts.groupby("replicate")["packet_seq"].diff().fillna(ts["packet_seq"]).ne(0) & ts["packet_seq"].gt(0)
    packets = ts[sent]
    received = packets[packets["packet_valid"].astype(bool)]
    assert len(packets) > 40
    assert (packets["arrival"] == 0).sum() > 5 and len(received) > 5  # nothing heard, and heard and decoded
    assert (received["arrival"] == 1).any() and (received["arrival"] > 1).any()  # direct and reflected ranges
    assert packets["snr"].std() > 1.0 and packets["detection_probability"].between(0.0, 1.0).all()
    share = 100.0 * received.groupby("replicate").size() / packets.groupby("replicate").size()
    np.testing.assert_allclose(result.metrics["detected_pct"], share.to_numpy(), rtol=1e-12)


@pytest.mark.parametrize("system", ["sbl", pytest.param("usbl", marks=pytest.mark.slow)])
def test_the_eigenray_table_of_a_run(fmu_dir, monkeypatch, system):
    """A semicircle through Munk gets an eigenray table (a random walk, above, gets none): both engines equal to
    1e-9 with it, and the run without it (every eigenray solved) gives the same travel times within 1 µs, the same
    paths and angles within 1e-5 rad."""
    from sblsim.orchestrator.cosim import plan as plan_module

    cfg = load_config("semicircle", ["platform.system=" + system, *RAY, "simulation.duration=5"], seed=4)
    table = make_plan(cfg).parameters["acoustics"]
    assert table["ray_table_rows"] == 512 and not any(table[f"ray_exact[{k}]"] for k in range(1, 513))
    local = both_engines(cfg, fmu_dir)
    monkeypatch.setattr(plan_module, "ray_box", lambda cfg: None)  # no box: every eigenray solved
    solved = run(cfg, "local", replicates=[0, 1])
    a, b = local.timeseries, solved.timeseries
    assert (a["arrival"] > 0).sum() > 40
    np.testing.assert_array_equal(a["arrival"], b["arrival"])
    assert (a["travel_time"] - b["travel_time"]).abs().max() <= 1e-6
    assert (a["travel_time"] != b["travel_time"]).any()  # interpolated, not solved
    for column in ("launch_angle", "arrival_angle"):
        assert (a[column] - b[column]).abs().max() <= 1e-5


#: The benchmark's snr geometry (``bench_campaign.py --snr``): the semicircle through Munk in 20 m of water (every
#: family exists), LBL's transponders 1 m above the floor, in a rough sea (the heave of the vessel's transducers),
#: at a source level and fluctuation that miss some direct arrivals (as :data:`SNR_CASES`)
SNR_TABLE = [*RAY, "acoustics.detection=snr", "acoustics.water_depth=20", "platform.beaufort=5",
             "acoustics.source_level=125", "acoustics.fluctuation=15"]


@pytest.mark.slow
@pytest.mark.parametrize("system", ["sbl", "lbl", "usbl"])
def test_the_family_table_of_a_run(fmu_dir, monkeypatch, system):
    """An ``snr`` semicircle gets the family table, every cell answered (a box of seafloor transponders neither
    heaves nor reaches below the floor): both engines equal to 1e-9 with it, and the run without it (every family
    solved) ranges on the same path of nearly every packet with the same travel time within 1 µs and SNR within
    0.02 dB."""
    from sblsim.orchestrator.cosim import plan as plan_module

    own = ["platform.seafloor_depth=19"] if system == "lbl" else []
    cfg = load_config("semicircle", ["platform.system=" + system, *SNR_TABLE, *own, "simulation.duration=10"],
                      seed=4)
    box = plan_module.ray_box(cfg)
    arms = make_plan(cfg).lever_arms
    assert box[1] <= 20.0 and box[3] <= 20.0  # no node below the water depth
    if system == "lbl":  # seafloor transponders: the depth margin alone
        assert box[:2] == (arms[:, 2].min() - 1.0, 20.0)
    else:  # vessel-mounted ones: the heave of Beaufort 5 (about a metre) widens it beyond the margin
        assert box[1] > arms[:, 2].max() + 1.5
    table = make_plan(cfg).parameters["acoustics"]
    assert table["ray_family_rows"] == 512 and not any(table[f"ray_family_exact[{k}]"] for k in range(1, 513))
    a = both_engines(cfg, fmu_dir).timeseries
    monkeypatch.setattr(plan_module, "ray_box", lambda cfg: None)  # no box: every eigenray solved
    b = run(cfg, "local", replicates=[0, 1]).timeseries
    heard = (a["arrival"] > 0) & (b["arrival"] > 0)
    assert heard.sum() > 40
    same = heard & (a["arrival"] == b["arrival"])
    assert same.sum() >= 0.98 * heard.sum()
    assert (a["arrival"] > 1).any()  # a reflected path ranges too
    assert (a["travel_time"] - b["travel_time"])[same].abs().max() <= 1e-6
    assert (a["travel_time"] != b["travel_time"])[same].any()  # interpolated, not solved
    assert (a["snr"] - b["snr"])[same].abs().max() <= 0.02


def test_the_channel_fmu_of_eigenrays_validates(fmu_dir):
    """The channel FMU that runs ``ray`` (the same FMU: the choice is a parameter) passes fmpy's validation and
    declares the propagation (0 straight, 1 ray), the water depth [m] and the eigenray's outputs."""
    from fmpy import read_model_description

    from sblsim.fmus.build import fmu_path, validate

    path = fmu_path(fmu_dir, "acoustics")
    assert validate(path) == []
    variables = {v.name: v for v in read_model_description(str(path)).modelVariables}
    propagation, depth = variables["propagation"], variables["water_depth"]
    assert (propagation.causality, propagation.type, propagation.start, propagation.min, propagation.max) == \
        ("parameter", "Integer", "0", "0", "1")
    assert "0: straight, 1: ray" in propagation.description
    assert (depth.causality, depth.type, depth.unit, float(depth.min), float(depth.max)) == \
        ("parameter", "Real", "m", 0.0, 11000.0)
    assert {(variables[n].causality, variables[n].unit) for n in ("launch_angle", "arrival_angle")} == \
        {("output", "rad")}
    assert (variables["arrival"].causality, variables["arrival"].type) == ("output", "Integer")


def test_the_channel_fmu_declares_detection_by_snr(fmu_dir):
    """fmpy validates an FMU's description, whatever its parameters are set to: the channel FMU that runs ``snr``
    is the one validated above (the choice is a parameter). It declares the detection (0 fixed, 1 snr), the
    issue's keys with their units and a range that holds their start, and the outputs ``snr`` [dB] and
    ``detection_probability``."""
    from fmpy import read_model_description

    from sblsim.fmus.build import fmu_path

    variables = {v.name: v for v in read_model_description(str(fmu_path(fmu_dir, "acoustics"))).modelVariables}
    detection = variables["detection"]
    assert (detection.causality, detection.type, detection.start, detection.min, detection.max) == \
        ("parameter", "Integer", "0", "0", "1")
    assert "0: fixed, 1: snr" in detection.description
    units = {"frequency": "Hz", "bandwidth": "Hz", "source_level": "dB", "detection_threshold": "dB",
             "directivity_index": "dB", "shipping": "1"}
    for name, unit in units.items():
        v = variables[name]
        assert (v.causality, v.type, v.unit) == ("parameter", "Real", unit), name
        assert float(v.min) <= float(v.start) <= float(v.max), name
    assert (float(variables["shipping"].min), float(variables["shipping"].max)) == (0.0, 1.0)
    assert "0: clay" in variables["bottom"].description and variables["bottom"].type == "Integer"
    assert {(variables[n].causality, variables[n].unit) for n in ("snr", "detection_probability")} == \
        {("output", "dB"), ("output", "1")}

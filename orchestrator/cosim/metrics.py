"""Position-error and consistency metrics (docs/model.md, "Metrics").

Per step: ``e_x = |x − x̂|``, ``e_y``, ``e_z`` and
``e_tot = sqrt(e_x² + e_y² + e_z²)``; per run: the time-average of each, the
RMS of e_tot and its standard deviation (population, ddof = 0). Steps where an
estimate is not available (NaN: a receiver's estimate before its first fix, which
is never its starting guess, or no instrumentation fix yet) are left out.

Consistency (Bar-Shalom, Li, Kirubarajan, Estimation with Applications to
Tracking and Navigation, Wiley 2001, Section 5.4): the position NEES
``ε = eᵀ P⁻¹ e`` (3 degrees of freedom, e = truth − estimate, P the reported
position covariance) per step, its mean ``nees_mean`` (3 for a consistent
filter) and ``coverage_95``, the share of steps with ε ≤ χ²₃(0.95) = 7.815
(the truth inside the 95 % ellipsoid; 0.95 for a consistent filter); steps
where P is not positive-definite are left out. ``nis_mean`` is the mean of
the receiver's ``nis`` output from the first slot on; ``gated_pct`` the share
of received slots whose range the gate rejected [%]; ``pcrb_rms`` the RMS of
the position PCRB (:mod:`sblsim.models.bound`) over the steps ``e_tot_rms``
averages, those with an estimate (:func:`bound_rms`): the two are comparable
(over every step it would count the first steps, where the bound is still the
prior, and the error does not). The PCRB itself is stepped from the start of
the run, whatever the receiver (it takes every slot from the first); receivers
whose first fix differs average it over different steps, so their
``pcrb_rms`` differ a little while their per-step bound is the same.
``diverged`` flags a run whose receiver lost the diver: an estimate that is
not finite after its first fix, or farther from the truth than both
:data:`DIVERGENCE_DISTANCE` and :data:`DIVERGENCE_RATIO` times the diver's
distance from the platform, or, by the receiver's own statistics, a run of
:data:`DIVERGENCE_REJECTIONS` received packets in a row that its NIS gate
rejected (every new measurement inconsistent with the estimate and with the
one before it: the receiver knows it has lost track; a receiver without a
gate, the paper's ``ekf``, is judged by its error alone); its other numbers
then mean nothing (an overconfident but tracking receiver is not flagged:
its NEES says so).

Two flags say when the numbers are not what they seem (:func:`run_flags`):
``updates`` counts the slots whose received range the receiver used (new,
received, not gated) and ``fix_steps`` the steps with a multilateration fix
(``instr_valid``); with no update the receiver never made a fix and reports
no estimate (NaN: its error metrics are NaN). And
``beyond_geometry`` flags a diver farther from the platform reference
(``max_distance``, horizontal) than :data:`REACH_RATIO` times the beacons'
horizontal spread: the horizontal position comes from range differences
across that spread, so its error grows about as σ_r · distance / spread: at
100 times the spread a centimetre of range noise is a metre across, and the
run measures the limit of the geometry (its ``pcrb_rms`` says how large),
not a divergence of the receiver.

The numpy functions here define the metrics and are the reference;
:func:`run_metrics` computes every per-run metric (and the PCRB) of a batch
in one compiled pass over the recorded outputs (``fmus/c/sblsim_metrics.c``),
without numpy's temporaries: the engines use it, a test holds it to these.
The names of the metrics and of the columns they read (``METRIC_NAMES``,
``RUN_METRICS``, ``METRIC_INPUTS``) are defined in :mod:`sblsim.models.columns`,
which the FMU build reads too.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from sblsim.fmus import compiled_metrics
from sblsim.models.columns import LANE_FIELDS, LANE_METRIC_INPUTS, METRIC_INPUTS, METRIC_NAMES, RUN_METRICS

#: A receiver has diverged when an estimate is not finite, or farther from the truth than this [m] and than
#: :data:`DIVERGENCE_RATIO` times the diver's distance from the platform reference, or when its own gate rejected
#: :data:`DIVERGENCE_REJECTIONS` received packets in a row (its own statistics: every new measurement disagrees
#: with its estimate, and with the one before, :func:`sblsim.models.receiver.gate.gate`).
DIVERGENCE_DISTANCE, DIVERGENCE_RATIO, DIVERGENCE_REJECTIONS = 100.0, 10.0, 10
#: A diver farther from the platform reference (horizontally) than this many times the beacons' horizontal
#: spread is beyond what the geometry serves (``beyond_geometry``; the command line warns).
REACH_RATIO = 100.0
#: Per-run flags computed besides the compiled pass (:func:`run_flags`; ``slot_overrun`` is the channel's own
#: output, :func:`sblsim.orchestrator.cosim.run.slot_overrun`): in ``summary.json`` and in a campaign's rows.
FLAG_NAMES = ("updates", "fix_steps", "max_distance", "beyond_geometry", "detected_pct", "slot_overrun")
#: χ²₃(0.95): the NEES inside the 95 % ellipsoid of a 3-D position, ``scipy.stats.chi2.ppf(0.95, 3)`` written out
#: (a test holds it to scipy's), so that a campaign's worker processes need not import scipy.stats.
NEES_95 = 7.814727903251179


def run_metrics(columns: Mapping[str, np.ndarray], fixed: np.ndarray, arms: np.ndarray,
                with_bound: bool = False) -> tuple[dict[str, np.ndarray], np.ndarray | None]:
    """Every per-run metric of B runs (:data:`RUN_METRICS`) in one compiled pass, and the PCRB.

    Parameters
    ----------
    columns : mapping of str to ndarray, shape (N, B)
        Every name of :data:`METRIC_INPUTS` -> its recorded values as floats (Boolean and Integer outputs
        as the master records them: 0/1 and whole numbers), and those of :data:`LANE_METRIC_INPUTS` that were
        recorded (a lane missing: no packet on it). A packet on a later lane of a delivery is a slot of the bound
        at the step's end, after lane 1's, with no prediction between them (as the receivers take it).
    fixed : ndarray, shape (B, 8)
        The bound's per-run inputs (:data:`sblsim.models.bound.FIXED`).
    arms : ndarray, shape (B, n_beacons, 3)
        Each run's beacon lever arms in NED [m].
    with_bound : bool
        Also return the position PCRB at every step.

    Returns
    -------
    metrics : dict
        Name -> array (B,), as :func:`summarize` (receiver and ``instr_``) and :func:`consistency` give them
        (equal to rounding: each run is summed in time order).
    bound : ndarray, shape (N, B), or None
        ``sqrt(trace)`` of the position PCRB [m] (:func:`sblsim.models.bound.pcrb`).
    """
    limits = (NEES_95, DIVERGENCE_DISTANCE, DIVERGENCE_RATIO, DIVERGENCE_REJECTIONS)
    shape = np.shape(columns[METRIC_INPUTS[0]])
    none = np.broadcast_to(np.zeros(shape[1:]), shape)  # a lane not recorded: no packet on it (read in place)
    values, bound = compiled_metrics.run_metrics([columns[name] for name in METRIC_INPUTS]
                                       + [columns.get(name, none) for name in LANE_METRIC_INPUTS],
                                       fixed, arms, limits, with_bound, n_beacons=arms.shape[1])
    out = {name: values[:, k] for k, name in enumerate(RUN_METRICS)}
    out["diverged"] = out["diverged"] > 0.5
    return out, bound


def errors(truth: np.ndarray, estimate: np.ndarray) -> np.ndarray:
    """Per-step errors.

    Parameters
    ----------
    truth, estimate : ndarray, shape (..., 3)
        Positions [m].

    Returns
    -------
    ndarray, shape (..., 4)
        ``e_x, e_y, e_z, e_tot`` [m].
    """
    e = np.abs(truth - estimate)
    return np.concatenate([e, np.sqrt(np.sum(e * e, axis=-1, keepdims=True))], axis=-1)


def summarize(err: np.ndarray, prefix: str = "") -> dict[str, np.ndarray]:
    """Run metrics from per-step errors.

    Parameters
    ----------
    err : ndarray, shape (N, B, 4)
        Per-step ``e_x, e_y, e_z, e_tot`` of B runs [m].
    prefix : str
        Prefix of the metric names (``instr_`` for the instrumentation).

    Returns
    -------
    dict
        Metric name -> array of shape (B,) [m]; NaN for a run with no valid step.
    """
    # run-major, time contiguous: every run is summed in the same order whatever B is
    err = np.ascontiguousarray(np.moveaxis(np.asarray(err, dtype=float), 0, -1))  # (B, 4, N)
    valid = np.all(np.isfinite(err), axis=1)  # (B, N)
    count = valid.sum(axis=-1)
    safe = np.where(valid[:, None, :], err, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = safe.sum(axis=-1) / count[:, None]
        rms = np.sqrt((safe[:, 3] ** 2).sum(axis=-1) / count)
        var = np.where(valid, (safe[:, 3] - mean[:, 3:4]) ** 2, 0.0).sum(axis=-1) / count
    values = (mean[:, 0], mean[:, 1], mean[:, 2], mean[:, 3], rms, np.sqrt(var))
    return {prefix + name: v for name, v in zip(METRIC_NAMES, values)}


def nees(err: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """Position NEES ``eᵀ P⁻¹ e`` per step.

    Parameters
    ----------
    err : ndarray, shape (..., 3)
        Signed errors truth − estimate [m].
    cov : ndarray, shape (..., 6)
        Reported covariance ``xx, xy, xz, yy, yz, zz`` [m²].

    Returns
    -------
    ndarray, shape (...)
        NEES [1]; NaN where the covariance is not positive-definite (e.g. a
        receiver reporting zeros before its first fix).
    """
    e0, e1, e2 = np.moveaxis(np.asarray(err, dtype=float), -1, 0)
    xx, xy, xz, yy, yz, zz = np.moveaxis(np.asarray(cov, dtype=float), -1, 0)
    # P⁻¹ = adj(P) / det(P) by cofactors; Sylvester's criterion: every leading principal minor positive
    c00, c11, c22 = yy * zz - yz * yz, xx * zz - xz * xz, xx * yy - xy * xy
    c01, c02, c12 = xz * yz - xy * zz, xy * yz - xz * yy, xy * xz - xx * yz
    det = xx * c00 + xy * c01 + xz * c02
    pd = (xx > 0) & (c22 > 0) & (det > 0)
    quadratic = e0 * e0 * c00 + e1 * e1 * c11 + e2 * e2 * c22 + 2.0 * (e0 * e1 * c01 + e0 * e2 * c02 + e1 * e2 * c12)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(pd, quadratic / det, np.nan)


def slots(packet_seq: np.ndarray, received: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steps with a new acoustic slot, and those whose packet was received.

    Parameters
    ----------
    packet_seq : ndarray, shape (N, B)
        The acoustic channel's slot counter at each step (0: none yet).
    received : ndarray of bool, shape (N, B)
        Packet valid with a beacon of the array.

    Returns
    -------
    slot, fresh : ndarray of bool, shape (N, B)
    """
    seq = np.asarray(packet_seq)
    previous = np.concatenate([np.zeros_like(seq[:1]), seq[:-1]])
    slot = seq != previous
    return slot, slot & np.asarray(received, bool)


def new_on_lane(packet_seq: np.ndarray) -> np.ndarray:
    """The steps at which a later lane of a delivery holds a new packet: its counter not 0 (an empty lane) and not
    the last packet the lane held (an empty lane keeps it in mind, as the receivers do).

    Parameters
    ----------
    packet_seq : ndarray, shape (N, ...)
        The lane's slot counter at each step (0: empty).

    Returns
    -------
    ndarray of bool, shape (N, ...)
    """
    seq = np.asarray(packet_seq)
    steps = np.arange(seq.shape[0]).reshape((-1,) + (1,) * (seq.ndim - 1))
    last = np.maximum.accumulate(np.where(seq > 0, steps, -1), axis=0)  # the last step that held a packet
    before = np.concatenate([np.full_like(last[:1], -1), last[:-1]])
    held = np.where(before >= 0, np.take_along_axis(seq, np.maximum(before, 0), axis=0), 0)
    return (seq > 0) & (seq != held)


def new_pings(packet_seqs: Sequence[np.ndarray], slots_taken: Sequence[np.ndarray], n_beacons: int) -> list[np.ndarray]:
    """The slots whose packet is the first a receiver takes of a new ping of an inverted LBL (its ping, ``⌈seq /
    n⌉``, not the previous slot's), as the receivers find them: the slots in the order they are taken, step by step
    and in each step lane by lane.

    Parameters
    ----------
    packet_seqs, slots_taken : sequence of ndarray, shapes (N, B)
        Per lane of a delivery (lane 1 first), its slot counter and the steps it holds a slot the receiver takes
        (:func:`slots`, :func:`lane_slots`).
    n_beacons : int
        The receivers of the array.

    Returns
    -------
    list of ndarray of bool, shapes (N, B)
        Per lane.
    """
    ping = np.stack([np.where(taken, np.ceil(np.asarray(seq, dtype=float) / n_beacons), np.nan)
                     for seq, taken in zip(packet_seqs, slots_taken)], axis=1)  # (N, L, B)
    shape = ping.shape
    flat = ping.reshape(shape[0] * shape[1], shape[2])  # in the order they are taken
    index = np.where(np.isnan(flat), -1, np.arange(flat.shape[0])[:, None])
    last = np.maximum.accumulate(index, axis=0)
    before = np.concatenate([np.full_like(last[:1], -1), last[:-1]])
    previous = np.where(before >= 0, np.take_along_axis(flat, np.maximum(before, 0), axis=0), np.nan)
    new = ~np.isnan(flat) & (flat != previous)
    return list(new.reshape(shape).transpose(1, 0, 2))


def lane_slots(columns: Mapping[str, np.ndarray], n_beacons: int) -> list[tuple[int, np.ndarray, np.ndarray]]:
    """Per later lane m of a delivery recorded in ``columns`` (``lane<m>_packet_seq``, ``_packet_valid``,
    ``_beacon_id``, (N, B) each): ``(m, new, fresh)``, the steps with a new packet on it (not 0, not the last one
    it held) and those whose packet was received from a beacon of the array, as :func:`slots` gives them for
    lane 1."""
    out = []
    for lane, name in enumerate(LANE_METRIC_INPUTS[::len(LANE_FIELDS)], start=2):
        prefix = name[:-len("packet_seq")]
        if name not in columns:
            continue
        new = new_on_lane(columns[name])
        beacon = np.asarray(columns[prefix + "beacon_id"])
        received = (np.asarray(columns[prefix + "packet_valid"]) > 0.5) & (beacon >= 1) & (beacon <= n_beacons)
        out.append((lane, new, new & received))
    return out


def rejected_run(rejected: np.ndarray, fresh: np.ndarray) -> np.ndarray:
    """The longest run of received packets in a row that the gate rejected, per run.

    Parameters
    ----------
    rejected, fresh : ndarray of bool, shape (B, N)
        Run-major: received packets the gate rejected, and received packets.

    Returns
    -------
    ndarray of int, shape (B,)
    """
    longest = np.zeros(rejected.shape[0], dtype=np.int64)
    for r in range(rejected.shape[0]):
        count = 0
        for gated in rejected[r][fresh[r]]:
            count = count + 1 if gated else 0
            longest[r] = max(longest[r], count)
    return longest


def bound_rms(bound: np.ndarray, estimated: np.ndarray) -> np.ndarray:
    """``pcrb_rms``: the RMS of the position PCRB over the steps with an estimate, those ``e_tot_rms`` averages.

    Parameters
    ----------
    bound : ndarray, shape (N, B)
        Position PCRB ``sqrt(trace)`` at each step [m] (NaN: not available).
    estimated : ndarray of bool, shape (N, B)
        The steps whose estimate is finite (none before a receiver's first fix).

    Returns
    -------
    ndarray, shape (B,)
        [m]; NaN for a run without an estimate.
    """
    bound = np.ascontiguousarray(np.asarray(bound, dtype=float).T)  # run-major: each run summed in time order
    estimated = np.ascontiguousarray(np.asarray(estimated, dtype=bool).T)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(np.where(estimated, bound * bound, 0.0).sum(axis=-1) / estimated.sum(axis=-1))


def consistency(err: np.ndarray, cov: np.ndarray, nis: np.ndarray, packet_seq: np.ndarray, fresh: np.ndarray,
                gated: np.ndarray, bound: np.ndarray, truth: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Consistency metrics of B runs (:data:`CONSISTENCY_NAMES`).

    Parameters
    ----------
    err : ndarray, shape (N, B, 3)
        Signed errors truth − estimate [m].
    cov : ndarray, shape (N, B, 6)
        Reported position covariance [m²].
    nis : ndarray, shape (N, B)
        The receiver's ``nis`` output.
    packet_seq : ndarray, shape (N, B)
        Slot counter (0 before the first slot).
    fresh : ndarray of bool, shape (N, B)
        Steps with a new, received slot (:func:`slots`).
    gated : ndarray of bool, shape (N, B)
        The receiver's ``gated`` output.
    bound : ndarray, shape (N, B)
        Position PCRB ``sqrt(trace)`` [m] (NaN: not available); ``pcrb_rms`` its RMS over the steps with an
        estimate (:func:`bound_rms`).
    truth : ndarray, shape (N, B, 3), optional
        True positions relative to the platform reference [m] (for the divergence test; default: at it).

    Returns
    -------
    dict
        Name -> array (B,); NaN where a metric has no step to average.
    """
    def runs(values, dtype=float):  # run-major, time contiguous: each run summed in the same order whatever B is
        return np.ascontiguousarray(np.asarray(values, dtype=dtype).T)

    e = runs(nees(err, cov))
    error = runs(np.sqrt(np.sum(np.asarray(err, dtype=float) ** 2, axis=-1)))
    reach = 0.0 if truth is None else runs(np.sqrt(np.sum(np.asarray(truth, dtype=float) ** 2, axis=-1)))
    fixed = np.logical_or.accumulate(np.isfinite(error), axis=-1)  # from the first fix on (NaN before it)
    lost = (fixed & ~np.isfinite(error)) | ((error > DIVERGENCE_DISTANCE) & (error > DIVERGENCE_RATIO * reach))
    lost = lost.any(axis=-1) | (rejected_run(runs(fresh, bool) & runs(gated, bool), runs(fresh, bool))
                                >= DIVERGENCE_REJECTIONS)
    valid = np.isfinite(e)
    count = valid.sum(axis=-1)
    started = runs(packet_seq) > 0
    fresh = runs(fresh, bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        return {
            "nees_mean": np.where(valid, e, 0.0).sum(axis=-1) / count,
            "coverage_95": (valid & (e <= NEES_95)).sum(axis=-1) / count,
            "nis_mean": np.where(started, runs(nis), 0.0).sum(axis=-1) / started.sum(axis=-1),
            "gated_pct": 100.0 * (fresh & runs(gated, bool)).sum(axis=-1) / fresh.sum(axis=-1),
            "pcrb_rms": bound_rms(bound, np.isfinite(error).T),
            "diverged": lost,
        }


def run_flags(columns: Mapping[str, np.ndarray], spread: np.ndarray, n_beacons: int) -> dict[str, np.ndarray]:
    """Per-run flags (:data:`FLAG_NAMES`) of B runs from their recorded outputs.

    Parameters
    ----------
    columns : mapping of str to ndarray, shape (N, B)
        ``packet_seq``, ``packet_valid``, ``beacon_id``, ``gated``, ``instr_valid``, ``true_x`` and
        ``true_y`` as recorded (floats).
    spread : ndarray, shape (B,)
        Each run's largest horizontal distance between two beacons [m]
        (:func:`sblsim.models.platform.geometry.horizontal_spread`).
    n_beacons : int
        Beacons of the array (ids 1 … n).

    Returns
    -------
    dict
        ``updates`` (int, slots whose received range the receiver used; a packet on a later lane of a
        delivery, in ``columns`` as ``lane<m>_packet_seq``, ``_packet_valid``, ``_beacon_id`` where recorded, counts
        as used: its gate decision is not an output), ``fix_steps`` (int, steps with a
        multilateration fix), ``max_distance`` (largest horizontal distance of the diver from the platform
        reference [m]), ``beyond_geometry`` (bool, ``max_distance > REACH_RATIO · spread``) and ``detected_pct``
        (the share of the slots sent whose packet was received [%]; NaN before the first slot), each (B,).
    """
    beacon = np.asarray(columns["beacon_id"])
    received = (np.asarray(columns["packet_valid"]) > 0.5) & (beacon >= 1) & (beacon <= n_beacons)
    slot, fresh = slots(columns["packet_seq"], received)
    updates = (fresh & ~(np.asarray(columns["gated"]) > 0.5)).sum(axis=0)
    sent, heard = slot.sum(axis=0), fresh.sum(axis=0)
    for _, lane_slot, lane_fresh in lane_slots(columns, n_beacons):  # the gate's decision is lane 1's alone
        sent, heard = sent + lane_slot.sum(axis=0), heard + lane_fresh.sum(axis=0)
        updates = updates + lane_fresh.sum(axis=0)
    fix_steps = (np.asarray(columns["instr_valid"]) > 0.5).sum(axis=0)
    distance = np.hypot(np.asarray(columns["true_x"], dtype=float), np.asarray(columns["true_y"], dtype=float))
    reach = distance.max(axis=0) if distance.shape[0] else np.zeros(distance.shape[1:])
    with np.errstate(invalid="ignore", divide="ignore"):
        detected = 100.0 * heard / sent
    return {"updates": updates.astype(np.int64), "fix_steps": fix_steps.astype(np.int64), "max_distance": reach,
            "beyond_geometry": reach > REACH_RATIO * np.asarray(spread, dtype=float), "detected_pct": detected}

"""The motion noise's EM (models/tracking/motion_noise.py) on a long record: its E-steps over windows of the record
(``em_windows``, each window's schedule ``PingSchedule.rows``) estimate the same ``q`` as over the whole record,
at the cost of the windows' pings."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sblsim.models.receiver import toa_tracking as tt
from sblsim.models.receiver.toa_bound import predict
from sblsim.models.tracking import motion_noise
from sblsim.models.tracking.schedule import PingSchedule
from sblsim.models.tracking.starts import anchored_start
from sblsim.models.tracking.timing import SIGMA_TOA


def test_the_windows_are_the_whole_record_or_spread_evenly_over_it():
    """Up to ``EM_PINGS`` pings the whole record; beyond, ``EM_WINDOWS`` windows of equal size, ``EM_PINGS`` pings
    together, inside the record, not overlapping, each centred in its quarter (checked by arithmetic here)."""
    pings, count = motion_noise.EM_PINGS, motion_noise.EM_WINDOWS
    assert motion_noise.em_windows(pings) == [(0, pings)]
    for m in (pings + 1, 3 * pings, 10**6 + 7):
        windows = motion_noise.em_windows(m)
        sizes = [b - a for a, b in windows]
        assert len(windows) == count and set(sizes) == {pings // count} and sum(sizes) <= pings
        assert windows[0][0] >= 0 and windows[-1][1] <= m
        assert all(b <= a for (_, b), (a, _) in zip(windows, windows[1:]))
        for k, (a, b) in enumerate(windows):
            assert abs((a + b) / 2 - (k + 0.5) * m / count) <= 1.0


def test_a_window_s_schedule_is_its_rows_steps_and_gaps():
    """``PingSchedule.rows(a, b)``: the steps between the rows a to b − 1 (their durations, intervals, offsets and
    sigmas) and the gaps among them, renumbered from a; the times its rows' own, from the first."""
    rng = np.random.default_rng(3)
    m = 40
    schedule = PingSchedule("rbi", 30.0, rng.integers(0, 3, m - 1).astype(float), rng.uniform(20, 40, m - 1),
                            rng.uniform(1e-3, 2e-3, m - 1), rng.uniform(1e-4, 2e-4, m - 1), gaps=(4, 17, 30))
    part = schedule.rows(10, 31)
    assert len(part.count) == 20 and part.gaps == (7,)  # the step 30 leads out of the rows: not theirs
    np.testing.assert_array_equal(part.steps(31.0), schedule.steps(31.0)[10:30])
    np.testing.assert_array_equal(part.te_sigma, schedule.te_sigma[10:30])
    np.testing.assert_array_equal(part.drift_sigma, schedule.drift_sigma[10:30])
    np.testing.assert_allclose(part.times(), schedule.times()[10:31] - schedule.times()[10], rtol=0, atol=1e-9)
    assert part.segments() == [(0, 8), (8, 21)]
    assert schedule.rows(0, m).gaps == schedule.gaps and len(schedule.rows(5, 6).count) == 0


def _expected_process_error(x, P, lag, count, offset, dim):
    """E[w_k w_kᵀ] of each step (m − 1, s, s), as the module docstring writes it, a step at a time in plain matrices:
    ``F_k`` built here from the motion model (``p ← p + T v``, ``t_e ← t_e + T``, T = n Δ + o), not taken from the
    module."""
    s = 2 * dim + 2
    out = np.empty((len(x) - 1, s, s))
    for k in range(len(x) - 1):
        T = count[k] * x[k, -1] + offset[k]
        F = np.eye(s)
        F[:dim, dim:2 * dim] = T * np.eye(dim)
        F[:dim, -1] = count[k] * x[k, dim:2 * dim]
        F[-2, -1] = count[k]
        f = x[k].copy()
        f[:dim] += T * x[k, dim:2 * dim]
        f[-2] += T
        w = x[k + 1] - f
        out[k] = np.outer(w, w) + P[k + 1] + F @ P[k] @ F.T - lag[k] @ F.T - F @ lag[k].T
    return out


def test_the_m_step_is_the_closed_form_of_the_expected_process_error():
    """``m_step``'s q against the closed form (module docstring) computed here step by step (each step's unit-q
    covariance inverted alone, the traces summed over the axes' (position, velocity) blocks) on random smoothed
    states, covariances and lag-one covariances in 2-D and 3-D; and to the last bit against the same expectation
    made as one (s, s) matrix a step and its blocks gathered (as the M-step was written first): its block of each axis
    alone must be laid out as that gather lays it out, or the trace's sum moves a last bit (mutation checked: 3 of
    these 40 cases)."""
    for seed in range(20):
        for dim in (2, 3):
            s, rng = 2 * dim + 2, np.random.default_rng(seed)
            m = 3000 if seed % 5 else 40
            x = rng.normal(size=(m, s)) * rng.lognormal(size=(m, 1))
            P, lag = rng.normal(size=(m, s, s)), rng.normal(size=(m - 1, s, s))
            count, offset = rng.integers(1, 3, m - 1).astype(float), rng.normal(size=m - 1)
            steps = rng.uniform(1.0, 30.0, m - 1)
            q = motion_noise.m_step(x, P, lag, steps, count, offset, dim)
            E = _expected_process_error(x, P, lag, count, offset, dim) if m <= 40 else None
            if E is not None:  # the independent closed form, a step at a time
                total = 0.0
                for k, T in enumerate(steps):
                    Ai = np.linalg.inv(np.array([[T**3 / 3, T**2 / 2], [T**2 / 2, T]]))
                    total += sum(np.trace(Ai @ E[k][np.ix_([a, dim + a], [a, dim + a])]) for a in range(dim))
                assert q == pytest.approx(total / ((m - 1) * 2 * dim), rel=1e-12)
            # the whole (s, s) expectation at once and its blocks gathered: the same bits
            predicted, F = predict(x[:-1], dim, count, offset)
            w = x[1:] - predicted
            whole = (np.einsum("ki,kj->kij", w, w) + P[1:] + np.einsum("kij,kjl,kml->kim", F, P[:-1], F)
                     - np.einsum("kij,klj->kil", lag, F) - np.einsum("kij,klj->kil", F, lag))
            A = np.stack([np.stack([steps**3 / 3, steps**2 / 2], -1), np.stack([steps**2 / 2, steps], -1)], -2)
            Ai, total = np.linalg.inv(A), np.zeros(m - 1)
            for a in range(dim):
                axis = [a, dim + a]
                total += np.einsum("kij,kji->k", Ai, whole[:, axis][:, :, axis])
            assert q == float(total.mean() / (2 * dim)), (seed, dim)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_em_over_windows_finds_the_whole_record_s_q(monkeypatch, seed):
    """8,000 pings of a tag whose velocity wanders as the motion model says (q = 10⁻³ m²/s³, a ping every 2.5 s,
    8 receivers, detection 0.8), EM from q = 10⁻²: over windows of a third of the record (4 of 666 pings) the
    estimate within 10 % of the whole record's (both about 1.2 times the truth: EM's own bias on this record, the
    same either way)."""
    angles = np.arange(8) * np.pi / 4
    receivers = 20000.0 * np.c_[np.cos(angles), np.sin(angles)]
    settings = tt.TrackerSettings(sound_speed=1480.0, sigma_toa=SIGMA_TOA, interval=2.5, acceleration_psd=1e-3)
    m = 8000
    toa, _, _ = tt.simulate_pings(receivers, m, settings, np.random.default_rng(seed), detection=0.8)
    fx, fe, _, fused, _ = tt.fix_pings(toa, receivers, 1480.0, SIGMA_TOA)
    schedule = PingSchedule.stable(m, 2.5, settings.jitter, settings.interval_drift)
    start = anchored_start((fx, fe, fused), np.isfinite(toa).sum(axis=1), settings, 2, schedule.times())
    first = replace(settings, acceleration_psd=1e-2)
    whole = motion_noise.estimate_acceleration_psd(toa, receivers, first, start, schedule)
    monkeypatch.setattr(motion_noise, "EM_PINGS", m // 3)
    windows = motion_noise.estimate_acceleration_psd(toa, receivers, first, start, schedule)
    assert whole.windows == ((0, m),) and len(windows.windows) == motion_noise.EM_WINDOWS
    assert abs(np.log(windows.q / whole.q)) < 0.1, (windows.q, whole.q)
    assert 0.5 < whole.q / 1e-3 < 2.0 and 0.5 < windows.q / 1e-3 < 2.0, (whole.q, windows.q)

"""A sound speed the pings cannot calibrate is replaced by the fallback only with a warning line (issue 98 item 3):
the replay says it once (tests/orchestrator/test_tracking_medium.py), the study once per tag that took it
(orchestrator/telemetry/study_report.py ``tag_lines``); never silently."""

from __future__ import annotations

import numpy as np
import pandas as pd

from sblsim.orchestrator.telemetry.study_report import tag_lines
from sblsim.orchestrator.tracks.speed import REPLACED_SOURCE, sound_speed_stage


def test_a_failed_calibration_takes_the_fallback_with_its_reason():
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    tag = np.array([40.0, 30.0])
    toa = 10.0 + np.linalg.norm(receivers - tag, axis=1)[None, :] / 1480.0  # one ping: nothing to calibrate from
    _, speed, info = sound_speed_stage(toa, receivers)
    assert info["source"] == "fallback" and info["calibration"] and speed == info["sound_speed_m_s"]


def _row(tag: str, source: str, speed: float) -> dict:
    return {"transmitter": tag, "tag": tag, "status": "tracked", "reason": "", "reason_code": "", "pings": 10,
            "positioned": 10, "set_aside": 0, "not_positioned": 0, "not_positioned_why": "", "flagged": 0,
            "median_sigma_m": 1.0, "ping_type": "rbi", "ping_type_stated": "inferred", "sound_speed_m_s": speed,
            "sound_speed_source": source, "first_utc": "", "last_utc": "", "detections": 30}


def test_the_study_warns_for_each_tag_that_took_the_fallback():
    table = pd.DataFrame([_row("A", "calibrated", 1476.5), _row("B", "fallback", 1500.0),
                          _row("C", REPLACED_SOURCE, 1482.3)])
    warnings = [line for line, warning in tag_lines(table) if warning]
    assert len(warnings) == 2
    assert "tag B" in warnings[0] and "1500.0 m/s" in warnings[0] and "--sound-speed" in warnings[0]
    assert "tag C" in warnings[1] and "1482.3 m/s" in warnings[1]


def test_a_study_s_own_speed_is_the_fallback_where_no_water_is_stated():
    """Four receivers (a ping heard by four: nothing to calibrate): the study's speed fitted with its clocks (its σ)
    is the fallback in place of the default's, said as such; with the water's temperature and salinity stated,
    TEOS-10's prior stays; a calibration the pings determine is not touched."""
    from sblsim.models.tracking.sound_speed import fallback_prior
    from sblsim.orchestrator.tracks.speed import STUDY_SPEED

    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    tag = np.array([40.0, 30.0])
    toa = 10.0 + np.linalg.norm(receivers - tag, axis=1)[None, :] / 1480.0
    _, speed, info = sound_speed_stage(toa, receivers, study_speed=(1478.7, 6.1))
    assert (speed, info["sigma_m_s"], info["method"], info["source"]) == (1478.7, 6.1, STUDY_SPEED, "fallback")
    _, speed, info = sound_speed_stage(toa, receivers, temperature=10.0, salinity=35.0, study_speed=(1478.7, 6.1))
    assert (speed, info["sigma_m_s"]) == fallback_prior(10.0, 35.0)[:2] and info["method"] != STUDY_SPEED
    rng = np.random.default_rng(1)  # eight receivers, a tag crossing them: calibrated from its own pings
    eight = np.array([[0.0, 0.0], [150.0, 0.0], [150.0, 120.0], [0.0, 120.0], [75.0, 60.0], [40.0, 110.0],
                      [110.0, 15.0], [20.0, 60.0]])
    path = np.column_stack([10.0 + 2.0 * np.arange(300) * 0.4, 20.0 + 0.25 * np.arange(300)])
    times = 2.0 * np.arange(300)[:, None] + np.linalg.norm(path[:, None] - eight[None], axis=2) / 1480.0
    times = times + rng.normal(0.0, 1e-4, times.shape)
    plain = sound_speed_stage(times, eight)[2]
    with_study = sound_speed_stage(times, eight, study_speed=(1400.0, 1.0))[2]
    assert plain["source"] == with_study["source"] == "calibrated" and plain == with_study
    assert abs(plain["sound_speed_m_s"] - 1480.0) < 2.0

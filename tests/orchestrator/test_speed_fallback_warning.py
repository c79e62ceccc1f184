"""A sound speed the pings cannot calibrate is replaced by the fallback only with a warning line
(orchestrator/tracks/speed.py ``replaced_line``; issue 98 item 3): never silently."""

from __future__ import annotations

import numpy as np

from sblsim.orchestrator.tracks.speed import replaced_line, sound_speed_stage


def test_a_failed_calibration_takes_the_fallback_and_says_so():
    receivers = np.array([[0.0, 0.0], [100.0, 0.0], [0.0, 100.0], [100.0, 100.0]])
    tag = np.array([40.0, 30.0])
    toa = 10.0 + np.linalg.norm(receivers - tag, axis=1)[None, :] / 1480.0  # one ping: nothing to calibrate from
    _, speed, info = sound_speed_stage(toa, receivers)
    assert info["source"] == "fallback" and info["calibration"]
    line = replaced_line(info)
    assert line is not None and "\n" not in line and f"{speed:.1f} m/s" in line and info["calibration"] in line


def test_a_kept_calibration_or_a_given_speed_says_nothing():
    assert replaced_line({"source": "given", "sound_speed_m_s": 1480.0}) is None
    assert replaced_line({"source": "calibrated", "sound_speed_m_s": 1480.0}) is None

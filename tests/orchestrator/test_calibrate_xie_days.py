"""Survey A's other four days (Xie et al. 2023, their Figure 9) as built-in surveys, against the authors' script."""

from __future__ import annotations

import numpy as np
import pytest

from sblsim.orchestrator.surveys.calibrate import calibrate, load_survey

#: Per segment: North, East [m] of the transponder from the a-priori point and the pings kept, from the authors'
#: own script posALL.py of suruixie/sfg_gnssa_sw (commit 51e9b13), run outside sblsim on the same files:
#:     git show 51e9b13:posALL.py > /tmp/x/posALL.py   (and its five data/gnssa_data_*.txt into /tmp/x/data/)
#:     appended: print(json.dumps({day: (fK_tNEUsss[:, 1], fK_tNEUsss[:, 2], fK_counts)})) for K = 1 ... 4
#:     cd /tmp/x && MPLBACKEND=Agg python posALL.py
#: (rounded here to 0.01 mm).
AUTHORS = {
    "xie-2021-08-23-1065": [
        (-0.01809, -0.03593, 71),
        (0.02424, 0.00900, 65),
        (0.01919, 0.01153, 59),
        (-0.01957, 0.03848, 60),
        (0.02449, -0.00045, 58),
    ],
    "xie-2021-08-23-1063": [
        (0.01182, 0.02116, 95),
        (0.02570, 0.01501, 97),
        (0.02706, 0.02702, 101),
        (-0.00107, 0.02955, 104),
        (0.00145, 0.02502, 105),
        (0.01105, 0.02138, 104),
        (0.00465, 0.03749, 103),
        (-0.01431, 0.03626, 103),
        (-0.01176, 0.00349, 101),
        (0.00740, 0.00656, 101),
    ],
    "xie-2021-12-10": [
        (0.08804, 0.05602, 27),
        (0.07408, 0.00521, 24),
        (0.05801, -0.06800, 17),
        (-0.01660, -0.01393, 14),
        (0.07309, 0.02370, 16),
    ],
    "xie-2022-03-21": [
        (0.08595, -0.01281, 35),
        (0.07128, 0.00984, 35),
        (0.07725, -0.01076, 37),
        (0.07815, 0.02469, 43),
        (0.01131, -0.06286, 29),
    ],
}


@pytest.mark.parametrize("name", sorted(AUTHORS))
def test_each_segment_equals_the_authors_script(name):
    result = calibrate(load_survey(name))
    segments = result.solution["segments"]
    want = np.array(AUTHORS[name])
    assert len(segments) == len(want)
    got_ne = np.array([[s["n_m"], s["e_m"]] for s in segments])
    np.testing.assert_allclose(got_ne, want[:, :2], atol=1e-3)  # the issue asks for 1 cm; they agree to 0.4 mm
    assert [s["pings_used"] for s in segments] == want[:, 2].astype(int).tolist()
    # the combination is a weighted mean of the segments: inside their range
    t = result.solution["transponders"][0]
    assert got_ne[:, 0].min() <= t["n_m"] <= got_ne[:, 0].max()
    assert got_ne[:, 1].min() <= t["e_m"] <= got_ne[:, 1].max()


def test_the_distance_limit_is_applied_to_the_transmit_points():
    """2021-12-10 uses transmit points within 120 m of the a-priori point; without the limit the segments hold more."""
    limited = calibrate(load_survey("xie-2021-12-10"))
    frame = limited.survey.log.frame
    used = limited.residuals
    assert np.all(np.hypot(used["tx_e_m"], used["tx_n_m"]) <= 120.0)
    assert (np.hypot(frame["tx_e_m"], frame["tx_n_m"]) > 120.0).any()
    wide = calibrate(load_survey("xie-2021-12-10", overrides=["solver.distance_limit_m=100000"]))
    assert len(wide.residuals) > len(used)

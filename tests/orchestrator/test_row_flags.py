"""A tag's rows flagged after its estimators made them (orchestrator/tracks/row_flags.py): a reason added to a
row's, the reasons counted, and the rows whose pings lie where the clocks are interpolated across a stretch of too
few pings flagged ``clocks_interpolated`` in every estimator, by ``track`` too, each against a selection made here."""

from __future__ import annotations

import numpy as np
import pandas as pd

from sblsim.orchestrator.tracks.row_flags import INTERPOLATED_REASON, flag_interpolated, reason_counts, with_reason
from sblsim.orchestrator.tracks.track import track

ORIGIN = 1.7e9


def test_a_reason_is_added_to_a_row_s_and_counted():
    reason = pd.Series(["", "untrusted_fix", "a;b"])
    added = with_reason(reason, "c")
    assert added.tolist() == ["c", "untrusted_fix;c", "a;b;c"]
    assert reason_counts(added) == {"c": 3, "untrusted_fix": 1, "a": 1, "b": 1}
    assert reason_counts(pd.Series(["", ""])) == {}


def test_the_rows_inside_a_stretch_are_flagged_in_every_estimator():
    """Rows strictly inside a stretch flagged with the reason added to any they had, the count of each estimator's
    flagged rows made again; rows at a stretch's ends or outside untouched; nothing without a UTC time."""
    t = np.arange(0.0, 100.0, 5.0)
    frames = {name: pd.DataFrame({"ping": np.arange(len(t)), "time": t, "quality": "ok", "quality_reason": ""})
              for name in ("robust", "ekf")}
    frames["ekf"].loc[[3, 12], ["quality", "quality_reason"]] = ["flagged", "untrusted_fix"]
    flagged = {"robust": 0, "ekf": 2}
    stretches = [(ORIGIN + 10.0, ORIGIN + 30.0), (ORIGIN + 60.0, ORIGIN + 62.0)]
    assert flag_interpolated(frames, dict(flagged), stretches, None) == 0
    marked = flag_interpolated(frames, flagged, stretches, ORIGIN)
    inside = ((t > 10.0) & (t < 30.0)) | ((t > 60.0) & (t < 62.0))
    assert marked == inside.sum() == 3
    for name, frame in frames.items():
        has = frame["quality_reason"].str.contains(INTERPOLATED_REASON).to_numpy()
        assert np.array_equal(has, inside) and (frame["quality"][inside] == "flagged").all(), name
        assert flagged[name] == (frame["quality"] == "flagged").sum()
    assert frames["ekf"]["quality_reason"][3] == "untrusted_fix;" + INTERPOLATED_REASON
    assert frames["ekf"]["quality_reason"][12] == "untrusted_fix"


def test_a_track_flags_its_rows_where_the_clocks_are_interpolated(tmp_path):
    """A tag crossing eight receivers, a ping every 2 s, tracked with a stretch of interpolated clocks from its 20th
    to its 40th second: exactly the rows whose emission (``epoch_s``) lies inside it are flagged
    ``clocks_interpolated``, in the track and each estimator, and counted in the summary's reasons; the same track
    without the stretch has no such row and the same places."""
    rng = np.random.default_rng(4)
    receivers = np.array([[0.0, 0.0], [150.0, 0.0], [150.0, 120.0], [0.0, 120.0], [75.0, 60.0], [40.0, 110.0],
                          [110.0, 15.0], [20.0, 60.0]])
    names = [f"R{k + 1}" for k in range(len(receivers))]
    t = 10.0 + 2.0 * np.arange(40)
    xy = np.column_stack([30.0 + 0.8 * np.arange(40), 25.0 + 0.5 * np.arange(40)])
    toa = t[:, None] + np.linalg.norm(xy[:, None] - receivers[None], axis=2) / 1480.0 + rng.normal(0, 1e-4, (40, 8))
    pd.DataFrame(toa, columns=names).to_csv(tmp_path / "toa.csv", index=False, float_format="%.9f")
    pd.DataFrame({"name": names, "x_m": receivers[:, 0], "y_m": receivers[:, 1]}).to_csv(tmp_path / "receivers.csv",
                                                                                         index=False)
    common = {"sound_speed": 1480.0, "acceleration_psd": 1e-3, "time_origin": ORIGIN}
    plain = track(tmp_path / "toa.csv", tmp_path / "receivers.csv", **common)
    bent = track(tmp_path / "toa.csv", tmp_path / "receivers.csv", **common,
                 clocks_interpolated=[(ORIGIN + 30.0, ORIGIN + 50.0)])
    inside = (bent.track["epoch_s"] > ORIGIN + 30.0) & (bent.track["epoch_s"] < ORIGIN + 50.0)
    assert 5 <= inside.sum() <= 15
    assert np.array_equal(bent.track["quality_reason"].str.contains(INTERPOLATED_REASON), inside)
    assert (bent.track["quality"][inside] == "flagged").all()
    for name, rows in bent.estimates.groupby("estimator"):
        within = (rows["time"] + ORIGIN > ORIGIN + 30.0) & (rows["time"] + ORIGIN < ORIGIN + 50.0)
        assert np.array_equal(rows["quality_reason"].str.contains(INTERPOLATED_REASON), within), name
    assert bent.summary["flag_reasons"][INTERPOLATED_REASON] == inside.sum()
    assert INTERPOLATED_REASON not in plain.summary["flag_reasons"]
    assert not plain.track["quality_reason"].str.contains(INTERPOLATED_REASON).any()
    assert np.array_equal(plain.track[["x", "y"]].to_numpy(), bent.track[["x", "y"]].to_numpy())

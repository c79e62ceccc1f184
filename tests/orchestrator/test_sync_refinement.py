"""``sync --refine-positions`` only where the sync tags determine the positions: a sparse sync array's refinement
refused in one line (exit 2, nothing written), and the refinement kept only where it does not worsen the sync
tags' leave-one-out."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.models.sync.simulate import simulate_sync
from sblsim.orchestrator.cli import main
from sblsim.orchestrator.sync.run import SyncOutcome, _kept

EPOCH = 1_700_000_000


@pytest.mark.slow
def test_a_sparse_sync_array_refinement_is_refused(tmp_path, capsys):
    """8 simulated receivers, 3 of them with a sync tag: --refine-positions refused in one line naming the 3 sync
    tags and what is needed, exit 2, no output folder; without it the same files synchronise."""
    sim = simulate_sync(n_receivers=8, hours=3.0, seed=4, noise=0.15e-3)
    keep = np.isin(sim.tag, [0, 3, 6])
    t = sim.time[keep] + EPOCH
    epo = np.floor(t).astype(np.int64)
    pd.DataFrame({"epo": epo, "frac": [f"{v:.7f}" for v in np.clip(t - epo, 0, 0.9999999)],
                  "tag": [f"S{i}" for i in sim.tag[keep]], "serial": [f"R{j}" for j in sim.receiver[keep]]}
                 ).iloc[np.argsort(t, kind="stable")].to_csv(tmp_path / "detections.csv", index=False)
    pd.DataFrame({"serial": [f"R{j}" for j in range(8)], "sync_tag": [f"S{j}" if j in (0, 3, 6) else ""
                                                                      for j in range(8)],
                  "x_m": sim.positions[:, 0], "y_m": sim.positions[:, 1]}).to_csv(tmp_path / "receivers.csv",
                                                                                  index=False)
    args = ["sync", str(tmp_path / "detections.csv"), "--receivers", str(tmp_path / "receivers.csv"),
            "--sound-speed", str(sim.sound_speed)]
    code = main([*args, "--refine-positions", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and not (tmp_path / "out").exists()
    assert "the 3 sync tags heard among 8 receivers determine no receiver's position" in err[0]
    assert "4 or more around the array" in err[0]
    assert main([*args, "--out", str(tmp_path / "plain")]) == 0


def _outcome(median: float, refined: bool) -> SyncOutcome:
    """A stand-in outcome with a leave-one-out median error [m] (the rule reads the summaries alone)."""
    summary = {"sync_tags": {"median_error_m": median, "nees_mean_inside": 2.0, "nees_median_inside": 1.4,
                             "tags": 5}, "model": "m"}
    positions = None
    if refined:
        summary["positions"] = {"refined": True, "survey_sigma_m": 3.0}
        positions = pd.DataFrame({"serial": ["A", "B"], "x_m": [1.0, 5.0], "y_m": [2.0, 6.0], "table_x_m": [0.0, 5.0],
                                  "table_y_m": [0.0, 6.0], "shift_x_m": [1.0, 0.0], "shift_y_m": [2.0, 0.0],
                                  "shift_m": [5 ** 0.5, 0.0], "sigma_x_m": [0.5, np.nan],
                                  "sigma_y_m": [0.5, np.nan], "correlation_xy": [0.0, np.nan],
                                  "refined": [True, False], "reason": ["", "not synchronised"]})
    frame = pd.DataFrame()
    return SyncOutcome(summary, frame, frame, frame, frame, None, 0.0, positions)


def test_the_refinement_is_kept_only_where_it_does_not_worsen_the_leave_one_out():
    """Refined 2 m against the table's 3 m: the refined kept, both recorded; refined 4 m: the table's positions
    kept (positions.csv the table's, refined false with the reason), said in one warning, both recorded."""
    better = _kept(_outcome(2.0, True), _outcome(3.0, False), 3.0)
    loo = better.summary["positions"]["leave_one_out"]
    assert better.positions["refined"].tolist() == [True, False] and loo["kept"] == "refined"
    assert loo["table"]["median_error_m"] == 3.0 and loo["refined"]["median_error_m"] == 2.0
    worse = _kept(_outcome(4.0, True), _outcome(3.0, False), 3.0)
    q = worse.positions
    assert not q["refined"].any() and worse.summary["positions"]["refined"] is False
    np.testing.assert_array_equal(q[["x_m", "y_m"]].to_numpy(), q[["table_x_m", "table_y_m"]].to_numpy())
    assert "worsened the sync tags' leave-one-out (median error 3 m with the table's, 4 m refined)" in q["reason"][0]
    assert q["reason"][1] == "not synchronised"
    warnings = worse.summary["warnings"]
    assert len(warnings) == 1 and "the table's positions kept" in warnings[0]
    assert worse.summary["positions"]["leave_one_out"]["kept"] == "table"

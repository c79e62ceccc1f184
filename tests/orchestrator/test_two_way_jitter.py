"""A two-way range under turnaround jitter is a measurement: ``c (round trip − nominal turnaround) / 2`` plus its
noise, negative where the jitter (cut at 0: no reply before the interrogation) exceeds the distance. The run hands
it to the receiver as it is, exports it as it is, and ``sblsim replay`` takes it (docs/log-format.md), so the replay
of a jittered two-way run's export is the run.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.orchestrator.cli import main
from sblsim.orchestrator.logs.receiver_log import read_log

#: 15 s of the harbour, two-way, a jitter of 20 ms on the 50 ms turnaround: some replies come back at once.
JITTERED = ["simulation.duration=15", "acoustics.ranging=twtt", "acoustics.turnaround_sigma=0.02"]
OUTPUTS = ("est_x", "est_y", "est_z", "est_vx", "est_vy", "est_vz", "instr_x", "instr_y", "instr_z", "nis",
           "pos_std", "cov_xx", "cov_yy", "cov_zz", "gated")


def test_a_jittered_two_way_export_replays_to_the_run(tmp_path, capsys):
    log = tmp_path / "jittered.csv"
    args = [a for key in JITTERED for a in ("--set", key)]
    assert main(["run", "harbour", *args, "--out", str(tmp_path / "run"), "--export-log", str(log)]) == 0
    frame = pd.read_csv(log, comment="#")
    ranges = frame["range_m"].dropna()
    assert (ranges < 0).sum() >= 5, "no negative two-way range: the case is not tested"
    # the negative ranges are what the run handed its receiver (the run's own record of the packet's range)
    series = pd.read_parquet(tmp_path / "run" / "timeseries.parquet")
    lanes = [c[:-len("packet_valid")] for c in series if c.endswith("packet_valid")]  # "", "lane2_", ...
    handed = np.concatenate([series.loc[series[f"{lane}packet_valid"].astype(bool), f"{lane}range"] for lane in lanes])
    assert np.isin(ranges[ranges < 0].to_numpy(), handed).all()
    assert read_log(log, 4).range.min() == pytest.approx(ranges.min(), abs=1e-9)

    out = tmp_path / "replay"
    assert main(["replay", str(log), "--out", str(out)]) == 0, capsys.readouterr().err
    replayed = pd.read_parquet(out / "timeseries.parquet")
    assert len(replayed) == len(series)
    np.testing.assert_array_equal(replayed["time"].to_numpy(), series["time"].to_numpy())
    for name in OUTPUTS:
        np.testing.assert_allclose(replayed[name].to_numpy(dtype=float), series[name].to_numpy(dtype=float),
                                   rtol=0, atol=1e-9, err_msg=name)

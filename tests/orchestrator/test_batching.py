"""The compiled batch gives every run the numbers it has alone, whatever the batch: batches of 1, 7 and 800
against runs of one replicate (B = 1) and against the FMU engine, to 1e-9 (the same C, so in fact equal)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.orchestrator.cosim.config import load_config
from sblsim.orchestrator.cosim.metrics import RUN_METRICS
from sblsim.orchestrator.cosim.run import run, run_batch, with_replicates

OVERRIDES = ["simulation.duration=5", "acoustics.loss_pct=20", "acoustics.outlier_pct=5", "receiver=ekf-seq"]


def metrics_of(result) -> pd.DataFrame:
    return result.metrics.set_index("replicate")[list(RUN_METRICS)].astype(float)


@pytest.fixture(scope="module")
def config():
    return load_config("random", OVERRIDES, seed=12)


@pytest.mark.parametrize("batch", [1, 7, 800])
def test_a_batch_equals_its_runs_alone_and_on_the_fmus(config, batch, fmu_dir):
    batched = run_batch(with_replicates(config, range(batch)), "local")
    assert len(batched.metrics) == batch
    picked = sorted({0, batch // 2, batch - 1})
    alone = pd.concat([metrics_of(run(config, "local", replicates=[r])) for r in picked])
    np.testing.assert_allclose(metrics_of(batched).loc[picked].to_numpy(), alone.to_numpy(), rtol=0, atol=1e-9)
    via_fmu = metrics_of(run(config, "fmu", replicates=picked, fmu_dir=fmu_dir))
    np.testing.assert_allclose(via_fmu.to_numpy(), alone.to_numpy(), rtol=0, atol=1e-9)
    # and the time series of a replicate in the batch equal those of its run alone
    last = batched.timeseries[batched.timeseries["replicate"] == picked[-1]].reset_index(drop=True)
    single = run(config, "local", replicates=[picked[-1]]).timeseries
    columns = [c for c in single.columns if single[c].dtype.kind == "f"]
    np.testing.assert_allclose(last[columns].to_numpy(), single[columns].to_numpy(), rtol=0, atol=1e-9,
                               equal_nan=True)
    # the replicates differ: the batch is not one run repeated
    assert metrics_of(batched)["e_tot_rms"].nunique() == batch

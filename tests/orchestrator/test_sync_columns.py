"""The synchronisation copies and holds the sync tags' rows with :data:`~sblsim.orchestrator.sync.run.SYNC_COLUMNS`
alone (a VUE export's sensor values, code space, model and station not): ``sblsim sync`` on a store (its rows read
with those columns) gives the clocks and the residuals that the same export read whole gives."""

from __future__ import annotations

import pandas as pd
import pytest

from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import read_detections
from sblsim.orchestrator.store.ingest import ingest
from sblsim.orchestrator.sync.run import SYNC_COLUMNS
from sblsim.orchestrator.sync.study_sync import synchronise_files, synchronise_study
from sblsim.orchestrator.telemetry.simulate import simulate_study


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("columns")
    written = simulate_study(n_receivers=5, n_tags=1, days=0.15, seed=3).write(folder / "study", "vue")
    ingest(written["detections"], folder / "store")
    return written, folder / "store"


@pytest.mark.slow  # the sync of the store with its sync tags left out in turn: about 3 s
def test_the_sync_of_a_store_equals_the_sync_of_its_file_read_whole(files):
    written, store = files
    whole = read_detections(written["detections"], None)
    assert {"sensor_value", "code_space", "station"} <= set(whole.frame.columns) - set(SYNC_COLUMNS)
    want = synchronise_study(whole, read_deployments(written["deployments"]), leave_one_out=False)
    got = synchronise_files(store, written["deployments"], None, None, None, 1.0, None)
    assert len(got.residuals) == len(want.residuals) > 200
    pd.testing.assert_frame_equal(got.offsets, want.offsets)
    pd.testing.assert_frame_equal(got.residuals, want.residuals)
    assert got.summary["synchronised"] == want.summary["synchronised"]

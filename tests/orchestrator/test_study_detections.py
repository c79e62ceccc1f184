"""A study's detections read from a store a batch of tags at a time
(:mod:`sblsim.orchestrator.telemetry.study_detections`) add up to what the whole file's do, and give each tag's rows
and the sync tags' as the whole file's assignment gives them, in a receiver's log and in a network extract."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.assign import assign
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import read_detections
from sblsim.orchestrator.store.ingest import ingest
from sblsim.orchestrator.sync.run import SYNC_COLUMNS
from sblsim.orchestrator.telemetry import study_detections
from sblsim.orchestrator.telemetry.simulate import simulate_study
from sblsim.orchestrator.telemetry.study_detections import StudyDetections, Tally


@pytest.fixture(scope="module")
def sim():
    """Five receivers, two of them redeployed (their sync tags deployed twice: named per deployment), three tags."""
    return simulate_study(n_receivers=5, n_tags=3, days=0.15, redeployed=2, seed=5)


def _files(sim, folder, format):
    """The study's files with detections set aside: one deployment left out of the sheet (its serial not in the
    table) and another recovered early (its later detections outside it)."""
    files = sim.write(folder, format)
    sheet = pd.read_csv(files["deployments"], dtype=str, keep_default_na=False)
    assert sheet["ins_serial_no"].value_counts().max() == 2  # a receiver deployed twice, its sync tag too
    sheet = sheet.drop(index=sheet.index[sheet["ins_serial_no"].map(sheet["ins_serial_no"].value_counts()) == 1][-1])
    sheet.loc[0, "recover_date_time"] = "2024-06-03T03:00:00Z"
    sheet.to_csv(files["deployments"], index=False)
    return files


@pytest.mark.parametrize("format", ["vue", "glatos"])
def test_a_store_read_in_batches_adds_up_to_its_file_and_gives_each_tags_rows(sim, tmp_path, monkeypatch, format):
    files = _files(sim, tmp_path / "f", format)
    ingest(files["detections"], tmp_path / "store", piece_bytes=16384)
    deployments = read_deployments(files["deployments"])
    whole = read_detections(files["detections"], None)
    got_whole = assign(whole, deployments)
    want = Tally.of(whole, got_whole)
    monkeypatch.setattr(study_detections, "BATCH_ROWS", 300)
    source = StudyDetections.stored(tmp_path / "store")
    assert len(source.batches(source.store.tags)) > 3  # the tags read in several batches
    assigned, tally = source.assigned(deployments)

    aside = want.set_aside
    assert aside["receiver_not_in_table"] > 0 and aside["outside_deployment"] > 0  # both causes exercised
    assert tally.set_aside == aside and tally.rows == want.rows and tally.used == want.used
    pd.testing.assert_series_equal(tally.kept.sort_index(), want.kept.sort_index(), check_names=False)
    assert tally.span == want.span and tally.quantum == want.quantum
    assert set(tally.serials) == set(want.serials)
    pd.testing.assert_frame_equal(tally.daily, want.daily)
    assert tally.tags.to_dict() == want.tags.to_dict() and tally.stored_as == want.stored_as
    assert any(k != v for k, v in want.stored_as.items())  # a sync tag named per deployment

    # the sync tags' rows: the whole file's, in its order, their columns the synchronisation's alone (a VUE
    # export's sensor values and code space not held through the study); each tag's rows the same, every column
    labels = set(got_whole.hydrophones["sync_tag"]) - {""}
    kept = got_whole.detections.frame
    held = [c for c in kept.columns if c in SYNC_COLUMNS]
    if format == "vue":
        assert {"sensor_value", "code_space"} <= set(kept.columns) - set(held)
    pd.testing.assert_frame_equal(assigned.detections.frame,
                                  kept.loc[kept["tag"].isin(labels), held].reset_index(drop=True))
    pd.testing.assert_frame_equal(assigned.hydrophones, got_whole.hydrophones)
    assert assigned.kept_span() == got_whole.kept_span()
    keys = [None, *want.tags.index[::-1]]
    seen = []
    for i, rows in source.frames(keys, tally, deployments, assigned):
        seen.append(i)
        if keys[i] is None:
            assert rows is None
        else:
            pd.testing.assert_frame_equal(rows.reset_index(drop=True),
                                          kept[kept["tag"] == keys[i]].reset_index(drop=True))
    assert sorted(seen) == list(range(len(keys)))


def test_a_file_read_whole_gives_its_own_rows_in_the_order_asked(sim, tmp_path):
    files = _files(sim, tmp_path / "f", "vue")
    data = read_detections(files["detections"], None)
    source = StudyDetections(data)
    assigned, tally = source.assigned(read_deployments(files["deployments"]))
    assert assigned.detections.frame is not None and len(assigned.detections.frame) == tally.used
    keys = list(tally.tags.index)
    order = [i for i, _ in source.frames(keys, tally, None, assigned)]
    assert order == list(range(len(keys)))
    by_hand = assigned.detections.frame["tag"].value_counts()
    assert tally.tags.to_dict() == by_hand.to_dict()
    day = np.floor(assigned.detections.frame["time"].to_numpy() / 86400.0)
    assert int(tally.daily["detections"].sum()) == len(day) == tally.used


def test_a_store_none_of_whose_detections_is_in_a_deployment_is_refused_as_its_file(sim, tmp_path):
    files = sim.write(tmp_path / "f", "vue")
    sheet = pd.read_csv(files["deployments"], dtype=str, keep_default_na=False)
    for column in ("deploy_date_time", "recover_date_time"):  # every deployment a year before the detections
        sheet[column] = (pd.to_datetime(sheet[column]) - pd.DateOffset(years=1)).dt.strftime("%Y-%m-%dT%H:%M:%SZ")
    sheet.to_csv(files["deployments"], index=False)
    ingest(files["detections"], tmp_path / "store", piece_bytes=16384)
    deployments = read_deployments(files["deployments"])
    with pytest.raises(ModelError) as whole:
        assign(read_detections(files["detections"], None), deployments)
    with pytest.raises(ModelError) as stored:
        StudyDetections.stored(tmp_path / "store").assigned(deployments)
    said = str(stored.value)
    assert said.startswith("detections: none of ") and "\n" not in said and "serials detected: 461000" in said
    assert said.split("(serials")[1] == str(whole.value).split("(serials")[1]  # the file's own line's serials

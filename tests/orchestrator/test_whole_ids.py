"""Ids written as decimals (orchestrator/readers/cells.py ``whole_ids``): a sheet's column of sync tags or serials
with blank cells is a float column to pandas and to a spreadsheet, which save ``802357.0`` where the receivers logged
``802357``. Before, such a deployments sheet (the boats' own, read and saved again by pandas) matched none of its
sync tags to the detections, and the study ended in "fewer than two detections of the receivers table's sync tags".
Every reader of an id (the deployments, the receivers table, the tag sheet, a YAPS table) now reads them as the
whole numbers, so that a sheet and a detections table saved either way still name one tag alike."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.orchestrator.readers.assign import assign
from sblsim.orchestrator.readers.cells import whole_ids
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import read_detections
from sblsim.orchestrator.readers.hydrophones import read_hydrophones
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet

DATA = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


def test_only_whole_numbers_written_as_decimals_are_read_anew():
    cells = pd.Series(["802357.0", "4555", "A69-1602-4555", "12.5", "1.00", "", "1623.0", "0.0", "7.01", "x.0"])
    read, count = whole_ids(cells)
    # independently: a cell of digits, a point and zeros alone is the integer its float is
    expected = [str(int(float(c))) if c.replace(".", "", 1).isdigit() and "." in c and float(c) == int(float(c))
                else c for c in cells]
    assert read.tolist() == expected and count == sum(a != b for a, b in zip(cells, expected)) == 4
    unchanged, none = whole_ids(pd.Series(["4555", "A69-1602-4555"]))
    assert unchanged.tolist() == ["4555", "A69-1602-4555"] and none == 0


def test_a_deployments_sheet_saved_by_pandas_keeps_its_sync_tags(tmp_path):
    """The boats' deployments read and saved by pandas (their transmitter column, blank at 3 of 20, written as
    802357.0): the same serials, sync tags and detections kept as the file's own, and a note of the 17 cells."""
    sheet = pd.read_csv(DATA / "deployments.csv")
    assert sheet["transmitter"].dtype == float  # the blanks made it a float column
    sheet.to_csv(tmp_path / "deployments.csv", index=False)
    assert "802357.0" in (tmp_path / "deployments.csv").read_text()
    own, saved = read_deployments(DATA / "deployments.csv"), read_deployments(tmp_path / "deployments.csv")
    pd.testing.assert_frame_equal(own.table.drop(columns="line"), saved.table.drop(columns="line"))
    given = int(sheet["transmitter"].notna().sum())
    assert [n for n in saved.notes if "read as whole numbers" in n] == [
        f"{given} cells of transmitter read as whole numbers (802357.0 as 802357: a number column with blank cells, "
        "as a spreadsheet or pandas writes it)"]
    assert not [n for n in own.notes if "read as whole numbers" in n]
    detections = read_detections(DATA / "detections.csv", None)
    kept_own, kept_saved = assign(detections, own), assign(detections, saved)
    pd.testing.assert_frame_equal(kept_own.detections.frame, kept_saved.detections.frame)
    assert set(kept_saved.hydrophones["sync_tag"]) - {""} == {str(int(t)) for t in sheet["transmitter"].dropna()}


@pytest.mark.parametrize("float_tags", [True, False])
def test_a_yaps_table_and_a_tag_sheet_saved_as_floats(tmp_path, float_tags):
    """A YAPS table whose tag and serial columns were floats, and a tag sheet's transmitters: read as the file's own
    (and a sheet read as floats against a table read as integers, both ways round, names the same tags)."""
    table = pd.read_csv(DATA / "detections.csv").head(3000)
    table.to_csv(tmp_path / "own.csv", index=False)
    floats = table.assign(tag=table["tag"].astype(float), serial=table["serial"].astype(float))
    (floats if float_tags else table).to_csv(tmp_path / "detections.csv", index=False)
    assert ("802955.0" in (tmp_path / "detections.csv").read_text()) == float_tags
    own, read = read_detections(tmp_path / "own.csv", None), read_detections(tmp_path / "detections.csv", None)
    pd.testing.assert_frame_equal(own.frame, read.frame)
    tags = pd.read_csv(DATA / "tags.csv")
    (tags.assign(transmitter=tags["transmitter"].astype(float)) if not float_tags else tags).to_csv(
        tmp_path / "tags.csv", index=False)
    sheet = read_tag_sheet(tmp_path / "tags.csv")
    assert [t.transmitter for t in sheet.tags] == tags["transmitter"].astype(str).tolist()
    named = {t.transmitter for t in sheet.tags} & set(read.frame["tag"])
    assert named == set(tags["transmitter"].astype(str)) & set(own.frame["tag"]) and len(named) > 10


def test_a_receivers_table_saved_by_pandas(tmp_path):
    """``sblsim sync``'s receivers table (the boats' hydrophones, sync_tag blank at some): the same frame."""
    table = pd.read_csv(DATA / "hydrophones.csv")
    assert table["sync_tag"].dtype == float and table["sync_tag"].isna().any()
    table.to_csv(tmp_path / "hydrophones.csv", index=False)
    own, saved = read_hydrophones(DATA / "hydrophones.csv"), read_hydrophones(tmp_path / "hydrophones.csv")
    pd.testing.assert_frame_equal(own, saved)
    sync_tags = own["sync_tag"][own["sync_tag"] != ""]
    assert len(sync_tags) and np.isin(sync_tags, pd.read_csv(DATA / "tags.csv")["transmitter"].astype(str)).all()


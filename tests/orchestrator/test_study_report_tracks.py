"""A report reads a season's ``tracks.csv`` a piece at a time and keeps only the columns it draws
(orchestrator/telemetry/report/folder.py ``read_tracks``): the same values as pandas reads from the whole file, in
any number of pieces; a bad cell named by its own line in a later piece; a blank line before the header skipped; the
rows bounded by ``MAX_TRACK_ROWS`` alone, refused in one line."""

from __future__ import annotations

import functools

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io import log_tables
from sblsim.orchestrator.telemetry.report import folder as report_folder


def _tracks(rows: int) -> pd.DataFrame:
    """A tracks.csv of two tags as sblsim track writes it (a row set aside without a position, reasons with ``;``)."""
    rng = np.random.default_rng(4)
    k = np.arange(rows)
    frame = pd.DataFrame({"tag": np.where(k < rows // 3, "A69-1602-7", "T 12"), "time_utc": "2024-06-03T00:00:00Z",
                          "epoch_s": 1.7e9 + 2.5 * k, "lat": 60.1 + rng.normal(0, 1e-4, rows), "lon": 5.3,
                          "x": rng.normal(3e5, 50, rows), "y": rng.normal(6.7e6, 50, rows),
                          "sigma_x": rng.uniform(0.1, 2, rows), "sigma_y": rng.uniform(0.1, 2, rows),
                          "receivers_heard": rng.integers(3, 9, rows),
                          "quality": np.where(k % 7 == 0, "flagged", "ok"),
                          "quality_reason": np.where(k % 7 == 0, "unverified;placed_less_well_than_a_fix", "")})
    aside = k % 50 == 3
    frame.loc[aside, ["epoch_s", "x", "y", "sigma_x", "sigma_y"]] = np.nan
    return frame


def _pieces(monkeypatch, size: int) -> None:
    monkeypatch.setattr(report_folder, "line_chunks", functools.partial(log_tables.line_chunks, chunk_bytes=size))


@pytest.mark.parametrize("size", [2**20, 3000])
def test_the_pieces_give_pandas_own_reading_of_the_whole_file(tmp_path, monkeypatch, size):
    _tracks(400).to_csv(tmp_path / "tracks.csv", index=False)
    _pieces(monkeypatch, size)
    got = report_folder.read_tracks(tmp_path, "study")
    want = pd.read_csv(tmp_path / "tracks.csv", keep_default_na=False, dtype=str)  # independent: pandas, whole
    assert list(got.columns) == [c for c in report_folder.TRACK_NUMBERS + report_folder.TRACK_TEXT if c in want]
    assert len(got) == len(want) == 400
    for c in report_folder.TRACK_NUMBERS:
        if c in want:
            expected = pd.to_numeric(want[c].replace("", np.nan)).to_numpy(float)
            np.testing.assert_array_equal(got[c].to_numpy(float), expected)
    for c in report_folder.TRACK_TEXT:
        assert isinstance(got[c].dtype, pd.CategoricalDtype)  # a category: a code a row, not a text a row
        assert got[c].astype(str).tolist() == want[c].tolist()
    assert (got["tag"] == "T 12").sum() == (want["tag"] == "T 12").sum()


def test_a_bad_cell_in_a_later_piece_is_named_by_its_own_line(tmp_path, monkeypatch):
    frame = _tracks(200)
    frame["x"] = frame["x"].astype(object)
    frame.loc[171, "x"] = "12,5"  # written quoted: one cell
    path = tmp_path / "tracks.csv"
    path.write_text("\n" + frame.to_csv(index=False))  # a blank line before the header
    _pieces(monkeypatch, 3000)
    with pytest.raises(ModelError) as caught:
        report_folder.read_tracks(tmp_path, "study")
    line = 1 + 1 + 171 + 1  # the blank line, the header, the rows before it
    assert str(caught.value).startswith(f"report: 'study/tracks.csv' line {line} column x: '12,5'")


def test_only_the_row_limit_bounds_it_in_one_line(tmp_path, monkeypatch):
    _tracks(60).to_csv(tmp_path / "tracks.csv", index=False)
    _pieces(monkeypatch, 3000)
    monkeypatch.setattr(report_folder, "MAX_TRACK_ROWS", 59)
    with pytest.raises(ModelError) as caught:
        report_folder.read_tracks(tmp_path, "study")
    assert str(caught.value) == "report: 'study/tracks.csv' holds more than 59 rows; allowed at most 59"
    monkeypatch.setattr(report_folder, "MAX_TRACK_ROWS", 60)
    assert len(report_folder.read_tracks(tmp_path, "study")) == 60
    (tmp_path / "tracks.csv").write_text("tag,epoch_s,x,y,sigma_x,sigma_y\n")  # no quality column
    with pytest.raises(ModelError, match="has no column quality; allowed"):
        report_folder.read_tracks(tmp_path, "study")

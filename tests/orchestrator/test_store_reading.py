"""A file read a piece at a time on threads (:mod:`sblsim.orchestrator.store.reading`): the pieces taken in the
file's order whatever thread ends first, the file's first fault the one named, the same store from one thread or
several, each piece's codes and counts those of pandas."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.store import reading
from sblsim.orchestrator.store.ingest import FILTERED, ingest
from sblsim.orchestrator.telemetry.simulate import fathom_text, simulate_study, vue_text


@pytest.fixture(scope="module")
def lines() -> list[str]:
    """A simulated VUE export's lines (about 40 pieces of 4 KiB)."""
    d = simulate_study(n_receivers=4, n_tags=3, days=0.1, seed=8).detections.reset_index(drop=True)
    return vue_text(d).splitlines()


def test_the_files_first_fault_is_named_though_a_later_piece_is_refused_first(lines, tmp_path):
    """A bad cell early and a NUL byte later: the pieces after the bad one are read (on threads) before its refusal is
    taken, and the NUL byte is found by the reading of the file itself; the bad cell, first in the file, is named."""
    early, late = len(lines) // 5, len(lines) // 5 + 50  # the next piece or the one after (of 4 KiB)
    bad = list(lines)
    bad[early] = bad[early].replace(",A69-", ",A69+", 1)
    bad[late] = bad[late][:10] + "\0" + bad[late][10:]
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(bad) + "\n")
    with pytest.raises(ModelError, match=f"line {early + 1} column Transmitter"):
        ingest(path, tmp_path / "s", "vue", piece_bytes=4096)  # the format given: the file's head not sniffed
    alone = list(lines)
    alone[late] = bad[late]
    path.write_text("\n".join(alone) + "\n")
    with pytest.raises(ModelError, match="holds a NUL byte"):
        ingest(path, tmp_path / "s", "vue", piece_bytes=4096)
    assert not (tmp_path / "s").exists()


def test_a_fathom_piece_read_in_order_refuses_in_its_turn(tmp_path):
    """A Fathom piece that is not plain (a quoted cell) is read in the command's own thread as it comes, while the
    plain pieces before it are still on their threads: a bad cell in one of those is named first all the same."""
    d = simulate_study(n_receivers=4, n_tags=3, days=0.1, seed=8).detections.reset_index(drop=True)
    lines = fathom_text(d).splitlines()
    early = next(k for k in range(len(lines) // 5, len(lines)) if lines[k].startswith("DET,"))
    late = next(k for k in range(early + 40, len(lines)) if lines[k].startswith("DET,"))
    lines[early] = lines[early].replace(",A69-", ",A69+", 1)
    cells = lines[late].split(",")
    k = next(k for k, cell in enumerate(cells) if cell.startswith("A69-"))
    cells[k] = '"' + cells[k].replace("A69-", "A69+") + '"'  # quoted (the piece not plain) and bad
    lines[late] = ",".join(cells)
    path = tmp_path / "bad.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelError, match=f"line {early + 1} "):
        ingest(path, tmp_path / "s", "fathom", piece_bytes=4096)
    lines[early] = lines[early].replace(",A69+", ",A69-", 1)  # the late one alone: it is refused
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ModelError, match=f"line {late + 1} "):
        ingest(path, tmp_path / "s", "fathom", piece_bytes=4096)


@pytest.mark.parametrize("change, said", [
    (lambda t: t.replace(",", ";"), "separated by semicolons"), (lambda t: t.replace(",", "\t"), "separated by tabs"),
    (lambda t: t.replace("\nDET_DESC,", "\nDET_DESCRIPTION,"), "no DET_DESC line")])
def test_a_fathom_csv_without_its_det_desc_line_is_refused_as_the_whole_file_reader_refuses_it(tmp_path, change, said):
    """A Fathom CSV a spreadsheet saved with semicolons or tabs, and one without a DET_DESC line: the store refuses it
    in the whole-file reader's own line (it said "holds a header and no detections"), no folder left."""
    from sblsim.orchestrator.readers.detections import read_detections

    d = simulate_study(n_receivers=4, n_tags=2, days=0.02, seed=8).detections.reset_index(drop=True)
    path = tmp_path / "fathom.csv"
    path.write_text(change(fathom_text(d)))
    with pytest.raises(ModelError) as whole:
        read_detections(path, "fathom")
    with pytest.raises(ModelError) as stored:
        ingest(path, tmp_path / "s", "fathom", piece_bytes=4096)
    assert said in str(stored.value) and str(stored.value) == str(whole.value), (stored.value, whole.value)
    assert not (tmp_path / "s").exists()


def test_one_thread_or_several_store_the_same_bytes(lines, tmp_path, monkeypatch):
    path = tmp_path / "d.csv"
    path.write_text("\n".join(lines) + "\n")
    stored = {}
    for threads in (1, 2, 3):
        monkeypatch.setattr(reading, "READING_THREADS", threads)
        ingest(path, tmp_path / f"s{threads}", piece_bytes=4096)
        stored[threads] = [f.read_bytes() for f in sorted((tmp_path / f"s{threads}" / "detections").glob("*.parquet"))]
    assert len(stored[1]) > 10 and stored[1] == stored[2] == stored[3]
    for file in sorted((tmp_path / "s2" / "detections").glob("*.parquet")):  # each part's rows by tag, then line
        rows = pq.read_table(file, columns=["tag", "line"]).to_pylist()
        assert [(r["tag"], r["line"]) for r in rows] == sorted((r["tag"], r["line"]) for r in rows)
    part = pq.ParquetFile(sorted((tmp_path / "s2" / "detections").glob("*.parquet"))[0])
    group = part.metadata.row_group(0)
    for k in range(group.num_columns):  # the queries' columns with statistics; text dictionary-encoded
        column = group.column(k)
        assert column.is_stats_set == (column.path_in_schema in FILTERED), column.path_in_schema
        text = str(part.schema_arrow.field(column.path_in_schema).type) in ("string", "large_string")
        assert ("PLAIN_DICTIONARY" in column.encodings or "RLE_DICTIONARY" in column.encodings) == text


def test_a_pieces_codes_count_its_rows_as_pandas_does():
    frame = pd.DataFrame({"receiver": pd.Series(["b", "a", "b", None, "c", "b"], dtype="str"),
                          "tag": pd.Series(["t1", "t2", "t1", "t1", "t3", "t2"], dtype="str")})
    coded = reading.coded_piece(frame)
    for column, which in (("receiver", "receivers"), ("tag", "tags")):
        codes, names = getattr(coded, which)
        assert coded.counts(which) == frame[column].value_counts().to_dict()
        np.testing.assert_array_equal(np.array(names, object)[codes[codes >= 0]], frame[column].dropna().to_numpy())

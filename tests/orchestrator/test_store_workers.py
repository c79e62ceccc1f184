"""A store's pieces read by workers (``ingest(..., workers=N)``, :func:`~sblsim.orchestrator.store.pieces.in_order`):
the same store, file for file, as one process makes, in the formats whose pieces carry what the pieces before them
said (the clock parts, a Fathom file's ``_DESC`` lines, a network extract's duplicates) and in Latin-1; an error said
where the file's order meets it, as one process says it; the workers' range refused. The fast tests put threads in
the worker processes' place (the same order of work, without a process's start); the slow one starts the processes."""

from __future__ import annotations

import json
import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import pyarrow.parquet as pq
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.store import ingest as ingest_module
from sblsim.orchestrator.store.ingest import MAX_WORKERS, ingest
from tests.orchestrator.test_store import _text, detections  # noqa: F401 (a fixture)


@pytest.fixture
def threads(monkeypatch):
    """Worker threads in the worker processes' place."""

    @contextmanager
    def pool(workers):
        with ThreadPoolExecutor(workers) as executor:
            yield executor

    monkeypatch.setattr(ingest_module, "_pool", pool)


def _same_store(a, b) -> None:
    """Two stores' parts equal, file for file and row for row, and their store.json but the time and the workers."""
    parts = sorted(p.name for p in (a / "detections").iterdir())
    assert parts == sorted(p.name for p in (b / "detections").iterdir()) and len(parts) > 5
    for name in parts:
        assert pq.read_table(a / "detections" / name).equals(pq.read_table(b / "detections" / name)), name
    info = [json.loads((s / "store.json").read_text()) for s in (a, b)]
    for one in info:
        one.pop("seconds")
        one.pop("workers")
    assert info[0] == info[1]


@pytest.mark.parametrize("format", ["vue", "fathom", pytest.param("glatos", marks=pytest.mark.slow)])
def test_pieces_read_by_workers_make_the_same_store(detections, tmp_path, threads, format):  # noqa: F811
    path = tmp_path / "d.csv"
    path.write_text(_text(detections, format))
    one = ingest(path, tmp_path / "one", piece_bytes=16384, workers=1)
    two = ingest(path, tmp_path / "two", piece_bytes=16384, workers=2)
    assert (one["workers"], two["workers"]) == (1, 2)
    _same_store(tmp_path / "one", tmp_path / "two")
    assert len(two["clock_resets"]) == (0 if format == "glatos" else 1)  # carried across the pieces read apart


def test_a_latin_1_file_read_by_workers_is_read_again_in_latin_1(detections, tmp_path, threads):  # noqa: F811
    text = _text(detections, "vue").replace("Station Name", "Station Name,Note", 1)
    rows = text.splitlines()
    rows = [rows[0]] + [r + (",19 °C" if k == len(rows) - 3 else ",") for k, r in enumerate(rows[1:], 1)]
    path = tmp_path / "latin.csv"
    path.write_bytes(("\n".join(rows) + "\n").encode("latin-1"))
    one = ingest(path, tmp_path / "one", piece_bytes=16384, workers=1)
    two = ingest(path, tmp_path / "two", piece_bytes=16384, workers=2)
    assert one["encoding"] == two["encoding"] == "latin-1"
    _same_store(tmp_path / "one", tmp_path / "two")


def test_an_error_is_said_where_the_files_order_meets_it(detections, tmp_path, threads):  # noqa: F811
    """A bad cell in an early piece and a NUL byte in the last: the bad cell is said (the pieces after it read
    ahead, their errors not said first), as one process says it; the NUL byte alone is said after the pieces before
    it; nothing is written either way."""
    lines = _text(detections, "vue").splitlines()
    k = len(lines) // 5
    bad = list(lines)
    bad[k] = bad[k].replace(",A69-", ",A69+", 1)
    nul = list(lines)
    nul[-2] = nul[-2] + "\0"
    for name, rows in (("bad", bad), ("nul", nul), ("both", [*bad[:-2], nul[-2], bad[-1]])):
        path = tmp_path / f"{name}.csv"
        path.write_text("\n".join(rows) + "\n")
        said = []
        for workers in (1, 2):
            with pytest.raises(ModelError) as error:
                ingest(path, tmp_path / "out" / f"{name}{workers}", piece_bytes=16384, workers=workers)
            said.append(str(error.value))
        assert said[0] == said[1], name
        assert (f"line {k + 1}" in said[0]) == (name != "nul") and ("NUL" in said[0]) == (name == "nul"), said[0]
    assert not (tmp_path / "out").exists()


def test_a_large_file_is_read_by_workers_by_default(detections, tmp_path, threads, monkeypatch):  # noqa: F811
    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    assert ingest(path, tmp_path / "small", piece_bytes=16384)["workers"] == 1
    monkeypatch.setattr(ingest_module, "PARALLEL_BYTES", path.stat().st_size)
    assert ingest(path, tmp_path / "large", piece_bytes=16384)["workers"] == min(os.cpu_count() or 1, MAX_WORKERS)


@pytest.mark.parametrize("workers", [0, 65, True, 2.5, "2"])
def test_workers_outside_their_range_are_refused(detections, tmp_path, workers):  # noqa: F811
    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    with pytest.raises(ModelError, match=r"^workers: .* is outside the allowed range \[1, 64\] \(an integer\)$"):
        ingest(path, tmp_path / "s", workers=workers)
    assert not (tmp_path / "s").exists()


@pytest.mark.slow
@pytest.mark.parametrize("format", ["vue", "fathom"])
def test_pieces_read_by_worker_processes_make_the_same_store(detections, tmp_path, format):  # noqa: F811
    path = tmp_path / "d.csv"
    path.write_text(_text(detections, format))
    ingest(path, tmp_path / "one", piece_bytes=16384, workers=1)
    assert ingest(path, tmp_path / "two", piece_bytes=16384, workers=2)["workers"] == 2
    _same_store(tmp_path / "one", tmp_path / "two")


def test_the_command_takes_workers_and_refuses_them_outside_their_range(detections, tmp_path, threads,  # noqa: F811
                                                                        capsys):
    from sblsim.orchestrator.cli import main

    path = tmp_path / "d.csv"
    path.write_text(_text(detections, "vue"))
    assert main(["store", str(path), "--workers", "2", "--out", str(tmp_path / "s")]) == 0
    assert json.loads((tmp_path / "s" / "store.json").read_text())["workers"] == 2
    capsys.readouterr()
    assert main(["store", str(path), "--workers", "0", "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--workers" in err[0] and "[1, 64]" in err[0] and not (tmp_path / "r").exists()

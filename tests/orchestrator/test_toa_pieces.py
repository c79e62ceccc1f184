"""A TOA matrix is read a piece at a time (orchestrator/readers/input_rows.py ``row_pieces``): a season's tag of
more pings than a file read whole allows (500,000) is read, the same numbers as numpy reads from the whole file, in
any number of pieces; a bad cell in a later piece named by its own line; the pings and the cells bounded alone, each
refused in one line."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io import log_tables
from sblsim.orchestrator.readers import input_rows
from sblsim.orchestrator.readers.toa_matrix import read_toa


def _matrix(pings: int, seed: int = 2) -> np.ndarray:
    rng = np.random.default_rng(seed)
    toa = np.arange(pings)[:, None] * 2.5 + rng.uniform(0, 0.2, (pings, 3))
    toa[rng.random(toa.shape) < 0.2] = np.nan
    return toa


def _write(path, toa: np.ndarray, depth: np.ndarray | None = None, comma: bool = False) -> None:
    sep = "," if comma else " "
    names = ["H1", "H 2" if comma else "H2", "H3"] + (["depth_m"] if depth is not None else [])
    cells = toa if depth is None else np.c_[toa, depth]
    lines = ["# a comment before the header", sep.join(f'"{n}"' if " " in n else n for n in names)]
    for k, row in enumerate(cells):
        lines.append(sep.join("NA" if np.isnan(v) else repr(float(v)) for v in row))
        if k % 97 == 5:
            lines.append("")  # blank lines between the rows
    path.write_text("\n".join(lines) + "\n")


def _pieces(monkeypatch, size: int) -> None:
    monkeypatch.setattr(input_rows, "line_chunks", functools.partial(log_tables.line_chunks, chunk_bytes=size))


@pytest.mark.parametrize("comma", [False, True])
def test_pieces_give_numpys_reading_of_the_whole_file(tmp_path, monkeypatch, comma):
    toa, depth = _matrix(700), np.linspace(0.5, 30.0, 700)
    _write(tmp_path / "toa.txt", toa, depth, comma)
    whole = read_toa(tmp_path / "toa.txt")
    _pieces(monkeypatch, 1500)  # some 30 pieces
    got = read_toa(tmp_path / "toa.txt")
    ref = np.genfromtxt(tmp_path / "toa.txt", comments="#", delimiter="," if comma else None, skip_header=2,
                        missing_values="NA", filling_values=np.nan)  # independent: numpy, whole
    np.testing.assert_array_equal(got.toa, ref[:, :3])
    np.testing.assert_array_equal(got.depth, ref[:, 3])
    assert got.names == whole.names == ["H1", "H 2" if comma else "H2", "H3"]
    np.testing.assert_array_equal(got.toa, whole.toa)


def test_a_bad_cell_in_a_later_piece_and_a_depth_out_of_range_are_named_by_their_own_lines(tmp_path, monkeypatch):
    toa = _matrix(300)
    _write(tmp_path / "toa.txt", toa)
    text = (tmp_path / "toa.txt").read_text().splitlines()
    row = 250 + 2 + 250 // 97 + (250 % 97 > 5)  # its line: the comment, the header, the blank lines before it
    assert text[row].split()[0] == repr(float(toa[250, 0])) if np.isfinite(toa[250, 0]) else "NA"
    text[row] = "1e400 " + " ".join(text[row].split()[1:])
    (tmp_path / "toa.txt").write_text("\n".join(text) + "\n")
    _pieces(monkeypatch, 900)
    with pytest.raises(ModelError) as caught:
        read_toa(tmp_path / "toa.txt")
    assert str(caught.value).startswith(f"toa: '{tmp_path / 'toa.txt'}' line {row + 1} column H1: '1e400' is not")
    depth = np.full(300, 5.0)
    depth[260] = 12000.0
    _write(tmp_path / "toa.txt", toa, depth)
    with pytest.raises(ModelError) as caught:
        read_toa(tmp_path / "toa.txt")
    line = 260 + 2 + 260 // 97 + (260 % 97 > 5) + 1
    assert f"line {line} column depth_m: 12000 is not allowed" in str(caught.value)


def test_the_pings_and_the_cells_are_its_only_bounds(tmp_path, monkeypatch):
    _write(tmp_path / "toa.txt", _matrix(120))
    _pieces(monkeypatch, 700)
    monkeypatch.setattr(input_rows, "MAX_MATRIX_PINGS", 119)
    monkeypatch.setattr("sblsim.orchestrator.readers.toa_matrix.MAX_MATRIX_PINGS", 119)
    with pytest.raises(ModelError, match="holds more than 119 pings; allowed at most 119 \\(split it in time\\)$"):
        read_toa(tmp_path / "toa.txt")
    monkeypatch.setattr("sblsim.orchestrator.readers.toa_matrix.MAX_MATRIX_PINGS", 120)
    assert read_toa(tmp_path / "toa.txt").toa.shape == (120, 3)
    monkeypatch.setattr(input_rows, "MAX_MATRIX_CELLS", 3 * 120)  # the header's 3 cells and the rows'
    with pytest.raises(ModelError) as caught:
        read_toa(tmp_path / "toa.txt")
    assert str(caught.value).endswith(f"holds {3 * 121:,} cells; allowed at most {3 * 120:,} cells in a table")
    monkeypatch.setattr(input_rows, "MAX_MATRIX_CELLS", 40)  # exceeded in the first piece: the rest counted
    with pytest.raises(ModelError) as caught:
        read_toa(tmp_path / "toa.txt")
    assert str(caught.value).endswith(f"holds {3 * 121:,} cells; allowed at most 40 cells in a table")


@pytest.mark.slow
def test_a_season_of_more_pings_than_a_whole_file_allows_is_read(tmp_path):
    pings = input_rows.MAX_PINGS + 100_000  # the limit of a file read whole
    toa = np.nan_to_num(_matrix(pings), nan=1.0)
    np.savetxt(tmp_path / "toa.txt", toa, fmt="%.17g", header="H1 H2 H3", comments="")
    got = read_toa(tmp_path / "toa.txt")
    assert got.toa.shape == (pings, 3)
    np.testing.assert_array_equal(got.toa, np.loadtxt(tmp_path / "toa.txt", skiprows=1))

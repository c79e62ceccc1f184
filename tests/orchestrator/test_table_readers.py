"""The tracking readers' tables parsed by a CSV parser (readers/toa_matrix.py, io/tables.py): a
quoted cell may hold the separator, a ragged row is refused naming its line (as an editor numbers it, comments and
blank lines counted) and its number of cells, a quote left open names its line."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.log_tables import read_table
from sblsim.orchestrator.io.tables import csv_cells
from sblsim.orchestrator.readers.burst_sequence import read_burst_sequence
from sblsim.orchestrator.readers.receivers_file import read_receivers
from sblsim.orchestrator.readers.time_series import read_track
from sblsim.orchestrator.readers.toa_matrix import read_toa

RECEIVERS = ('# the array, surveyed\nname,x_m,y_m,z_m,status\n"H1, north pier",10.5,-3,-2,ok\nH2,0,20,-2,"ok, '
             're-surveyed"\n"H3 ""old""",-12,4,-3,ok\n')


def test_a_quoted_comma_is_one_cell(tmp_path):
    path = tmp_path / "receivers.csv"
    path.write_text(RECEIVERS)
    expected = pd.read_csv(path, comment="#")  # pandas' own CSV parser, independent of ours
    receivers = read_receivers(path)
    assert receivers.names == list(expected["name"]) == ["H1, north pier", "H2", 'H3 "old"']
    np.testing.assert_array_equal(receivers.positions, expected[["x_m", "y_m", "z_m"]].to_numpy(float))
    # a TOA header naming them, quoted, and a receiver column with an empty cell
    toa = tmp_path / "toa.csv"
    toa.write_text('"H1, north pier",H2,"H3 ""old"""\n1.5,,2.25\n3,4,NA\n')
    matrix = read_toa(toa)
    assert matrix.names == list(pd.read_csv(toa, nrows=0).columns)
    np.testing.assert_array_equal(matrix.toa, pd.read_csv(toa, na_values=["NA"]).to_numpy(float))


def test_a_whitespace_table_reads_as_pandas_reads_it(tmp_path):
    path = tmp_path / "gps.txt"
    path.write_text("t  x\ty  \n0.0   1.0\t2.0\n1.0 \t 1.5 2.5\n2.0 2.0 3.0  \n")
    expected = pd.read_csv(path, sep=r"\s+")
    np.testing.assert_array_equal(read_track(path, "truth"), expected[["t", "x", "y"]].to_numpy(float))


@pytest.mark.parametrize("short", [True, False], ids=["one cell short", "one cell long"])
def test_a_ragged_row_names_its_line_and_its_cells(tmp_path, short):
    rows = ["H1,H2,H3", "# pings from the first day", "1,2,3", "", "4,5,6", "7,8" if short else "7,8,9,10", "9,9,9"]
    path = tmp_path / "toa.csv"
    path.write_text("\n".join(rows) + "\n")
    line = rows.index("7,8" if short else "7,8,9,10") + 1  # as an editor numbers it: 6
    with pytest.raises(ModelError) as caught:
        read_toa(path)
    message = str(caught.value)
    assert "\n" not in message and "nan" not in message
    assert f"line {line} has {2 if short else 4} cells, the header 3" in message, message


def test_a_ragged_row_of_a_headerless_matrix_and_of_a_burst_sequence(tmp_path):
    path = tmp_path / "toa.txt"
    path.write_text("1 2 3\n4 5 6\n7 8\n")
    with pytest.raises(ModelError, match="line 3 has 2 cells, the first row 3"):
        read_toa(path)
    bursts = tmp_path / "bursts.csv"
    bursts.write_text("interval_s,note\n1.5,a\n2.5\n")
    with pytest.raises(ModelError, match="line 3 has 1 cells, the header 2"):
        read_burst_sequence(bursts)


def test_a_quote_left_open_names_its_line(tmp_path):
    path = tmp_path / "toa.csv"
    path.write_text('H1,H2\n1,2\n3,"4\n5,6\n')
    with pytest.raises(ModelError, match="line 3 does not parse as CSV"):
        read_toa(path)
    log = tmp_path / "log.csv"
    log.write_text('# a log\ntime_s,beacon_id,note\n0.1,1,"a, b"\n0.2,2,"c\n')
    with pytest.raises(ModelError, match="line 4 does not parse as CSV"):
        read_table(log, "log")
    log.write_text('# a log\ntime_s,beacon_id,note\n0.1,1,"a, b"\n0.2,2,c\n')
    assert [cells for _, cells in read_table(log, "log").rows] == [["0.1", "1", "a, b"], ["0.2", "2", "c"]]


def test_csv_cells_keeps_the_line_numbers():
    lines = [(3, 'a,"b,c",d'), (7, "e,f,g")]
    assert csv_cells(lines, "t") == [(3, ["a", "b,c", "d"]), (7, ["e", "f", "g"])]
    assert csv_cells([(1, ' "x y"\t 2  3 ')], "t", " ") == [(1, ["x y", "2", "3"])]

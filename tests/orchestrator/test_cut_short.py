"""A table cut short (an export, a download or a copy interrupted: its last line ends without a line break, fewer
cells than the line before; orchestrator/readers/cells.py ``cut_short``) is refused in one line by every reader
that takes a study's files: the detections (GLATOS, Fathom), the store, the deployments and the tag sheet. Before,
the cut line was read as a row whose missing cells were empty, and the rest of the export was lost unsaid."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.cells import cut_short
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import read_detections
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet
from sblsim.orchestrator.store.ingest import ingest
from sblsim.orchestrator.telemetry.simulate import fathom_text, glatos_text

DATA = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


def _detections(n: int = 250) -> pd.DataFrame:
    """Two receivers hearing a tag every 30 s (the simulator's columns)."""
    t = 1.7e9 + 30.0 * np.arange(n)
    return pd.DataFrame({"time": np.r_[t, t + 0.1], "model": "VR2W", "serial": ["461001"] * n + ["461002"] * n,
                         "transmitter": "A69-1602-1000"})


def _cut(text: str, into_last: int = 40) -> str:
    """The text cut ``into_last`` characters into its last line (its line break and the rest of that line lost)."""
    start = text.rstrip("\n").rfind("\n") + 1
    return text[:start + into_last]


@pytest.mark.parametrize("write", [glatos_text, fathom_text])
def test_detections_cut_mid_line_are_refused_and_whole_lines_without_a_break_are_read(tmp_path, write):
    """A GLATOS extract and a Fathom CSV cut 40 characters into their last line: refused in one line naming the file
    and the cells of the two lines (counted here by pandas); the same files ending at a line's end without its
    break are read, with every row."""
    text = write(_detections())
    path = tmp_path / "detections.csv"
    path.write_text(_cut(text))
    with pytest.raises(ModelError) as refused:
        read_detections(path, None)
    said = str(refused.value)
    assert "\n" not in said and str(path) in said and "cut short" in said, said
    last = text.rstrip("\n").rsplit("\n", 2)
    cells = [pd.read_csv(pd.io.common.StringIO(line), header=None).shape[1] for line in (_cut(last[-1] + "\n"),
                                                                                         last[-2])]
    assert f"holds {cells[0]} cells where the line before holds {cells[1]}" in said, (said, cells)
    path.write_text(text.rstrip("\n"))
    whole = read_detections(path, None)
    path.write_text(text)
    assert whole.frame.equals(read_detections(path, None).frame) and len(whole.frame) == 500


def test_a_store_of_a_cut_file_is_refused_before_anything_is_written(tmp_path):
    """``ingest`` of the cut GLATOS extract: the same refusal, and no store folder made."""
    path = tmp_path / "detections.csv"
    path.write_text(_cut(glatos_text(_detections())))
    out = tmp_path / "store"
    with pytest.raises(ModelError, match="cut short"):
        ingest(path, out)
    assert not out.exists()


def test_fathoms_records_are_compared_with_their_own_type():
    """A Fathom CSV ending in a whole TEMP record (9 cells) after DET records (21), without a line break: read; a DET
    record cut after a TEMP record: refused (compared with the last DET record, not the TEMP one); one cut inside its
    record type (``DE``, a type no record before has): refused against the record before it."""
    text = fathom_text(_detections(3))
    temp = "TEMP,2023-11-14 22:13:20,2023-11-14 22:13:20,+0,0,VR2W,461001,9.5,10.0"
    cut_short(text + temp, "f.csv", "detections", by_record=True)  # no refusal
    det = text.rstrip("\n").rsplit("\n", 1)[1][:60]
    cells = pd.read_csv(pd.io.common.StringIO(det), header=None).shape[1]
    with pytest.raises(ModelError, match=f"holds {cells} cells where the line before holds 21"):
        cut_short(text + temp + "\n" + det, "f.csv", "detections", by_record=True)
    with pytest.raises(ModelError, match="holds 9 cells where the line before holds 21"):
        cut_short(text + temp, "f.csv", "detections", by_record=False)  # (a plain table's rule would refuse it)
    with pytest.raises(ModelError, match="holds 1 cells where the line before holds 9"):  # cut inside its type
        cut_short(text + temp + "\nDE", "f.csv", "detections", by_record=True)


def test_a_header_wider_than_its_rows_or_a_note_across_lines_is_not_taken_for_a_cut():
    """Rows each a cell shorter than their header (a trailing comma in the header alone), the last without a line
    break: compared with the row before it, not the header: read. A last row whose quoted note spans two lines (its
    last physical line one cell): read as one record of three cells."""
    cut_short("a,b,c,\n1,2,3\n4,5,6", "t.csv", "tags")
    cut_short('a,b,c\r\n1,2,3\r\n4,5,"a note\r\nacross lines"', "t.csv", "tags")
    with pytest.raises(ModelError, match="holds 2 cells where the line before holds 3"):
        cut_short("a,b,c,\n1,2,3\n4,5", "t.csv", "tags")


@pytest.mark.parametrize("name, into", [("deployments.csv", 12), ("tags.csv", 9)])
def test_the_boats_deployments_and_tag_sheet_cut_are_refused(tmp_path, name, into):
    """The boats' deployments and tag sheet cut into their last line, a cell short: refused in one line (read whole,
    they are read). (A cut inside a line's last cell leaves its cells' count: not told from a whole line.)"""
    read = read_deployments if name == "deployments.csv" else read_tag_sheet
    text = (DATA / name).read_text()
    read(DATA / name)
    path = tmp_path / name
    path.write_text(_cut(text, into))
    with pytest.raises(ModelError) as refused:
        read(path)
    assert "cut short" in str(refused.value) and "\n" not in str(refused.value), refused.value


def test_every_table_read_whole_refuses_a_cut(tmp_path):
    """The readers of a table read whole share one reading (``file_table``): a receivers table in x/y
    (``read_hydrophones``) and actel's biometrics cut a cell short are refused as the deployments are."""
    from sblsim.orchestrator.readers.actel import read_biometrics
    from sblsim.orchestrator.readers.hydrophones import read_hydrophones

    receivers = tmp_path / "receivers.csv"
    receivers.write_text("name,x_m,y_m\nH1,0,0\nH2,100,0\nH3,0")
    with pytest.raises(ModelError, match="holds 2 cells where the line before holds 3"):
        read_hydrophones(receivers)
    receivers.write_text("name,x_m,y_m\nH1,0,0\nH2,100,0\nH3,0,100")
    assert len(read_hydrophones(receivers)) == 3
    biometrics = tmp_path / "biometrics.csv"
    biometrics.write_text('"Release.date","Release.site","Signal","Code.space"\n'
                          '"2021-03-22 08:00:00","Pier",610,"R64K"\n"2021-03-22 08:05","Pier",611')
    with pytest.raises(ModelError, match="cut short"):
        read_biometrics(biometrics, "Europe/Copenhagen")

"""A tag sheet delivered as a workbook (readers/workbook.py through readers/tag_sheet.py): Innovasea's tag
specifications (sheet ``Tag Summary``, its header under a title, four programme steps, a sensor's slope and
intercept) as ``.xlsx`` and ``.xls``, OTN's tagging metadata (sheet ``Tag Metadata``), a plain sheet; each read against
what the rows written say, computed here; bad cells, formulas, zip bombs and damaged files refused in one line naming
the sheet, its row and its column. The workbooks are written here from the documented layouts, with invented tags."""

from __future__ import annotations

import io
import zipfile

import openpyxl
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers import workbook
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet

#: Innovasea's Tag Summary columns (glatos's vemco_tag_spec_schema: the names as a vendor's workbook spells them).
STEP_COLUMNS = [f"Step {k} {c}" for k in range(1, 5) for c in ("Status", "Min Delay (sec)", "Max Delay (sec)")]
SUMMARY = ["Sales Order", "Serial No. ", "VUE Tag ID", *STEP_COLUMNS, "Sensor type", "Range", "Units", "Slope",
           "Intercept ", "Ship Date"]


def _step(status="OFF", low="", high=""):
    return [status, low, high]


#: Four tags: step 1 only (numbers as text, as vendors' cells often are), a depth sensor, two steps ON (the bounds
#: over both), a step OFF whose delays are not the tag's; invented serials and ids.
TAGS = [
    ["9001", "1000001", "A69-1601-501", *_step("ON", "45", "90"), *_step(), *_step(), *_step(), "", "", "", "", "",
     "2020-01-02"],
    [9001, 1000002, "A69-9002-602", *_step("ON", 20, 60), *_step(), *_step(), *_step(), "P", 68, "Meters", 0.3033,
     -1.2131, "2020-01-02"],
    [9002, 1000003, "A180-1702-703", *_step("ON", 150, 300), *_step("ON", 40, 120), *_step(), *_step(), "", "", "",
     "", "", ""],
    [9002, 1000004, "A69-1601-804", *_step("ON", 100, 200), *_step("OFF", 5, 10), *_step(), *_step(), "", "", "",
     "", "", ""],
]


def _expected(row):
    """What a row states, computed from the layout: the bounds over the steps that are ON, the sensor's line."""
    cells = dict(zip(SUMMARY, row))
    on = [k for k in range(1, 5) if cells[f"Step {k} Status"] == "ON"]
    low = min(float(cells[f"Step {k} Min Delay (sec)"]) for k in on)
    high = max(float(cells[f"Step {k} Max Delay (sec)"]) for k in on)
    return cells["VUE Tag ID"], (low, high), "depth" if cells["Sensor type"] == "P" else ""


def _xlsx(path, sheets):
    """A workbook of ``sheets`` ({name: rows}), written by openpyxl."""
    book = openpyxl.Workbook()
    book.remove(book.active)
    for title, rows in sheets.items():
        sheet = book.create_sheet(title)
        for row in rows:
            sheet.append([None if c == "" else c for c in row])
    book.save(path)
    return path


def _xls(path, sheets):
    """The same workbook as an .xls (BIFF8), written by xlwt."""
    xlwt = pytest.importorskip("xlwt")
    book = xlwt.Workbook()
    for title, rows in sheets.items():
        sheet = book.add_sheet(title)
        for r, row in enumerate(rows):
            for c, value in enumerate(row):
                if value != "":
                    sheet.write(r, c, value)
    book.save(str(path))
    return path


WRITERS = {"xlsx": _xlsx, "xls": _xls}


def _summary(tmp_path, kind, rows=TAGS, header=SUMMARY, title=True):
    above = [["Tag Specifications"], ["Customer: a lake survey"], []] if title else []
    sheets = {"License": [["Licence terms"]], "Tag Summary": above + [header] + rows}
    return WRITERS[kind](tmp_path / f"tags.{kind}", sheets), len(above) + 1


@pytest.mark.parametrize("kind", ["xlsx", "xls"])
def test_innovasea_tag_summary_read_under_its_title(tmp_path, kind):
    path, header_row = _summary(tmp_path, kind)
    sheet = read_tag_sheet(path)
    assert [t.transmitter for t in sheet.tags] == [row[2] for row in TAGS]
    for tag, row in zip(sheet.tags, TAGS):
        transmitter, bounds, sensor = _expected(row)
        assert (tag.transmitter, tag.ping_type, tag.burst_interval, tag.sensor) == (transmitter, "rbi", bounds, sensor)
        assert tag.role == "animal" and tag.line == header_row + 1 + TAGS.index(row)
    depth = sheet.tags[1]
    assert (depth.slope, depth.intercept) == (0.3033, -1.2131)  # the sensor's conversion, as the sheet gives it
    assert sheet.tags[2].shortest_interval() == 40.0  # the second step's delay: the echo limit holds for both


def test_equal_delays_are_a_stable_interval_and_no_step_on_leaves_it_to_the_detections(tmp_path):
    rows = [["1", "2", "A69-1601-11", *_step("ON", 30, 30), *_step(), *_step(), *_step(), "", "", "", "", "", ""],
            ["1", "3", "A69-1601-12", *_step("OFF", 30, 60), *_step(), *_step(), *_step(), "", "", "", "", "", ""]]
    path, _ = _summary(tmp_path, "xlsx", rows, title=False)
    stable, silent = read_tag_sheet(path).tags
    assert (stable.ping_type, stable.interval) == ("sbi", 30.0)
    assert (silent.ping_type, silent.burst_interval, silent.interval) == (None, None, None)


def _refused(path) -> str:
    with pytest.raises(ModelError) as caught:
        read_tag_sheet(path)
    message = str(caught.value)
    assert "\n" not in message and "Traceback" not in message
    return message


def _changed(row, column, value):
    row = list(row)
    row[SUMMARY.index(column)] = value
    return row


@pytest.mark.parametrize("kind", ["xlsx", "xls"])
@pytest.mark.parametrize("column, value, found", [
    ("Step 1 Min Delay (sec)", "forty", "column Step 1 Min Delay (sec): 'forty' is not allowed"),
    ("Step 1 Max Delay (sec)", 200000, "column Step 1 Max Delay (sec): '200000' is not allowed"),
    ("Step 1 Max Delay (sec)", "", "column Step 1 Max Delay (sec): empty in a step that is ON"),
    ("Step 1 Min Delay (sec)", 95, "step 1's Min Delay 95 s is more than its Max Delay 90 s"),
    ("Step 1 Status", "MAYBE", "column Step 1 Status: 'MAYBE' is not allowed; allowed: ON, OFF or empty"),
    ("VUE Tag ID", "A69-1601-501; rm", "column VUE Tag ID: 'A69-1601-501; rm' is not allowed"),
    ("VUE Tag ID", "A69-9002-602", "transmitter A69-9002-602 is listed twice"),
])
def test_a_bad_cell_is_refused_naming_the_sheet_row_and_column(tmp_path, kind, column, value, found):
    rows = [_changed(TAGS[0], column, value)] + TAGS[1:]
    path, header_row = _summary(tmp_path, kind, rows)
    message = _refused(path)
    row = header_row + 1 if column != "VUE Tag ID" or "twice" not in found else header_row + 2
    assert f"tags: '{path}' sheet 'Tag Summary' row {row}" in message and found in message, message


def test_a_depth_sensor_in_another_unit_is_refused(tmp_path):
    rows = [TAGS[0], _changed(TAGS[1], "Units", "PSI")]
    path, header_row = _summary(tmp_path, "xlsx", rows)
    message = _refused(path)
    assert f"sheet 'Tag Summary' row {header_row + 2} column Units: 'PSI' is not allowed" in message, message


@pytest.mark.parametrize("column, formula, found", [
    ("VUE Tag ID", '="A69-1601-"&"501"', "column VUE Tag ID: '' is not allowed"),
    ("Step 1 Min Delay (sec)", "=20+25", "column Step 1 Min Delay (sec): empty in a step that is ON"),
])
def test_a_formula_is_never_evaluated(tmp_path, column, formula, found):
    # a formula that would make a valid full ID or delay, written without a saved value: read as the empty cell it
    # holds, not computed
    path, header_row = _summary(tmp_path, "xlsx", [_changed(TAGS[0], column, formula)])
    message = _refused(path)
    assert f"row {header_row + 1} {found}" in message, message


def test_otn_tagging_metadata_under_its_title(tmp_path):
    header = ["ANIMAL_ID   (floy tag ID, pit tag code, etc.)", "TAG_TYPE", "TAG_MANUFACTURER", "TAG_MODEL",
              "TAG_SERIAL_NUMBER", "TAG_ID_CODE", "TAG_CODE_SPACE", "EST_TAG_LIFE", "RELEASE_LATITUDE"]
    rows = [["Ada", "Acoustic", "Vemco", "V16-4x", 2000001, 31001, "A69-9001", "3650 days", 44.5],
            ["Ben", "satellite", "Wildlife Computers", "MiniPAT", "15P0001", "", "", "", 44.6],
            ["Cy", "ACOUSTIC", "Vemco", "V13-1x", 2000002, 31002.0, "A69-9001", "900 days", 44.7]]
    title = [["", "", "TAGGING METADATA"], ["", "", "DATA SHEET"], ["", "", "version 4.1"], []]
    path = _xlsx(tmp_path / "otn.xlsx", {"Data Dictionary": [["Field Name"]], "Tag Metadata": title + [header] + rows})
    sheet = read_tag_sheet(path)
    acoustic = [r for r in rows if r[1].lower() == "acoustic"]  # the satellite tag is not a transmitter
    assert [(t.transmitter, t.name) for t in sheet.tags] == [(f"{r[6]}-{int(r[5])}", r[0]) for r in acoustic]
    assert [t.line for t in sheet.tags] == [len(title) + 1 + 1 + rows.index(r) for r in acoustic]
    assert all(t.ping_type is None for t in sheet.tags)
    rows[2][6] = "A69 9001"
    path = _xlsx(tmp_path / "otn2.xlsx", {"Tag Metadata": title + [header] + rows})
    assert f"sheet 'Tag Metadata' row {len(title) + 4} column TAG_CODE_SPACE: 'A69 9001'" in _refused(path)


def test_a_plain_sheet_in_a_workbook_reads_as_the_csv_sheet(tmp_path):
    rows = [["transmitter", "min_delay", "max_delay", "role", "name"], ["A69-1602-7", 60, 120, "animal", "eel"],
            ["A69-1601-8", 540, 660, "sync", ""]]
    path = _xlsx(tmp_path / "mine.xlsx", {"Sheet1": rows})
    csv = tmp_path / "mine.csv"
    csv.write_text("\n".join(",".join(str(c) for c in r) for r in rows) + "\n")
    assert [(t.transmitter, t.role, t.burst_interval, t.name) for t in read_tag_sheet(path).tags] == \
        [(t.transmitter, t.role, t.burst_interval, t.name) for t in read_tag_sheet(csv).tags]


def test_a_workbook_without_a_tag_header_names_its_sheets(tmp_path):
    path = _xlsx(tmp_path / "deploy.xlsx", {"Deployments": [["station", "lat", "lon"], ["S1", 44.1, -63.2]]})
    message = _refused(path)
    assert "no sheet holds a tag sheet's header in its first 30 rows" in message and "'Deployments'" in message


def test_a_zip_bomb_is_refused_before_it_is_opened(tmp_path, monkeypatch):
    path, _ = _summary(tmp_path, "xlsx")
    with zipfile.ZipFile(path) as archive:
        unpacked = sum(m.file_size for m in archive.infolist())
    import openpyxl

    monkeypatch.setattr(openpyxl, "load_workbook", lambda *a, **k: pytest.fail("opened"))
    monkeypatch.setattr(workbook, "MAX_UNPACKED_BYTES", unpacked - 1)
    assert "MiB unpacked" in _refused(path)
    monkeypatch.setattr(workbook, "MAX_UNPACKED_BYTES", unpacked)
    with zipfile.ZipFile(path) as archive:
        monkeypatch.setattr(workbook, "MAX_MEMBERS", len(archive.infolist()) - 1)
        # the elements counted independently: every part's opening and empty tags, as unpacked
        elements = sum(archive.read(m).count(b"<") - archive.read(m).count(b"</") for m in archive.infolist())
    assert "parts" in _refused(path)
    monkeypatch.setattr(workbook, "MAX_MEMBERS", 10**6)
    monkeypatch.setattr(workbook, "MAX_ELEMENTS", elements - 1)
    assert f"holds {elements:,} XML elements" in _refused(path)


def test_a_stated_size_that_lies_does_not_unpack_more(tmp_path):
    # a part whose stated size is small and whose data inflates far beyond: the zip reader stops at the stated size
    # (and finds the checksum wrong): refused in one line, nothing inflated past the stated sizes
    path, _ = _summary(tmp_path, "xlsx")
    buffer = io.BytesIO()
    with zipfile.ZipFile(path) as source, zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as target:
        for item in source.infolist():
            data = source.read(item)
            if item.filename.endswith("sheet2.xml"):
                data = data.replace(b"</sheetData>", b"<row r=\"99\"><c r=\"A99\" t=\"inlineStr\"><is><t>"
                                    + b"x" * 2**22 + b"</t></is></c></row></sheetData>")
            target.writestr(item, data)
    raw = bytearray(buffer.getvalue())
    bomb = tmp_path / "bomb.xlsx"
    # state every part's size as at most 1 MiB in the central directory (what the reader trusts)
    at = raw.find(b"PK\x01\x02")
    while at >= 0:
        size = int.from_bytes(raw[at + 24:at + 28], "little")
        raw[at + 24:at + 28] = min(size, 2**20).to_bytes(4, "little")
        at = raw.find(b"PK\x01\x02", at + 4)
    bomb.write_bytes(bytes(raw))
    with zipfile.ZipFile(bomb) as archive:  # what the reader checks: the stated sizes, under the limit
        assert sum(m.file_size for m in archive.infolist()) < workbook.MAX_UNPACKED_BYTES
    message = _refused(bomb)
    assert "is not a readable .xlsx workbook (Bad CRC-32" in message, message


def test_too_large_and_damaged_workbooks_are_refused_in_one_line(tmp_path, monkeypatch):
    path, _ = _summary(tmp_path, "xlsx")
    monkeypatch.setattr(workbook, "MAX_WORKBOOK_BYTES", path.stat().st_size - 1)
    assert "allowed at most" in _refused(path) and "for a workbook" in _refused(path)
    monkeypatch.undo()
    xls = tmp_path / "broken.xls"
    xls.write_bytes(bytes.fromhex("d0cf11e0a1b11ae1") + b"\x00\x01" * 300)
    assert f"tags: '{xls}' is not a readable .xls workbook" in _refused(xls)
    xlsx = tmp_path / "broken.xlsx"
    xlsx.write_bytes(b"PK\x03\x04" + b"\x00" * 100)
    assert f"tags: '{xlsx}' is not a readable .xlsx workbook" in _refused(xlsx)

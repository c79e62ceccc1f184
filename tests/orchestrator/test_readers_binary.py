"""A receiver's binary log (readers/binary.py through readers/cells.py and the tag sheet): a VRL or VDAT file, told by
its first bytes or its extension, refused by every reader in one line that names the format and the export that makes
a CSV of it; a workbook given where CSV text is read named as one; other binary files still refused for their NUL
byte. The logs here are invented bytes after each format's magic, not receivers' files."""

from __future__ import annotations

import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import read_detections, sniff_format
from sblsim.orchestrator.readers.sound_speed import read_sound_speed
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet

READERS = {"detections": lambda p: read_detections(p, None), "sniffed detections": sniff_format,
           "receivers": read_deployments, "tags": read_tag_sheet, "sound speed": read_sound_speed}
#: Each log's magic (the first four bytes of the receivers' files) and the words its refusal must hold.
LOGS = {"VRL": (b"VRLF", ("is a VRL file", "VR2W", "VUE's detection export", "Fathom Connect's CSV export")),
        "VDAT": (b"VDAT", ("is a VDAT file", "HR2", "Fathom Connect's CSV export", "--format=csv.fathom"))}


def _message(reader, path) -> str:
    with pytest.raises(ModelError) as caught:
        READERS[reader](path)
    message = str(caught.value)
    assert "\n" not in message and "Traceback" not in message
    return message


@pytest.mark.parametrize("reader", list(READERS))
@pytest.mark.parametrize("log", list(LOGS))
def test_a_log_is_told_by_its_first_bytes_under_any_name(tmp_path, reader, log):
    magic, words = LOGS[log]
    path = tmp_path / "receiver_export.csv"  # a log renamed: its bytes tell it
    path.write_bytes(magic + bytes([3, 1, 0, 0, 0, 0, 0, 128, 255, 238]) + b"\x00\x07" * 200)
    message = _message(reader, path)
    assert f"'{path}' is a {log} file" in message and all(w in message for w in words), message
    assert "NUL" not in message


@pytest.mark.parametrize("log, name", [("VRL", "VR2W_1_20200101_1.vrl"), ("VDAT", "HR2-180_2_2021-01-01.VDAT")])
def test_a_log_is_told_by_its_extension(tmp_path, log, name):
    path = tmp_path / name
    path.write_bytes(b"\x01\x02 a log whose first bytes were lost\n")
    assert all(w in _message("detections", path) for w in LOGS[log][1])


def test_other_binary_files_keep_the_nul_byte_refusal(tmp_path):
    path = tmp_path / "detections.csv"
    path.write_bytes(b"Date and Time (UTC),Receiver\n\x00\x01\x02")
    assert "holds a NUL byte (byte 29); allowed: CSV text" in _message("detections", path)


@pytest.mark.parametrize("magic, kind", [(bytes.fromhex("d0cf11e0a1b11ae1"), "xls"), (b"PK\x03\x04", "xlsx")])
def test_a_workbook_where_csv_is_read_is_named(tmp_path, magic, kind):
    path = tmp_path / "receivers.csv"
    path.write_bytes(magic + b"\x00" * 64)
    assert f"is an Excel workbook (.{kind}), not CSV text; allowed: CSV text (its sheet saved as CSV)" in \
        _message("receivers", path)


def _zipped(path, members):
    import zipfile

    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, text in members:
            archive.writestr(name, text)
    return path


@pytest.mark.parametrize("reader", ["sniffed detections", "receivers", "sound speed"])
def test_an_archive_is_named_as_one_and_nothing_extracted(tmp_path, reader):
    """A zipped CSV and a gzipped one, given where CSV text is read and an archive is not (every reader but the
    detections', which reads the CSV inside: ``test_readers_archives.py``; the store's sniffing of a file's format):
    each named as what it is, with the file the zip holds first, where before a zip was called an Excel workbook and
    a gzip file said to hold a NUL byte; a real workbook is still named a workbook, and an OpenDocument spreadsheet
    one."""
    import gzip

    import openpyxl

    text = "Date and Time (UTC),Receiver,Transmitter\n2024-06-03 00:01:00.742,VR2AR-461000,A69-1601-60001\n"
    zipped = _zipped(tmp_path / "extract.zip", [("proj_matched_detections_2024.csv", text), ("README.txt", "x")])
    message = _message(reader, zipped)
    assert f"'{zipped}' is a zip archive (its first file 'proj_matched_detections_2024.csv'), not CSV text; " \
           "allowed: CSV text (the archive's CSV extracted first)" in message, message
    (tmp_path / "extract.csv.gz").write_bytes(gzip.compress(text.encode()))
    message = _message(reader, tmp_path / "extract.csv.gz")
    assert "is gzip-compressed, not CSV text" in message and "NUL" not in message, message
    book = openpyxl.Workbook()
    book.save(tmp_path / "sheet.xlsx")
    assert "is an Excel workbook (.xlsx)" in _message(reader, tmp_path / "sheet.xlsx")
    ods = _zipped(tmp_path / "sheet.ods", [("mimetype", "application/vnd.oasis.opendocument.spreadsheet"),
                                           ("content.xml", "<x/>")])
    assert "is an OpenDocument spreadsheet (.ods), not CSV text" in _message(reader, ods)


def test_an_archive_s_hostile_first_name_is_shown_safely(tmp_path):
    """A zip whose first file's name holds control characters, a line end and 300 characters: said in one line, 80
    characters of the name at most, each not printable as '?'."""
    name = "a\nb\x1b[31mred\x07" + "x" * 300
    message = _message("receivers", _zipped(tmp_path / "odd.zip", [(name, "t")]))
    shown = message.split("its first file ", 1)[1].split("), not CSV text", 1)[0]
    assert shown == repr(("a?b?[31mred?" + "x" * 300)[:80]), shown

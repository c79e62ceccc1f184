"""A detections file as a network hands out its extracts, zipped (or gzipped): read through
(orchestrator/readers/binary.py ``archive_stream``, orchestrator/readers/cells.py ``read_text(archives=True)``) as
the CSV it holds, every row as the CSV's own; read as hostile input: its directory bounded before Python's zipfile
parses it, its CSV decompressed no further than the reader's bound (a zip bomb refused at the bound, not unpacked),
nothing written anywhere (a name inside never a path), one line for each fault: no CSV or several, too many files,
encrypted, damaged."""

from __future__ import annotations

import gzip
import zipfile
from pathlib import Path

import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers import detections as detections_module
from sblsim.orchestrator.readers.binary import MAX_ARCHIVE_FILES
from sblsim.orchestrator.readers.detections import read_detections

DATA = Path(__file__).resolve().parents[2] / "data" / "boats-norway"


def _zip(path: Path, members: list[tuple[str, bytes]], method=zipfile.ZIP_DEFLATED) -> Path:
    with zipfile.ZipFile(path, "w", method) as archive:
        for name, data in members:
            archive.writestr(name, data)
    return path


def _refused(path: Path) -> str:
    with pytest.raises(ModelError) as refused:
        read_detections(path, None)
    said = str(refused.value)
    assert "\n" not in said and str(path) in said, said
    return said


def test_a_zipped_and_a_gzipped_extract_read_as_the_csv(tmp_path):
    """The boats' detections zipped (beside a readme and macOS's resource fork of the CSV, as a Finder zip holds it)
    and gzipped: the same table as the CSV's, row for row."""
    text = (DATA / "detections.csv").read_bytes()
    own = read_detections(DATA / "detections.csv", None)
    zipped = _zip(tmp_path / "extract.zip", [("README.txt", b"about the extract\n"),
                                              ("__MACOSX/._detections.csv", b"\x00\x05\x16\x07 resource fork"),
                                              ("project/detections.csv", text)])
    (tmp_path / "extract.csv.gz").write_bytes(gzip.compress(text))
    for path in (zipped, tmp_path / "extract.csv.gz"):
        read = read_detections(path, None)
        pd.testing.assert_frame_equal(read.frame, own.frame)
        assert read.format == own.format and read.source == str(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["extract.csv.gz", "extract.zip"]  # nothing unpacked


def test_an_archive_holding_no_csv_or_several_is_refused_naming_them(tmp_path):
    none = _refused(_zip(tmp_path / "a.zip", [("notes.txt", b"x"), ("map.png", b"\x89PNG")]))
    assert "is a zip archive holding no CSV file (its files: 'notes.txt', 'map.png')" in none, none
    two = _refused(_zip(tmp_path / "b.zip", [("2019.csv", b"epo,frac,tag,serial\n"),
                                             ("2020.csv", b"epo,frac,tag,serial\n")]))
    assert "holding 2 CSV files ('2019.csv', '2020.csv')" in two and "given as files or a folder" in two, two


def test_a_zip_bomb_is_refused_at_the_readers_bound_not_unpacked(tmp_path, monkeypatch):
    """A CSV of 64 MiB compressed to a few hundred KiB, read with the detections' bound set to 1 MiB: refused as
    more than 1 MiB, from the first 1 MiB + 1 byte decompressed (the archive's stated sizes not trusted)."""
    monkeypatch.setattr(detections_module, "MAX_DETECTION_BYTES", 2**20)
    path = tmp_path / "bomb.zip"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive, archive.open("bomb.csv", "w") as member:
        member.write(b"epo,frac,tag,serial\n")
        for _ in range(64):
            member.write(b"1" * 2**20)
    assert path.stat().st_size < 2**20
    said = _refused(path)
    assert "is more than 1 MiB" in said, said


def test_too_many_files_are_refused_before_the_directory_is_parsed(tmp_path, monkeypatch):
    """An archive of more files than a detections archive holds: refused from its end record, before Python's
    zipfile makes an object of each (its ZipFile never called)."""
    path = _zip(tmp_path / "many.zip", [(f"f{k}.csv", b"x") for k in range(MAX_ARCHIVE_FILES + 1)])
    monkeypatch.setattr(zipfile, "ZipFile", lambda *a, **k: pytest.fail("the directory was parsed"))
    said = _refused(path)
    assert f"holds {MAX_ARCHIVE_FILES + 1} files" in said and f"at most {MAX_ARCHIVE_FILES} files" in said, said


def test_an_encrypted_or_damaged_archive_is_refused_in_one_line(tmp_path):
    text = (DATA / "detections.csv").read_bytes()[:200_000].rsplit(b"\n", 1)[0] + b"\n"
    data = bytearray(_zip(tmp_path / "plain.zip", [("detections.csv", text)]).read_bytes())
    for header, flags in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):  # marked encrypted (APPNOTE § 4.4.4, bit 0)
        at = data.find(header) + flags
        data[at] |= 0x1
    (tmp_path / "locked.zip").write_bytes(bytes(data))
    assert "holds 'detections.csv' encrypted" in _refused(tmp_path / "locked.zip")
    damaged = bytearray(_zip(tmp_path / "ok.zip", [("detections.csv", text)]).read_bytes())
    middle = len(damaged) // 2
    damaged[middle:middle + 64] = bytes(64)  # the deflate stream cut through
    (tmp_path / "damaged.zip").write_bytes(bytes(damaged))
    assert "is an archive that cannot be read" in _refused(tmp_path / "damaged.zip")
    (tmp_path / "cut.csv.gz").write_bytes(gzip.compress(text)[:5000])
    assert "is an archive that cannot be read" in _refused(tmp_path / "cut.csv.gz")


def test_a_name_inside_is_never_a_path(tmp_path):
    """A member named to climb out of the folder (``../../outside.csv``) is read as the CSV it is, and nothing is
    written, there or anywhere near."""
    text = (DATA / "detections.csv").read_bytes()[:20_000].rsplit(b"\n", 1)[0] + b"\n"
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    path = _zip(work / "odd.zip", [("../../outside.csv", text)])
    read = read_detections(path, None)
    assert len(read.frame) == text.count(b"\n") - 1
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == ["a", "a/b", "a/b/odd.zip"]

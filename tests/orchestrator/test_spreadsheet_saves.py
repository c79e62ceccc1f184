"""A study's table as a spreadsheet saves it other than as CSV UTF-8 (orchestrator/readers/binary.py ``not_text``,
orchestrator/readers/cells.py ``text_table``): its 'Unicode Text' (UTF-16, with or without a byte-order mark) and a
CSV of a decimal-comma locale (semicolons) or tabs are each refused in one line that says so and how to save it.
Before, the first said "holds a NUL byte" and the second that the header needs a column it has."""

from __future__ import annotations

from pathlib import Path

import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.binary import utf16
from sblsim.orchestrator.readers.deployments import read_deployments
from sblsim.orchestrator.readers.detections import read_detections
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet

DATA = Path(__file__).resolve().parents[2] / "data" / "boats-norway"
READERS = {"deployments.csv": read_deployments, "tags.csv": read_tag_sheet,
           "detections.csv": lambda path: read_detections(path, None)}


def _refusal(path: Path, name: str) -> str:
    with pytest.raises(ModelError) as refused:
        READERS[name](path)
    said = str(refused.value)
    assert "\n" not in said and str(path) in said, said
    return said


@pytest.mark.parametrize("name", list(READERS))
@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be"])
def test_utf16_is_said_to_be_utf16(tmp_path, name, encoding):
    """The boats' file (its first 200 lines) in UTF-16 (Python's codec: little-endian with a byte-order mark, and
    either order without one): refused as UTF-16 text, saying to save it as CSV UTF-8."""
    text = "".join((DATA / name).read_text().splitlines(keepends=True)[:200])
    path = tmp_path / name
    path.write_bytes(text.encode(encoding))
    said = _refusal(path, name)
    assert "is UTF-16 text" in said and "CSV UTF-8" in said, said


@pytest.mark.parametrize("name", list(READERS))
@pytest.mark.parametrize("separator, said", [(";", "semicolons"), ("\t", "tabs")])
def test_another_separator_is_named(tmp_path, name, separator, said):
    """The same file with its commas replaced by semicolons or tabs: refused, naming the separator (the file as it
    is is read)."""
    text = "".join((DATA / name).read_text().splitlines(keepends=True)[:200])
    path = tmp_path / name
    path.write_text(text)
    READERS[name](path)
    path.write_text(text.replace(",", separator))
    refused = _refusal(path, name)
    assert f"separated by {said}" in refused and "comma-separated" in refused, refused


def test_utf16_is_told_from_other_bytes():
    """The byte-order marks and ASCII text with every other byte NUL are UTF-16; UTF-8 text with a stray NUL, a
    binary header and too few bytes are not."""
    assert utf16(b"\xff\xfeA\x00") and utf16(b"\xfe\xff\x00A") and utf16("tag,x\n".encode("utf-16-le"))
    assert utf16("tag,x\n".encode("utf-16-be"))
    assert not utf16(b"tag,x\x00,y\n1,2,3") and not utf16(b"PK\x03\x04\x14\x00\x06\x00") and not utf16(b"\x00")

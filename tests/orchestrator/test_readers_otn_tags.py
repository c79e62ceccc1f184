"""OTN's tag releases table as a tag sheet (readers/otn_tags.py through readers/tag_sheet.py): its ERDDAP units row
dropped, ``tag_device_id`` the full ID, the release's reference the name, a tag without a code space (a satellite
tag) skipped; OTN's animals table refused in one line naming the table that has the transmitters. The tables are
written here from OTN's documented columns, with invented tags and animals."""

from __future__ import annotations

import io

import pandas as pd
import pytest

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.tag_sheet import read_tag_sheet

HEADER = ("release_project_reference,datacenter_reference,tag_device_id,release_guid,release_reference_id,"
          "release_reference_type,latitude,longitude,time,expected_enddate,manufacturer,tag_model,tag_serial_number,"
          "tag_frequency,tag_coding_system,transmitted_id,transmittername,transmitter_type,tag_programming_id")
UNITS = ",,,,,,degrees_north,degrees_east,UTC,UTC,,,,,,,,,"
ROWS = [
    "PRJ,OTN-Global,A69-9001-41001,OTN-GlobalPRJA69-9001-41001,PRJ-Ada,ANIMAL,45.1,-62.1,2019-07-01T00:00:00Z,"
    "2024-07-01T00:00:00Z,VEMCO,V16-6X,3000001,,A69-9001,41001,A69-9001-41001,,",
    "PRJ,OTN-Global,A69-9002-41002,OTN-GlobalPRJA69-9002-41002,PRJ-Bo,ANIMAL,45.2,-62.2,2019-07-02T00:00:00Z,"
    "2024-07-02T00:00:00Z,VEMCO,V16TP-6X,3000002,,A69-9002,41002,A69-9002-41002,,",
    "PRJ,OTN-Global,777001,OTN-GlobalPRJ777001,PRJ-Cal,ANIMAL,45.3,-62.3,2019-07-03T00:00:00Z,"
    "2020-07-03T00:00:00Z,Wildlife Computers,MiniPAT,19P0001,,777001,777001,777001,,",
    "PRJ,OTN-Global,A69-9002-41003,OTN-GlobalPRJA69-9002-41003,PRJ-Bo,ANIMAL,45.2,-62.2,2019-07-02T00:00:00Z,"
    "2024-07-02T00:00:00Z,VEMCO,V16TP-6X,3000002,,A69-9002,41003,A69-9002-41003,,",
]


def _expected(text: str, units: bool) -> pd.DataFrame:
    """The acoustic tags, by pandas from the same text: the units row skipped, the tags with a code space kept."""
    table = pd.read_csv(io.StringIO(text), dtype=str, skiprows=[1] if units else None)
    table["line"] = range(2 + units, 2 + units + len(table))
    return table[table["tag_device_id"].str.contains("-")]


@pytest.mark.parametrize("units", [True, False], ids=["ERDDAP units row", "no units row"])
def test_tag_releases_read_as_a_tag_sheet(tmp_path, units):
    text = "\n".join([HEADER] + ([UNITS] if units else []) + ROWS) + "\n"
    path = tmp_path / "otn_tag_releases.csv"
    path.write_text(text)
    expected = _expected(text, units)
    sheet = read_tag_sheet(path)
    assert [(t.transmitter, t.name, t.line) for t in sheet.tags] == \
        list(zip(expected["tag_device_id"], expected["release_reference_id"], expected["line"]))
    assert all(t.role == "animal" and t.ping_type is None and t.sensor == "" for t in sheet.tags)
    assert "777001" not in {t.transmitter for t in sheet.tags}  # the satellite tag is no acoustic transmitter


def test_a_bad_tag_device_id_is_refused_naming_its_line(tmp_path):
    rows = ROWS[:1] + [ROWS[1].replace("A69-9002-41002,OTN", "A69-9002-41002;x,OTN", 1)]
    path = tmp_path / "releases.csv"
    path.write_text("\n".join([HEADER, UNITS] + rows) + "\n")
    with pytest.raises(ModelError) as caught:
        read_tag_sheet(path)
    message = str(caught.value)
    assert f"tags: '{path}' line 4 column tag_device_id: 'A69-9002-41002;x' is not allowed" in message, message
    assert "\n" not in message


def test_the_animals_table_is_refused_naming_the_releases_table(tmp_path):
    path = tmp_path / "otn_animals.csv"
    path.write_text("animal_project_reference,datacenter_reference,animal_reference_id,animal_guid,vernacularname,"
                    "scientificname,length,sex\n,,,,,,,\nPRJ,OTN-Global,PRJ-Ada,OTN-GlobalPRJPRJ-Ada,blue shark,"
                    "Prionace glauca,1.5,F\n")
    with pytest.raises(ModelError) as caught:
        read_tag_sheet(path)
    message = str(caught.value)
    assert "is OTN's animals table" in message and "tag releases table (tag_device_id" in message, message
    assert "\n" not in message

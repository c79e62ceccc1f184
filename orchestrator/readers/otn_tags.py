"""OTN's tag tables from its ERDDAP (glatos's ``otn_aat_tag_releases.csv`` and ``otn_aat_animals.csv``) as a tag
sheet, each told by its header, for :func:`~sblsim.orchestrator.readers.tag_sheet.read_tag_sheet`.

* **Tag releases** (a ``tag_device_id`` column): one row per tag released, under a units row (ERDDAP's: ``,,,
  degrees_north,degrees_east,UTC,UTC,,,``, dropped: :func:`~sblsim.orchestrator.readers.cells.units_row`):
  ``tag_device_id`` (the transmitter's full ID, ``A69-9001-26651``), ``release_reference_id`` (the animal's
  reference, ``NSBS-Eva``: the tag's name; else ``animal_reference_id``), and ``transmitter_type``, ``tag_model``,
  ``time`` (the release), ``expected_enddate``, ``latitude``, ``longitude``, which a tag sheet does not use. A row
  whose ``tag_device_id`` has no code space (a satellite or archival tag, ``152092``; or none) is not an acoustic
  transmitter and is skipped; every other one must be a full ID.
* **Animals** (``animal_reference_id`` and no ``tag_device_id``; its units row blank): it names animals, not
  transmitters, and is refused in one line naming the table that has them.

Source: OTN's ERDDAP tables as glatos ships and reads them (``convert_otn_erddap_to_att``: ``tag_device_id`` is the
transmitter, ``release_reference_id`` and ``animal_reference_id`` the animal).
"""

from __future__ import annotations

import pandas as pd

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.readers.cells import named, pattern, units_row
from sblsim.orchestrator.readers.transmitters import FULL_ID, TAG_ID

#: The column that tells each table.
RELEASES = "tag_device_id"
ANIMALS = "animal_reference_id"
#: The columns a release's name is taken from, first preferred.
NAMES = ("release_reference_id", "animal_reference_id")


def otn_table(header: list[str]) -> str | None:
    """Which of OTN's tag tables a header shows: ``"releases"``, ``"animals"``, or None for neither."""
    if named(header, (RELEASES,)) is not None:
        return "releases"
    if named(header, (ANIMALS,)) is not None:
        return "animals"
    return None


def releases(header: list[str], body: pd.DataFrame, lines: list[int], name: str, what: str
             ) -> tuple[pd.DataFrame, list[int], dict[str, int | None]]:
    """An OTN tag releases table's acoustic tags (the module docstring): its rows without the units row and the
    tags without a code space, each row's line, and the tag sheet's fields to their columns (``transmitter``,
    ``name``; no other field read).

    Raises
    ------
    ModelError
        An animals table (no transmitter: one line naming the releases table); a ``tag_device_id`` that is neither
        a full ID nor an id alone; a units row stating another unit (one line naming the line and the column).
    """
    if otn_table(header) == "animals":
        raise ModelError(f"{what}: {name!r} is OTN's animals table (animal_reference_id, vernacularname, ...): it "
                         "names animals, not transmitters; allowed: OTN's tag releases table (tag_device_id, the "
                         "full ID, and release_reference_id, the animal), or a tag sheet")
    body, lines, _ = units_row(header, body, lines, {}, name, what)
    at = named(header, (RELEASES,))
    cells = body[at].astype(str).str.strip()
    acoustic = ~(cells.str.fullmatch(TAG_ID.pattern).fillna(False) | (cells == "")).to_numpy(bool)
    body, lines = body[acoustic].reset_index(drop=True), [n for n, keep in zip(lines, acoustic) if keep]
    pattern(body[at], FULL_ID, what, name, lines, header[at], "a transmitter's full ID (A69-9001-26651), or an id "
            "alone for a tag that is not acoustic (skipped)")
    return body, lines, {"transmitter": at, "name": named(header, NAMES)}


__all__ = ["ANIMALS", "NAMES", "RELEASES", "otn_table", "releases"]

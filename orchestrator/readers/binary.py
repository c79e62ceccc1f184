"""Files that are not CSV text, told by their first bytes: a receiver's binary log, which no reader takes and each
refuses in one line naming the format and the export that makes the CSV sblsim reads, and a spreadsheet workbook
(read as a tag sheet by :mod:`.workbook`; refused as text elsewhere).

* **VRL** (first bytes ``VRLF``; extension ``.vrl``): the log a VR2W, VR2W-180, VR2AR or VR2Tx receiver is offloaded
  to. Its detections are read from VUE's detection export (a CSV: :mod:`.vue`) or Fathom Connect's (a Fathom CSV:
  :mod:`.fathom`; its command-line converter ``vdat convert --format=csv.fathom FILE``, as glatos's ``vdat_convert``
  calls it).
* **VDAT** (first bytes ``VDAT``; extension ``.vdat``): the log of Innovasea's current receivers (HR2, NexTrak) as
  Fathom Connect offloads it; VUE does not read it. Read from Fathom Connect's CSV export (the same converter).
* **Workbooks**: an ``.xls`` (a BIFF8 workbook in an OLE2 compound document, first bytes ``D0 CF 11 E0 A1 B1 1A
  E1``) and an ``.xlsx`` (a zip archive of XML parts, first bytes ``PK 03 04``, its first part one of the Office Open
  XML package's: ECMA-376 Part 2, the Open Packaging Conventions).
* **Archives**: an OpenDocument spreadsheet (a zip archive whose first file is ``mimetype``), any other zip archive
  (as OTN and GLATOS hand out their extracts: a CSV zipped), named with its first file (read from its first local
  header, PKWARE's APPNOTE § 4.3.7), and a gzip file (first bytes ``1F 8B``, RFC 1952): refused as text, saying to
  extract the CSV first. Nothing is extracted.

Sources: the example logs glatos ships (``inst/extdata/detection_files_raw``: five VRL files of four receiver
models and one HR2 VDAT file) and glatos's ``vdat_convert`` and ``vue_convert`` (the conversions).
"""

from __future__ import annotations

from pathlib import Path

from sblsim.models.declarations import ModelError
from sblsim.orchestrator.io.tables import regular_file

#: Each binary log's first bytes, extension and what it is, and the export that makes a CSV of it.
LOGS = {
    "VRL": (b"VRLF", ".vrl", "a VR2W, VR2AR or VR2Tx receiver's binary log",
            "its CSV export: VUE's detection export (File > Export > Detections), or Fathom Connect's CSV export "
            "(vdat convert --format=csv.fathom FILE)"),
    "VDAT": (b"VDAT", ".vdat", "an HR2 or NexTrak receiver's binary log, as Fathom Connect offloads it",
             "its Fathom CSV: Fathom Connect's CSV export (vdat convert --format=csv.fathom FILE)"),
}
#: A workbook's first bytes: an .xls (an OLE2 compound document) and an .xlsx (a zip archive).
XLS_MAGIC = bytes.fromhex("d0cf11e0a1b11ae1")
XLSX_MAGIC = b"PK\x03\x04"
#: A gzip file's first bytes (RFC 1952 § 2.3.1).
GZIP_MAGIC = b"\x1f\x8b"
#: The first part of an Office Open XML package (a workbook) is one of these, or under one of these folders.
OOXML_PARTS = ("[Content_Types].xml", "_rels/", "docProps/", "xl/", "customXml/")
#: The bytes read to tell a file's kind.
HEAD_BYTES = 8


def kind_of(head: bytes, suffix: str = "") -> str | None:
    """What a file's first bytes (and its name's extension, for a log) show it to be: ``"VRL"``, ``"VDAT"``,
    ``"xls"``, ``"xlsx"``, or None (text, or a binary file of no kind named here)."""
    suffix = suffix.lower()
    for log, (magic, extension, _, _) in LOGS.items():
        if head.startswith(magic) or suffix == extension:
            return log
    if head.startswith(XLS_MAGIC):
        return "xls"
    if head.startswith(XLSX_MAGIC):
        return "xlsx"
    return None


def first_bytes(path: Path, what: str) -> bytes:
    """A regular file's first :data:`HEAD_BYTES` bytes (checked to be a regular file before it is opened).

    Raises
    ------
    ModelError
        A missing or unreadable file, or one that is not a regular file.
    """
    regular_file(path, what)
    try:
        with open(path, "rb") as handle:
            return handle.read(HEAD_BYTES)
    except OSError as exc:
        raise ModelError(f"{what}: {str(path)!r} cannot be read ({exc.strerror or type(exc).__name__})") from None


def log_refused(name: str, what: str, log: str) -> ModelError:
    """The one line refusing a binary receiver log (``log``, a key of :data:`LOGS`)."""
    _, _, kind, export = LOGS[log]
    return ModelError(f"{what}: {name!r} is a {log} file ({kind}), not CSV text; allowed: {export}")


def refuse_log(path: Path, what: str) -> None:
    """Refuse a binary receiver log (:data:`LOGS`), told by its extension or its first bytes, before it is read.

    Raises
    ------
    ModelError
        A VRL or VDAT file (one line naming the format and its CSV export); a missing or unreadable file, or one
        that is not a regular file.
    """
    kind = kind_of(first_bytes(path, what), Path(path).suffix)
    if kind in LOGS:
        raise log_refused(str(path), what, kind)


def not_text(name: str, what: str, data: bytes, nul: int) -> ModelError:
    """The one line refusing a file that holds a NUL byte at ``nul``: a workbook named as one (to be saved as CSV),
    else a binary file."""
    kind = kind_of(data[:HEAD_BYTES])
    first = zip_first_name(data) if kind == "xlsx" else None
    if first == "mimetype":  # an OpenDocument package's first file (ODF 1.2 Part 3 § 3.3): a spreadsheet's
        return ModelError(f"{what}: {name!r} is an OpenDocument spreadsheet (.ods), not CSV text; allowed: CSV text "
                          "(its sheet saved as CSV)")
    if first is not None and not first.startswith(OOXML_PARTS):
        return ModelError(f"{what}: {name!r} is a zip archive (its first file {first!r}), not CSV text; allowed: CSV "
                          "text (the archive's CSV extracted first)")
    if data.startswith(GZIP_MAGIC):
        return ModelError(f"{what}: {name!r} is gzip-compressed, not CSV text; allowed: CSV text (the file "
                          "decompressed first: gunzip)")
    if kind in ("xls", "xlsx"):
        return ModelError(f"{what}: {name!r} is an Excel workbook (.{kind}), not CSV text; allowed: CSV text (its "
                          "sheet saved as CSV)")
    if utf16(data[:HEAD_BYTES]):
        return ModelError(f"{what}: {name!r} is UTF-16 text (as a spreadsheet's 'Unicode Text' saves it), not "
                          "UTF-8; allowed: CSV text in UTF-8 (save it as 'CSV UTF-8')")
    return ModelError(f"{what}: {name!r} holds a NUL byte (byte {nul}); allowed: CSV text")


def zip_first_name(head: bytes) -> str | None:
    """The name of a zip archive's first file, from the local header its first bytes hold (signature ``PK 03 04``,
    the name's length at byte 26, the name from byte 30: PKWARE's APPNOTE § 4.3.7), shown safely (80 characters at
    most, each not printable as ``?``); None where ``head`` holds no whole local header."""
    if not head.startswith(XLSX_MAGIC) or len(head) < 30:
        return None
    length = int.from_bytes(head[26:28], "little")
    if length == 0 or len(head) < 30 + length:
        return None
    text = head[30:30 + length].decode("utf-8", errors="replace")[:80]
    return "".join(c if c.isprintable() else "?" for c in text)


def utf16(head: bytes) -> bool:
    """Whether a file's first bytes are UTF-16 text: its byte-order mark, or (without one) a NUL byte at every other
    position of text that is otherwise ASCII (its first 64 characters at most)."""
    if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
        return True
    head = head[:128]
    if len(head) < 4:
        return False
    for zeros, text in ((head[1::2], head[0::2]), (head[0::2], head[1::2])):
        if not zeros.strip(b"\0") and all(32 <= b < 127 or b in (9, 10, 13) for b in text):
            return True
    return False


__all__ = ["GZIP_MAGIC", "HEAD_BYTES", "LOGS", "OOXML_PARTS", "XLSX_MAGIC", "XLS_MAGIC", "first_bytes", "kind_of",
           "log_refused", "not_text", "refuse_log", "utf16", "zip_first_name"]

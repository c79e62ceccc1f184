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
  (as a network hands out its detection extracts: a CSV zipped), named with its first file (read from its
  first local header, PKWARE's APPNOTE § 4.3.7), and a gzip file (first bytes ``1F 8B``, RFC 1952): refused as text
  by every reader but the detections', saying to extract the CSV first. The detections' reader reads the one CSV
  such an archive holds (:func:`archive_stream`) as hostile input: nothing written to disk, a name inside never
  opened as a path, the archive's directory bounded before it is parsed (its end record, APPNOTE § 4.3.16: at most
  :data:`MAX_ARCHIVE_FILES` files and :data:`MAX_DIRECTORY_BYTES` of directory), its CSV decompressed only as far as
  the reader's bound on its text, an encrypted or ZIP64 archive refused.

Sources: the example logs glatos ships (``inst/extdata/detection_files_raw``: five VRL files of four receiver
models and one HR2 VDAT file) and glatos's ``vdat_convert`` and ``vue_convert`` (the conversions).
"""

from __future__ import annotations

import gzip
import zipfile
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO, Iterator

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
#: The most files a zip archive of detections may hold (a CSV, its readme and metadata: a few).
MAX_ARCHIVE_FILES = 64
#: The most bytes a zip archive's central directory may take (a few files' names: a few KiB).
MAX_DIRECTORY_BYTES = 2**20
#: A zip archive's end of central directory record: its signature and the bytes from its end it can start at (its
#: 22 bytes and a comment of at most 65,535).
END_RECORD = b"PK\x05\x06"
END_SEARCH = 22 + 65535
#: The files a zip archive may hold besides the CSV read, not counted as tables: macOS's resource forks.
RESOURCE_FORKS = "__MACOSX/"


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
    kind, archive = kind_of(data[:HEAD_BYTES]), _archive_of(data)
    if archive == "ods":
        return ModelError(f"{what}: {name!r} is an OpenDocument spreadsheet (.ods), not CSV text; allowed: CSV text "
                          "(its sheet saved as CSV)")
    if archive == "zip":
        return ModelError(f"{what}: {name!r} is a zip archive (its first file {zip_first_name(data)!r}), not CSV "
                          "text; allowed: CSV text (the archive's CSV extracted first)")
    if archive == "gzip":
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
    return _shown(head[30:30 + length].decode("utf-8", errors="replace"))


def _archive_of(head: bytes) -> str | None:
    """The archive a file's first bytes show: ``"gzip"``, ``"ods"`` (an OpenDocument package: its first file
    ``mimetype``, ODF 1.2 Part 3 § 3.3), ``"zip"`` (any other zip archive whose first file is none of an Office Open
    XML package's parts), or None (a workbook, or no archive)."""
    if head.startswith(GZIP_MAGIC):
        return "gzip"
    first = zip_first_name(head)
    if first is None or first.startswith(OOXML_PARTS):
        return None
    return "ods" if first == "mimetype" else "zip"


def archive_kind(path: Path) -> str | None:
    """``"zip"`` (a zip archive that is no workbook nor spreadsheet), ``"gzip"``, or None (any other file), told by
    its first bytes (:func:`_archive_of`)."""
    try:
        with open(path, "rb") as handle:
            head = handle.read(4096)
    except OSError:
        return None
    kind = _archive_of(head)
    return kind if kind in ("zip", "gzip") else None


def _checked_directory(path: Path, name: str, what: str) -> None:
    """Refuse a zip archive whose central directory is larger than a detections archive's before Python's zipfile
    parses it (it makes an object of every entry): its end record's count of files and directory size (APPNOTE
    § 4.3.16), ZIP64's marks (0xFFFF, 0xFFFFFFFF) refused."""
    try:
        with open(path, "rb") as handle:
            handle.seek(0, 2)
            size = handle.tell()
            handle.seek(max(0, size - END_SEARCH))
            tail = handle.read()
    except OSError as exc:
        raise archive_error(name, what, exc) from None
    at = tail.rfind(END_RECORD)
    if at < 0 or len(tail) < at + 22:
        raise ModelError(f"{what}: {name!r} is not a readable zip archive (no end of its directory); allowed: a zip "
                         "archive holding one CSV, or the CSV")
    files = int.from_bytes(tail[at + 10:at + 12], "little")
    directory = int.from_bytes(tail[at + 12:at + 16], "little")
    if files == 0xFFFF or directory == 0xFFFFFFFF:
        raise ModelError(f"{what}: {name!r} is a ZIP64 archive; allowed: a zip archive holding one CSV (at most "
                         f"{MAX_ARCHIVE_FILES} files), or the CSV")
    if files > MAX_ARCHIVE_FILES or directory > MAX_DIRECTORY_BYTES:
        raise ModelError(f"{what}: {name!r} holds {files:,} files ({directory:,} bytes of directory); allowed at most "
                         f"{MAX_ARCHIVE_FILES} files in a zip archive of detections (one CSV, its readme)")


def _shown(text: str) -> str:
    """A name from a file shown safely: 80 characters at most, each not printable as ``?``."""
    return "".join(c if c.isprintable() else "?" for c in text[:80])


@contextmanager
def archive_stream(path: Path, what: str) -> Iterator[BinaryIO]:
    """The CSV a zip or gzip archive holds (:func:`archive_kind`), as a binary stream that decompresses as it is read
    (the caller reads at most its bound); nothing written.

    Raises
    ------
    ModelError
        One line: a zip archive holding no CSV or more than one (``__MACOSX/`` resource forks not counted), an
        encrypted one, one with more than :data:`MAX_ARCHIVE_FILES` files or a ZIP64 one, one that is damaged or
        compressed in a way Python's zipfile does not read; a gzip file that is not one. An error while the stream is
        read (a damaged deflate stream, a checksum) is the caller's (:func:`archive_error`).
    """
    name = str(path)
    if archive_kind(path) == "gzip":
        with gzip.open(path, "rb") as stream:
            yield stream
        return
    _checked_directory(path, name, what)
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise archive_error(name, what, exc) from None
    with archive:
        files = [m for m in archive.infolist() if not m.is_dir() and not m.filename.startswith(RESOURCE_FORKS)]
        tables = [m for m in files if m.filename.lower().endswith(".csv")]
        if len(tables) != 1:
            shown = ", ".join(repr(_shown(m.filename)) for m in (tables or files)[:5])
            held = f"{len(tables)} CSV files ({shown})" if tables else f"no CSV file (its files: {shown or 'none'})"
            raise ModelError(f"{what}: {name!r} is a zip archive holding {held}; allowed: a zip archive holding one "
                             "CSV, or the CSVs extracted and given as files or a folder")
        member = tables[0]
        if member.flag_bits & 0x1:
            raise ModelError(f"{what}: {name!r} holds {_shown(member.filename)!r} encrypted; allowed: a zip archive "
                             "that is not encrypted, or the CSV")
        try:
            stream = archive.open(member)
        except (zipfile.BadZipFile, OSError, ValueError, EOFError, NotImplementedError, RuntimeError) as exc:
            raise archive_error(name, what, exc) from None
        with stream:
            yield stream


def archive_error(name: str, what: str, exc: Exception) -> ModelError:
    """The one line refusing an archive that cannot be read (a library's error named, at most 120 characters)."""
    reason = " ".join(str(exc).split())[:120] or type(exc).__name__
    return ModelError(f"{what}: {name!r} is an archive that cannot be read ({reason}); allowed: a zip or gzip "
                      "archive holding one CSV, or the CSV")


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


__all__ = ["END_RECORD", "END_SEARCH", "GZIP_MAGIC", "HEAD_BYTES", "LOGS", "MAX_ARCHIVE_FILES", "MAX_DIRECTORY_BYTES",
           "OOXML_PARTS", "RESOURCE_FORKS", "XLSX_MAGIC", "XLS_MAGIC", "archive_error", "archive_kind",
           "archive_stream", "first_bytes", "kind_of", "log_refused", "not_text", "refuse_log", "utf16",
           "zip_first_name"]

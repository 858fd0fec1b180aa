"""Format detection from content (zip/OLE2 signatures, byte-order mark, first lines), then the matching reader.

The extension is only a hint: a ``.txt`` may be a TRIOS text export or a TA LIMS export, a ``.csv`` a
RheoCompass, TRIOS, rSpace or tidy file. Order matters where formats share markers: a LIMS export also holds
``[Step]`` and ``Instrument name`` (TRIOS markers), so it is recognised first.
"""
from __future__ import annotations

import zipfile
from pathlib import Path

from .blocks import Block
from .consistency import check_redundant_columns
from .errors import IngestError
from .lims import looks_like_lims, read_lims
from .rheocompass import looks_like_rheocompass, read_rheocompass, read_rheocompass_xlsx
from .rspace import looks_like_rspace, read_rspace
from .table import looks_like_table, read_table
from .textfile import decode_text
from .tidy import looks_like_tidy, read_tidy
from .trios import looks_like_trios, read_trios_text, read_trios_xls

SUPPORTED = ("Anton Paar RheoCompass CSV/TXT (UTF-16/UTF-8, EN/FR/DE) and .xlsx", "TA TRIOS text/CSV/.xls",
             "TA LIMS export (.txt)", "Malvern Kinexus rSpace CSV", "tidy CSV",
             "plain tables (RheoCompass labels or canonical names; units from a [unit] row or dataset.yaml 'columns')")
_OLE2 = b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1"


def detect_format(path) -> str:
    """Name of the reader a file needs (``rheocompass``, ``rheocompass_xlsx``, ``trios_text``, ``trios_xls``,
    ``lims``, ``rspace``, ``tidy`` or ``table``); raises :class:`IngestError` for unsupported or unrecognised
    content."""
    path = Path(path)
    if not path.is_file():
        raise IngestError(path, "file not found")
    head = path.read_bytes()[:8]
    if head[:4] == b"PK\x03\x04":
        try:
            names = zipfile.ZipFile(path).namelist()
        except zipfile.BadZipFile as exc:
            raise IngestError(path, f"corrupt zip container (truncated file?): {exc}") from exc
        if path.suffix.lower() == ".rhpts" or "Directory.XML" in names:
            raise IngestError(path, "Anton Paar .RhPts object export (zipped XML with binary .NET blobs) is not "
                                    "supported: export the data as CSV/TXT or .xlsx from RheoCompass")
        if "xl/workbook.xml" in names:
            return "rheocompass_xlsx"
        raise IngestError(path, f"zip container that is not an .xlsx workbook; supported: {', '.join(SUPPORTED)}")
    if head[:8] == _OLE2:
        return "trios_xls"
    text = decode_text(path)
    return _text_format(path, text)


def _text_format(path: Path, text: str, columns=None) -> str:
    if not text.strip():
        raise IngestError(path, "empty file")
    if looks_like_lims(text):
        return "lims"
    if looks_like_rheocompass(text):
        return "rheocompass"
    if looks_like_rspace(text):
        return "rspace"
    if looks_like_trios(text):
        return "trios_text"
    if columns or looks_like_tidy(text):
        return "tidy"
    if looks_like_table(text):
        return "table"
    raise IngestError(path, f"unrecognised export format; supported: {', '.join(SUPPORTED)}", line=1)


def read_export(path, **options) -> list[Block]:
    """Read an instrument export into canonical blocks.

    Parameters
    ----------
    path : the file
    options : reader options: from the sample sheet ``columns``, ``units`` (headerless tidy files); from
        ``dataset.yaml`` ``column_units`` (label -> unit pairs of its ``columns``, for tables without units)

    Raises
    ------
    IngestError : unreadable, unsupported (e.g. ``.RhPts``) or malformed files, with file/line/column; a text
        export whose last line has no line end (every real export ends its last line, and a file cut inside its
        last number would otherwise read as another number).
    """
    path = Path(path)
    if not path.is_file():
        raise IngestError(path, "file not found")
    return check_redundant_columns(path, _read_blocks(path, options))


def _read_blocks(path: Path, options: dict) -> list[Block]:
    head = path.read_bytes()[:8]
    if head[:4] == b"PK\x03\x04" or head[:8] == _OLE2:
        kind = detect_format(path)
        return read_rheocompass_xlsx(path) if kind == "rheocompass_xlsx" else read_trios_xls(path)
    text = decode_text(path)
    blocks = _read_text(path, text, options)
    if text.strip() and not text.endswith(("\n", "\r")):
        # every real export ends its last line: a file cut inside its last row would read as a shorter number
        raise IngestError(path, "the file ends without a line end (truncated inside its last row?); if the file "
                                "is complete, end it with a line break", line=len(text.splitlines()))
    return blocks


def _read_text(path: Path, text: str, options: dict) -> list[Block]:
    kind = _text_format(path, text, options.get("columns"))
    if kind == "lims":
        return read_lims(path, text)
    if kind == "rheocompass":
        return read_rheocompass(path, text)
    if kind == "rspace":
        return read_rspace(path, text)
    if kind == "trios_text":
        return read_trios_text(path, text)
    if kind == "table":
        return read_table(path, text, column_units=options.get("column_units"))
    return read_tidy(path, text, columns=options.get("columns"), units=options.get("units"))

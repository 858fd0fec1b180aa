"""Format detection from content (byte-order mark, first lines), then the matching reader."""
from __future__ import annotations

import zipfile
from pathlib import Path

from .blocks import Block, decode_text
from .errors import IngestError
from .rheocompass import looks_like_rheocompass, read_rheocompass
from .tidy import looks_like_tidy, read_tidy
from .trios import looks_like_trios, read_trios_text, read_trios_xls

SUPPORTED = ("Anton Paar RheoCompass CSV/TXT (UTF-16/UTF-8, EN/FR/DE)", "TA TRIOS text/CSV/.xls", "tidy CSV")


def read_export(path, **options) -> list[Block]:
    """Read an instrument export into canonical blocks.

    Parameters
    ----------
    path : the file
    options : reader options from the sample sheet (``columns``, ``units`` for headerless tidy files)

    Raises
    ------
    IngestError : unreadable, unsupported (e.g. ``.RhPts``) or malformed files, with file/line/column.
    """
    path = Path(path)
    if not path.is_file():
        raise IngestError(path, "file not found")
    head = path.read_bytes()[:8]
    if head[:4] == b"PK\x03\x04":
        try:
            names = zipfile.ZipFile(path).namelist()
        except zipfile.BadZipFile as exc:
            raise IngestError(path, f"corrupt zip container: {exc}") from exc
        if path.suffix.lower() == ".rhpts" or "Directory.XML" in names:
            raise IngestError(path, "Anton Paar .RhPts object export (zipped XML with binary .NET blobs) is not "
                                    "supported: export the data as CSV/TXT from RheoCompass")
        raise IngestError(path, "spreadsheet container (.xlsx) is not supported for this file; export as CSV")
    if head[:8] == b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1":  # OLE2 (BIFF8 .xls)
        return read_trios_xls(path)
    text = decode_text(path)
    if not text.strip():
        raise IngestError(path, "empty file")
    if looks_like_rheocompass(text):
        return read_rheocompass(path, text)
    if looks_like_trios(text):
        return read_trios_text(path, text)
    if options.get("columns") or looks_like_tidy(text):
        return read_tidy(path, text, columns=options.get("columns"), units=options.get("units"))
    raise IngestError(path, f"unrecognised export format; supported: {', '.join(SUPPORTED)}", line=1)

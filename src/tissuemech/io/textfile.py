"""Text of an input file (an export or a sample sheet): UTF-16 with a byte-order mark, or UTF-8.

Kept apart from the readers' shared pieces (:mod:`tissuemech.io.blocks`, which loads the unit registry) so that
the sample sheet can be read without them.
"""
from __future__ import annotations

from pathlib import Path

from .errors import IngestError


def decode_text(path: Path) -> str:
    """File text: UTF-16 (BOM) or UTF-8 (optional BOM); other encodings are rejected with the reason."""
    raw = Path(path).read_bytes()
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        try:
            return raw.decode("utf-16")
        except UnicodeDecodeError as exc:
            raise IngestError(path, f"not valid UTF-16 text ({exc.reason} at byte {exc.start})") from exc
    if raw[:4] == b"PK\x03\x04":
        raise IngestError(path, "is a zip container (xlsx, or an Anton Paar .RhPts object export), not text")
    if b"\x00" in raw[:200]:
        raise IngestError(path, "binary content or UTF-16 without a byte-order mark; export as UTF-8 or UTF-16 text")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        column = exc.start - (raw.rfind(b"\n", 0, exc.start) + 1) + 1  # 1-based byte position in the line
        raise IngestError(path, f"wrong encoding: not UTF-8/UTF-16 (invalid byte 0x{raw[exc.start]:02x}, e.g. "
                                "Latin-1/Windows-1252 text); re-export as UTF-8 or UTF-16", line=line,
                          column=column) from exc

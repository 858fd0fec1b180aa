"""Seeded mutation fuzzing of the readers: damage an export, read it, judge the outcome against the original.

Used by ``tests/io/test_fuzz.py`` (CI-sized) and ``benchmarks/ingest_fuzz.py`` (large runs). Mutations
(:data:`TEXT_MUTATIONS`, :data:`BINARY_MUTATIONS`): truncate, delete or duplicate a line, cut a row short (at a
field separator, re-ended with its line end),
flip the case of a unit prefix (``mPa`` <-> ``MPa``, ``mN`` <-> ``MN``), put ``1e400`` in a numeric cell,
swap the decimal separator of a cell, replace a number cell (point numbers and counts included) by a
100,000-digit number (beyond Python's integer-string limit); for ``.xls``/``.xlsx``: truncate and overwrite bytes.
:func:`reader_options_for` gives an export the reader options its folder's ``dataset.yaml`` declares (the units
of tables without a unit row), as ingest would.

Outcomes (:func:`judge`):

* ``error``: :class:`~tissuemech.io.errors.IngestError` (what a damaged file must give);
* ``same``: the blocks equal the original's (the mutation did not touch data);
* ``scaled``: after a prefix flip, exactly the flipped column changed, by the right factor;
* ``file_shorter``: the mutation removed data from the file itself and the reader returned every point the
  mutant still holds: after ``delete_line`` exactly one point is missing (the deleted row), after ``truncate``
  only a tail is missing (the blocks kept are a prefix of the original's, and only the last kept block is
  shortened, to a prefix of its rows). A format that declares no point count cannot tell such a file from a
  shorter test, and nothing in the file is lost;
* ``lost``: points are missing that the mutation did not remove from the file (a defect: silently lost data);
* ``crash``: any exception other than IngestError (a defect);
* ``wrong``: values, columns, block names or indices differ from the original (a defect), except after byte
  corruption of a binary workbook, which has no checksum: that is ``undetectable``.
"""
from __future__ import annotations

import random
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from ..canonical import CANONICAL_VARIABLES
from ..units import UnknownUnitError, unit_factor
from .dispatch import read_export
from .errors import IngestError
from .ingest import reader_options

TEXT_MUTATIONS = ("truncate", "delete_line", "duplicate_line", "cut_row", "flip_prefix", "overflow",
                  "swap_decimal", "long_number")
BINARY_MUTATIONS = ("truncate_bytes", "corrupt_bytes")
_PREFIX = re.compile(r"(?<![A-Za-z])([mM])(?=(Pa|N)(?![A-Za-z]))")
_NUMERIC_CELL = re.compile(r"(?<=[\t;,])[-+]?\d+[.,]\d+(?:[eE][-+]?\d+)?(?=[\t;,\r\n]|$)")
#: a whole cell holding a number, integers (point numbers, counts) included
_NUMBER_CELL = re.compile(r"(?<![^\t;,\n])[-+]?\d+(?:[.,]\d+)?(?:[eE][-+]?\d+)?(?![^\t;,\r\n])")
LONG_NUMBER = "9" * 100_000


@dataclass
class Mutant:
    """One damaged copy of an export: ``kind`` of mutation, ``detail`` in words, the bytes to write."""

    kind: str
    detail: str
    data: bytes


def _encoding(raw: bytes) -> str:
    return "utf-16" if raw[:2] in (b"\xff\xfe", b"\xfe\xff") else "utf-8-sig" if raw[:3] == b"\xef\xbb\xbf" else "utf-8"


def _field_separator(line: str) -> str:
    """The line's field separator: tab or semicolon where the line has one, else the comma (a decimal comma of a
    tab- or semicolon-separated file is not a field boundary: cutting there is the ``truncate`` damage)."""
    return "\t" if "\t" in line else ";" if ";" in line else ","


def mutate(raw: bytes, kind: str, rng: random.Random) -> Mutant:
    """A mutant of an export's bytes (text mutations on the decoded text, re-encoded the same way)."""
    if kind == "truncate_bytes":
        cut = rng.randrange(1, max(2, len(raw)))
        return Mutant(kind, f"cut at byte {cut}", raw[:cut])
    if kind == "corrupt_bytes":
        data = bytearray(raw)
        at = rng.randrange(len(data))
        n = rng.randint(1, 16)
        for k in range(at, min(len(data), at + n)):
            data[k] = rng.randrange(256)
        return Mutant(kind, f"{n} bytes overwritten at {at}", bytes(data))
    enc = _encoding(raw)
    text = raw.decode(enc)
    lines = text.splitlines(keepends=True)
    detail = ""
    if kind == "truncate":
        cut = rng.randrange(1, max(2, len(text)))
        text, detail = text[:cut], f"cut at character {cut}"
    elif kind in ("delete_line", "duplicate_line", "cut_row"):
        k = rng.randrange(len(lines))
        if kind == "delete_line":
            del lines[k]
        elif kind == "duplicate_line":
            lines.insert(k, lines[k])
        else:
            seps = [m.start() for m in re.finditer(re.escape(_field_separator(lines[k])), lines[k])]
            if seps:
                lines[k] = lines[k][: rng.choice(seps)] + "\r\n" * lines[k].endswith("\r\n") + "\n" * (
                    not lines[k].endswith("\r\n") and lines[k].endswith("\n"))
        text, detail = "".join(lines), f"line {k + 1}"
    elif kind in ("flip_prefix", "overflow", "swap_decimal", "long_number"):
        pattern = {"flip_prefix": _PREFIX, "long_number": _NUMBER_CELL}.get(kind, _NUMERIC_CELL)
        hits = list(pattern.finditer(text))
        if hits:
            m = rng.choice(hits)
            line = text.count("\n", 0, m.start()) + 1
            if kind == "flip_prefix":
                new = m.group(1).swapcase()
            elif kind == "overflow":
                new = "1e400"
            elif kind == "long_number":
                new = LONG_NUMBER
            else:
                new = m.group(0).translate(str.maketrans(".,", ",."))
            shown = new if len(new) < 40 else f"<{len(new):,} digits>"
            text, detail = text[: m.start()] + new + text[m.end():], f"line {line}: {m.group(0)!r} -> {shown}"
    else:
        raise ValueError(f"unknown mutation {kind!r}")
    return Mutant(kind, detail, text.encode(enc))


def _frames_equal(a, b) -> bool:
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=1e-12, atol=0.0, equal_nan=True))


def _is_subsequence(short: np.ndarray, long: np.ndarray) -> bool:
    j = 0
    for row in short:
        while j < len(long) and not np.allclose(row, long[j], rtol=1e-12, atol=0.0, equal_nan=True):
            j += 1
        if j == len(long):
            return False
        j += 1
    return True


def judge(original: list, path: Path, kind: str, **options) -> tuple[str, str]:
    """Read a mutant and classify the outcome against the original blocks (see module docstring)."""
    try:
        blocks = read_export(path, **options)
    except IngestError as exc:
        return "error", exc.problem
    except Exception as exc:  # noqa: BLE001 - any other exception type is the defect being counted
        return "crash", f"{type(exc).__name__}: {exc}"
    undetectable = "undetectable" if kind == "corrupt_bytes" else "wrong"
    names = [(b.index, b.name) for b in blocks]
    if names != [(b.index, b.name) for b in original][: len(names)]:
        return undetectable, "blocks differ: " + ", ".join(f"{b.index}:{b.name}" for b in blocks)[:200]
    missing_blocks = len(original) - len(blocks)
    shortened = []                                    # (block position, points kept, points in the original)
    outcome = "same"
    for pos, (new, old) in enumerate(zip(blocks, original)):
        if list(new.data.columns) != list(old.data.columns):
            return undetectable, f"block {old.name!r}: columns {list(new.data.columns)} vs {list(old.data.columns)}"
        ratio = np.ones(len(old.data.columns))
        for k, col in enumerate(old.data.columns):
            u_new, u_old = new.meta.get("labels", {}).get(col), old.meta.get("labels", {}).get(col)
            if u_new != u_old:
                try:
                    expected = None if col == "temperature" else _expected(col)
                    ratio[k] = unit_factor(u_new, expected)[0] / unit_factor(u_old, expected)[0]
                except UnknownUnitError:
                    return "wrong", f"column {col!r} unit {u_new!r} accepted"
        a, b = new.data.to_numpy(float), old.data.to_numpy(float) * ratio
        if _frames_equal(a, b):
            outcome = "scaled" if (ratio != 1).any() or outcome == "scaled" else outcome
            continue
        if a.shape[0] < b.shape[0] and _is_subsequence(a, b):
            shortened.append((pos, a.shape[0], b.shape[0], _frames_equal(a, b[: a.shape[0]])))
            continue
        return undetectable, f"block {old.name!r}: values differ"
    if not missing_blocks and not shortened:
        return outcome, ""
    return _judge_missing(kind, missing_blocks, shortened, len(blocks), original)


def _judge_missing(kind: str, missing_blocks: int, shortened: list, kept_blocks: int,
                   original: list) -> tuple[str, str]:
    """``file_shorter`` when the missing points are exactly what the mutation took out of the file, else ``lost``."""
    n_missing = sum(total - kept for _, kept, total, _ in shortened) + sum(
        len(b.data) for b in original[kept_blocks:])
    where = ", ".join(f"block {original[pos].name!r}: {kept} of {total} points" for pos, kept, total, _ in shortened)
    if missing_blocks:
        where = (where + ", " if where else "") + f"{missing_blocks} trailing block(s) missing"
    if kind == "delete_line" and n_missing == 1 and not missing_blocks:
        return "file_shorter", f"the deleted row ({where})"
    if kind == "truncate":
        only_last = all(pos == kept_blocks - 1 and prefix for pos, _, _, prefix in shortened)
        if only_last:
            return "file_shorter", f"the cut-off tail ({where})"
    return "lost", f"{n_missing} point(s) missing that the {kind} mutation left in the file ({where})"


def _expected(column: str) -> str:
    return CANONICAL_VARIABLES[column][0]


def reader_options_for(path: Path) -> dict:
    """Reader options an export gets from the ``dataset.yaml`` of its folder (``columns``: units of tables
    without a unit row), as :func:`tissuemech.io.ingest.reader_options` gives them; empty without one."""
    described = Path(path).parent / "dataset.yaml"
    meta = yaml.safe_load(described.read_text(encoding="utf-8")) if described.is_file() else None
    return reader_options({}, meta if isinstance(meta, dict) else {})


def fuzz_file(path: Path, workdir: Path, n: int, seed: int, **options) -> list[tuple[str, str, str, str]]:
    """``n`` seeded mutants of one export: ``(mutation, detail, outcome, message)`` per mutant."""
    path, workdir = Path(path), Path(workdir)
    raw = path.read_bytes()
    binary = raw[:4] == b"PK\x03\x04" or raw[:8] == b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1"
    kinds = BINARY_MUTATIONS if binary else TEXT_MUTATIONS
    original = read_export(path, **options)
    rng = random.Random(f"{seed}:{path.name}")
    out = []
    for i in range(n):
        kind = kinds[i % len(kinds)]
        mutant = mutate(raw, kind, rng)
        target = workdir / f"mutant{path.suffix}"
        target.write_bytes(mutant.data)
        outcome, message = judge(original, target, kind, **options)
        out.append((kind, mutant.detail, outcome, message))
    return out

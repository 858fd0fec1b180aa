"""The dataset description: ``samples.csv`` (one row per run) and ``dataset.yaml``, both schema-validated.

``samples.csv`` columns: required ``file`` (path inside the dataset folder, or inside ``source_dir`` when
``dataset.yaml`` names one), ``specimen``, ``sample``, ``test`` (one of
:data:`tissuemech.canonical.TEST_KINDS`), ``order`` (test sequence within the sample, an integer); optional
``block`` (block/interval/step index or name when a file holds several; without it the one block holding the
test's variables is chosen), ``shear_rate_1_per_s``, ``strain_pct``, ``stress_pa``, ``frequency_hz``,
``radius_mm``, ``gap_mm``, ``temperature_c``, ``rise_time_s``, ``started_at`` (ISO 8601); reader options
``columns``/``units`` (headerless tidy files). Any other column is kept as a covariate (run attribute
``covariate_<name>``); a column whose name is close to a standard one (``raduis_mm``) is an error with the
suggestion.

The sheet is read as Excel writes it: comma, semicolon or tab separated (the separator is the one that splits the
header into the required columns), UTF-8 (with or without BOM) or UTF-16; in a semicolon- or tab-separated sheet
numbers may carry a decimal comma (``12,5``), in a comma-separated one a decimal comma is an error that says so.
A cell that is not a number where one is expected is an error naming line and column, never a missing value.
"""
from __future__ import annotations

import csv
import difflib
import io
import json
import math
import re
from datetime import datetime
from importlib import resources
from pathlib import Path

import jsonschema
import pandas as pd
import yaml

from .errors import IngestError
from .plausibility import range_problem, ranges_with
from .textfile import decode_text

REQUIRED = ("file", "specimen", "sample", "test", "order")
NUMERIC = ("order", "shear_rate_1_per_s", "strain_pct", "stress_pa", "frequency_hz", "radius_mm", "gap_mm",
           "temperature_c", "rise_time_s")
READER_OPTIONS = ("columns", "units")
STANDARD = ("file", "specimen", "sample", "test", "order", "block", "started_at") + NUMERIC + READER_OPTIONS
#: sample-sheet values checked against :data:`tissuemech.io.plausibility.PLAUSIBLE_RANGES`
PLAUSIBILITY_CHECKED = ("radius_mm", "gap_mm", "temperature_c", "strain_pct")
SEPARATORS = (",", ";", "\t")
#: a column name this close (difflib ratio) to a standard one is taken as a misspelling of it
NEAR_MISS_CUTOFF = 0.8
_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")
_COMMA_DECIMAL = re.compile(r"^[+-]?\d*,\d+([eE][+-]?\d+)?$")
_POINT_DECIMAL = re.compile(r"^[+-]?\d*\.\d+([eE][+-]?\d+)?$")


def _schema(name: str) -> dict:
    return json.loads(resources.files("tissuemech.io").joinpath("schemas", name).read_text())


def suggestion(word: str, known) -> str:
    """`` did you mean `x`?`` for the closest known word (difflib), or an empty string."""
    close = difflib.get_close_matches(str(word), list(known), n=1, cutoff=0.6)
    return f"; did you mean `{close[0]}`?" if close else ""


def row_problems(row: dict) -> list[str]:
    """Schema violations of one sample-sheet row (empty list when valid)."""
    record = {k: v for k, v in row.items() if v is not None and not (isinstance(v, float) and pd.isna(v))}
    errors = sorted(jsonschema.Draft202012Validator(_schema("samples.schema.json")).iter_errors(record),
                    key=lambda e: list(e.path))
    problems = [f"{'/'.join(map(str, e.path)) or 'row'}: {e.message}" for e in errors]
    if "started_at" in record:
        try:
            datetime.fromisoformat(str(record["started_at"]))
        except ValueError:
            problems.append(f"started_at: {record['started_at']!r} is not ISO 8601")
    return problems


def _separator(header: str) -> str:
    """The separator that splits the header line into the most required columns (csv.Sniffer on a tie)."""
    def hits(sep):
        return sum(c.strip().strip('"') in REQUIRED for c in header.split(sep))
    best = max(SEPARATORS, key=hits)
    if hits(best) == 0:
        try:
            return csv.Sniffer().sniff(header, delimiters="".join(SEPARATORS)).delimiter
        except csv.Error:
            return ","
    return best


def read_sheet(path) -> pd.DataFrame:
    """A sample sheet as text cells (``None`` for empty ones), indexed by the line each row is on.

    ``attrs``: ``path``, ``separator`` and ``decimal_comma`` (numbers written ``12,5``: a semicolon- or
    tab-separated sheet whose numeric cells use a comma). Rows whose cells are all empty (Excel writes ``;;;``
    lines) are skipped.

    Raises
    ------
    IngestError : no sheet, unreadable text, missing required or misspelled columns, a row with more cells than
        the header, or decimal marks mixed within the sheet
    """
    path = Path(path)
    if not path.is_file():
        raise IngestError(path, "sample sheet not found")
    text = decode_text(path)
    if not text.strip():
        raise IngestError(path, "empty sample sheet")
    sep = _separator(text.splitlines()[0])
    reader = csv.reader(io.StringIO(text), delimiter=sep)
    try:
        header = [c.strip() for c in next(reader)]
        records = [(reader.line_num, row) for row in reader]
    except csv.Error as exc:
        raise IngestError(path, f"malformed CSV: {exc}", line=reader.line_num) from exc
    while header and not header[-1]:
        header.pop()
    _check_header(path, header, sep)
    rows, lines = [], []
    for line, cells in records:
        cells = [c.strip() for c in cells]
        if not any(cells):
            continue
        if len(cells) > len(header) and any(cells[len(header):]):
            hint = " (a decimal comma in a comma-separated sheet?)" if sep == "," else ""
            raise IngestError(path, f"row has {len(cells)} cells, the header {len(header)}{hint}", line=line)
        cells = cells[: len(header)] + [""] * (len(header) - len(cells))
        rows.append([c if c else None for c in cells])
        lines.append(line)
    sheet = pd.DataFrame(rows, columns=header, index=pd.Index(lines, name="line"), dtype=object)
    sheet.attrs.update(path=str(path), separator=sep, decimal_comma=_decimal_comma(path, sheet, sep))
    return sheet


def _check_header(path: Path, header: list[str], sep: str) -> None:
    empty = [k + 1 for k, name in enumerate(header) if not name]
    if empty:
        raise IngestError(path, "empty column name in the header", line=1, column=empty[0])
    seen = set()
    for name in header:
        if name in seen:
            raise IngestError(path, f"column {name!r} appears twice in the header", line=1, column=name)
        seen.add(name)
    for name in header:
        if name in STANDARD:
            continue
        close = difflib.get_close_matches(name, STANDARD, n=1, cutoff=NEAR_MISS_CUTOFF)
        if close and close[0] not in header:
            raise IngestError(path, f"unknown column {name!r}; did you mean `{close[0]}`? (other columns are "
                                    "covariates: rename this one if it is meant as a covariate)", line=1, column=name)
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        named = {"\t": "tab", ",": "comma", ";": "semicolon"}[sep] if sep in SEPARATORS else repr(sep)
        raise IngestError(path, f"missing required column(s) {missing} in a {named}-separated header "
                                f"{header[:8]}", line=1)


def _decimal_comma(path: Path, sheet: pd.DataFrame, sep: str) -> bool:
    """True when the numeric cells of a semicolon/tab sheet use a decimal comma; mixed marks are an error."""
    if sep == ",":
        return False
    first = {}
    for column in (c for c in sheet.columns if c in NUMERIC):
        for line, cell in sheet[column].items():
            if cell is None:
                continue
            kind = "comma" if _COMMA_DECIMAL.match(cell) else "point" if _POINT_DECIMAL.match(cell) else None
            if kind and kind not in first:
                first[kind] = (line, column, cell)
    if len(first) == 2:
        (l1, c1, v1), (l2, c2, v2) = sorted(first.values())
        raise IngestError(path, f"mixed decimal marks: {v1!r} (line {l1}, column {c1!r}) and {v2!r}: use one "
                                "decimal mark throughout the sheet", line=l2, column=c2)
    return "comma" in first


def load_samples(dataset_dir) -> pd.DataFrame:
    """``dataset_dir/samples.csv`` read by :func:`read_sheet` (text cells, index = line numbers).

    Row values are converted and checked per row by :func:`parse_row` during ingest, so that one bad row does
    not stop the others.
    """
    return read_sheet(Path(dataset_dir) / "samples.csv")


def sheet_number(text: str, decimal_comma: bool) -> float:
    """A number as the sheet writes it (decimal comma only in a decimal-comma sheet); ValueError with the reason."""
    s = str(text).strip()
    if decimal_comma and "." not in s:
        s = s.replace(",", ".")
    if not _NUMBER.match(s):
        if "," in s and not decimal_comma:
            raise ValueError(f"{text!r} has a decimal comma in a comma-separated sheet: write "
                             f"{s.replace(',', '.')}, or save the sheet with ';' separators (as Excel does in "
                             "decimal-comma locales)")
        raise ValueError(f"{text!r} is not a number")
    value = float(s)
    if not math.isfinite(value):
        raise ValueError(f"{text!r} is out of range")
    return value


def parse_row(row: dict, line: int, sheet_path, decimal_comma: bool = False, ranges=None) -> dict:
    """One sample-sheet row with its numbers converted, validated against the schema and the plausible ranges.

    Parameters
    ----------
    row : column -> text cell (``None`` when empty), as :func:`read_sheet` gives it
    line : the row's line in the sheet (named by errors)
    decimal_comma : the sheet writes numbers with a decimal comma
    ranges : plausible ranges (:func:`tissuemech.io.plausibility.ranges_with`; default the standard ones)

    Raises
    ------
    IngestError : naming ``sheet_path``, the line and the column, e.g. ``order must be an integer``,
        ``'12,5' has a decimal comma in a comma-separated sheet``, ``radius_mm 0.0125 mm ... looks like metres``
    """
    clean: dict = {}
    for key, value in row.items():
        if value is None or (isinstance(value, float) and math.isnan(value)) or str(value).strip() == "":
            clean[key] = None
            continue
        if key == "order":
            try:
                number = sheet_number(value, decimal_comma)
            except ValueError:
                number = math.nan
            if not (math.isfinite(number) and number == int(number)):
                raise IngestError(sheet_path, f"order must be an integer (the test's position in the sample's "
                                              f"sequence: 1, 2, ...), not {value!r}", line=line, column="order")
            clean[key] = int(number)
        elif key in NUMERIC:
            try:
                clean[key] = sheet_number(value, decimal_comma)
            except ValueError as exc:
                raise IngestError(sheet_path, f"{key}: {exc}", line=line, column=key) from None
        elif key not in STANDARD:                       # a covariate: a number where it reads as one, else text
            try:
                clean[key] = sheet_number(value, decimal_comma)
            except ValueError:
                clean[key] = str(value)
        else:
            clean[key] = str(value).strip()
    problems = row_problems(clean)
    if problems:
        field = problems[0].split(":", 1)[0]
        raise IngestError(sheet_path, "; ".join(problems), line=line, column=field if field in row else None)
    for key in PLAUSIBILITY_CHECKED:
        problem = range_problem(key, clean.get(key), ranges)
        if problem:
            raise IngestError(sheet_path, problem, line=line, column=key)
    return clean


#: dataset.yaml keys whose absence is a warning in the ingest report (only ``material`` is required)
RECOMMENDED = ("citation", "license")


def dataset_warnings(meta: dict) -> list[str]:
    """Warnings about a valid ``dataset.yaml``: missing ``citation``/``license``."""
    return [f"dataset.yaml has no {key!r}" for key in RECOMMENDED if not meta.get(key)]


def _yaml_position(text: str, keys: list, key_itself: bool = False) -> tuple[int | None, int | None]:
    """1-based (line, column) of the value at ``keys`` in a YAML document (of the key when ``key_itself``)."""
    try:
        node = yaml.compose(text)
    except yaml.YAMLError:
        return None, None
    mark = None if node is None else node.start_mark
    for depth, key in enumerate(keys):
        found = None
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                if k.value == str(key):
                    found = (k, v)
                    break
        elif isinstance(node, yaml.SequenceNode) and isinstance(key, int) and key < len(node.value):
            found = (node.value[key], node.value[key])
        if found is None:
            break
        last = depth == len(keys) - 1
        mark = (found[0] if last and key_itself else found[1]).start_mark
        node = found[1]
    return (None, None) if mark is None else (mark.line + 1, mark.column + 1)


def _schema_errors(path: Path, text: str, data) -> IngestError | None:
    """The schema violations of ``dataset.yaml`` as one IngestError (unknown keys with the closest known key)."""
    problems, first = [], None
    for error in jsonschema.Draft202012Validator(_schema("dataset.schema.json")).iter_errors(data):
        where = list(error.absolute_path)
        if error.validator == "additionalProperties" and isinstance(error.instance, dict):
            known = list(error.schema.get("properties", {}))
            for key in (k for k in error.instance if k not in known):
                name = "/".join(map(str, where + [key]))
                problems.append(f"unknown key {name!r}{suggestion(key, known)}")
                first = first or _yaml_position(text, where + [key], key_itself=True)
            continue
        problems.append(f"{'/'.join(map(str, where)) or 'document'}: {error.message}")
        first = first or _yaml_position(text, where)
    if not problems:
        return None
    line, column = first or (None, None)
    return IngestError(path, "; ".join(problems), line=line, column=column)


def load_dataset_yaml(dataset_dir) -> dict:
    """``dataset.yaml`` validated against its schema and the plausible ranges (IngestError naming the key).

    Only ``material`` is required; unknown keys are errors with the closest known key (``geomtry`` -> did you
    mean `geometry`?); ``geometry`` is a mapping or a string (see :mod:`tissuemech.io.geometry`); its
    ``radius_mm`` and ``gap_mm``, and ``temperature_c``, are checked against the plausible ranges (``plausible_ranges``
    replaces them).
    """
    path = Path(dataset_dir) / "dataset.yaml"
    if not path.is_file():
        raise IngestError(path, "dataset description not found")
    text = decode_text(path)
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise IngestError(path, f"invalid YAML: {exc}", line=None if mark is None else mark.line + 1,
                          column=None if mark is None else mark.column + 1) from exc
    if not isinstance(data, dict):
        raise IngestError(path, f"the document is a {type(data).__name__}, not a mapping of keys", line=1)
    error = _schema_errors(path, text, data)
    if error:
        raise error
    ranges = ranges_with(data.get("plausible_ranges"))
    geometry = data.get("geometry") if isinstance(data.get("geometry"), dict) else {}
    stated = [(["temperature_c"], "temperature_c", data.get("temperature_c"))]
    for key in ("radius_mm", "gap_mm"):
        values = geometry.get(key)
        for k, v in enumerate(values if isinstance(values, list) else [values]):
            stated.append((["geometry", key] + ([k] if isinstance(values, list) else []), key, v))
    for where, key, value in stated:
        problem = range_problem(key, value, ranges)
        if problem:
            line, column = _yaml_position(text, where)
            raise IngestError(path, f"{'/'.join(map(str, where))}: {problem}", line=line, column=column)
    return data


def source_folder(dataset_dir) -> Path:
    """Folder the sample sheet's ``file`` paths are relative to (``source_dir`` of dataset.yaml, if any)."""
    dataset_dir = Path(dataset_dir)
    meta = yaml.safe_load((dataset_dir / "dataset.yaml").read_text()) if (dataset_dir / "dataset.yaml").is_file() else {}
    return (dataset_dir / meta["source_dir"]) if meta and meta.get("source_dir") else dataset_dir

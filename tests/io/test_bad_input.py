"""Bad input (issue 2): each error names the file, the line/column and the problem; the ingest stage reports a
bad run and still processes the others, never writes into the input folder, and writes its outputs atomically.

Every bad file here is a project look-alike with one defect put in on purpose.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tissuemech.canonical import read_netcdf
from tissuemech.io.dispatch import read_export
from tissuemech.io.errors import IngestError
from tissuemech.io.ingest import ingest_dataset
from tissuemech.synth.writer import rheocompass_text

FIXTURES = Path(__file__).resolve().parent / "fixtures"
_spec = importlib.util.spec_from_file_location("io_make_fixtures_bad", FIXTURES / "make_fixtures.py")
make = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make)


def error_of(path, **options) -> IngestError:
    with pytest.raises(IngestError) as info:
        read_export(path, **options)
    return info.value


def assert_names(exc: IngestError, path: Path, line: int | None, column, problem: str):
    """The message carries the file, the line, the column (when given) and the problem."""
    text = str(exc)
    assert text.startswith(str(path)), text
    assert exc.path == Path(path)
    assert exc.line == line, text
    if line is not None:
        assert f"line {line}" in text
    if column is not None:
        assert exc.column == column, text
        assert (f"column {column!r}" if isinstance(column, str) else f"column {column}") in text
    assert re.search(problem, text), text


def kinexus_lines() -> list[str]:
    return make.kinexus_text().splitlines()


def lims_lines() -> list[str]:
    return make.lims_text().splitlines()


def write_lines(path: Path, lines: list[str], newline_at_end: bool = True) -> Path:
    path.write_text("\n".join(lines) + ("\n" if newline_at_end else ""), encoding="utf-8")
    return path


def line_of(lines: list[str], startswith: str, nth: int = 0) -> int:
    """1-based number of the ``nth`` line starting with the given text."""
    return [i for i, line in enumerate(lines, start=1) if line.startswith(startswith)][nth]


# --- truncated files -------------------------------------------------------------------------------------------
def test_truncated_lims_at_a_line_boundary(tmp_path):
    lines = lims_lines()[:-1]                       # last "Data point" of the last step lost
    path = write_lines(tmp_path / "cut.txt", lines)
    assert_names(error_of(path), path, len(lines), None,
                 r"truncated file: step 'Frequency sweep \(40\.0 °C\)' declares 3 points, found 2")


def test_truncated_lims_mid_row(tmp_path):
    lines = lims_lines()
    lines[-1] = lines[-1][:60]                      # the copy stopped inside the last row
    path = write_lines(tmp_path / "cut.txt", lines, newline_at_end=False)
    assert_names(error_of(path), path, len(lines), None, r"truncated or malformed data row: \d+ values for 26")


def test_truncated_kinexus_mid_row(tmp_path):
    lines = kinexus_lines()
    lines[-1] = lines[-1][:25]
    path = write_lines(tmp_path / "cut.csv", lines, newline_at_end=False)
    assert_names(error_of(path), path, len(lines), None, r"truncated or malformed row: \d fields, the header has 17")


def test_truncated_rheocompass_interval(tmp_path):
    t = np.arange(1.0, 11.0)
    text = rheocompass_text({"time": t, "shear_stress": 100 * np.exp(-t / 5)}, "relax", "Step strain",
                            header="project")
    lines = text.splitlines()
    keep = [i for i, line in enumerate(lines) if line.startswith("\t7\t")][0]   # points 7..10 lost
    path = tmp_path / "cut.csv"
    path.write_bytes(b"\xff\xfe" + "\r\n".join(lines[:keep]).encode("utf-16-le"))
    assert_names(error_of(path), path, keep, None,
                 r"truncated file: interval 'Step strain / 1' declares 10 points, found 6")
    # cut inside a row: the row has fewer cells than the column row
    path.write_bytes(b"\xff\xfe" + "\r\n".join(lines[:keep] + [lines[keep][:4]]).encode("utf-16-le"))
    assert_names(error_of(path), path, keep + 1, None, r"truncated row: \d cells, the column row has \d+")


def test_truncated_xlsx(tmp_path):
    data = (FIXTURES / "rheocompass_lookalike.xlsx").read_bytes()
    path = tmp_path / "cut.xlsx"
    path.write_bytes(data[: len(data) // 2])
    assert_names(error_of(path), path, None, None, r"corrupt zip container \(truncated file\?\)")


def test_xlsx_with_a_damaged_member_name_is_an_error_not_a_lost_sheet(tmp_path):
    """Bytes overwritten in the central directory's name of sheet1: openpyxl alone would skip that sheet."""
    data = (FIXTURES / "rheocompass_lookalike.xlsx").read_bytes()
    at = data.rindex(b"xl/worksheets/sheet1.xml")
    path = tmp_path / "damaged.xlsx"
    path.write_bytes(data[:at] + b"xl/wor\xc8T`\xbd\x12&\xf9\xaagU\x0b\xbb\xe81.xml" + data[at + 24:])
    assert_names(error_of(path), path, None, None, r"damaged \.xlsx workbook: member .* fails its CRC-32 check")


# --- encoding --------------------------------------------------------------------------------------------------
def test_wrong_encoding_names_line_and_byte(tmp_path):
    text = make.kinexus_text()
    raw = text.encode("cp1252")                     # "s-¹" -> 0xB9, "°C" -> 0xB0: not UTF-8
    path = tmp_path / "latin.csv"
    path.write_bytes(raw)
    header = raw.split(b"\n")[0]
    column = header.index(b"\xb9") + 1
    assert_names(error_of(path), path, 1, column, r"wrong encoding: not UTF-8/UTF-16 \(invalid byte 0xb9")


def test_utf16_without_bom(tmp_path):
    path = tmp_path / "nobom.csv"
    path.write_bytes(make.kinexus_text().encode("utf-16-le"))
    assert_names(error_of(path), path, None, None, "UTF-16 without a byte-order mark")


# --- missing column / unknown unit / text in numbers ------------------------------------------------------------
def test_lims_step_without_units_row(tmp_path):
    lines = lims_lines()
    n = line_of(lines, "Units", nth=1)
    del lines[n - 1]
    path = write_lines(tmp_path / "nounits.txt", lines)
    step_line = [i for i, line in enumerate(lines, start=1) if line == "[Step]"][1]
    assert_names(error_of(path), path, step_line, None,
                 r"step 'Frequency sweep \(40\.0 °C\)' has no 'Units' row")


def test_unknown_unit_in_kinexus_header(tmp_path):
    lines = kinexus_lines()
    lines[0] = lines[0].replace("Shear stress(Pa)", "Shear stress(Pascal)")   # pint's pascal is lower case
    path = write_lines(tmp_path / "pascal.csv", lines)
    assert_names(error_of(path), path, 1, "Shear stress(Pascal)", r"unknown unit 'Pascal' in column 'shear_stress'")


def test_unit_of_another_quantity_in_lims(tmp_path):
    lines = lims_lines()
    n = line_of(lines, "Units")
    units = lines[n - 1].split("\t")
    units[make.LIMS_VARIABLES.index("Oscillation torque") + 1] = "s"   # a torque "in seconds"
    lines[n - 1] = "\t".join(units)
    path = write_lines(tmp_path / "torque_s.txt", lines)
    assert_names(error_of(path), path, n, "Oscillation torque",
                 r"unit 's' \(a s quantity\) cannot be converted to N m in column 'torque'")


def test_modulus_without_unit_is_not_assumed_pascal(tmp_path):
    lines = lims_lines()
    n = line_of(lines, "Units")
    units = lines[n - 1].split("\t")
    units[make.LIMS_VARIABLES.index("Storage modulus") + 1] = ""
    lines[n - 1] = "\t".join(units)
    path = write_lines(tmp_path / "nounit.txt", lines)
    assert_names(error_of(path), path, n, "Storage modulus",
                 r"no unit given where Pa is expected \(never assumed\) in column 'storage_modulus'")


def test_text_in_a_numeric_column(tmp_path):
    lines = kinexus_lines()
    cells = lines[2].split(";")
    cells[3] = "n/a"
    lines[2] = ";".join(cells)
    path = write_lines(tmp_path / "text.csv", lines)
    assert_names(error_of(path), path, 3, "Shear stress(Pa)", r"text in a numeric column: 'n/a'")


def test_text_in_a_numeric_column_of_xlsx(tmp_path):
    import openpyxl

    src = FIXTURES / "rheocompass_lookalike.xlsx"
    book = openpyxl.load_workbook(src)
    book["Creep"]["C8"] = "overload"                # row 8 = point 2, column C = Shear Stress
    path = tmp_path / "text.xlsx"
    book.save(path)
    assert_names(error_of(path), path, 8, "Shear Stress", r"sheet 'Creep': text in a numeric column: 'overload'")


# --- time ----------------------------------------------------------------------------------------------------
def test_nan_time(tmp_path):
    lines = kinexus_lines()
    cells = lines[3].split(";")
    cells[2] = ""                                   # Time (action) missing on line 4
    lines[3] = ";".join(cells)
    path = write_lines(tmp_path / "nan.csv", lines)
    assert_names(error_of(path), path, 4, "time", r"missing \(NaN\) time value")


def test_duplicate_time(tmp_path):
    lines = lims_lines()
    k = make.LIMS_VARIABLES.index("Step time") + 1
    n1, n2 = line_of(lines, "Data point", 0), line_of(lines, "Data point", 1)
    cells = lines[n2 - 1].split("\t")
    cells[k] = lines[n1 - 1].split("\t")[k]
    lines[n2 - 1] = "\t".join(cells)
    path = write_lines(tmp_path / "dup.txt", lines)
    assert_names(error_of(path), path, n2, "time", r"duplicate time 10 s")


def test_non_monotonic_time(tmp_path):
    lines = lims_lines()
    k = make.LIMS_VARIABLES.index("Step time") + 1
    n3 = line_of(lines, "Data point", 2)
    cells = lines[n3 - 1].split("\t")
    cells[k] = "15.0"                               # 10, 20, 15 s
    lines[n3 - 1] = "\t".join(cells)
    path = write_lines(tmp_path / "back.txt", lines)
    assert_names(error_of(path), path, n3, "time", r"non-monotonic time: 15 s after 20 s")


# --- the ingest stage ----------------------------------------------------------------------------------------
DATASET_YAML = "material: look-alike\nlicense: CC0-1.0\ncitation: tissuemech test fixture\n"


def folder_state(folder: Path) -> dict:
    """Every file under ``folder`` with its hash and modification time (to prove nothing was written)."""
    return {str(p.relative_to(folder)): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*"))}


def make_dataset(root: Path, rows: list[dict]) -> Path:
    raw = root / "raw" / "lookalike"
    raw.mkdir(parents=True)
    (raw / "dataset.yaml").write_text(DATASET_YAML)
    (raw / "kinexus.csv").write_bytes((FIXTURES / "kinexus_lookalike.csv").read_bytes())
    (raw / "lims.txt").write_bytes((FIXTURES / "ta_lims_lookalike.txt").read_bytes())
    cut = kinexus_lines()
    cut[-1] = cut[-1][:25]
    write_lines(raw / "kinexus_cut.csv", cut, newline_at_end=False)
    pd.DataFrame(rows).to_csv(raw / "samples.csv", index=False)
    return raw


GOOD = {"file": "kinexus.csv", "specimen": "s1", "sample": "a", "test": "flow_curve", "order": 1, "block": "3"}
GOOD_LIMS = {"file": "lims.txt", "specimen": "s1", "sample": "b", "test": "frequency_sweep", "order": 1,
             "block": "Frequency sweep (40.0 °C)"}


def test_ingest_reports_bad_runs_and_keeps_the_good_ones(tmp_path):
    rows = [
        GOOD,                                                                             # line 2: ok
        {**GOOD, "file": "kinexus_cut.csv", "sample": "c"},                               # 3: truncated export
        {**GOOD, "file": "missing.csv", "sample": "d"},                                   # 4: missing file
        {**GOOD, "test": "tensile_banana", "sample": "e"},                                # 5: unknown test
        {**GOOD, "block": "7", "sample": "f"},                                            # 6: mismatched block
        {**GOOD, "test": "flow_curve", "block": "Oscillation Single Frequency", "sample": "g"},  # 7: no shear rate
        GOOD_LIMS,                                                                        # 8: ok
    ]
    raw = make_dataset(tmp_path, rows)
    before = folder_state(raw)
    out = tmp_path / "results" / "lookalike"
    report = ingest_dataset(raw, out / "runs", out / "ingest_report.csv")
    assert folder_state(raw) == before                                 # raw/ is never written
    on_disk = pd.read_csv(out / "ingest_report.csv", keep_default_na=False)
    assert list(on_disk["status"]) == list(report["status"]) == ["ok"] + ["error"] * 5 + ["ok"]
    reasons = dict(zip(on_disk["sample"], on_disk["reason"]))
    sheet = raw / "samples.csv"
    assert re.fullmatch(rf"{re.escape(str(raw / 'kinexus_cut.csv'))}, line 17: truncated or malformed row: .*",
                        reasons["c"])
    assert reasons["d"] == f"{sheet}, line 4, column 'file': file 'missing.csv' not found"
    assert reasons["e"].startswith(f"{sheet}, line 5, column 'test': test: 'tensile_banana' is not one of [")
    assert reasons["f"] == (f"{sheet}, line 6, column 'block': block '7' not found (mismatched 'block'); "
                            "available: 1: Pre Shear, 2: Oscillation Single Frequency, 3: Flow Curve in kinexus.csv")
    assert reasons["g"].startswith(f"{raw / 'kinexus.csv'}, line 12, column 'shear_rate': missing column: "
                                   "block 'Oscillation Single Frequency' has no 'shear_rate' data, needed for a "
                                   "flow_curve run")
    runs = sorted(p.name for p in (out / "runs").iterdir())
    assert runs == ["s1_a_flow_curve_1_b3.nc", "s1_b_frequency_sweep_1_bFrequency-sweep-40.0-C-.nc"]
    flow = read_netcdf(out / "runs" / "s1_a_flow_curve_1_b3.nc")
    np.testing.assert_allclose(flow["shear_stress"] / flow["shear_rate"], make.KINEXUS_ETA)
    assert flow.attrs["format"] == "malvern_rspace" and flow.attrs["block"] == "Flow Curve"
    sweep = read_netcdf(out / "runs" / "s1_b_frequency_sweep_1_bFrequency-sweep-40.0-C-.nc")
    np.testing.assert_allclose(sweep["storage_modulus"], make.maxwell(np.array(make.LIMS_OMEGA))[0])
    assert sweep.attrs["radius_m"] == pytest.approx(make.LIMS_RADIUS_M)     # geometry from the LIMS header


def test_ingest_outputs_are_atomic(tmp_path, monkeypatch):
    """A write that fails midway leaves the previous run file intact and no partial file behind."""
    import xarray as xr

    raw = make_dataset(tmp_path, [GOOD])
    out = tmp_path / "results" / "lookalike"
    ingest_dataset(raw, out / "runs", out / "ingest_report.csv")
    run = out / "runs" / "s1_a_flow_curve_1_b3.nc"
    good_bytes = run.read_bytes()

    def failing_to_netcdf(self, path, *args, **kwargs):
        Path(path).write_bytes(b"\x89HDF half written")
        raise OSError("No space left on device")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", failing_to_netcdf)
    report = ingest_dataset(raw, out / "runs", out / "ingest_report.csv")
    assert list(report["status"]) == ["error"] and "No space left on device" in report["reason"][0]
    assert run.read_bytes() == good_bytes
    assert sorted(os.listdir(out / "runs")) == [run.name]             # no temporary file left
    assert not [p for p in out.iterdir() if p.name.endswith(".tmp")]


# --- ingest fuzz findings (issue 34) ----------------------------------------------------------------------------
def test_a_100000_digit_point_number_is_an_ingest_error(tmp_path):
    """Beyond Python's integer-string limit (4300 digits): an IngestError naming the cell, not a bare ValueError."""
    t = np.arange(1.0, 6.0)
    lines = rheocompass_text({"time": t, "shear_stress": 100 * np.exp(-t / 5)}, "relax", "Step strain",
                             header="simple").splitlines()
    n = line_of(lines, "3\t") if any(line.startswith("3\t") for line in lines) else line_of(lines, "\t3\t")
    lines[n - 1] = lines[n - 1].replace("3", "9" * 100_000, 1)
    path = tmp_path / "long.csv"
    path.write_bytes(b"\xff\xfe" + ("\r\n".join(lines) + "\r\n").encode("utf-16-le"))
    exc = error_of(path)
    assert exc.line == n and re.search(r"point number is not a count: '9{40}'\.\.\.", exc.problem), str(exc)[:300]


def test_a_100000_digit_value_is_an_ingest_error(tmp_path):
    lines = lims_lines()
    n = line_of(lines, "Data point", 1)
    cells = lines[n - 1].split("\t")
    k = make.LIMS_VARIABLES.index("Storage modulus") + 1
    cells[k] = "9" * 100_000
    lines[n - 1] = "\t".join(cells)
    path = write_lines(tmp_path / "long.txt", lines)
    assert_names(error_of(path), path, n, "Storage modulus", r"value out of range \(overflows to ±inf\)")


TRIOS_TEXT = ("Filename\tlookalike\nInstrument name\t0000\nProcedure name\tPeak hold\nproceduresegments\tPeak hold"
              "\n[step]\nPeak hold - 1\nStep time\tStress\tShear rate\ns\tPa\t1/s\n1\t10\t1\n2\t10\t1\n3\t10\t1\n")


def test_trios_step_whose_column_row_was_deleted_is_an_error(tmp_path):
    good = tmp_path / "good.txt"
    good.write_text(TRIOS_TEXT, encoding="utf-8")
    assert list(read_export(good)[0].data.columns) == ["time", "shear_stress", "shear_rate"]
    path = tmp_path / "no_columns.txt"
    path.write_text(TRIOS_TEXT.replace("Step time\tStress\tShear rate\n", ""), encoding="utf-8")
    assert_names(error_of(path), path, 7, None, r"step 'Peak hold - 1': no recognised column \(column row missing "
                                                r"or damaged\?\); labels: \['s', 'Pa', '1/s'\]")
    path.write_text(TRIOS_TEXT.replace("s\tPa\t1/s\n", ""), encoding="utf-8")
    assert_names(error_of(path), path, 8, None, r"step 'Peak hold - 1': the units row holds numbers")


def test_a_text_export_cut_inside_its_last_number_is_an_error(tmp_path):
    """A last row '3, 10, 15' cut to '3, 10, 1' would read as another shear rate: a last line without a line end
    is refused."""
    path = tmp_path / "cut.txt"
    path.write_text(TRIOS_TEXT.replace("3\t10\t1\n", "3\t10\t1"), encoding="utf-8")
    assert_names(error_of(path), path, 11, None, r"the file ends without a line end \(truncated inside its last "
                                                 r"row\?\); if the file is complete, end it with a line break")

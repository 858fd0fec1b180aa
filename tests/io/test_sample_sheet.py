"""Sample-sheet and dataset.yaml mistakes (issue 34, item 4): each gives ``tissuemech check`` a non-zero exit and an
IngestError naming the file, the line, the column and, where one is likely, the mistake and its remedy.

The dataset is a look-alike folder: the Kinexus fixture (temperature logged at 20.00 degC, flow curve in block 3)
and the LIMS fixture (25 mm plate: radius 12.5 mm, frequency sweeps at 25 and 40 degC).
"""
from __future__ import annotations

from pathlib import Path

import pytest

from tissuemech.canonical import read_netcdf
from tissuemech.io.check import check_dataset, main as check_main
from tissuemech.io.errors import IngestError
from tissuemech.io.ingest import ingest_dataset
from tissuemech.io.samples import load_dataset_yaml

FIXTURES = Path(__file__).resolve().parent / "fixtures"
HEADER = ["file", "specimen", "sample", "test", "order", "block"]
FLOW = ["kinexus.csv", "s1", "a", "flow_curve", "1", "3"]
SWEEP = ["lims.txt", "s1", "b", "frequency_sweep", "1", "1"]
YAML = "material: look-alike\nlicense: CC0-1.0\ncitation: tissuemech test fixture\n"


def dataset(tmp_path: Path, rows: list[list[str]], header=HEADER, sep: str = ",", yaml_text: str = YAML) -> Path:
    folder = tmp_path / "lookalike"
    folder.mkdir(parents=True)
    (folder / "dataset.yaml").write_text(yaml_text, encoding="utf-8")
    (folder / "kinexus.csv").write_bytes((FIXTURES / "kinexus_lookalike.csv").read_bytes())
    (folder / "lims.txt").write_bytes((FIXTURES / "ta_lims_lookalike.txt").read_bytes())
    (folder / "samples.csv").write_text("\n".join(sep.join(r) for r in [header, *rows]) + "\n", encoding="utf-8")
    return folder


def report_of(folder: Path):
    return ingest_dataset(folder, folder.parent / "out" / "runs", folder.parent / "out" / "report.csv")


def check_fails(folder: Path, capsys) -> str:
    """``tissuemech check`` exits 1; returns what it printed."""
    assert check_main([str(folder)]) == 1
    return capsys.readouterr().out


def only_error(folder: Path) -> dict:
    report = report_of(folder)
    bad = report[report["status"] == "error"]
    assert len(bad) == 1, report.to_string()
    return bad.iloc[0].to_dict()


# --- separators and decimal marks ---------------------------------------------------------------------------
def test_semicolon_decimal_comma_sheet_is_read(tmp_path, capsys):
    """Excel in a decimal-comma locale: ';' between cells, '12,5' for 12.5."""
    folder = dataset(tmp_path, [FLOW + ["12,5", "1,25"]], HEADER + ["radius_mm", "gap_mm"], sep=";")
    assert check_main([str(folder)]) == 0, capsys.readouterr().out
    report = report_of(folder)
    assert list(report["status"]) == ["ok"]
    run = read_netcdf(folder.parent / "out" / "runs" / "s1_a_flow_curve_1_b3.nc")
    assert run.attrs["radius_m"] == pytest.approx(12.5e-3) and run.attrs["radius_source"] == "samples.csv"
    assert run.attrs["gap_m"] == pytest.approx(1.25e-3)


def test_tab_separated_sheet_is_read(tmp_path):
    folder = dataset(tmp_path, [FLOW], sep="\t")
    assert list(report_of(folder)["status"]) == ["ok"]


def test_decimal_comma_in_a_comma_sheet_is_refused_with_the_reason(tmp_path, capsys):
    folder = dataset(tmp_path, [FLOW + ['"12,5"']], HEADER + ["radius_mm"])
    out = check_fails(folder, capsys)
    assert "no plate radius" not in out
    bad = only_error(folder)
    assert bad["line"] == 2 and bad["column"] == "radius_mm"
    assert bad["reason"].startswith(f"{folder / 'samples.csv'}, line 2, column 'radius_mm': radius_mm: '12,5' has a "
                                    "decimal comma in a comma-separated sheet: write 12.5")


def test_unquoted_decimal_comma_splits_the_row_and_is_named(tmp_path):
    folder = dataset(tmp_path, [FLOW + ["12,5"]], HEADER + ["radius_mm"])
    with pytest.raises(IngestError, match=r"line 2: row has 8 cells, the header 7 \(a decimal comma in a "
                                          r"comma-separated sheet\?\)"):
        report_of(folder)


def test_mixed_decimal_marks_are_refused(tmp_path):
    folder = dataset(tmp_path, [FLOW + ["12,5"], SWEEP + ["12.5"]], HEADER + ["radius_mm"], sep=";")
    with pytest.raises(IngestError, match=r"line 3, column 'radius_mm': mixed decimal marks: '12,5' \(line 2"):
        report_of(folder)


def test_misspelled_sheet_column_gets_a_suggestion(tmp_path, capsys):
    folder = dataset(tmp_path, [FLOW + ["12.5"]], HEADER + ["raduis_mm"])
    out = check_fails(folder, capsys)
    assert "line 1, column 'raduis_mm': unknown column 'raduis_mm'; did you mean `radius_mm`?" in out


# --- order ------------------------------------------------------------------------------------------------------
def test_order_must_be_an_integer(tmp_path, capsys):
    row = list(FLOW)
    row[4] = "first"
    folder = dataset(tmp_path, [SWEEP, row])
    out = check_fails(folder, capsys)
    bad = only_error(folder)
    assert (bad["line"], bad["column"]) == (3, "order")
    assert bad["reason"] == (f"{folder / 'samples.csv'}, line 3, column 'order': order must be an integer (the test's "
                             "position in the sample's sequence: 1, 2, ...), not 'first'")
    assert "ValueError" not in out


# --- dataset.yaml ----------------------------------------------------------------------------------------------
def test_misspelled_dataset_yaml_keys_are_errors_with_suggestions(tmp_path, capsys):
    text = YAML.replace("license", "licence") + "geomtry:\n  type: parallel plate\n  raduis_mm: 12.5\n"
    folder = dataset(tmp_path, [FLOW], yaml_text=text)
    out = check_fails(folder, capsys)
    assert "unknown key 'geomtry'; did you mean `geometry`?" in out
    assert "unknown key 'licence'; did you mean `license`?" in out
    with pytest.raises(IngestError) as info:
        load_dataset_yaml(folder)
    assert (info.value.line, info.value.column) == (2, 1)                # 'licence' is the first unknown key
    nested = YAML + "geometry:\n  type: parallel plate\n  raduis_mm: 12.5\n"
    (folder / "dataset.yaml").write_text(nested, encoding="utf-8")
    with pytest.raises(IngestError, match=r"line 6, column 3: unknown key 'geometry/raduis_mm'; did you mean "
                                          r"`radius_mm`\?"):
        load_dataset_yaml(folder)


def test_every_dataset_yaml_of_the_project_passes_the_schema(repo_root):
    folders = [p.parent for p in (repo_root / "raw").glob("*/dataset.yaml")]
    folders += [p.parent for p in (repo_root / "config" / "external").glob("*/dataset.yaml")]
    assert len(folders) >= 9
    for folder in folders:
        assert load_dataset_yaml(folder)["material"]


# --- plausible ranges ----------------------------------------------------------------------------------------
def test_radius_and_gap_typed_in_metres(tmp_path, capsys):
    folder = dataset(tmp_path, [FLOW + ["0.0125", "2"], SWEEP + ["12.5", "0.001"]], HEADER + ["radius_mm", "gap_mm"])
    out = check_fails(folder, capsys)
    assert ("line 2, column 'radius_mm': radius_mm 0.0125 mm is outside the plausible range 1 to 50 mm: looks like "
            "metres (0.0125 m = 12.5 mm); write 12.5") in out
    assert ("line 3, column 'gap_mm': gap_mm 0.001 mm is outside the plausible range 0.01 to 20 mm: looks like "
            "metres (0.001 m = 1 mm); write 1") in out


def test_dataset_yaml_geometry_in_metres(tmp_path):
    folder = dataset(tmp_path, [FLOW], yaml_text=YAML + "geometry:\n  radius_mm: 0.0125\n")
    with pytest.raises(IngestError, match=r"dataset.yaml, line 5, column 14: geometry/radius_mm: .*looks like metres"):
        load_dataset_yaml(folder)


def test_a_wider_range_can_be_declared(tmp_path):
    folder = dataset(tmp_path, [FLOW + ["0.5"]], HEADER + ["gap_mm"],
                     yaml_text=YAML + "plausible_ranges:\n  gap_mm: [0.001, 1]\n")
    folder_default = dataset(tmp_path / "b", [FLOW + ["0.005"]], HEADER + ["gap_mm"])
    assert list(report_of(folder)["status"]) == ["ok"]
    assert "looks like metres" in only_error(folder_default)["reason"]


def test_radius_twice_the_exports_looks_like_a_diameter(tmp_path, capsys):
    """The LIMS export states a 25 mm plate (radius 12.5 mm); the sheet gives 25."""
    folder = dataset(tmp_path, [SWEEP + ["25"]], HEADER + ["radius_mm"])
    out = check_fails(folder, capsys)
    assert ("line 2, column 'radius_mm': samples.csv radius 25 mm is twice the export's plate radius 12.5 mm: looks "
            "like a diameter; write the radius 12.5 mm (half the diameter)") in out


def test_kelvin_out_of_range_and_against_the_logged_temperature(tmp_path, capsys):
    """293.15 for 20 degC: out of range, and (with the range widened) against the Kinexus export's logged 20.00."""
    folder = dataset(tmp_path, [FLOW + ["293.15"]], HEADER + ["temperature_c"])
    out = check_fails(folder, capsys)
    assert "line 2, column 'temperature_c': temperature_c 293.15 °C is outside" in out
    assert "looks like kelvin (293.15 K = 20 °C); write 20" in out
    wide = dataset(tmp_path / "wide", [FLOW + ["293.15"]], HEADER + ["temperature_c"],
                   yaml_text=YAML + "plausible_ranges:\n  temperature_c: [-150, 400]\n")
    out = check_fails(wide, capsys)
    assert ("line 2, column 'temperature_c': temperature_c 293.15 against the export's logged 20 °C: looks like "
            "kelvin (293.15 K = 20 °C); write 20") in out


def test_another_temperature_than_the_logged_one_is_a_warning(tmp_path):
    folder = dataset(tmp_path, [FLOW + ["37"]], HEADER + ["temperature_c"])
    report = report_of(folder)
    assert list(report["status"]) == ["ok"]
    assert "temperature: samples.csv 37 °C, the export logs 20 °C (median); samples.csv used" in report["warnings"][0]


# --- rows and points --------------------------------------------------------------------------------------------
def test_duplicated_row_names_both_lines(tmp_path, capsys):
    folder = dataset(tmp_path, [FLOW, SWEEP, FLOW])
    out = check_fails(folder, capsys)
    bad = only_error(folder)
    assert (bad["line"], bad["column"]) == (4, "file")
    assert ("line 4, column 'file': duplicate row: same file 'kinexus.csv', block 'Flow Curve' and test 'flow_curve' "
            "as line 2") in bad["reason"]
    assert "2 of 3 runs readable, 1 with errors" in out


def test_an_export_with_one_data_row_is_refused(tmp_path, capsys):
    folder = dataset(tmp_path, [["one.csv", "s1", "a", "stress_relaxation", "1", ""]])
    (folder / "one.csv").write_text("time [s],shear_stress [Pa]\n1.0,20.0\n", encoding="utf-8")
    out = check_fails(folder, capsys)
    assert (f"{folder / 'one.csv'}, line 2: block 'data' holds 1 data point(s) with the stress_relaxation variables: "
            "a curve needs at least 2") in out


def test_the_check_names_file_line_and_column_for_every_row_error(tmp_path):
    row = list(FLOW)
    row[4] = "1.5"
    result = check_dataset(dataset(tmp_path, [row]))
    assert not result.ok and "line 2, column 'order': order must be an integer" in result.runs[0].reason


def test_plausible_ranges_by_value():
    """Each documented bound, from both sides (strain by magnitude: a compression is written negative)."""
    from tissuemech.io.plausibility import range_problem

    assert range_problem("strain_pct", -10.0) is None and range_problem("strain_pct", 0.5) is None
    assert "outside the plausible range 0.0001 to 5000 %" in range_problem("strain_pct", 1e5)
    assert "outside" in range_problem("strain_pct", 1e-6)
    assert "looks like micrometres (1000 µm = 1 mm); write 1" in range_problem("gap_mm", 1000.0)
    assert range_problem("temperature_c", -40.0) is None and range_problem("temperature_c", 37.0) is None
    assert "looks like kelvin (310.15 K = 37 °C)" in range_problem("temperature_c", 310.15)
    assert range_problem("radius_mm", 4.0) is None and range_problem("gap_mm", 8.5) is None
    assert "widen the range in dataset.yaml: plausible_ranges: {radius_mm: [low, high]}" in range_problem(
        "radius_mm", 0.0125)

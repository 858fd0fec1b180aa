"""The new readers on the project's look-alike fixtures (known closed-form truths), format detection, units."""
from __future__ import annotations

import importlib.util
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tissuemech.io.dispatch import detect_format, read_export
from tissuemech.io.errors import IngestError
from tissuemech.units import UnknownUnitError, normalise_unit, to_si

FIXTURES = Path(__file__).resolve().parent / "fixtures"
_spec = importlib.util.spec_from_file_location("io_make_fixtures", FIXTURES / "make_fixtures.py")
make = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make)


def test_fixtures_are_what_the_generator_writes(tmp_path):
    """The committed text fixtures are reproducible from make_fixtures.py (no hand edits drift)."""
    assert (FIXTURES / "ta_lims_lookalike.txt").read_text(encoding="utf-8") == make.lims_text()
    assert (FIXTURES / "kinexus_lookalike.csv").read_text(encoding="utf-8") == make.kinexus_text()


# --- TA LIMS ---------------------------------------------------------------------------------------------------
def test_lims_lookalike_against_maxwell_truth():
    blocks = read_export(FIXTURES / "ta_lims_lookalike.txt")
    assert [b.name for b in blocks] == ["Frequency sweep (25.0 °C)", "Frequency sweep (40.0 °C)"]
    assert [b.index for b in blocks] == [1, 2]
    first = blocks[0]
    assert first.meta["format"] == "ta_lims"
    assert first.meta["radius_m"] == pytest.approx(make.LIMS_RADIUS_M)     # "Diameter 25.0 mm"
    assert first.meta["gap_m"] == pytest.approx(make.LIMS_GAP_M)           # "Gap 1.000000 mm"
    d = first.data
    omega = np.array(make.LIMS_OMEGA)
    g1, g2 = make.maxwell(omega)
    np.testing.assert_allclose(d["angular_frequency"], omega)
    np.testing.assert_allclose(d["storage_modulus"], g1, rtol=1e-12)
    np.testing.assert_allclose(d["loss_modulus"], g2, rtol=1e-12)
    np.testing.assert_allclose(d["shear_strain"], make.LIMS_STRAIN)       # 1.0 % -> 0.01
    # torque written in g.cm; back in N·m it must equal the rim-stress torque pi R^3 tau / 2
    np.testing.assert_allclose(d["torque"], d["shear_stress"] * np.pi * first.meta["radius_m"] ** 3 / 2, rtol=1e-12)
    np.testing.assert_allclose(d["phase_angle"], np.arctan2(g2, g1), rtol=1e-12)   # ° -> rad
    np.testing.assert_allclose(d["gap"], make.LIMS_GAP_M)
    # oscillation twins win over their empty/steady siblings; the all-empty Viscosity is left out
    np.testing.assert_allclose(d["shear_stress"], np.hypot(g1, g2) * make.LIMS_STRAIN)
    assert "viscosity" not in d
    assert first.meta["labels"]["torque"] == "g.cm"
    aux = first.meta["auxiliary"]
    np.testing.assert_allclose(aux["Storage compliance"], g1 / (g1**2 + g2**2), rtol=1e-12)   # 1/MPa -> 1/Pa
    np.testing.assert_allclose(aux["G*.sin(delta)"], g2, rtol=1e-12)                           # kPa -> Pa
    assert "Status bits" not in aux and "Date and time" not in aux                              # text columns
    np.testing.assert_allclose(blocks[1].data["total_time"], [110.0, 120.0, 130.0])
    np.testing.assert_allclose(blocks[1].data["temperature"], 40.0)


# --- Malvern Kinexus rSpace ------------------------------------------------------------------------------------
def test_kinexus_lookalike_actions_waveforms_and_units():
    blocks = read_export(FIXTURES / "kinexus_lookalike.csv")
    assert [b.name for b in blocks] == ["Pre Shear", "Oscillation Single Frequency", "Flow Curve"]
    pre, osc, flow = blocks
    np.testing.assert_allclose(pre.data["shear_rate"], 10.0)              # "Shear rate(s-¹)"
    np.testing.assert_allclose(pre.data["shear_strain"], 10.0 * pre.data["time"])   # % -> 1
    np.testing.assert_allclose(pre.data["gap"], 1e-3)                      # mm -> m
    assert osc.meta["waveform_rows"] == 6 and len(osc.data) == 3
    assert osc.meta["first_data_line"] == 12
    np.testing.assert_allclose(osc.data["storage_modulus"], make.KINEXUS_G1)
    np.testing.assert_allclose(osc.data["loss_modulus"], make.KINEXUS_G2)
    np.testing.assert_allclose(osc.data["shear_strain"], make.KINEXUS_STRAIN)
    np.testing.assert_allclose(osc.data["complex_modulus"], osc.data["shear_stress"] / osc.data["shear_strain"],
                               rtol=1e-3)
    assert "shear_rate" not in osc.data                                     # empty throughout the action
    np.testing.assert_allclose(flow.data["shear_stress"] / flow.data["shear_rate"], make.KINEXUS_ETA)
    np.testing.assert_allclose(flow.data["total_time"], [135.0, 140.0, 145.0])


def test_kinexus_point_decimal_comma_separated_variant(tmp_path):
    """English-locale rSpace exports: comma separator, decimal point."""
    text = make.kinexus_text()
    lines = [line.replace(",", ".").replace(";", ",") for line in text.splitlines()]
    path = tmp_path / "kinexus_en.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    flow = read_export(path)[2]
    np.testing.assert_allclose(flow.data["shear_stress"], [200.0, 20.0, 2.0])


# --- RheoCompass .xlsx -----------------------------------------------------------------------------------------
def test_rheocompass_xlsx_both_sheet_layouts():
    path = FIXTURES / "rheocompass_lookalike.xlsx"
    assert detect_format(path) == "rheocompass_xlsx"
    creep, sweep = read_export(path)
    assert creep.name == "Creep 1 / 1" and creep.index == 1
    assert creep.meta["sheet"] == "Creep" and creep.meta["test_name"] == "lookalike_creep_10Pa"
    assert creep.meta["invalid_points"] == 1 and creep.meta["first_data_line"] == 7
    t = creep.data["time"].to_numpy()
    np.testing.assert_allclose(t, [1.0, 2.0, 5.0, 20.0])                   # point 4 "(invalid)" dropped
    truth = 1 / make.CREEP_G_PA + t / make.CREEP_ETA_PAS
    np.testing.assert_allclose(creep.data["creep_compliance"], truth, rtol=1e-12)
    np.testing.assert_allclose(creep.data["shear_strain"], make.CREEP_STRESS_PA * truth, rtol=1e-12)   # % -> 1
    np.testing.assert_allclose(creep.data["torque"], make.CREEP_STRESS_PA * np.pi * make.CREEP_RADIUS_M**3 / 2,
                               rtol=1e-12)                                 # µN·m -> N·m
    # title-row layout: blocks numbered through the workbook, named after the sheet, waveform rows dropped
    assert sweep.index == 2 and sweep.name == "0.5% strain / 1"
    assert sweep.meta["test_name"] == "tissuemech look-alike pp 0.5% strain freq sweep"
    assert len(sweep.data) == 3
    np.testing.assert_allclose(sweep.data["frequency"], [10.0, 1.0, 0.1])
    np.testing.assert_allclose(sweep.data["shear_strain"], 0.005)           # the point column, not the waveform
    np.testing.assert_allclose(sweep.data["storage_modulus"], make.SWEEP_G1)
    gstar = np.hypot(make.SWEEP_G1, make.SWEEP_G2)
    np.testing.assert_allclose(sweep.data["torque"], gstar * 0.005 * np.pi * make.CREEP_RADIUS_M**3 / 2,
                               rtol=1e-12)                                 # mN·m -> N·m


def test_xlsx_text_cells_with_decimal_comma(tmp_path):
    import openpyxl

    book = openpyxl.Workbook()
    ws = book.active
    for row in (["Test:", "t"], ["Result:", "Relaxation"], ["Interval:", 1],
                ["Point No.", "Time", "Shear Stress"], [None, None, None], [None, "[s]", "[kPa]"],
                [1, "0,5", "1,25"], [2, "1,5", "0,75"]):
        ws.append(row)
    book.save(tmp_path / "comma.xlsx")
    (block,) = read_export(tmp_path / "comma.xlsx")
    np.testing.assert_allclose(block.data["time"], [0.5, 1.5])
    np.testing.assert_allclose(block.data["shear_stress"], [1250.0, 750.0])   # kPa -> Pa


def test_xlsx_without_rheocompass_sheet_is_rejected(tmp_path):
    import openpyxl

    book = openpyxl.Workbook()
    book.active.append(["some", "other", "table"])
    book.save(tmp_path / "other.xlsx")
    with pytest.raises(IngestError, match=r"other\.xlsx: no RheoCompass data sheet"):
        read_export(tmp_path / "other.xlsx")


def test_rhpts_is_rejected_clearly(tmp_path):
    path = tmp_path / "run.RhPts"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("run.XML", "<Export Version=\"1.23.0.0\"/>")
        z.writestr("Directory.XML", "<Directory/>")
    with pytest.raises(IngestError, match=r"run\.RhPts: Anton Paar \.RhPts object export .* not supported"):
        read_export(path)
    renamed = tmp_path / "renamed.zip"
    renamed.write_bytes(path.read_bytes())                 # detected by content, not by extension
    with pytest.raises(IngestError, match="RhPts"):
        read_export(renamed)


def test_detection_is_by_content_not_extension(tmp_path):
    for src, kind in (("ta_lims_lookalike.txt", "lims"), ("kinexus_lookalike.csv", "rspace"),
                      ("rheocompass_lookalike.xlsx", "rheocompass_xlsx")):
        dst = tmp_path / (Path(src).stem + ".dat")
        dst.write_bytes((FIXTURES / src).read_bytes())
        assert detect_format(dst) == kind
        assert len(read_export(dst)) >= 2


# --- units -----------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("unit, value, si", [
    ("g.cm", 1.0, 9.80665e-5), ("gf·cm", 2.0, 2 * 9.80665e-5), ("[mN·m]", 1.0, 1e-3), ("µN.m", 1.0, 1e-6),
    ("N m", 1.0, 1.0), ("min", 1.5, 90.0), ("%", 50.0, 0.5), ("kPa", 1.2, 1200.0), ("1/MPa", 89.9, 89.9e-6),
    ("s-¹", 3.0, 3.0), ("°", 180.0, np.pi), ("°C", 21.0, 21.0), ("K", 293.15, 20.0), ("µm", 1000.0, 1e-3),
    ("mPa·s", 5.0, 5e-3), ("[1/Pa]", 2.0, 2.0),
])
def test_unit_conversions(unit, value, si):
    assert float(to_si(value, unit)) == pytest.approx(si, rel=1e-12, abs=1e-12)


def test_units_of_another_quantity_are_refused():
    assert normalise_unit("Shear rate(s-¹)".split("(")[1].rstrip(")")) == "s-1"
    with pytest.raises(UnknownUnitError, match="unknown unit 'Pascal'"):
        to_si(1.0, "Pascal")
    with pytest.raises(UnknownUnitError, match=r"unit 'Hz' \(a 1/s quantity\) cannot be converted to rad/s"):
        to_si(1.0, "Hz", expected="rad/s")
    with pytest.raises(UnknownUnitError, match=r"no unit given where Pa is expected \(never assumed\)"):
        to_si(1.0, "", expected="Pa")
    assert float(to_si(2.0, "1/s", expected="Hz")) == 2.0

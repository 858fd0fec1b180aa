"""Export variants seen in other labs' files (issue 34, items 5 and 6), on the project's look-alike fixtures.

* the RheoCompass "table" export (``Test:``/``Result:``/``Interval:``, column row, empty sub-label row, ``[unit]``
  row, decimal comma, several tests in one UTF-16 file): every block with its result name and units;
* the same without its header (no unit row) and a plain table (``Time``, ``Relaxation Modulus``): read with the
  units ``dataset.yaml`` declares, refused with that remedy otherwise;
* a TRIOS export whose sweep follows an ``Axial`` step: the block is chosen from the test kind, and the gap is the
  axial step's last record (``export (axial step)``).

The oracle is the closed form each fixture was written from (``make_fixtures.py``), printed with 5 or 6
significant digits, hence the relative tolerances.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tissuemech.canonical import read_netcdf
from tissuemech.io.dispatch import detect_format, read_export
from tissuemech.io.errors import IngestError
from tissuemech.io.ingest import ingest_dataset

FIXTURES = Path(__file__).resolve().parent / "fixtures"
_spec = importlib.util.spec_from_file_location("io_make_fixtures_variants", FIXTURES / "make_fixtures.py")
make = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make)
SWEEP_UNITS = (("Angular Frequency", "rad/s"), ("Loss Modulus", "Pa"), ("Storage Modulus", "Pa"))
PLAIN_UNITS = (("Relaxation Modulus", "Pa"), ("Time", "s"))


def test_fixtures_are_what_the_generator_writes():
    for name in make.TEXT_FIXTURES:
        assert (FIXTURES / name).read_bytes() == make.fixture_bytes(name), name


# --- RheoCompass table export -------------------------------------------------------------------------------------
def test_table_export_every_block_with_its_result_and_units():
    path = FIXTURES / "rheocompass_table_lookalike.csv"
    assert path.read_bytes()[:2] == b"\xff\xfe"                       # UTF-16 LE with BOM, as RheoCompass writes
    blocks = read_export(path)
    assert [(b.index, b.name) for b in blocks] == [
        (1, "Frequency sweep 20C-cooling / 1"), (2, "Frequency sweep 30C-cooling / 1"),
        (3, "Frequency sweep 40C-cooling / 1")]
    for block, temperature in zip(blocks, make.TABLE_TEMPERATURES_C):
        assert block.meta["result"] == f"Frequency sweep {temperature:.0f}C-cooling"
        assert block.meta["test_name"] == f"lookalike_fs_{temperature:.0f}C"
        assert block.meta["labels"] == {"angular_frequency": "[rad/s]", "storage_modulus": "[Pa]",
                                        "loss_modulus": "[Pa]"}
        assert block.meta["layout"] == "table"
        g1, g2 = make.table_moduli(temperature)
        np.testing.assert_allclose(block.data["angular_frequency"], make.TABLE_OMEGA, rtol=1e-12)
        np.testing.assert_allclose(block.data["storage_modulus"], g1, rtol=5e-5)    # 5 significant digits
        np.testing.assert_allclose(block.data["loss_modulus"], g2, rtol=5e-5)


def test_table_export_units_come_from_its_unit_row(tmp_path):
    text = (FIXTURES / "rheocompass_table_lookalike.csv").read_bytes().decode("utf-16")
    first, rest = text.split("[rad/s]\t[Pa]\t[Pa]", 1)
    path = tmp_path / "kpa.csv"
    path.write_bytes(b"\xff\xfe" + (first + "[rad/s]\t[kPa]\t[Pa]" + rest).encode("utf-16-le"))
    kpa, pa = read_export(path)[0], read_export(FIXTURES / "rheocompass_table_lookalike.csv")[0]
    np.testing.assert_allclose(kpa.data["storage_modulus"], 1e3 * pa.data["storage_modulus"], rtol=1e-12)
    np.testing.assert_allclose(kpa.data["loss_modulus"], pa.data["loss_modulus"], rtol=1e-12)


@pytest.mark.parametrize("damage, problem", [
    (lambda t: t.replace("Result:\tFrequency sweep 30C-cooling\r\n", ""),
     r"line 14: 'Test:' row \(line 12\) without its 'Result:' row"),
    (lambda t: t.replace("Interval:\t1\r\nAngular", "Angular", 2).replace("Angular", "Interval:\t1\r\nAngular", 1),
     r"line 17: data row outside any block"),
    (lambda t: t.replace("0,1\t4,9988\t316,15\r\n", "0,1\t4,9988\t316,15\r\n" * 2),
     r"line 19: row repeats line 18 cell for cell"),
    (lambda t: t.replace("[rad/s]\t[Pa]\t[Pa]\r\n", "", 1), r"line 6: expected the '\[unit\]' row"),
    (lambda t: t.replace("Interval:\t1", "Interval:\t" + "9" * 100_000, 1), r"line 3, column 2: interval number is "
                                                                             r"not a count"),
    (lambda t: t[:-4], r"the file ends without a line end"),
])
def test_a_damaged_table_export_is_an_error(tmp_path, damage, problem):
    text = (FIXTURES / "rheocompass_table_lookalike.csv").read_bytes().decode("utf-16")
    path = tmp_path / "damaged.csv"
    path.write_bytes(b"\xff\xfe" + damage(text).encode("utf-16-le"))
    with pytest.raises(IngestError, match=problem):
        read_export(path)


# --- tables without units ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("name, units", [("rheocompass_table_headerless.csv", SWEEP_UNITS),
                                         ("plain_table_lookalike.txt", PLAIN_UNITS)])
def test_a_table_without_units_names_the_remedy(name, units):
    path = FIXTURES / name
    assert detect_format(path) == "table"
    with pytest.raises(IngestError) as info:
        read_export(path)
    first = "Angular Frequency" if name.startswith("rheocompass") else "Time"
    assert info.value.line == 1 and info.value.column == first
    assert f"no unit for column {first!r} in the file (never assumed): declare the table's units in dataset.yaml, e.g. " \
           "columns: {" in info.value.problem
    for label, _ in units:
        assert f'"{label}": <unit>' in info.value.problem


def test_headerless_table_export_with_declared_units():
    block, = read_export(FIXTURES / "rheocompass_table_headerless.csv", column_units=SWEEP_UNITS)
    g1, g2 = make.table_moduli(make.TABLE_TEMPERATURES_C[0])
    np.testing.assert_allclose(block.data["angular_frequency"], make.TABLE_OMEGA, rtol=1e-12)
    np.testing.assert_allclose(block.data["storage_modulus"], g1, rtol=5e-5)
    np.testing.assert_allclose(block.data["loss_modulus"], g2, rtol=5e-5)
    assert block.meta["units_from"] == "dataset.yaml columns" and block.meta["decimal_comma"]


def test_plain_table_with_declared_units_in_minutes():
    """The declared unit is used, whatever it is: minutes give 60 times the seconds."""
    block, = read_export(FIXTURES / "plain_table_lookalike.txt", column_units=PLAIN_UNITS)
    np.testing.assert_allclose(block.data["time"], make.PLAIN_TIMES_S, rtol=1e-12)
    np.testing.assert_allclose(block.data["relaxation_modulus"], make.plain_relaxation_pa(make.PLAIN_TIMES_S),
                               rtol=5e-6)                                        # 6 significant digits
    minutes, = read_export(FIXTURES / "plain_table_lookalike.txt",
                           column_units=(("Relaxation Modulus", "kPa"), ("Time", "min")))
    np.testing.assert_allclose(minutes.data["time"], 60 * block.data["time"], rtol=1e-12)
    np.testing.assert_allclose(minutes.data["relaxation_modulus"], 1e3 * block.data["relaxation_modulus"], rtol=1e-12)


def test_a_misspelled_declared_label_is_pointed_out():
    with pytest.raises(IngestError, match=r"dataset.yaml declares 'Tme', not 'Time' \(a misspelling\?\)"):
        read_export(FIXTURES / "plain_table_lookalike.txt", column_units=(("Relaxation Modulus", "Pa"), ("Tme", "s")))


def test_a_declared_unit_that_contradicts_the_file_is_an_error(tmp_path):
    path = tmp_path / "with_units.txt"
    path.write_text("Time\tRelaxation Modulus\n[s]\t[Pa]\n1\t10\n2\t9\n", encoding="utf-8")
    assert read_export(path, column_units=(("Time", "s"),))[0].meta["units_from"] == "unit row"
    with pytest.raises(IngestError, match=r"line 2, column 'Time': dataset.yaml declares 'min' for column 'Time', "
                                          r"the file writes '\[s\]'"):
        read_export(path, column_units=(("Time", "min"),))


def test_ingest_reads_a_plain_table_with_the_units_of_dataset_yaml(tmp_path):
    folder = tmp_path / "plain"
    folder.mkdir()
    (folder / "relax.txt").write_bytes((FIXTURES / "plain_table_lookalike.txt").read_bytes())
    pd.DataFrame([{"file": "relax.txt", "specimen": "s1", "sample": "a", "test": "stress_relaxation",
                   "order": 1}]).to_csv(folder / "samples.csv", index=False)
    (folder / "dataset.yaml").write_text("material: look-alike\n", encoding="utf-8")
    report = ingest_dataset(folder, tmp_path / "runs", tmp_path / "report.csv")
    assert list(report["status"]) == ["error"] and "declare the table's units in dataset.yaml" in report["reason"][0]
    (folder / "dataset.yaml").write_text('material: look-alike\ncolumns: {Time: s, "Relaxation Modulus": Pa}\n',
                                         encoding="utf-8")
    report = ingest_dataset(folder, tmp_path / "runs", tmp_path / "report.csv")
    assert list(report["status"]) == ["ok"], report["reason"][0]
    run = read_netcdf(tmp_path / "runs" / "s1_a_stress_relaxation_1.nc")
    np.testing.assert_allclose(run["relaxation_modulus"], make.plain_relaxation_pa(make.PLAIN_TIMES_S), rtol=5e-6)


# --- TRIOS: a sweep after an Axial step ------------------------------------------------------------------------
def axial_dataset(tmp_path: Path, text: str | None = None, rows=None) -> Path:
    folder = tmp_path / "axial"
    folder.mkdir(exist_ok=True)
    (folder / "dataset.yaml").write_text("material: look-alike\n", encoding="utf-8")
    (folder / "trios.txt").write_text(text or make.trios_axial_text(), encoding="utf-8")
    rows = rows or [{"file": "trios.txt", "specimen": "s1", "sample": "a", "test": "frequency_sweep", "order": 1}]
    pd.DataFrame(rows).to_csv(folder / "samples.csv", index=False)
    return folder


def test_sweep_after_an_axial_step_chosen_and_given_the_axial_gap(tmp_path):
    folder = axial_dataset(tmp_path)
    report = ingest_dataset(folder, tmp_path / "runs", tmp_path / "report.csv")
    assert list(report["status"]) == ["ok"], report["reason"][0]
    run = read_netcdf(tmp_path / "runs" / "s1_a_frequency_sweep_1.nc")
    assert run.attrs["block"] == "Frequency sweep - 2" and run.attrs["block_index"] == 2
    last_um = make.axial_gap_um(make.AXIAL_TIMES_S[-1])
    assert run.attrs["gap_m"] == pytest.approx(last_um * 1e-6, rel=1e-9)
    assert run.attrs["gap_source"] == "export (axial step)"
    assert run.attrs["radius_m"] == pytest.approx(4e-3) and run.attrs["radius_source"] == "export"
    notes = report["notes"][0]
    assert "block chosen: 2: 'Frequency sweep - 2', the only one of the file's 2 blocks with frequency_sweep data" in notes
    assert (f"gap {last_um * 1e-3:.5g} mm: the last record (at 1 s) of the preceding step 'Axial - 1' "
            "(source: export (axial step))") in notes
    # 1.054 %/s of ~1.98 mm: the last 3 records close by 2 x 0.1 s x ~20.9 um/s
    assert "the gap was still closing when that step ended (-4.18 µm over its last 3 records, 20.9 µm/s" in notes
    assert "no gap" not in report["warnings"][0]


def test_no_axial_gap_when_the_axial_step_is_not_directly_before(tmp_path):
    text = make.trios_axial_text().replace("Frequency sweep - 2", "Frequency sweep - 3")
    folder = axial_dataset(tmp_path, text.replace("proceduresegments\tAxial#Frequency sweep",
                                                  "proceduresegments\tAxial#Frequency sweep"))
    report = ingest_dataset(folder, tmp_path / "runs", tmp_path / "report.csv")
    run = read_netcdf(tmp_path / "runs" / "s1_a_frequency_sweep_1.nc")
    assert "gap_m" not in run.attrs and "no gap" in report["warnings"][0]


def test_no_automatic_choice_between_two_matching_blocks(tmp_path):
    text = make.trios_axial_text()
    sweep = text[text.index("[step]\nFrequency sweep - 2"):]
    text = text.replace("Axial#Frequency sweep", "Axial#Frequency sweep#Frequency sweep") + sweep.replace(
        "Frequency sweep - 2", "Frequency sweep - 3")
    report = ingest_dataset(axial_dataset(tmp_path, text), tmp_path / "runs", tmp_path / "report.csv")
    assert list(report["status"]) == ["error"]
    assert ("column 'block': file holds 3 blocks (1: Axial - 1, 2: Frequency sweep - 2, 3: Frequency sweep - 3); 2 of "
            "them hold frequency_sweep data (2: Frequency sweep - 2, 3: Frequency sweep - 3): the sample sheet must "
            "select one with 'block'") in report["reason"][0]


def test_real_fungi_trios_sweeps_ingest_with_a_gap_and_no_block_column(repo_root, shared_real, tmp_path):
    """config/external/trios names no block: each sweep is chosen, and its gap is the Axial step's last record."""
    import yaml

    src = repo_root / "config" / "external" / "trios"
    sheet = pd.read_csv(src / "samples.csv", dtype=str)
    assert "block" not in sheet
    folder = tmp_path / "trios"
    folder.mkdir()
    sheet.to_csv(folder / "samples.csv", index=False)
    meta = yaml.safe_load((src / "dataset.yaml").read_text())
    meta["source_dir"] = str(shared_real / "trios")
    (folder / "dataset.yaml").write_text(yaml.safe_dump(meta))
    report = ingest_dataset(folder, tmp_path / "runs", tmp_path / "report.csv")
    assert list(report["status"]) == ["ok", "ok"], report.to_string()
    gaps = {}
    for rec in report.to_dict("records"):
        run = read_netcdf(tmp_path / "runs" / f"{rec['run']}.nc")
        assert run.attrs["gap_source"] == "export (axial step)" and run.attrs["radius_m"] == pytest.approx(4e-3)
        gaps[run.attrs["test"]] = run.attrs["gap_m"]
        assert "still closing" in rec["notes"] and "block chosen: 2:" in rec["notes"]
    # the last Gap cells of the 'Axial - 1' sheets: 7683.5 um (amplitude), 8518.32 um (frequency)
    assert gaps == {"amplitude_sweep": pytest.approx(7683.5e-6), "frequency_sweep": pytest.approx(8518.32e-6)}

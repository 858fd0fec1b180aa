"""Seeded mutation fuzz of the readers over the bundled exports and, when present, the real ones.

A damaged export must give an IngestError or correct values: never another exception, never values that
differ from the undamaged file (a prefix-case flip must scale exactly its column by the right factor).
Outcomes are judged by :func:`tissuemech.io.fuzz.judge` against the original file read by the same reader;
the factor of a flipped prefix comes from the SI definitions (``test_units.py`` checks those by hand).
"""
import random
from pathlib import Path

import pandas as pd
import pytest

from tissuemech.canonical import read_netcdf
from tissuemech.io.dispatch import read_export
from tissuemech.io.fuzz import fuzz_file, judge, mutate, reader_options_for
from tissuemech.io.ingest import ingest_dataset

ROOT = Path(__file__).resolve().parents[2]
FIXTURES = Path(__file__).parent / "fixtures"
REAL = ROOT / ".." / "shared" / "data" / "real"
SEED = 20260113

BUNDLED = [ROOT / "raw" / "porcine_brain_thesis" / "brain01_s01_01_as.csv",
           ROOT / "raw" / "porcine_brain_thesis" / "brain01_s07_01_csr0.005.csv",
           ROOT / "raw" / "agar_3pct_thesis" / "batch01_s10_01_cr40Pa.csv",
           FIXTURES / "kinexus_lookalike.csv", FIXTURES / "ta_lims_lookalike.txt",
           FIXTURES / "rheocompass_lookalike.xlsx",
           # the export variants of issue 34 (the two tables without units get them from fixtures/dataset.yaml)
           FIXTURES / "rheocompass_table_lookalike.csv", FIXTURES / "rheocompass_table_headerless.csv",
           FIXTURES / "plain_table_lookalike.txt", FIXTURES / "trios_axial_lookalike.txt"]
REAL_FILES = ["rheocompass_cnf_hydrogel/HC1_stressrelaxation_20C_2.csv", "trios/hr30_multistep_minutes.csv",
              "trios/hr20_fungi_frequency_sweep.xls", "trios/arg2_hs60_las.xls", "ta_lims/ares_g2_frequency_sweep_tts.txt",
              "rheocompass_misc/flowcurve_laos_oscillation_fr.csv"]
ALLOWED = {"error", "same", "scaled", "file_shorter"}


def _check(results, name):
    bad = [r for r in results if r[2] not in ALLOWED and not (r[2] == "undetectable" and r[0] == "corrupt_bytes")]
    assert not bad, f"{name}: " + "; ".join(f"{k} ({d}) -> {o}: {m}" for k, d, o, m in bad)
    return {r[2] for r in results}


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.name)
def test_fuzz_bundled_exports(path, tmp_path):
    outcomes = _check(fuzz_file(path, tmp_path, 16, SEED, **reader_options_for(path)), path.name)
    assert "error" in outcomes                       # the mutations do damage: the test can fail


@pytest.mark.parametrize("name", REAL_FILES)
def test_fuzz_real_exports(name, tmp_path):
    path = REAL / name
    if not path.is_file():
        pytest.skip("../shared/data/real not present")
    _check(fuzz_file(path, tmp_path, 7, SEED), name)


def test_prefix_flip_scales_the_column_by_the_si_factor(tmp_path):
    """The RheoCompass torque unit mN·m flipped to MN·m: torque x 1e9, every other column unchanged."""
    src = ROOT / "raw" / "porcine_brain_thesis" / "brain01_s07_01_csr0.005.csv"
    results = fuzz_file(src, tmp_path, 35, SEED)
    flips = [r for r in results if r[0] == "flip_prefix"]
    assert flips and {r[2] for r in flips} <= {"scaled", "same"} and any(r[2] == "scaled" for r in flips)


@pytest.mark.parametrize("path", [p for p in BUNDLED if p.suffix != ".xlsx"], ids=lambda p: p.name)
def test_a_100000_digit_cell_is_an_ingest_error(path, tmp_path):
    """Number cells (point numbers, counts, values) replaced by 100,000 digits: an IngestError, never the bare
    ValueError of Python's integer-string limit; a cell of a row the reader drops (a waveform row) changes nothing."""
    options = reader_options_for(path)
    blocks = read_export(path, **options)
    rng = random.Random(f"{SEED}:{path.name}:long")
    outcomes = []
    for _ in range(4):
        mutant = mutate(path.read_bytes(), "long_number", rng)
        target = tmp_path / f"mutant{path.suffix}"
        target.write_bytes(mutant.data)
        outcome, message = judge(blocks, target, "long_number", **options)
        assert outcome in ("error", "same"), f"{path.name} {mutant.detail}: {outcome} {message}"
        outcomes.append(outcome)
    assert "error" in outcomes


TRUNCATED_XLS = b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1" + bytes(range(256)) * 2   # OLE2 signature, then cut


def test_truncated_xls_does_not_take_the_dataset_down(tmp_path):
    """A dataset holding one truncated .xls writes its report; the good files still give runs.
    dataset.yaml holds only 'material' (citation/license missing are warnings)."""
    raw = tmp_path / "raw" / "mixed"
    raw.mkdir(parents=True)
    (raw / "dataset.yaml").write_text("material: look-alike gel\n")
    (raw / "kinexus.csv").write_bytes((FIXTURES / "kinexus_lookalike.csv").read_bytes())
    (raw / "sweep.xls").write_bytes(TRUNCATED_XLS)
    pd.DataFrame([
        {"file": "sweep.xls", "specimen": "s1", "sample": "a", "test": "frequency_sweep", "order": 1, "block": ""},
        {"file": "kinexus.csv", "specimen": "s1", "sample": "b", "test": "flow_curve", "order": 1, "block": "3"},
    ]).to_csv(raw / "samples.csv", index=False)
    out = tmp_path / "results"
    report = ingest_dataset(raw, out / "runs", out / "ingest_report.csv")
    on_disk = pd.read_csv(out / "ingest_report.csv", keep_default_na=False)
    assert list(on_disk["status"]) == list(report["status"]) == ["error", "ok"]
    assert on_disk["reason"][0].startswith(f"{raw / 'sweep.xls'}: not a readable TRIOS .xls workbook")
    assert [p.name for p in (out / "runs").iterdir()] == ["s1_b_flow_curve_1_b3.nc"]
    run = read_netcdf(out / "runs" / "s1_b_flow_curve_1_b3.nc")
    assert "radius_m" not in run.attrs and "radius_source" not in run.attrs      # absent, never a default
    assert run.attrs["gap_m"] == pytest.approx(1e-3) and run.attrs["gap_source"] == "export"  # Gap(mm) 1,0000
    warnings = on_disk["warnings"][1].split("; ")
    assert "no plate radius" in warnings and "no gap" not in warnings
    assert "dataset.yaml has no 'citation'" in warnings and "dataset.yaml has no 'license'" in warnings

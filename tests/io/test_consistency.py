"""Integrity checks that turn silent damage into IngestError: redundant oscillation columns, LIMS structure,
and the fuzz oracle's distinction between a shorter file and lost data."""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from tissuemech.io.blocks import Block
from tissuemech.io.consistency import check_redundant_columns, printed_relative_precision
from tissuemech.io.dispatch import read_export
from tissuemech.io.errors import IngestError
from tissuemech.io.fuzz import judge

FIXTURES = Path(__file__).parent / "fixtures"


def _sweep(g1, g2, tan, w=(1.0, 10.0, 100.0)):
    data = pd.DataFrame({"storage_modulus": g1, "loss_modulus": g2, "loss_factor": tan, "angular_frequency": w})
    return Block(name="Frequency sweep - 2", index=2, data=data, meta={"first_data_line": 5})


def test_printed_precision_is_half_the_last_digit():
    # hand-computed: 0.17 -> 0.005/0.17; 16554.1 -> 0.05/16554.1; 1.0 -> 0.5
    got = printed_relative_precision([0.17, 16554.1, 1.0, 0.0])
    np.testing.assert_allclose(got[:3], [0.005 / 0.17, 0.05 / 16554.1, 0.5], rtol=1e-9)
    assert np.isnan(got[3])


def test_rounded_cells_within_their_printed_precision_pass():
    # G' printed as 0.17 (2 digits): the instrument's tan delta from unrounded values differs by 2 %
    blocks = [_sweep([0.17, 100.0, 200.0], [2.25, 50.0, 20.0], [13.512, 0.5, 0.1])]
    assert check_redundant_columns("x.csv", blocks) is blocks


def test_a_damaged_storage_modulus_is_an_error_naming_column_and_line():
    # a binary double overwritten: 16554.1 -> 24.95122375 (what a corrupted TRIOS .xls gave)
    g1 = np.array([16554.1, 20000.0, 24.95122375])
    g2 = np.array([1655.41, 2000.0, 2500.0])
    tan = np.array([0.1, 0.1, 0.1])
    with pytest.raises(IngestError) as err:
        check_redundant_columns("sweep.xls", [_sweep(g1, g2, tan)])
    assert err.value.column == "loss_factor" and err.value.line == 7
    assert "point 3" in err.value.problem and "disagrees" in err.value.problem


def test_complex_viscosity_is_checked_against_the_moduli():
    w = np.array([1.2566, 12.566, 125.66])                    # 5 digits, as instruments print
    g1, g2 = np.array([301.25, 402.5, 503.75]), np.array([402.25, 503.5, 604.75])
    b = _sweep(g1, g2, np.round(g2 / g1, 5), w)
    b.data["complex_viscosity"] = np.round(np.hypot(g1, g2) / w, 4) * [1.0, 1.0, 1.2]
    with pytest.raises(IngestError, match=r"point 3: complex_viscosity [0-9.]+ disagrees"):
        check_redundant_columns("sweep.csv", [b])


def test_lims_step_rows_without_their_step_header_are_an_error(tmp_path):
    lines = (FIXTURES / "ta_lims_lookalike.txt").read_text(encoding="utf-8").splitlines(keepends=True)
    first = next(i for i, line in enumerate(lines) if line.strip() == "[Step]")
    (tmp_path / "no_header.txt").write_text("".join(lines[:first] + lines[first + 1:]), encoding="utf-8")
    with pytest.raises(IngestError, match=r"before the first \[Step\] header"):
        read_export(tmp_path / "no_header.txt")
    (tmp_path / "no_name.txt").write_text("".join(lines[:first + 1] + lines[first + 2:]), encoding="utf-8")
    with pytest.raises(IngestError, match="without a 'Step name' row"):
        read_export(tmp_path / "no_name.txt")


def test_fuzz_oracle_tells_a_deleted_row_from_lost_points(tmp_path):
    """The oracle must be able to fail: points missing beyond the deleted row are 'lost'."""
    src = FIXTURES / "ta_lims_lookalike.txt"
    original = read_export(src)
    text = src.read_text(encoding="utf-8").splitlines(keepends=True)
    data_rows = [i for i, line in enumerate(text) if line.startswith("Data point")]
    # the step declares its point count, so deleting a data row is an error, not a shorter file
    (tmp_path / "m.txt").write_text("".join(text[:data_rows[0]] + text[data_rows[0] + 1:]), encoding="utf-8")
    assert judge(original, tmp_path / "m.txt", "delete_line")[0] == "error"
    # the same step read back with two points fewer than the original holds: lost after one deleted line,
    # a tail cut off after a truncation
    from tissuemech.io import fuzz
    shortened = [(0, len(original[0].data) - 2, len(original[0].data), True)]
    assert fuzz._judge_missing("delete_line", 0, shortened, len(original), original)[0] == "lost"
    assert fuzz._judge_missing("truncate", 0, [(len(original) - 1, 1, 3, True)], len(original),
                               original)[0] == "file_shorter"
    assert fuzz._judge_missing("truncate", 0, [(0, 1, 3, True)], len(original), original)[0] == (
        "lost" if len(original) > 1 else "file_shorter")


def test_a_trios_step_sheet_emptied_by_byte_damage_is_an_error(tmp_path):
    """Five bytes of the real TRIOS workbook's BIFF record overwritten (what fuzz seed 7 found): xlrd then reads
    the 'Frequency sweep - 2' sheet as empty, which used to be skipped like Excel's empty 'Sheet1'."""
    real = Path(__file__).resolve().parents[2] / ".." / "shared" / "data" / "real" / "trios" / "hr20_fungi_frequency_sweep.xls"
    if not real.is_file():
        pytest.skip("../shared/data/real not present")
    data = bytearray(real.read_bytes())
    assert bytes(data[27256:27261]) == b"\x0f\x00\x08\x02\x10"          # the file this offset was found in
    data[27256:27261] = b"A>\\\x9a\xb9"
    (tmp_path / "damaged.xls").write_bytes(bytes(data))
    assert len(read_export(real)) == 2                                  # the undamaged file: both step sheets
    with pytest.raises(IngestError, match="step sheet 'Frequency sweep - 2' has 0 row"):
        read_export(tmp_path / "damaged.xls")

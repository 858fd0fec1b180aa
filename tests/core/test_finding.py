"""records.Finding: the diagnosis finding as written to diagnosis.json and read back by the report (issue 14)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from tissuemech.diagnosis.findings import fix_record, make_finding, untested_finding, write_diagnosis_json
from tissuemech.records import Finding, FindingError
from tissuemech.summary import diagnosis_html


def _named_finding() -> dict:
    test = {"statistic": 6.73, "p_value": 1.2e-9, "log10_p": math.log10(1.2e-9)}
    fix = fix_record("qlv_rp3_prony4+offset", "rmse_log", before=0.20, after=0.15, cv="leave-one-condition-out",
                     offset_nm=4.3e-6)
    return make_finding("torque_offset", test, "t", 0.05, "x", True, "offset of 4.3 uN m", fix,
                        detected=np.bool_(True), significant=True, p_holm=2.4e-8, design="held-out conditions")


def test_a_named_finding_round_trips_through_diagnosis_json(tmp_path):
    path = write_diagnosis_json({"findings": [_named_finding(), untested_finding("wall_slip", "one gap")]},
                                tmp_path / "diagnosis.json", dataset="d")
    named, untested = (Finding.from_dict(f) for f in json.loads(path.read_text())["findings"])
    assert named.effect == "torque_offset" and named.detected and named.tested and named.practical
    assert named.p_holm == pytest.approx(2.4e-8) and named.statistic == pytest.approx(6.73)
    # the held-out gain is (before - after) / before of the fix, 0.05 / 0.20
    assert named.fix_gain == pytest.approx(0.25)
    assert named.data["design"] == "held-out conditions"          # detector-specific keys are kept
    assert untested.effect == "wall_slip" and not untested.tested and not untested.detected
    assert math.isnan(untested.p_value) and untested.fix is None and untested.evidence == "one gap"


@pytest.mark.parametrize("change, message", [
    ({"effect": ""}, "'effect' must be a non-empty string"),
    ({"p_value": "0.01"}, "torque_offset: 'p_value' must be a number or null"),
    ({"detected": "yes"}, "torque_offset: 'detected' must be true or false"),
    ({"fix": {"before": 1.0}}, "torque_offset: 'fix' must hold 'model' and 'metric'"),
    ({"evidence": 3}, "torque_offset: 'evidence' must be a string"),
])
def test_malformed_findings_are_refused_with_the_field_named(change, message):
    bad = dict(_named_finding(), **change)
    with pytest.raises(FindingError, match=message):
        Finding.from_dict(bad)


def test_the_writer_refuses_a_malformed_finding_and_writes_nothing(tmp_path):
    bad = dict(_named_finding(), fix={"gain": 0.3})
    with pytest.raises(FindingError, match="torque_offset: 'fix'"):
        write_diagnosis_json({"findings": [bad]}, tmp_path / "diagnosis.json")
    assert not (tmp_path / "diagnosis.json").exists()


def test_the_report_prints_detected_findings_with_their_fix(tmp_path):
    quiet = dict(untested_finding("elapsed_time_drift", "no clock"), detected=False)
    path = write_diagnosis_json({"findings": [_named_finding(), quiet]}, tmp_path / "diagnosis.json")
    text = diagnosis_html(path)
    assert "<code>torque_offset</code>" in text and "gain 0.25" in text and "qlv_rp3_prony4+offset" in text
    assert "elapsed_time_drift" not in text


def _page_with_extension_table(tmp_path, table_csv: str) -> str:
    """The diagnosis text of a page whose dataset has ``uq/extension_indentation.csv`` with ``table_csv``."""
    path = write_diagnosis_json({"findings": [_named_finding()]}, tmp_path / "diagnosis.json")
    (tmp_path / "uq").mkdir()
    (tmp_path / "uq" / "extension_indentation.csv").write_text(table_csv)
    return diagnosis_html(path)


def test_the_report_says_what_the_named_extension_changes_in_the_indentation(tmp_path):
    text = _page_with_extension_table(
        tmp_path,
        "cause,extension_model,baseline_model,depth_m,baseline_force_n,extension_force_n,difference_n,"
        "relative_difference,measurement_q05_n,measurement_q95_n,specimen_q05_n,specimen_q95_n,"
        "outside_measurement_band,outside_specimen_band,status\n"
        "torque_offset,ext,base,0.0015,0.012,0.015,0.003,0.25,0.0118,0.0122,0.009,0.0148,True,True,ok\n")
    assert ("1.5 mm flat-punch indentation the extension's card changes the force from 12 to 15 mN (25 %), "
            "outside the baseline's posterior 5-95 % band (11.8-12.2 mN) and outside the spread between "
            "specimens") in text


def test_the_report_says_what_the_extension_changes_in_the_brain(tmp_path):
    text = _page_with_extension_table(
        tmp_path,
        "cause,geometry,extension_model,baseline_model,depth_m,baseline_force_n,extension_force_n,difference_n,"
        "relative_difference,measurement_q05_n,measurement_q95_n,specimen_q05_n,specimen_q95_n,"
        "outside_measurement_band,outside_specimen_band,punch_nodes,status\n"
        "torque_offset,flat punch on a tissue block,ext,base,0.0015,0.012,0.015,0.003,0.25,0.0118,0.0122,0.009,"
        "0.0148,True,True,,ok\n"
        "torque_offset,MNI brain,ext,base,0.0015,0.004,0.0039,-0.0001,-0.025,0.0039,0.0041,0.003,0.005,False,False,"
        "1,ok\n")
    flat = text.index("1.5 mm flat-punch indentation the extension's card changes the force from 12 to 15 mN")
    brain = text.index("Pressed 1.5 mm into the MNI brain, it changes the force from 4 to 3.9 mN (-2.5 %): inside "
                       "the baseline's posterior 5-95 % band taken relative, inside the spread between specimens; the "
                       "mesh puts 1 surface node on the punch face, so the force is a mesh-level estimate")
    assert flat < brain

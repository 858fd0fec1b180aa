"""Each named cause on a constructed design with that single effect (tests/diagnosis/constructed.py):
its detector must be the top finding, with a positive held-out gain of its fix where one is scored;
the null design must raise nothing (alpha = 0.01, Holm across every catalogue and generic test)."""
from __future__ import annotations

import numpy as np
import pytest

from tissuemech.diagnosis import CATALOGUE_IDS, CAUSE_IDS
from tissuemech.diagnosis.report import top_finding

SMALL = {"n_specimens": 4, "n_samples": 2, "n_points": 16}
#: design overrides per effect: the outlier needs a tighter specimen population to be distinguishable from
#: 6 specimens at alpha = 0.01 (power at the realistic 25 % spread: benchmarks/power_study.py); the I2
#: dependence needs the normal-force channel
DESIGN = {"elapsed_time_drift": {"n_samples": 4, "magnitude": 2.0}, "outlier_specimen": {"specimen_sd": 0.08, "n_specimens": 10, "n_samples": 1, "magnitude": 2.0}, "unidentified_i2_dependence": {"with_normal_force": True}}


def finding(result, effect):
    return next(f for f in result["findings"] if f["effect"] == effect)


def test_null_design_raises_no_finding(diagnosed):
    _, _, res = diagnosed(None, **SMALL)
    assert [f["effect"] for f in res["findings"] if f["detected"]] == []
    assert res["unexplained"] == []
    assert {f["effect"] for f in res["findings"]} == set(CAUSE_IDS)
    i2 = finding(res, "unidentified_i2_dependence")
    assert i2["identifiable"] is False and "not identifiable" in i2["evidence"].lower()


#: causes whose fix is a model-level refit (scored by report.with_model_fixes on a fitted baseline) or is read from
#: data these constructed designs do not have: on a constructed design (a given prediction, nothing refitted) their
#: fix cannot be scored, so they must be significant, listed as such, and never named. Fixed here, not read from
#: the findings, so that a fix that silently goes missing (or appears from nowhere) fails the test.
NO_SCORED_FIX = {"nonseparable_relaxation", "unidentified_i2_dependence"}


@pytest.mark.parametrize("effect", CATALOGUE_IDS)
def test_single_effect_is_top_finding_with_positive_gain(diagnosed, effect):
    """The injected cause, and no other, is named with a fix that beats the noise-calibrated margin; a cause of
    :data:`NO_SCORED_FIX` is never named but listed as significant with its fix not evaluated, and nothing else is
    named in its place."""
    _, _, res = diagnosed(effect, **{**SMALL, **DESIGN.get(effect, {})})
    f = finding(res, effect)
    named = [g["effect"] for g in res["findings"] if g["detected"]]
    if effect in NO_SCORED_FIX:
        assert f["fix"] is None and not f["detected"] and named == [], named
        assert [e["effect"] for e in res["significant_fix_not_evaluated"]][:1] == [effect]
        assert res["significant_fix_not_evaluated"][0]["p_holm"] < 0.01
        assert "fix was not scored" in f["decision"] and f["what_to_do"].startswith("Not named")
        # its structure is not named either: every unexplained entry lists it among the candidates
        assert all(effect in u["candidates"] for u in res["unexplained"]), res["unexplained"]
    else:
        assert named == [effect], [(g["effect"], g["log10_p"]) for g in res["findings"][:3]]
        top = res["findings"][0]
        assert top["p_holm"] < 0.01 and top["evidence"] and top["what_to_do"]
        assert top["fix"]["before"] - top["fix"]["after"] > top["fix"]["margin"] > 0, top["fix"]
        assert res["unexplained"] == []


def test_effect_sizes_are_recovered(diagnosed):
    # drift injected at 10 %/h, preconditioning +20 %, inertia dI = 2e-7 kg m^2, offset 0.1 Pa, C01 = 30 Pa
    # the small design's fixed test order leaves the drift to the sample means within each specimen (2 per specimen
    # there, 3 df): the drift is read on the effect's own design (4 samples per specimen, 20 %/h)
    drift = finding(diagnosed("elapsed_time_drift", **{**SMALL, **DESIGN["elapsed_time_drift"]})[2],
                    "elapsed_time_drift")
    assert drift["effect_size"] == pytest.approx(0.20, abs=0.05)
    pre = finding(diagnosed("preconditioning", **SMALL)[2], "preconditioning")
    assert pre["effect_size"] == pytest.approx(0.20, abs=0.05)
    inertia = finding(diagnosed("instrument_inertia", **SMALL)[2], "instrument_inertia")
    assert inertia["effect_size"] == pytest.approx(2e-7, rel=0.15)
    offset = finding(diagnosed("torque_offset", **SMALL)[2], "torque_offset")
    radius = 12.5e-3
    assert offset["effect_size"] == pytest.approx(0.1 * np.pi * radius ** 3 / 2 * 1e6, rel=0.2)
    i2 = finding(diagnosed("unidentified_i2_dependence", **SMALL, with_normal_force=True)[2],
                 "unidentified_i2_dependence")
    assert i2["effect_size"] == pytest.approx(30.0, rel=0.1)


def test_nonseparable_sign_pattern_named_in_evidence(diagnosed):
    f = finding(diagnosed("nonseparable_relaxation", **SMALL)[2], "nonseparable_relaxation")
    assert "change sign with rate" in f["evidence"] and "strain-specific shapes" in f["evidence"]
    assert f["effect_size"] > 0  # data above QLV at fast rates, below at slow rates (science.md 1.1)


def test_structure_outside_the_catalogue_is_reported_as_unexplained(diagnosed):
    # stiffness falling 8 % per degC of bath temperature: no catalogue cause, the channel must be named
    _, _, res = diagnosed(None, **SMALL, temperature_effect=0.08)
    assert top_finding(res) is None
    covs = {u["covariate"] for u in res["unexplained"]}
    assert covs == {"channel_temperature"}
    u = res["unexplained"][0]
    assert u["effect"] == "unexplained_structure" and u["p_holm"] < 0.01
    assert u["effect_size"] == pytest.approx(-0.08 * 1.8, rel=0.3)  # 5-95 % range of +-1 degC

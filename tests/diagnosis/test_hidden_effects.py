"""Hidden-effect suite on the virtual rheometer (tissuemech.synth): one effect injected at its realistic
default magnitude (science.md section 3) into a small thesis-like design (6 specimens x 2 samples; each sample
runs the amplitude sweep first -- the LVE check -- then FS, three CSR rates and four relaxations in an order
shuffled per sample, so that elapsed time and test condition are not confounded; gaps 2-4 mm), a linear QLV
baseline fitted with lmfit to the ramps and relaxations, then the diagnose stage. The top finding must name
the injected effect and its fix must improve the held-out metric; the null design raises nothing. Every dataset is
diagnosed under one analysis, whatever was injected, on a seed the detectors were not developed on.

``finite_rise_time`` and ``rim_stress_nonlinearity`` are errors of the analysis: they are injected as the analysis
(a ramp analysed as a step; a stiffening baseline, qlv_rp2_prony4, fitted the thesis way: homogeneous law at the
rim strain vs the reported 2M/(pi R^3)), and the null design under the same analysis must not name them.

Not in this suite (covered on constructed designs in test_catalogue.py): ``outlier_specimen``. A x2.5 specimen
among specimens with log-SD 0.25 is a 3.5 sigma deviation; with 6 specimens the deletion t-test (df = 4,
Bonferroni over specimens, then Holm over the catalogue) cannot reach alpha = 0.01 (uncorrected p 0.5 and
0.025 measured on seeds 0, 1; power computed in docs/power_study.md).
"""
from __future__ import annotations

import pytest

from synth_pipeline import ANALYSIS, DESIGN, diagnose_synthetic
from tissuemech.diagnosis.report import top_finding

pytestmark = pytest.mark.slow

#: the seed of the suite's datasets: not the development seed 0 the detectors were examined on
SEED = 7

#: catalogue id -> what the realistic magnitude is (synth.effects.DEFAULTS, science.md section 3). Every one is
#: diagnosed under the same analysis (linear QLV through the torque, measured strain history): the analysis is
#: never chosen from the effect injected
SUITE = {
    "nonseparable_relaxation": "PR weights growing with strain, kappa = 0.6, gamma_s = 0.2",
    "wall_slip": "sigma_c = 30 Pa, beta_s = 2e-6 m/Pa",
    "preconditioning": "first load 20 % stiffer",
    "instrument_inertia": "1 % motor-inertia calibration error",
    "torque_offset": "0.2 uN m offset + 1e-3 uN m/s drift",
    "amplitude_softening": "Kraus gamma_c = 3 %, m = 1, G'inf/G'0 = 0.7",
    "unidentified_i2_dependence": "C01/C10 = 0.4, visible in the normal force only",
    "elapsed_time_drift": "stiffening of 10 % per hour of session time",
}
#: causes that are errors of the analysis, not of the data: injected as the analysis (synth_pipeline.ANALYSIS) --
#: a 0.5 s relaxation ramp analysed as a step; a stiffening law fitted the thesis way (homogeneous law at the rim
#: strain vs the reported 2M/(pi R^3)) -- and checked against the null design under the same analysis
ANALYSIS_ERRORS = ("finite_rise_time", "rim_stress_nonlinearity")


def test_null_synthetic_dataset_raises_nothing(tmp_path):
    _, _, res, _ = diagnose_synthetic(None, SEED, tmp_path, **DESIGN)
    assert top_finding(res) is None
    assert res["unexplained"] == []


#: the tests that read the nonseparable_relaxation diagnosis of ``synthetic`` run on one worker (computed once)
NONSEPARABLE_GROUP = pytest.mark.xdist_group("hidden_nonseparable")


@pytest.fixture(scope="module")
def synthetic(tmp_path_factory):
    """``(effect, seed, **kwargs) -> diagnose_synthetic(...)``, computed once per module (and worker).

    The nonseparable_relaxation dataset serves two tests: the suite case below and the Pipkin-Rogers fix test,
    which reads the fix that ``with_model_fixes`` scored through ``fixes.nonseparable_fix`` (about a minute of
    refits) instead of refitting it on a second dataset."""
    cache = {}

    def get(effect, seed, **kwargs):
        key = (effect, seed, tuple(sorted(kwargs.items())))
        if key not in cache:
            cache[key] = diagnose_synthetic(effect, seed, tmp_path_factory.mktemp(f"synthetic_{effect}"), **kwargs)
        return cache[key]

    return get


@pytest.mark.parametrize("effect", [pytest.param(e, marks=NONSEPARABLE_GROUP) if e == "nonseparable_relaxation"
                                    else e for e in SUITE])
def test_injected_effect_is_named_and_fixed(effect, tmp_path, synthetic):
    if effect == "nonseparable_relaxation":
        _, _, res, _ = synthetic(effect, SEED, **DESIGN)
    else:
        _, _, res, _ = diagnose_synthetic(effect, SEED, tmp_path, **DESIGN)
    if effect == "unidentified_i2_dependence":
        # no fix is scored for it (C01 is read from the normal force): significant, never named, nothing else named
        assert [e["effect"] for e in res["significant_fix_not_evaluated"]][:1] == [effect]
        assert top_finding(res) is None
        return
    assert top_finding(res) == effect, [(f["effect"], f["log10_p"], f["detected"]) for f in res["findings"][:3]]
    top = res["findings"][0]
    # named only with a fix whose held-out improvement beats the noise-calibrated margin
    assert top["fix"]["before"] - top["fix"]["after"] > top["fix"]["margin"] > 0, top["fix"]
    # the analysis errors cannot be named from data analysed the right way
    assert not {f["effect"] for f in res["findings"] if f["detected"]} & set(ANALYSIS_ERRORS)


@pytest.mark.parametrize("effect", ANALYSIS_ERRORS)
def test_an_analysis_error_is_named_and_its_analysis_alone_raises_nothing(effect, tmp_path):
    _, _, res, _ = diagnose_synthetic(effect, SEED, tmp_path / "effect", **DESIGN, **ANALYSIS[effect])
    assert top_finding(res) == effect, [(f["effect"], f["log10_p"], f["detected"]) for f in res["findings"][:3]]
    top = res["findings"][0]
    assert top["fix"]["before"] - top["fix"]["after"] > top["fix"]["margin"] > 0, top["fix"]
    # the null design under the same analysis: the analysis is not a cause where the data do not expose it
    _, _, null, _ = diagnose_synthetic(None, SEED, tmp_path / "null", **DESIGN, **ANALYSIS[effect])
    assert effect not in {f["effect"] for f in null["findings"] if f["detected"]}


def test_elapsed_time_drift_rate_is_recovered(tmp_path):
    """The injected stiffening of 10 % per hour of session time is recovered by the drift detector."""
    _, _, res, _ = diagnose_synthetic("elapsed_time_drift", 1, tmp_path, **DESIGN)
    drift = next(f for f in res["findings"] if f["effect"] == "elapsed_time_drift")
    assert drift["detected"] and drift["effect_size_unit"] == "1/h"
    assert drift["effect_size"] == pytest.approx(0.10, abs=0.03)


def test_rim_exponent_and_thesis_bias_of_c20(tmp_path):
    """n = dlnM/dln(gamma_R) at 50 % of sigma = G0 (g + g^3) is (1 + 2 g^2)/(1 + 2 g^2/3) = 1.29 in the reported
    stress; the thesis-way fit returns C20 at 2/3 of the injected G0/4 = 50 Pa (science.md 2.1)."""
    _, _, res, fit = diagnose_synthetic("rim_stress_nonlinearity", 1, tmp_path, **DESIGN,
                                        **ANALYSIS["rim_stress_nonlinearity"])
    rim = next(f for f in res["findings"] if f["effect"] == "rim_stress_nonlinearity")
    assert rim["detected"]
    assert rim["fix"]["parameters"]["n"] == pytest.approx(1.286, abs=0.05)
    assert rim["effect_size"] == pytest.approx(4 / 4.286 - 1, abs=0.015)
    # C20/C10 is free of the specimen scale: truth 2/3 x 50 / 100
    assert fit.params["C20"] / fit.params["C10"] == pytest.approx(1 / 3, rel=0.1)


@NONSEPARABLE_GROUP
def test_nonseparable_fix_is_the_pipkin_rogers_extension(synthetic):
    """run_diagnosis path: QLV -> Pipkin-Rogers fitted leaving out the extreme CSR rates; held-out gain > 0.

    The fix is the one ``with_model_fixes`` scored with ``fixes.nonseparable_fix(runs, "qlv_linear_prony4", "torque")``
    on the suite's nonseparable_relaxation dataset (shared with the suite case above)."""
    _, _, res, _ = synthetic("nonseparable_relaxation", SEED, **DESIGN)
    assert res["model"] == "qlv_linear_prony4" and res["fit_info"]["target"] == "torque"
    finding = next(f for f in res["findings"] if f["effect"] == "nonseparable_relaxation")
    fix = finding["fix"]
    assert fix is not None, "with_model_fixes did not score the Pipkin-Rogers fix"
    assert fix["model"] == "pr_linear_prony4"
    assert fix["gain"] > 0 and fix["parameters"]["delta_aicc"] < -10, fix
    assert fix["extension_params"]["kappa"] > 0  # the injected weights grow with strain (kappa = 0.6)


def test_shuffled_design_decorrelates_test_order_from_condition():
    """Every sample starts with the amplitude sweep; the other tests take sample-specific positions."""
    import numpy as np

    from synth_pipeline import config
    from tissuemech.synth.generator import plan_runs

    planned = plan_runs(config(None, **DESIGN), np.random.default_rng(0))
    by_sample = {}
    for r in planned:
        by_sample.setdefault((r.specimen, r.sample), []).append(r)
    assert len(by_sample) == 12
    assert all(runs[0].test == "amplitude_sweep" and runs[0].order == 1 for runs in by_sample.values())
    orders = {tuple(f"{r.test}{r.settings}" for r in runs) for runs in by_sample.values()}
    assert len(orders) == 12
    with pytest.raises(ValueError, match="sequence.order must be 'fixed' or 'shuffled'"):
        plan_runs(config(None, order="random"), np.random.default_rng(0))

"""FEBio cards: the written XML against FEBio's documented structure, the conversions against hand-written FEBio
stress forms, and the valid range and uncertainty every card carries.

The oracle table :data:`FEBIO_SCHEMA` was read by hand from the FEBio source (febiosoftware/FEBio, commit 65622b5:
``REGISTER_FECORE_CLASS`` in FEBioMech/FEBioMechModule.cpp, ``ADD_PARAMETER`` in each material's .cpp,
``k``/``pressure_model`` of FEUncoupledMaterial.cpp) and the FEBio User Manual's material chapter; it is
independent of the writer in ``tissuemech.cards_febio``.
"""
from __future__ import annotations

import dataclasses
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from febio_reference import documented_relaxation, documented_shear_stress

from tissuemech import cards as C
from tissuemech import fitting as F
from tissuemech.cards_febio import febio_card_material
from tissuemech import regression as REG
from tissuemech.models.registry import build_model, get_model, model_on_times
from tissuemech.records import MaterialCard

ROOT = Path(__file__).resolve().parents[2]
GAMMA = np.linspace(0.01, 0.5, 25)

_UNCOUPLED_COMMON = {"k", "pressure_model", "density"}
#: FEBio type -> (uncoupled?, allowed parameter tags, required parameter tags)
FEBIO_SCHEMA = {
    "Mooney-Rivlin": (True, {"c1", "c2"} | _UNCOUPLED_COMMON, {"c1", "c2"}),
    "Ogden": (True, {f"c{i}" for i in range(1, 7)} | {f"m{i}" for i in range(1, 7)} | _UNCOUPLED_COMMON, {"c1", "m1"}),
    "Gent": (True, {"G", "Jm"} | _UNCOUPLED_COMMON, {"G", "Jm"}),
    "polynomial": (False, {"c01", "c02", "c10", "c11", "c12", "c20", "c21", "c22", "D1", "D2", "density"},
                   {"c10", "D1"}),
    "uncoupled viscoelastic": (True, {"g0"} | {f"g{i}" for i in range(1, 7)} | {f"t{i}" for i in range(1, 7)}
                               | _UNCOUPLED_COMMON | {"elastic"}, {"g0", "g1", "t1", "elastic"}),
}


def check_febio_structure(text: str) -> list[str]:
    """Problems of a FEBio card document against the documented structure ([] when it conforms)."""
    problems = []
    root = ET.fromstring(text)
    if root.tag != "febio_spec" or root.get("version") != "4.0":
        problems.append(f"root is <{root.tag} version={root.get('version')}>, expected febio_spec 4.0")
    mats = root.findall("Material/material")
    if len(mats) != 1:
        return problems + [f"{len(mats)} Material/material elements"]
    mat = mats[0]
    if not mat.get("id", "").isdigit():
        problems.append("material id is not a positive integer")

    def numbers(el):
        out = {}
        for child in el:
            if child.tag == "elastic":
                continue
            try:
                out[child.tag] = float(child.text)
            except (TypeError, ValueError):
                problems.append(f"<{child.tag}> of {el.get('type')} is not a number: {child.text!r}")
        return out

    def check(el, nested=False):
        kind = el.get("type")
        if kind not in FEBIO_SCHEMA:
            problems.append(f"unknown FEBio material type {kind!r}")
            return {}
        uncoupled, allowed, required = FEBIO_SCHEMA[kind]
        tags = [c.tag for c in el]
        problems.extend(f"<{t}> is not a parameter of {kind!r}" for t in tags if t not in allowed)
        problems.extend(f"{kind!r} lacks <{t}>" for t in required if t not in tags)
        vals = numbers(el)
        problems.extend(f"<{t}> = {v} is not finite" for t, v in vals.items() if not math.isfinite(v))
        if nested and not uncoupled:
            problems.append(f"the elastic base {kind!r} of 'uncoupled viscoelastic' is not an uncoupled material")
        return vals

    vals = check(mat)
    kind = mat.get("type")
    if kind == "uncoupled viscoelastic":
        base = mat.find("elastic")
        check(base, nested=True)
        gs = {int(t[1:]) for t in vals if t[0] == "g" and t[1:].isdigit() and t != "g0"}
        ts = {int(t[1:]) for t in vals if t[0] == "t" and t[1:].isdigit()}
        if gs != ts:
            problems.append(f"Prony pairs incomplete: g{sorted(gs)} vs t{sorted(ts)}")
        if any(vals[f"t{i}"] <= 0 for i in ts):
            problems.append("a relaxation time t_i is not positive")
        if any(not 0.0 <= vals[f"g{i}"] <= 1.0 for i in gs) or not 0.0 <= vals["g0"] <= 1.0:
            problems.append("a Prony weight lies outside [0, 1]")
        total = vals["g0"] + sum(vals[f"g{i}"] for i in gs)
        if not math.isclose(total, 1.0, rel_tol=1e-6):
            problems.append(f"g0 + sum g_i = {total}, expected 1 (weights relative to the instantaneous modulus)")
        bulk = vals.get("k", 0.0) + numbers(base).get("k", 0.0)
    elif kind == "polynomial":
        bulk = 2.0 * vals.get("D1", 0.0)  # FEBio U = D1 (J-1)^2 + D2 (J-1)^4
    else:
        bulk = vals.get("k", 0.0)
    if not bulk > 0:
        problems.append("no positive bulk modulus (k, or D1 of 'polynomial')")
    for name in ("c1", "G", "Jm", "c10"):
        if name in vals and not vals[name] > 0:
            problems.append(f"<{name}> = {vals[name]} is not positive")
    return problems


def _result(model, params, stderr=None, strain=(0.005, 0.5), rate=(1e-3, 0.1), time=(0.1, 300.0), scope="test"):
    """A FitResult record as the fit writes it (values given, no fitting): the card path's input."""
    names = list(model.param_names)
    se = {n: float((stderr or {}).get(n, 0.01 * abs(params[n]))) for n in names}
    ranges = {"strain_min": strain[0], "strain_max": strain[1], "rate_min_1_per_s": rate[0],
              "rate_max_1_per_s": rate[1], "omega_min_rad_per_s": np.nan, "omega_max_rad_per_s": np.nan,
              "time_min_s": time[0], "time_max_s": time[1]}
    return F.FitResult(model_key=model.name, family=model.family, scope=scope, target="torque", params=dict(params),
                       stderr=se, units={n: "" for n in names}, varying=names, correlation=np.eye(len(names)),
                       flags=[], success=True, message="", chisqr=1.0, redchi=1.0, rmse=1.0, nrmse=0.01, n=50,
                       n_eff=50.0, k=len(names), aic=0.0, aicc=0.0, bic=0.0, aicc_eff=0.0, bic_eff=0.0, nfev=1,
                       n_starts=1, curve_labels=["c"], curve_rmse={}, curve_nrmse={}, residuals=[], ranges=ranges,
                       selection=[{"label": "ramp 0.01/s", "test": "constant_shear_rate"}], structure={})


def _fitted(model, truth, gmax=0.5):
    g = np.linspace(gmax / 30, gmax, 30)
    curve = F.Curve(test="simple_shear", condition="shear", response="elastic_shear", inputs={"shear_strain": g},
                    observed={"shear_stress": model.elastic_shear_stress(truth, g)})
    return F.fit(F.FitProblem(model, [curve], target="none", model_key=model.name), starts=[truth], n_random=0)


# ------------------------------------------------------------------------------------------------
# every card of the bundled brain: a FEBio document that passes the structure test, or a stated reason
# ------------------------------------------------------------------------------------------------
def _brain_cards():
    """Cards of the bundled brain's reference fits (tests/regression/porcine_brain_thesis.csv, the committed
    fitted values and standard errors), built through cards.make_card."""
    table = pd.read_csv(ROOT / "tests" / "regression" / "porcine_brain_thesis.csv")
    nu = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["fem"]["poisson_ratio"]
    out = []
    for (scope, key), rows in table.groupby(["scope", "model"], sort=True):
        # the material baseline's relaxation times are rows of the table (the data chose them)
        times = rows[rows["parameter"].str.startswith(REG.RELAXATION_TIME)]
        rows = rows.drop(times.index)
        model = model_on_times(key, times["value"].to_numpy()) if len(times) else get_model(key)
        params = {**model.default_params(), **dict(zip(rows["parameter"], rows["value"]))}
        stderr = dict(zip(rows["parameter"], rows["stderr"]))
        out.append((scope, key, C.make_card(_result(model, params, stderr, scope=scope), model, poisson_ratio=nu)))
    return out


BRAIN_CARDS = _brain_cards()


@pytest.mark.parametrize("scope,key,card", BRAIN_CARDS, ids=[f"{s}-{k}" for s, k, _ in BRAIN_CARDS])
def test_every_bundled_brain_card_has_a_valid_febio_document_or_a_reason(scope, key, card, tmp_path):
    paths = C.write_card_files(card, tmp_path)
    if card["febio_form"] is None:
        assert "febio" not in paths and card["febio_reason"], f"{key}: no FEBio block and no reason"
        assert any(card["febio_reason"] in n for n in card["notes"]) or card["elastic_law"] is None
        return
    text = paths["febio"].read_text()
    assert check_febio_structure(text) == []
    # the document's material is the fitted model: FEBio's documented energy (febio_reference, not the builder's
    # evaluator) reproduces the fitted model's instantaneous shear stress, and FEBio's documented relaxation
    # function the fitted model's response to an ideal step (small strain)
    model, p = build_model(key, card["structure"]), card["parameters"]
    if card["prony"] is None:
        g = np.linspace(0.01, card["valid_range"]["shear_strain"][1], 20)
        np.testing.assert_allclose(documented_shear_stress(text, g), model.elastic_shear_stress(p, g), rtol=0.01)
        return
    # a linear viscoelastic or fractional model: G(t) of the document (small strain: sigma / gamma of the documented
    # energy times the documented relaxation function) against the model's step response on the card's time window,
    # as close as the card says its Prony series is (its fit_rel_error: exact for a Prony model)
    t = np.r_[0.0, np.geomspace(*card["valid_range"]["time_s"], 200)]
    modulus = np.asarray(model.shear_stress_history(p, t, np.full(t.size, 1e-3)), float)[1:] / 1e-3
    documented = (documented_shear_stress(text, [1e-3])[0] / 1e-3 * documented_relaxation(text, t[1:])
                  / documented_relaxation(text, [0.0])[0])
    rms = np.sqrt(np.mean((documented / modulus - 1) ** 2))
    assert rms <= 1.02 * card["prony"]["fit_rel_error"] + 1e-6, (rms, card["prony"]["fit_rel_error"])


def test_bundled_brain_cards_name_their_reasons():
    """The reasons are those of the FEBio source, by name (not just 'no block')."""
    by_key = {k: c for _, k, c in BRAIN_CARDS}
    material = next(c for s, _, c in BRAIN_CARDS if s == "material")   # the material model: QLV on RP3
    assert material["elastic_law"] == "reduced_polynomial3" and "FEYeoh" in material["febio_reason"]  # RP3 = Yeoh
    assert "FEYeoh" in by_key["reduced_polynomial3"]["febio_reason"]
    nu = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())["fem"]["poisson_ratio"]
    model = get_model("pr_rp3_prony4")   # the nonseparable extension the diagnosis names on the brain
    pr = C.make_card(_result(model, model.default_params(), {n: 0.01 for n in model.param_names},
                             scope="material"), model, poisson_ratio=nu)
    assert "uncoupled reactive viscoelastic" in pr["febio_reason"] and "FEUncoupledReactiveViscoelastic" in \
        pr["febio_reason"] and "recruitment" in pr["febio_reason"]
    assert by_key["prony3"]["febio_form"] == "Mooney-Rivlin" and by_key["prony3"]["prony"]
    assert by_key["neo_hookean"]["febio_form"] == "Mooney-Rivlin"


def test_pipkin_rogers_card_states_its_solver_law_and_why_abaqus_and_febio_have_none(tmp_path):
    """The nonseparable extension's card: the fitted Pipkin-Rogers parameters unchanged in its 'pipkin_rogers' block
    (the TLED law), the small-strain Prony series, no FEBio, Abaqus or NiftySim file and the reason for each, and it
    reads back from disk (Abaqus, FEBio writers on the card read back give the same: nothing)."""
    model = get_model("pr_rp3_prony4")
    params = {"C10": 147.5, "C20": -33.0, "C30": 240.5, "beta_1": 1.39, "beta_2": 0.47, "beta_3": 0.47,
              "beta_4": 0.05, "kappa": 0.54, "gamma_s": 0.122}
    card = C.make_card(_result(model, params), model, poisson_ratio=0.49)
    paths = C.write_card_files(card, tmp_path, stem=model.name)
    assert set(paths) == {"json"}
    read = MaterialCard.from_json(paths["json"])
    pr = read.pipkin_rogers
    assert pr["beta"] == [1.39, 0.47, 0.47, 0.05] and pr["kappa"] == [0.54] * 4 and pr["gamma_s"] == 0.122
    assert "I1bar - 3" in pr["strain_measure"]
    np.testing.assert_allclose(read.prony["g"], np.array(pr["beta"]) / (1 + sum(pr["beta"])))
    assert read.prony["tau"] == [0.1, 1.0, 10.0, 100.0] and read.elastic_law == "reduced_polynomial3"
    assert "UMAT" in read.data["abaqus_reason"] and "TIME=PRONY" in read.data["abaqus_reason"]
    assert "reactive viscoelastic" in read.data["febio_reason"] and "NiftySim" in read.data["niftysim_reason"]
    assert C.abaqus_block(read) is None and C.febio_block(read) is None


def test_the_documented_oracle_fails_on_a_wrong_block():
    """The oracle can fail: a document with c1 doubled (Mooney-Rivlin) or a relaxation time changed is off the
    fitted model by far more than the tolerance."""
    card = next(c for _, k, c in BRAIN_CARDS if k == "prony3")
    text = C.febio_file_text(card)
    model, p = get_model("prony3"), card["parameters"]
    g = np.linspace(0.01, 0.3, 10)
    t = np.r_[0.0, np.geomspace(1e-3, 1e3, 40)]
    step = np.asarray(model.shear_stress_history(p, t, np.full(t.size, 1e-3)), float)
    assert documented_relaxation(text, t) == pytest.approx(step / step[0], rel=1e-9)  # the unbroken block
    root = ET.fromstring(text)
    c1 = root.find("Material/material/elastic/c1")
    c1.text = str(2 * float(c1.text))
    doubled = ET.tostring(root, encoding="unicode")
    elastic = step[0] / 1e-3 * g
    assert np.max(np.abs(documented_shear_stress(doubled, g) / elastic - 1)) > 0.5
    root = ET.fromstring(text)
    t1 = root.find("Material/material/t1")
    t1.text = str(10 * float(t1.text))
    slower = ET.tostring(root, encoding="unicode")
    assert np.max(np.abs(documented_relaxation(slower, t) - step / step[0])) > 0.01


def test_structure_check_catches_a_broken_document():
    """The structure oracle itself fails on documents that break FEBio's structure (a test that can fail)."""
    card = next(c for _, k, c in BRAIN_CARDS if k == "prony3")
    good = C.febio_file_text(card)
    assert check_febio_structure(good) == []
    bad_version = good.replace('version="4.0"', 'version="2.5"')
    assert any("febio_spec 4.0" in p for p in check_febio_structure(bad_version))
    root = ET.fromstring(good)
    mat = root.find("Material/material")
    mat.remove(mat.find("t2"))
    assert any("Prony pairs" in p for p in check_febio_structure(ET.tostring(root, encoding="unicode")))
    wrong_name = good.replace("<c1>", "<C10>").replace("</c1>", "</C10>")
    problems = check_febio_structure(wrong_name)
    assert any("<C10> is not a parameter" in p for p in problems) and any("lacks <c1>" in p for p in problems)


# ------------------------------------------------------------------------------------------------
# conversions, against FEBio's stress forms written out by hand
# ------------------------------------------------------------------------------------------------
def test_gent_card_is_febio_gent_with_the_same_constants():
    model = get_model("gent")
    truth = {"mu": 300.0, "Jm": 2.0}
    card = C.make_card(_fitted(model, truth), model, poisson_ratio=0.45)
    root = ET.fromstring(C.febio_file_text(card))
    mat = root.find("Material/material")
    assert mat.get("type") == "Gent" and check_febio_structure(C.febio_file_text(card)) == []
    G, jm, k = (float(mat.findtext(t)) for t in ("G", "Jm", "k"))
    assert G == pytest.approx(300.0, rel=1e-4) and jm == pytest.approx(2.0, rel=1e-4)
    assert k == pytest.approx(2 * 300.0 * 1.45 / (3 * 0.1), rel=1e-4)  # nu from the caller (config), not 0.49
    # FEGentMaterial::DevStress: W1 = G Jm / (2 (Jm - I1 + 3)), sigma12 = 2 gamma W1, I1 - 3 = gamma^2
    np.testing.assert_allclose(G * jm * GAMMA / (jm - GAMMA ** 2), model.elastic_shear_stress(truth, GAMMA), rtol=1e-3)


def test_polynomial2_card_uses_febio_d1_convention():
    model = get_model("polynomial2")
    truth = {"C10": 40.0, "C01": 15.0, "C20": 60.0, "C11": -10.0, "C02": 20.0}
    card = C.make_card(_fitted(model, truth), model, poisson_ratio=0.49)
    text = C.febio_file_text(card)
    assert check_febio_structure(text) == []
    mat = ET.fromstring(text).find("Material/material")
    assert mat.get("type") == "polynomial"
    c = {t: float(mat.findtext(t)) for t in ("c10", "c01", "c20", "c11", "c02", "D1")}
    # FEBio U = D1 (J-1)^2 -> K = U''(1) = 2 D1 (Abaqus's D1 is 2/K instead)
    assert c["D1"] == pytest.approx(card["bulk_modulus"] / 2, rel=1e-9)
    x = GAMMA ** 2  # FEPolynomialHyperElastic::Stress, W1 and W2 at I1 = I2 = 3 + gamma^2
    w1 = c["c10"] + c["c11"] * x + 2 * x * c["c20"]
    w2 = c["c01"] + c["c11"] * x + 2 * x * c["c02"]
    np.testing.assert_allclose(2 * GAMMA * (w1 + w2), model.elastic_shear_stress(truth, GAMMA), rtol=1e-3)


def test_ogden2_and_mooney_rivlin_conventions():
    model = get_model("ogden2")
    truth = {"mu1": 300.0, "alpha1": 4.0, "mu2": 200.0, "alpha2": -6.0}
    card = C.make_card(_fitted(model, truth), model, poisson_ratio=0.49)
    mat = ET.fromstring(C.febio_file_text(card)).find("Material/material")
    c = {t: float(mat.findtext(t)) for t in ("c1", "m1", "c2", "m2")}
    # FEOgdenMaterial::DevStress: principal stress sum c/m (lambda^m - 1) -> sigma12 = sum c/m (l^m - l^-m)/(l + 1/l)
    lam = GAMMA / 2 + np.sqrt(1 + GAMMA ** 2 / 4)
    s = sum(c[f"c{i}"] / c[f"m{i}"] * (lam ** c[f"m{i}"] - lam ** -c[f"m{i}"]) / (lam + 1 / lam) for i in (1, 2))
    np.testing.assert_allclose(s, model.elastic_shear_stress(truth, GAMMA), rtol=1e-3)
    mr = get_model("mooney_rivlin")
    mr_card = C.make_card(_fitted(mr, {"C10": 60.0, "C01": 20.0}), mr, poisson_ratio=0.49)
    mat = ET.fromstring(C.febio_file_text(mr_card)).find("Material/material")
    assert (float(mat.findtext("c1")), float(mat.findtext("c2"))) == pytest.approx((60.0, 20.0), rel=1e-4)


@pytest.mark.parametrize("key,truth,reason", [
    ("yeoh", {"C10": 40.0, "C20": 100.0, "C30": 400.0}, "FEYeoh"),
    ("arruda_boyce", {"mu": 200.0, "lambda_m": 3.0}, "Arruda-Boyce"),
    ("lopez_pamies2", {"mu1": 300.0, "alpha1": 2.0, "mu2": 100.0, "alpha2": -3.0}, "no native material"),
])
def test_laws_without_a_faithful_febio_form_get_a_reason(key, truth, reason, tmp_path):
    model = get_model(key)
    card = C.make_card(_result(model, truth), model, poisson_ratio=0.49)
    assert card["febio_form"] is None and C.febio_block(card) is None and reason in card["febio_reason"]
    assert "febio" not in C.write_card_files(card, tmp_path)


def test_more_than_six_prony_terms_are_refused():
    prony = {"g": [0.1] * 7, "tau": list(np.geomspace(0.01, 100, 7)), "g_inf": 0.3}
    out = febio_card_material("neo_hookean", {"mu": 100.0}, 1e4, prony, lambda g: 100.0 * g, 0.5)
    assert out["febio_form"] is None and "at most 6" in out["febio_reason"]


# ------------------------------------------------------------------------------------------------
# valid range and uncertainty
# ------------------------------------------------------------------------------------------------
def test_card_lists_the_fitted_strain_range_and_says_what_the_data_did_not_give():
    model = get_model("mooney_rivlin")
    res = _fitted(model, {"C10": 60.0, "C01": 20.0}, gmax=0.3)
    card = C.make_card(res, model, poisson_ratio=0.49)
    vr = card["valid_range"]
    assert vr["shear_strain"] == pytest.approx([0.01, 0.3])  # the fitted curve: gamma = 0.3/30 .. 0.3
    # an elastic simple-shear curve carries no rate, time or frequency: reported missing, not invented
    assert vr["shear_rate_1_per_s"] is None and set(vr["not_given"]) == {"shear_rate_1_per_s", "time_s",
                                                                          "angular_frequency_rad_per_s"}
    assert vr["tests"] == ["simple_shear"]
    assert "shear rate 1/s not given by the data" in C.febio_file_text(card)


def test_uncertainty_propagates_the_covariance_to_the_initial_modulus():
    model = get_model("mooney_rivlin")
    res = _result(model, {"C10": 60.0, "C01": 20.0}, {"C10": 3.0, "C01": 4.0})
    res = dataclasses.replace(res, correlation=np.array([[1.0, -0.5], [-0.5, 1.0]]))
    unc = C.make_card(res, model, poisson_ratio=0.49)["uncertainty"]
    assert unc["standard_errors"] == {"C10": 3.0, "C01": 4.0}
    assert unc["relative_standard_errors"]["C01"] == pytest.approx(0.2)
    # mu0 = 2 (C10 + C01): var = 4 (s1^2 + s2^2 + 2 rho s1 s2)
    assert unc["initial_shear_modulus_stderr"] == pytest.approx(2 * math.sqrt(9 + 16 - 2 * 0.5 * 12), rel=1e-4)
    nan_res = dataclasses.replace(res, stderr={"C10": float("nan"), "C01": 4.0})
    nan_unc = C.make_card(nan_res, model, poisson_ratio=0.49)["uncertainty"]
    assert nan_unc["not_determined"] == ["C10"] and nan_unc["initial_shear_modulus_stderr"] is None

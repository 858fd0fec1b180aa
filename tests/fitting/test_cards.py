"""Material cards: JSON shape, Abaqus/FEBio syntax and conventions, and the round trip card -> material law
(single material point in simple shear) -> the fitted curve within 1 %."""
from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from doubles import ProxyLopezPamies, ProxyMooneyRivlin, ProxyOgden, ProxyProny, ProxyReducedPolynomial
from febio_reference import documented_shear_stress

from tissuemech import cards as C
from tissuemech import fitting as F
from tissuemech.fem import materials as mats
from tissuemech.models.qlv import QLVModel, qlv_params
from tissuemech.models.registry import get_model

GAMMA = np.linspace(0.01, 0.5, 25)
G_PRONY = [0.10, 0.23, 0.21, 0.14]


def fitted(model, truth, key, gmax=0.5):
    """A FitResult of ``model`` on its own noise-free simple-shear curve (the card's 'fitted curve')."""
    g = np.linspace(gmax / 30, gmax, 30)
    curve = F.Curve(test="simple_shear", condition="shear", response="elastic_shear", inputs={"shear_strain": g},
                    observed={"shear_stress": model.elastic_shear_stress(truth, g)})
    return F.fit(F.FitProblem(model, [curve], target="none", model_key=key), starts=[truth], n_random=0)


def fitted_qlv(model, truth, key, gmax=0.5):
    t = np.linspace(0, gmax / 0.01, 41)
    g = 0.01 * t
    curve = F.Curve(test="constant_shear_rate", condition="rate=0.01/s", response="shear_history",
                    inputs={"time": t, "shear_strain": g}, observed={"shear_stress": model.shear_stress_history(truth, t, g)[1:]},
                    obs_index=np.arange(1, 41), nominal={"shear_rate_1_per_s": 0.01})
    return F.fit(F.FitProblem(model, [curve], target="none", model_key=key), starts=[truth], n_random=0)


def fem_simple_shear(card, gamma):
    """Cauchy shear stress of the card's law in the project's FEM material routine (one material point,
    homogeneous simple shear, nearly incompressible)."""
    assert card["elastic_law"] in mats.available_laws(), f"FEM has no law {card['elastic_law']!r}"
    mat = mats.make_material(card["elastic_law"], card["elastic_parameters"], bulk_modulus_pa=card["bulk_modulus"])
    out = []
    for g in gamma:
        F_ = np.eye(3)
        F_[0, 1] = g
        out.append(mats.cauchy_stress(mat, F_)[0, 1])
    return np.array(out)


# ------------------------------------------------------------------------------------------------
# independent oracle of an Abaqus block: the strain energy of the Abaqus manual's form along the
# incompressible simple-shear path, differentiated numerically, sigma_12 = dW/dgamma. It shares nothing with
# cards.abaqus_simple_shear_stress (which the card builder uses for its own self-check and which evaluates
# closed-form derivatives): its own parsing, the energies W rather than their derivatives.
# ------------------------------------------------------------------------------------------------
def _abaqus_sections(block: str) -> dict[str, list[float]]:
    sections: dict[str, list[float]] = {}
    key = None
    for line in block.splitlines():
        line = line.strip()
        if not line or line.startswith("**"):
            continue
        if line.startswith("*"):
            key = line.upper()
            sections[key] = []
        else:
            sections[key] += [float(v) for v in line.split(",") if v.strip()]
    return sections


def _shear_stretch(gamma):
    """Largest principal stretch of simple shear (the others are 1/lambda and 1)."""
    return gamma / 2.0 + np.sqrt(1.0 + gamma ** 2 / 4.0)


def _abaqus_energy(block: str):
    """``W(gamma)`` (Pa) of the block's hyperelastic form in incompressible simple shear (I1 = I2 = 3 + gamma^2)."""
    sections = _abaqus_sections(block)
    option = next(k for k in sections if k.startswith("*HYPERELASTIC"))
    c = sections[option]
    n = int(re.search(r"N=(\d+)", option).group(1)) if "N=" in option else 1
    if "MARLOW" in option:
        table = np.array(sections["*UNIAXIAL TEST DATA"]).reshape(-1, 2)
        nominal_stress, nominal_strain = table[:, 0], table[:, 1]
        # W of the uniaxial test at stretch lambda_u: the integral of the (piecewise linear) nominal stress
        w_nodes = np.r_[0.0, np.cumsum(np.diff(nominal_strain) * (nominal_stress[1:] + nominal_stress[:-1]) / 2)]

        def energy(gamma):
            i1 = 3.0 + gamma ** 2
            # uniaxial stretch with the same I1: lambda^2 + 2/lambda = I1, lambda >= 1
            lam = np.array([max(np.roots([1.0, 0.0, -v, 2.0]).real) for v in np.atleast_1d(i1)])
            e = lam - 1.0
            k = np.clip(np.searchsorted(nominal_strain, e) - 1, 0, len(nominal_strain) - 2)
            slope = (nominal_stress[k + 1] - nominal_stress[k]) / (nominal_strain[k + 1] - nominal_strain[k])
            de = e - nominal_strain[k]
            return w_nodes[k] + nominal_stress[k] * de + slope * de ** 2 / 2
        return energy
    if "OGDEN" in option:
        mu, alpha = np.array(c[0:2 * n:2]), np.array(c[1:2 * n:2])

        def energy(gamma):
            lam = _shear_stretch(np.asarray(gamma, float))[..., None]
            return np.sum(2 * mu / alpha ** 2 * (lam ** alpha + lam ** -alpha + 1.0 - 3.0), axis=-1)
        return energy
    if "NEO HOOKE" in option:
        terms = {(1, 0): c[0]}
    elif "MOONEY-RIVLIN" in option:
        terms = {(1, 0): c[0], (0, 1): c[1]}
    elif "REDUCED POLYNOMIAL" in option:
        terms = {(i, 0): c[i - 1] for i in range(1, n + 1)}
    elif "POLYNOMIAL" in option:
        # data order C10, C01, C20, C11, C02, C30, ... (Abaqus manual, "Polynomial form")
        order = [(t - j, j) for t in range(1, n + 1) for j in range(t + 1)]
        terms = dict(zip(order, c))
    else:
        raise AssertionError(f"no oracle for {option}")

    def energy(gamma):
        x = np.asarray(gamma, float) ** 2          # I1 - 3 = I2 - 3
        return sum(cij * x ** i * x ** j for (i, j), cij in terms.items())
    return energy


def abaqus_shear_oracle(block: str, gamma: np.ndarray) -> np.ndarray:
    """sigma_12 = dW/dgamma of the block's energy (central difference)."""
    energy = _abaqus_energy(block)
    g = np.asarray(gamma, float)
    h = 1e-5 * np.maximum(g, 1e-3)
    return (energy(g + h) - energy(g - h)) / (2 * h)


def test_shear_oracle_on_known_energies():
    """The oracle itself: neo-Hooke 2 C10 gamma; Ogden with alpha = 2 is neo-Hooke with C10 = mu/2."""
    g = np.array([0.01, 0.3, 1.0])
    neo = "*MATERIAL, NAME=A\n*HYPERELASTIC, NEO HOOKE\n50., 0.001\n"
    np.testing.assert_allclose(abaqus_shear_oracle(neo, g), 100.0 * g, rtol=1e-7)
    ogden = "*MATERIAL, NAME=B\n*HYPERELASTIC, OGDEN, N=1\n100., 2., 0.001\n"
    np.testing.assert_allclose(abaqus_shear_oracle(ogden, g), 100.0 * g, rtol=1e-7)


# ------------------------------------------------------------------------------------------------
def test_qlv_card_shape_prony_normalisation_and_abaqus_syntax():
    qlv = get_model("qlv_linear_prony4")
    truth = qlv_params(qlv, {"G0": 200.0}, G_PRONY)
    res = fitted_qlv(qlv, truth, "qlv_linear_prony4")
    card = C.make_card(res, qlv, dataset="demo", poisson_ratio=0.49)
    data = json.loads(C.card_json(card))
    for key in ("model", "family", "parameters", "units", "prony", "poisson_ratio", "validity", "provenance",
                "fit_quality", "elastic_law", "bulk_modulus"):
        assert key in data
    assert data["model"] == "qlv_linear_prony4" and data["poisson_ratio"] == 0.49
    np.testing.assert_allclose(data["prony"]["g"], G_PRONY, rtol=1e-6)
    assert data["prony"]["g_inf"] == pytest.approx(1 - sum(G_PRONY))
    mu0 = 200.0
    assert data["initial_shear_modulus"] == pytest.approx(mu0, rel=1e-6)
    assert data["bulk_modulus"] == pytest.approx(2 * mu0 * 1.49 / (3 * 0.02), rel=1e-6)

    block = C.abaqus_block(card)
    parsed = C.parse_abaqus_block(block)
    keys = list(parsed)
    assert keys[0].startswith("*MATERIAL, NAME=QLV_LINEAR_PRONY4")
    assert keys[1] == "*HYPERELASTIC, NEO HOOKE, MODULI=INSTANTANEOUS"
    c10, d1 = parsed[keys[1]][0]
    assert c10 == pytest.approx(mu0 / 2) and d1 == pytest.approx(2 / data["bulk_modulus"])
    assert keys[2] == "*VISCOELASTIC, TIME=PRONY"
    rows = np.array(parsed[keys[2]])
    np.testing.assert_allclose(rows[:, 0], G_PRONY, rtol=1e-6)  # g_i relative to the instantaneous modulus
    assert np.all(rows[:, 1] == 0.0)  # shear-only relaxation: k_i = 0
    np.testing.assert_allclose(rows[:, 2], qlv.taus(truth))

    # FEBio: S = g0 S_e + sum g_i H_i with the instantaneous law as base
    root = ET.fromstring(C.febio_block(card))
    assert root.get("type") == "uncoupled viscoelastic"
    assert float(root.findtext("g0")) == pytest.approx(1 - sum(G_PRONY))
    assert float(root.findtext("g2")) == pytest.approx(0.23) and float(root.findtext("t4")) == pytest.approx(100.0)
    el = root.find("elastic")
    assert el.get("type") == "Mooney-Rivlin" and float(el.findtext("c1")) == pytest.approx(100.0)
    assert float(el.findtext("c2")) == 0.0
    # the project's FEM routine evaluates the same instantaneous law
    assert data["elastic_law"] == "neo_hookean"
    np.testing.assert_allclose(fem_simple_shear(card, GAMMA), mu0 * GAMMA, rtol=0.01)


@pytest.mark.parametrize("make,truth,form", [
    (lambda: ProxyReducedPolynomial(order=3), {"C10": 40.0, "C20": 100.0, "C30": 400.0}, "REDUCED POLYNOMIAL, N=3"),
    (ProxyMooneyRivlin, {"C10": 60.0, "C01": 20.0}, "MOONEY-RIVLIN"),
    (ProxyOgden, {"mu1": 600.0, "alpha1": -12.0}, "OGDEN, N=1"),
    (ProxyLopezPamies, {"mu1": 500.0, "alpha1": 3.0}, "MARLOW"),
])
def test_round_trip_card_law_matches_fitted_curve(make, truth, form):
    model = make()
    res = fitted(model, truth, model.name)
    card = C.make_card(res, model, poisson_ratio=0.49)
    assert card["abaqus_form"] == form
    fitted_curve = model.elastic_shear_stress(res.params, GAMMA)
    block = C.abaqus_block(card)
    # the Abaqus energy form with the card's constants (the test's own oracle, not the builder's check)
    np.testing.assert_allclose(abaqus_shear_oracle(block, GAMMA), fitted_curve, rtol=0.01)
    # the builder's own self-check evaluator agrees with the oracle (Marlow: two interpolations of one table)
    np.testing.assert_allclose(C.abaqus_simple_shear_stress(block, GAMMA), abaqus_shear_oracle(block, GAMMA), rtol=0.01)
    fb = C.febio_block(card)
    if fb is not None:  # FEBio's documented energy (febio_reference), not the builder's own evaluator
        np.testing.assert_allclose(documented_shear_stress(fb, GAMMA), fitted_curve, rtol=0.01)
    # the project's FEM material routine (single material point, simple shear)
    np.testing.assert_allclose(fem_simple_shear(card, GAMMA), fitted_curve, rtol=0.01)


def test_ogden_conventions_in_abaqus_and_febio():
    model = ProxyOgden()
    truth = {"mu1": 600.0, "alpha1": -12.0}
    card = C.make_card(fitted(model, truth, "ogden1"), model, poisson_ratio=0.49)
    parsed = C.parse_abaqus_block(C.abaqus_block(card))
    mu, alpha, d1 = parsed["*HYPERELASTIC, OGDEN, N=1"][0]
    assert mu == pytest.approx(600.0, rel=1e-4) and alpha == pytest.approx(-12.0, rel=1e-4)
    root = ET.fromstring(C.febio_block(card))
    assert root.get("type") == "Ogden"
    assert float(root.findtext("c1")) == pytest.approx(1200.0, rel=1e-4)  # c = 2 mu (FEBio W = c/m^2 (...))
    assert card["initial_shear_modulus"] == pytest.approx(600.0, rel=1e-4)


def test_marlow_table_is_uniaxial_and_covers_the_validity_range():
    model = ProxyLopezPamies()
    card = C.make_card(fitted(model, {"mu1": 500.0, "alpha1": 3.0}, "lopez_pamies1"), model, poisson_ratio=0.49)
    parsed = C.parse_abaqus_block(C.abaqus_block(card))
    assert "*HYPERELASTIC, MARLOW, POISSON=0.49" in parsed and parsed["*HYPERELASTIC, MARLOW, POISSON=0.49"] == []
    stress, strain = np.array(parsed["*UNIAXIAL TEST DATA"]).T
    assert stress[0] == 0 and strain[0] == 0 and np.all(np.diff(strain) > 0) and np.all(np.diff(stress) > 0)
    lam = 1 + strain[-1]
    assert lam ** 2 + 2 / lam - 3 >= (0.5 * 1.2) ** 2 - 1e-9  # I1 range of simple shear up to 1.2 x gamma_max
    assert C.febio_block(card) is None and any("MARLOW" in n for n in card["notes"])


def test_linear_viscoelastic_card_prony_from_step_response():
    model = ProxyProny()
    truth = {"G_inf": 81.4, "G_1": 30.0, "G_2": 46.9, "G_3": 42.7, "G_4": 28.9}
    t = np.r_[0.0, np.geomspace(0.01, 300, 60)]
    g = np.full(t.size, 0.01)
    curve = F.Curve(test="stress_relaxation", condition="strain=1%", response="shear_history",
                    inputs={"time": t, "shear_strain": g}, observed={"shear_stress": model.shear_stress_history(truth, t, g)[1:]},
                    obs_index=np.arange(1, t.size))
    res = F.fit(F.FitProblem(model, [curve], target="none", model_key="prony4"), starts=[truth], n_random=0)
    card = C.make_card(res, model, poisson_ratio=0.49)
    g0 = sum(truth.values())
    assert card["initial_shear_modulus"] == pytest.approx(g0, rel=1e-3)
    np.testing.assert_allclose(card["prony"]["g"], np.array(list(truth.values())[1:]) / g0, atol=1e-3)
    assert card["prony"]["fit_rel_error"] < 1e-3
    parsed = C.parse_abaqus_block(C.abaqus_block(card))
    assert "*HYPERELASTIC, NEO HOOKE, MODULI=INSTANTANEOUS" in parsed


def test_write_card_files(tmp_path):
    qlv = get_model("qlv_linear_prony4")
    truth = qlv_params(qlv, {"G0": 200.0}, G_PRONY)
    card = C.make_card(fitted_qlv(qlv, truth, "qlv_linear_prony4"), qlv, poisson_ratio=0.49)
    paths = C.write_card_files(card, tmp_path / "cards")
    # a linear QLV card's law is neo-Hookean (mu = G0): NiftySim NHV with the four Prony terms as well
    assert set(paths) == {"json", "abaqus", "febio", "niftysim"}
    assert json.loads(paths["json"].read_text())["model"] == "qlv_linear_prony4"
    assert 'NumIsoTerms="4"' in paths["niftysim"].read_text() and card["niftysim_reason"] is None
    assert paths["abaqus"].read_text().count("*") >= 3


def test_pipkin_rogers_card_has_a_solver_law_but_no_fe_block_and_says_why():
    """Pipkin-Rogers: the TLED law in the card (instantaneous law, small-strain Prony series, 'pipkin_rogers'), no
    Abaqus/FEBio/NiftySim block, each with its reason; another beyond-QLV law (Schapery) has no solid law at all."""
    key = "pr_linear_prony4"
    model = get_model(key)
    p = {**model.default_params(), "kappa": 0.8}
    res = fitted_qlv(model, p, key)
    card = C.make_card(res, model, poisson_ratio=0.49)
    assert card["elastic_law"] == "neo_hookean" and card["pipkin_rogers"]["kappa"] == [pytest.approx(0.8)] * 4
    assert C.abaqus_block(card) is None and C.febio_block(card) is None
    assert any("user material" in n for n in card["notes"]) and "UMAT" in card["abaqus_reason"]
    assert "beyond-QLV" in card["niftysim_reason"]  # and no NiftySim element, with the reason stated
    schapery = get_model("schapery_prony4")
    s_card = C.make_card(fitted_qlv(schapery, schapery.default_params(), "schapery_prony4"), schapery,
                         poisson_ratio=0.49)
    assert s_card["elastic_law"] is None and s_card["pipkin_rogers"] is None
    assert "no TLED law" in s_card["abaqus_reason"]


@pytest.mark.parametrize("which", ["marlow", "native", "qlv"])
def test_abaqus_block_of_a_card_read_back_from_disk_is_the_written_one(which, tmp_path):
    """Every format is written from the card's content alone: the Abaqus (and FEBio) text of the card read back
    through records.MaterialCard equals the one of the card as built (a MARLOW card carries its table)."""
    from tissuemech.records import MaterialCard

    if which == "marlow":
        model = ProxyLopezPamies()
        card = C.make_card(fitted(model, {"mu1": 500.0, "alpha1": 3.0}, "lopez_pamies1"), model, poisson_ratio=0.49)
    elif which == "native":
        model = ProxyMooneyRivlin()
        card = C.make_card(fitted(model, {"C10": 60.0, "C01": 20.0}, "mooney_rivlin"), model, poisson_ratio=0.49)
    else:
        model = get_model("qlv_linear_prony4")
        card = C.make_card(fitted_qlv(model, qlv_params(model, {"G0": 200.0}, G_PRONY), "qlv_linear_prony4"), model,
                           poisson_ratio=0.49)
    paths = C.write_card_files(card, tmp_path)
    read = MaterialCard.from_json(paths["json"])
    assert C.abaqus_block(read) == C.abaqus_block(card) == paths["abaqus"].read_text() is not None
    assert C.febio_block(read) == C.febio_block(card)
    if which == "marlow":
        assert len(read.data["abaqus_marlow_table"]["nominal_strain"]) == C.MARLOW_POINTS


def test_qlv_with_nonlinear_law_round_trip():
    model = QLVModel(ProxyReducedPolynomial(order=3), 4, name="qlv_rp3_prony4")
    truth = qlv_params(model, {"C10": 40.0, "C20": 100.0, "C30": 400.0}, G_PRONY)
    card = C.make_card(fitted_qlv(model, truth, "qlv_rp3_prony4"), model, poisson_ratio=0.49)
    block = C.abaqus_block(card)
    assert "*HYPERELASTIC, REDUCED POLYNOMIAL, N=3, MODULI=INSTANTANEOUS" in block
    np.testing.assert_allclose(abaqus_shear_oracle(block, GAMMA), model.elastic_shear_stress(truth, GAMMA),
                               rtol=0.01)


def test_prony_from_complex_modulus_recovers_a_prony_spectrum():
    model = ProxyProny()
    truth = {"G_inf": 81.4, "G_1": 30.0, "G_2": 46.9, "G_3": 42.7, "G_4": 28.9}
    pr = C.prony_from_complex_modulus(model, truth, np.array(model.taus), 1e-3, 1e2)
    g0 = sum(truth.values())
    assert pr["G0"] == pytest.approx(g0, rel=1e-3) and pr["fit_rel_error"] < 1e-3
    np.testing.assert_allclose(pr["g"], np.array(list(truth.values())[1:]) / g0, atol=1e-3)


def test_classical_ogden_convention_is_converted_and_checked():
    """A law written as W = mu/alpha (sum l^alpha - 3) (classical form) must reach Abaqus as mu alpha/2."""

    class ClassicalOgden(ProxyOgden):
        def elastic_shear_stress(self, p, strain):
            g = np.asarray(strain, float)
            lam = g / 2 + np.sqrt(1 + g ** 2 / 4)
            a = p["alpha1"]
            return p["mu1"] * (lam ** a - lam ** -a) / (lam + 1 / lam)

    model = ClassicalOgden()
    truth = {"mu1": 100.0, "alpha1": -12.0}
    card = C.make_card(fitted(model, truth, "ogden1"), model, poisson_ratio=0.49)
    mu, alpha = card["abaqus_constants"]
    assert card["abaqus_form"] == "OGDEN, N=1" and mu == pytest.approx(100.0 * -12.0 / 2, rel=1e-4)
    assert any("do not reproduce" in n for n in card["notes"])
    np.testing.assert_allclose(abaqus_shear_oracle(C.abaqus_block(card), GAMMA),
                               model.elastic_shear_stress(truth, GAMMA), rtol=0.01)


# ------------------------------------------------------------------------------------------------
# laws added with issue 4: Nunes, Amin, full polynomial N = 3..6, generalized Kelvin-Voigt
# ------------------------------------------------------------------------------------------------
POLY3 = {"C10": 40.0, "C01": 15.0, "C20": 60.0, "C11": -10.0, "C02": 20.0, "C30": 50.0, "C21": 10.0, "C12": -5.0,
         "C03": 8.0}


def _poly6_truth():
    names = [f"C{t - j}{j}" for t in range(1, 7) for j in range(t + 1)]
    return {n: (40.0 if n == "C10" else 15.0 if n == "C01" else 30.0 / (int(n[1]) + int(n[2])) ** 2) for n in names}


@pytest.mark.parametrize("key,truth,form", [
    ("nunes", {"C1": 60.0, "C2": 15.0}, "MARLOW"),
    ("amin", {"C5": 60.0, "C3": 40.0, "C4": 300.0, "C2": 15.0, "N": 1.0, "M": 3.0}, "MARLOW"),
    ("polynomial3", POLY3, "POLYNOMIAL, N=3"),
    ("polynomial6", _poly6_truth(), "POLYNOMIAL, N=6"),
])
def test_round_trip_cards_of_the_new_hyperelastic_laws(key, truth, form):
    model = get_model(key)
    res = fitted(model, truth, key)
    card = C.make_card(res, model, poisson_ratio=0.49)
    assert card["abaqus_form"] == form and card["elastic_law"] == key
    fitted_curve = model.elastic_shear_stress(res.params, GAMMA)
    block = C.abaqus_block(card)
    np.testing.assert_allclose(abaqus_shear_oracle(block, GAMMA), fitted_curve, rtol=0.01)
    # the builder's own self-check evaluator agrees with the oracle (Marlow: two interpolations of one table)
    np.testing.assert_allclose(C.abaqus_simple_shear_stress(block, GAMMA), abaqus_shear_oracle(block, GAMMA), rtol=0.01)
    # no FEBio material for these forms: no block, and the card says why
    assert C.febio_block(card) is None and any("no FEBio block" in n for n in card["notes"])
    np.testing.assert_allclose(fem_simple_shear(card, GAMMA), fitted_curve, rtol=0.01)


def test_polynomial_card_writes_the_constants_in_abaqus_order():
    model = get_model("polynomial3")
    card = C.make_card(fitted(model, POLY3, "polynomial3"), model, poisson_ratio=0.49)
    parsed = C.parse_abaqus_block(C.abaqus_block(card))
    values = [v for row in parsed["*HYPERELASTIC, POLYNOMIAL, N=3"] for v in row]
    # Abaqus data lines: C10, C01, C20, C11, C02, C30, C21, C12 / C03, D1, D2, D3
    expected = [40.0, 15.0, 60.0, -10.0, 20.0, 50.0, 10.0, -5.0, 8.0, 2 / card["bulk_modulus"], 0.0, 0.0]
    np.testing.assert_allclose(values, expected, rtol=1e-6)
    assert [len(row) for row in parsed["*HYPERELASTIC, POLYNOMIAL, N=3"]] == [8, 4]
    assert card["initial_shear_modulus"] == pytest.approx(2 * (40.0 + 15.0), rel=1e-6)


def test_nunes_card_has_no_finite_initial_modulus_and_a_log_spaced_marlow_table():
    model = get_model("nunes")
    card = C.make_card(fitted(model, {"C1": 60.0, "C2": 15.0}, "nunes"), model, poisson_ratio=0.49)
    gamma_ref = 0.5 / 20
    assert card["initial_shear_modulus"] == pytest.approx(2 * 60.0 + 2 * 15.0 / np.sqrt(gamma_ref), rel=1e-9)
    assert any("unbounded initial tangent modulus" in n for n in card["notes"])
    assert card["bulk_modulus"] == pytest.approx(2 * card["initial_shear_modulus"] * 1.49 / (3 * 0.02), rel=1e-9)
    stress, strain = np.array(C.parse_abaqus_block(C.abaqus_block(card))["*UNIAXIAL TEST DATA"]).T
    assert np.all(np.diff(strain) > 0) and np.all(np.diff(stress) > 0)
    # three decades of nominal strain resolve the square-root start
    assert strain[1] == pytest.approx(1e-3 * strain[-1], rel=1e-9)
    # an ordinary law keeps its secant-free initial modulus and the linear table
    rp = get_model("reduced_polynomial3")
    rp_card = C.make_card(fitted(rp, {"C10": 40.0, "C20": 100.0, "C30": 400.0}, "reduced_polynomial3"), rp,
                          poisson_ratio=0.49)
    assert rp_card["initial_shear_modulus"] == pytest.approx(80.0, rel=1e-6)
    assert "marlow_spacing" not in rp_card["validity"]


def _without_strain_range(result):
    """The same fit as if its data gave no strain range (a sweep or a relaxation modulus)."""
    result.ranges = {k: v for k, v in result.ranges.items() if k != "strain_max"}
    return result


def test_a_card_without_a_fitted_strain_range_states_no_strain_validity():
    model = get_model("neo_hookean")
    card = C.make_card(_without_strain_range(fitted(model, {"mu": 500.0}, "neo_hookean")), model, poisson_ratio=0.49)
    assert card["validity"]["marlow_strain_max"] is None
    assert any("no strain range" in n and f"gamma = {C.CONVERSION_CHECK_STRAIN_MAX:g}" in n for n in card["notes"])
    # the conversion is still checked and written (neo-Hookean has a native form in both codes)
    assert card["abaqus_form"] == "NEO HOOKE" and card["abaqus_check_max_rel_error"] < 1e-6
    assert card["initial_shear_modulus"] == pytest.approx(500.0, rel=1e-9)


def test_a_law_without_a_native_form_and_without_a_strain_range_gets_no_marlow_table():
    model = get_model("nunes")   # unbounded initial tangent, no native Abaqus form
    card = C.make_card(_without_strain_range(fitted(model, {"C1": 60.0, "C2": 15.0}, "nunes")), model,
                       poisson_ratio=0.49)
    assert card["abaqus_form"] is None and C.abaqus_block(card) is None
    assert np.isnan(card["initial_shear_modulus"]) and np.isnan(card["bulk_modulus"])
    assert any("no secant modulus" in n for n in card["notes"])
    assert any("no fitted strain range for a MARLOW table" in n for n in card["notes"])


def test_a_spectrum_model_without_a_time_or_frequency_window_gets_no_prony_series():
    model = get_model("fractional_zener")
    p = {spec.name: spec.init for spec in model.param_specs}
    law, lp, prony, notes = C.family_material(model, p, {})
    assert law is None and prony is None and lp == {}
    assert any("no time or frequency window" in n for n in notes)
    # with the window of a sweep it has both
    law, _, prony, _ = C.family_material(model, p, {"omega_min_rad_per_s": 0.1, "omega_max_rad_per_s": 100.0})
    assert law is not None and len(prony["g"]) > 0 and "over [0.01, 10] s" in prony["source"]   # 1/omega


def test_gkv_card_prony_series_is_the_exact_relaxation_spectrum():
    model = get_model("gkv3")
    truth = {"G0": 800.0, "G_1": 300.0, "G_2": 150.0, "G_3": 400.0, "tau_ret_1": 0.05, "tau_ret_2": 2.0,
             "tau_ret_3": 80.0}
    t = np.r_[0.0, np.geomspace(0.005, 500.0, 80)]
    stress = np.full_like(t, 5.0)
    curve = F.Curve(test="creep_recovery", condition="5 Pa", response="creep", inputs={"time": t, "shear_stress": stress},
                    observed={"shear_strain": model.creep_strain(truth, t, stress)})
    res = F.fit(F.FitProblem(model, [curve], target="none", model_key="gkv3"), starts=[truth], n_random=0)
    card = C.make_card(res, model, poisson_ratio=0.49)
    assert card["initial_shear_modulus"] == pytest.approx(800.0, rel=1e-6)
    assert card["prony"]["fit_rel_error"] == 0.0 and "Kelvin-Voigt" in card["prony"]["source"]
    parsed = C.parse_abaqus_block(C.abaqus_block(card))
    (c10, d1), = parsed["*HYPERELASTIC, NEO HOOKE, MODULI=INSTANTANEOUS"]
    assert c10 == pytest.approx(400.0, rel=1e-6)
    rows = np.array(parsed["*VISCOELASTIC, TIME=PRONY"])
    assert rows.shape == (3, 3) and np.all(rows[:, 1] == 0.0)
    g, tau = rows[:, 0], rows[:, 2]
    # independent check: the card's G*(omega) = 2 C10 (1 - sum g_i + sum g_i i w tau_i/(1 + i w tau_i)) inverts the
    # Kelvin-Voigt complex compliance J*(omega) = 1/G0 + sum 1/(G_i (1 + i w tau_ret_i))
    w = np.geomspace(1e-4, 1e4, 41)
    g_star = 2 * c10 * (1 - g.sum() + np.sum(g * (1j * w[:, None] * tau) / (1 + 1j * w[:, None] * tau), axis=1))
    gv = np.array([300.0, 150.0, 400.0])
    j_star = 1 / 800.0 + np.sum(1 / (gv * (1 + 1j * w[:, None] * np.array([0.05, 2.0, 80.0]))), axis=1)
    np.testing.assert_allclose(g_star * j_star, 1.0, atol=1e-6)
    # long-term modulus: the springs in series
    assert 2 * c10 * (1 - g.sum()) == pytest.approx(1 / (1 / 800.0 + np.sum(1 / gv)), rel=1e-6)
    root = ET.fromstring(C.febio_block(card))
    assert root.get("type") == "uncoupled viscoelastic"
    assert float(root.findtext("g0")) == pytest.approx(1 - g.sum(), rel=1e-6) and root.find("g4") is None
    np.testing.assert_allclose(fem_simple_shear(card, GAMMA), 800.0 * GAMMA, rtol=0.01)

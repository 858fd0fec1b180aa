"""The JSON card as the TLED solver's input format (issue 16 item 4): a QLV card written to disk by
``cards.write_card_files`` and read back is the material the solver runs, and one sheared element driven by a
ramp-and-hold reproduces the fitted model's 1-D stress history (small strain) -- fit -> file -> FEM, no shortcut."""
from __future__ import annotations

import json

import numpy as np
import pytest
from test_verification import L, _shear_cube

from tissuemech import cards as C
from tissuemech.fem.experiments import card_material
from tissuemech.fem.tled import solve_quasistatic


def test_qlv_card_file_round_trip_through_the_solver(tmp_path, qlv_rp3_fit):
    model, result = qlv_rp3_fit
    key = result.model_key
    paths = C.write_card_files(C.make_card(result, model, poisson_ratio=0.49), tmp_path, stem=key)
    card = json.loads(paths["json"].read_text())  # what an FE user (or the TLED engine) gets
    assert card["elastic_law"] == "reduced_polynomial3" and len(card["prony"]["g"]) == 4
    assert card["valid_range"] and card["uncertainty"]
    material = card_material(card)
    # ramp to 1 % in 0.2 s, hold 40 s: small strain, where the 3-D element and the 1-D model agree
    t = np.concatenate([[0.0], np.linspace(0.05, 0.2, 4), 0.2 + np.array([0.05, 0.3, 1.0, 3.0, 10.0, 40.0])])
    gamma = np.minimum(t / 0.2, 1.0) * 0.01
    res = solve_quasistatic(_shear_cube(material, t, gamma), t[1:], tol_m=1e-14)
    fx = res.reaction_force_n["top"][:, 0] / L**2
    one_d = model.shear_stress_history(result.params, t, gamma)[1:]
    np.testing.assert_allclose(fx, one_d, rtol=5e-4)
    assert fx[-1] < 0.6 * fx[3]  # it relaxed, as the card's Prony series says


def _ramp_hold_stress(mu, g_inf, g, tau, t, t_ramp, gamma_max):
    """Independent oracle: small-strain Boltzmann integral of a ramp (rate gamma_max / t_ramp) and hold with
    G(t) = mu (g_inf + sum g_i exp(-t / tau_i)), in closed form."""
    rate = gamma_max / t_ramp
    t = np.asarray(t, float)
    te = np.minimum(t, t_ramp)  # the strain rate is non-zero on [0, te]
    out = g_inf * (rate * te)
    for gi, ti in zip(g, tau):
        out = out + gi * rate * ti * (np.exp(-(t - te) / ti) - np.exp(-t / ti))
    return mu * out


def test_niftysim_card_round_trip_through_the_solver(tmp_path):
    """A neo-Hookean QLV card written as a NiftySim NHV element (cards.write_card_files) and read back
    (cards_niftysim.read_niftysim_material) is the same material for the TLED solver: one sheared element driven by a
    ramp and hold gives the same stress from both cards, and both follow the closed-form Boltzmann integral of the
    card's relaxation function (small strain). A reduced-polynomial card gets no file and says why."""
    from tissuemech.cards_niftysim import niftysim_reason, read_niftysim_material
    from tissuemech.models.registry import get_model

    prony = {"g": [0.3, 0.2], "tau": [0.5, 5.0], "g_inf": 0.5}
    fields, _, _ = C.material_fields(get_model("neo_hookean"), {"mu": 300.0}, 0.49, prony, 0.5)
    card = {"model": "qlv_nh_demo", **fields, "valid_range": {"shear_strain": [0.0, 0.5]}}
    assert niftysim_reason(card) is None
    paths = C.write_card_files(card, tmp_path, stem="qlv_nh_demo")
    text = paths["niftysim"].read_text()
    assert 'Type="NHV"' in text and 'NumIsoTerms="2"' in text
    back = read_niftysim_material(text)
    assert back["elastic_parameters"]["mu"] == pytest.approx(card["elastic_parameters"]["mu"], rel=1e-9)
    assert back["bulk_modulus"] == pytest.approx(card["bulk_modulus"], rel=1e-9)
    np.testing.assert_allclose(back["prony"]["g"], card["prony"]["g"], rtol=1e-9)
    np.testing.assert_allclose(back["prony"]["tau"], card["prony"]["tau"], rtol=1e-9)
    t_ramp, gamma_max = 0.2, 0.01
    t = np.concatenate([[0.0], np.linspace(0.05, t_ramp, 4), t_ramp + np.array([0.05, 0.3, 1.0, 3.0, 10.0, 40.0])])
    gamma = np.minimum(t / t_ramp, 1.0) * gamma_max
    stress = {}
    for name, c in (("json", card), ("niftysim", back)):
        res = solve_quasistatic(_shear_cube(card_material(c), t, gamma), t[1:], tol_m=1e-14)
        stress[name] = res.reaction_force_n["top"][:, 0] / L**2
    np.testing.assert_allclose(stress["niftysim"], stress["json"], rtol=1e-9)
    oracle = _ramp_hold_stress(300.0, card["prony"]["g_inf"], card["prony"]["g"], card["prony"]["tau"], t[1:],
                               t_ramp, gamma_max)
    np.testing.assert_allclose(stress["niftysim"], oracle, rtol=2e-3)
    rp3 = {**card, "elastic_law": "reduced_polynomial3"}
    assert "reduced_polynomial3" in niftysim_reason(rp3)
    assert "niftysim" not in C.write_card_files(rp3, tmp_path / "rp3", stem="rp3")

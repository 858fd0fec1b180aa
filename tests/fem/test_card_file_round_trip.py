"""The JSON card as the TLED solver's input format (issue 16 item 4): a QLV card written to disk by
``cards.write_card_files`` and read back is the material the solver runs, and one sheared element driven by a
ramp-and-hold reproduces the fitted model's 1-D stress history (small strain) -- fit -> file -> FEM, no shortcut."""
from __future__ import annotations

import json

import numpy as np
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

"""The nonseparable extension in the TLED solver: Pipkin-Rogers (strain-dependent Prony weights) from the fit through
the card file into the solver, with the fitted parameters unchanged.

Oracle: the fitting code's own 1-D stress history (``models.beyond_qlv.PipkinRogersModel.shear_stress_history``, the
exact recursion the fits and the diagnosis use). One cube of 6 tets in simple shear (every node prescribed, J = 1),
relaxation after a ramp, at three strains: the 3-D strain measure ``I1bar - 3`` equals gamma^2 there, so the weights
are the 1-D model's; what remains is that the solver relaxes the 2nd Piola-Kirchhoff stress (objective, as NiftySim
and FEBio do) while the 1-D model relaxes the shear stress itself, which differs during a ramp by terms of order
``gamma^2 g (t_ramp / tau)`` and not at all in a step.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from test_verification import L, _shear_cube

from tissuemech import cards as C
from tissuemech import fitting as F
from tissuemech.fem.materials import card_shift_factor, make_material, material_from_card
from tissuemech.fem.tled import run_explicit, solve_quasistatic
from tissuemech.models.registry import get_model
from tissuemech.records import MaterialCard

#: the bundled brain's joint Pipkin-Rogers fit (tests/regression/porcine_brain_thesis.csv, beta_4 made non-zero)
BRAIN_PR = {"C10": 147.47, "C20": -33.03, "C30": 240.48, "beta_1": 1.387, "beta_2": 0.470, "beta_3": 0.469,
            "beta_4": 0.05, "kappa": 0.537, "gamma_s": 0.1223}


def _pr_result(model, params):
    """A Pipkin-Rogers ``FitResult`` as the fit stage hands it to ``cards.make_card`` (values given, no fitting)."""
    names = list(model.param_names)
    ranges = {"strain_min": 0.001, "strain_max": 0.5, "rate_min_1_per_s": 0.01, "rate_max_1_per_s": 1.0,
              "omega_min_rad_per_s": np.nan, "omega_max_rad_per_s": np.nan, "time_min_s": 0.01, "time_max_s": 300.0}
    return F.FitResult(model_key=model.name, family=model.family, scope="viscoelastic_joint", target="torque",
                       params=dict(params), stderr={n: 0.01 * abs(params[n]) + 1e-3 for n in names},
                       units={n: "" for n in names}, varying=names, correlation=np.eye(len(names)), flags=[],
                       success=True, message="", chisqr=1.0, redchi=1.0, rmse=1.0, nrmse=0.01, n=50, n_eff=50.0,
                       k=len(names), aic=0.0, aicc=0.0, bic=0.0, aicc_eff=0.0, bic_eff=0.0, nfev=1, n_starts=1,
                       curve_labels=["c"], curve_rmse={}, curve_nrmse={}, residuals=[], ranges=ranges,
                       selection=[{"label": "relaxation", "test": "stress_relaxation"}], structure=model.structure)


def _ramp_hold(gamma0, t_ramp, t_end=300.0, n_ramp=8, n_hold=30):
    t = np.concatenate([np.linspace(0.0, t_ramp, n_ramp + 1), t_ramp + np.geomspace(1e-3, t_end, n_hold)])
    return t, gamma0 * np.minimum(t / t_ramp, 1.0)


@pytest.fixture(scope="module")
def brain_pr_card_file(tmp_path_factory):
    """The Pipkin-Rogers card of the brain fit, written by the card writer and read back from disk."""
    model = get_model("pr_rp3_prony4")
    card = C.make_card(_pr_result(model, BRAIN_PR), model, poisson_ratio=0.49)
    paths = C.write_card_files(card, tmp_path_factory.mktemp("cards"), stem=model.name)
    return model, paths


@pytest.mark.parametrize("kernel", ["generic", "vectorised"])
@pytest.mark.parametrize("gamma0", [0.05, 0.2, 0.4])
def test_single_element_relaxation_after_a_ramp_is_the_fitting_models(gamma0, kernel, brain_pr_card_file):
    """Card file -> solver material -> one sheared element, ramp in 0.2 s then hold to 300 s: the reaction traction
    is the 1-D Pipkin-Rogers stress history within 0.5 % at every output (measured at the end of the ramp, the
    largest: 0.004 / 0.07 / 0.26 % at gamma = 0.05 / 0.2 / 0.4, growing as gamma^2: the 2nd Piola-Kirchhoff
    relaxation), to 1e-6 once the ramp has relaxed, and not the QLV history of the same card (kappa = 0)."""
    model, paths = brain_pr_card_file
    card = MaterialCard.from_json(paths["json"])
    material = material_from_card(card)
    assert material.pipkin_rogers and material.pr_params.shape == (4, 3)
    np.testing.assert_allclose(material.pr_params[:, 0], [BRAIN_PR[f"beta_{i}"] for i in range(1, 5)])
    np.testing.assert_allclose(material.pr_params[:, 1], BRAIN_PR["kappa"])
    np.testing.assert_allclose(material.pr_params[:, 2], BRAIN_PR["gamma_s"] ** 2)
    t, gamma = _ramp_hold(gamma0, 0.2)
    res = solve_quasistatic(_shear_cube(material, t, gamma), t[1:], tol_m=1e-14, kernel=kernel)
    assert res.kernel == kernel
    fem = res.reaction_force_n["top"][:, 0] / L**2
    one_d = model.shear_stress_history(BRAIN_PR, t, gamma)[1:]
    np.testing.assert_allclose(fem, one_d, rtol=5e-3)
    assert fem[-1] == pytest.approx(one_d[-1], rel=1e-6)
    qlv = model.shear_stress_history({**BRAIN_PR, "kappa": 0.0}, t, gamma)[1:]
    if gamma0 > 0.1:  # above gamma_s the weights have changed: far from the separable (QLV) history
        assert abs(fem[-1] / qlv[-1] - 1) > 0.1


def test_relaxed_fraction_grows_with_strain_as_the_weights_say():
    """A near-ideal step (1 ms) to two strains: the TLED's relaxed fraction after 300 s equals g_inf(gamma) of the
    weight law evaluated here from its formula (beta_i (1 + kappa s) / (1 + sum), s = gamma^2 / (gamma^2 +
    gamma_s^2)), and differs between the strains (kappa > 0: more relaxation at the larger strain)."""
    beta, kappa, gamma_s, tau = np.array([0.8, 0.5]), 2.0, 0.1, np.array([0.5, 5.0])
    material = make_material("neo_hookean", {"mu": 600.0}, poisson_ratio=0.49, prony_tau_s=tau,
                             pipkin_rogers={"beta": beta, "kappa": [kappa, kappa], "gamma_s": gamma_s})
    fractions = []
    for gamma0 in (0.02, 0.3):
        t, gamma = _ramp_hold(gamma0, 1e-3, t_end=500.0, n_ramp=1)
        sigma = solve_quasistatic(_shear_cube(material, t, gamma), t[1:], tol_m=1e-14).reaction_force_n["top"][:, 0]
        s = gamma0**2 / (gamma0**2 + gamma_s**2)
        g_inf = 1.0 / (1.0 + np.sum(beta * (1.0 + kappa * s)))
        assert sigma[-1] / sigma[0] == pytest.approx(g_inf, rel=2e-3)
        fractions.append(sigma[-1] / sigma[0])
    assert fractions[1] < fractions[0] - 0.1


def test_explicit_vectorised_and_generic_kernels_agree_and_keep_the_states():
    """The vectorised Pipkin-Rogers pass equals the generic kernel's (forces, displacements, states incl. the
    previous weights)."""
    from tissuemech.fem.mesh import block_mesh
    from tissuemech.fem.tled import build_model, fixed_group, translation_group

    material = make_material("reduced_polynomial3", {k: BRAIN_PR[k] for k in ("C10", "C20", "C30")},
                             poisson_ratio=0.45, prony_tau_s=[0.002, 0.02, 0.2, 2.0],
                             pipkin_rogers={"beta": [1.387, 0.47, 0.469, 0.05], "kappa": [0.537] * 4,
                                            "gamma_s": 0.1223})
    mesh = block_mesh((L, L, L), (3, 3, 3))
    z = mesh.nodes[:, 2]
    groups = [fixed_group("bottom", np.flatnonzero(np.isclose(z, 0))),
              translation_group("top", np.flatnonzero(np.isclose(z, L)), (1, 0, 0.3), [0, 0.02], [0, 3e-3])]
    model = build_model(mesh, material, groups, anp=True, n_chunks=3)
    gen = run_explicit(model, 0.02, damping_1_s=100.0, kernel="generic", n_outputs=5)
    vec = run_explicit(model, 0.02, damping_1_s=100.0, kernel="vectorised", n_outputs=5)
    assert (gen.kernel, vec.kernel) == ("generic", "vectorised")
    f_gen = gen.reaction_force_n["top"]
    np.testing.assert_allclose(vec.reaction_force_n["top"], f_gen, rtol=0, atol=1e-11 * np.abs(f_gen).max())
    np.testing.assert_allclose(vec.displacement_m, gen.displacement_m, rtol=0, atol=1e-14)
    assert np.abs(gen.state[2]).max() > 0.05  # the previous weights are in the state
    for a, b in zip(vec.state, gen.state):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-10 * max(1.0, np.abs(b).max()))


# ------------------------------------------------------------------------------------------------------------------
# temperature through the card's time-temperature shift
# ------------------------------------------------------------------------------------------------------------------
#: a WLF shift card as tts.tts_card writes it (constants of the WLF form, not fitted here)
SHIFT = {"kind": "time_temperature_shift", "shift_function": "WLF", "t_ref_c": 37.0, "vertical_shift": False,
         "wlf": {"c1": 8.0, "c2_k": 120.0}, "valid_range": {"temperature_c": [20.0, 40.0]}}


def test_a_card_at_another_temperature_relaxes_on_the_shifted_time_scale(brain_pr_card_file):
    """log10 aT = -C1 (T - Tref) / (C2 + T - Tref) written out here; the material at 25 degC has its times times
    aT, and its stress history on the time grid aT t equals the reference material's on t."""
    model, paths = brain_pr_card_file
    card = {**json.loads(paths["json"].read_text()), "time_temperature_shift": SHIFT}
    a_t = 10.0 ** (-8.0 * (25.0 - 37.0) / (120.0 + 25.0 - 37.0))
    assert card_shift_factor(MaterialCard.from_dict(card), 25.0) == pytest.approx(a_t, rel=1e-12)
    ref, cold = material_from_card(card), material_from_card(card, temperature_c=25.0)
    np.testing.assert_allclose(cold.prony_tau_s, a_t * ref.prony_tau_s, rtol=1e-12)
    assert material_from_card(card, shift_factor=a_t).prony_tau_s == pytest.approx(cold.prony_tau_s)
    t, gamma = _ramp_hold(0.2, 0.2, t_end=30.0, n_hold=8)
    s_ref = solve_quasistatic(_shear_cube(ref, t, gamma), t[1:], tol_m=1e-14).reaction_force_n["top"][:, 0]
    s_cold = solve_quasistatic(_shear_cube(cold, a_t * t, gamma), a_t * t[1:],
                               tol_m=1e-14).reaction_force_n["top"][:, 0]
    np.testing.assert_allclose(s_cold, s_ref, rtol=1e-7)
    assert s_cold[-1] != pytest.approx(solve_quasistatic(_shear_cube(ref, a_t * t, gamma), a_t * t[1:], tol_m=1e-14)
                                       .reaction_force_n["top"][-1, 0], rel=1e-3)


@pytest.mark.parametrize("change, message", [
    ({"time_temperature_shift": None}, "needs the card's time_temperature_shift"),
    ({"time_temperature_shift": {**SHIFT, "vertical_shift": True}}, "vertical factor"),
    ({"time_temperature_shift": {**SHIFT, "valid_range": {"temperature_c": [30.0, 40.0]}}}, "outside the temperatures"),
])
def test_a_temperature_the_card_cannot_give_is_refused(change, message, brain_pr_card_file):
    _, paths = brain_pr_card_file
    card = {**json.loads(paths["json"].read_text()), "time_temperature_shift": SHIFT, **change}
    with pytest.raises(ValueError, match=message):
        material_from_card(card, temperature_c=25.0)

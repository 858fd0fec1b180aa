"""Hyperelastic closed forms (science.md sections 1.7, 2.1, 2.2)."""
import numpy as np
import pytest

from tissuemech.models.hyperelastic import HYPERELASTIC_LAWS, stability_flags
from tissuemech.models.registry import get_model

GAMMA = np.linspace(0.0, 0.8, 17)


def test_neo_hookean_shear_is_linear_with_universal_normal_stresses():
    m = get_model("neo_hookean")
    np.testing.assert_allclose(m.elastic_shear_stress({"mu": 150.0}, GAMMA), 150.0 * GAMMA, rtol=1e-12)
    n1, n2 = m.normal_stress_differences({"mu": 150.0}, GAMMA)
    np.testing.assert_allclose(n1, 150.0 * GAMMA**2, rtol=1e-12)
    np.testing.assert_allclose(n2, 0.0, atol=1e-12)


def test_mooney_rivlin_second_normal_stress_difference():
    m = get_model("mooney_rivlin")
    _, n2 = m.normal_stress_differences({"C10": 60.0, "C01": 25.0}, GAMMA)
    np.testing.assert_allclose(n2, -2 * 25.0 * GAMMA**2, rtol=1e-12)


def test_ogden_alpha_two_is_neo_hookean_and_budday_asymmetry():
    og, nh = get_model("ogden1"), get_model("neo_hookean")
    np.testing.assert_allclose(og.elastic_shear_stress({"mu1": 90.0, "alpha1": 2.0}, GAMMA),
                               nh.elastic_shear_stress({"mu": 90.0}, GAMMA), rtol=1e-12, atol=1e-12)
    lam = np.array([0.9, 1.1])
    for alpha, ratio in ((2.0, 1.22), (-4.7, 1.72), (-20.0, 3.94)):
        p = og.uniaxial_nominal_stress({"mu1": 1000.0, "alpha1": alpha}, lam)
        assert abs(p[0]) / p[1] == pytest.approx(ratio, abs=0.005)


def test_ogden_shear_matches_science_formula():
    og = get_model("ogden1")
    mu, a = 500.0, -20.0
    lam = GAMMA / 2 + np.sqrt(1 + GAMMA**2 / 4)
    expected = (2 * mu / a) * (lam**a - lam**-a) / (lam + 1 / lam)
    np.testing.assert_allclose(og.elastic_shear_stress({"mu1": mu, "alpha1": a}, GAMMA), expected, rtol=1e-10)


def test_reduced_polynomial_example_of_science_md():
    """a = 80, 400, 2000 Pa (sigma = a1 g + a2 g^3 + a3 g^5): 152.5 Pa at gamma = 0.5."""
    rp = get_model("reduced_polynomial3")
    s = rp.elastic_shear_stress({"C10": 40.0, "C20": 100.0, "C30": 2000.0 / 6}, np.array([0.5]))
    assert s[0] == pytest.approx(152.5, abs=1e-6)


def test_uniaxial_neo_hookean_and_lopez_pamies_reduction():
    lam = np.linspace(0.7, 1.4, 9)
    nh = get_model("neo_hookean")
    np.testing.assert_allclose(nh.uniaxial_nominal_stress({"mu": 300.0}, lam), 300.0 * (lam - lam**-2), rtol=1e-12)
    lp = get_model("lopez_pamies1")  # alpha = 1 is neo-Hookean with mu
    np.testing.assert_allclose(lp.uniaxial_nominal_stress({"mu1": 300.0, "alpha1": 1.0}, lam),
                               300.0 * (lam - lam**-2), rtol=1e-12)


def test_initial_modulus_and_stability_flags():
    og = get_model("ogden2")
    p = {"mu1": 100.0, "alpha1": 2.0, "mu2": 50.0, "alpha2": -4.0}
    assert og.initial_shear_modulus(p) == pytest.approx(150.0, rel=1e-5)
    assert stability_flags(og, p) == []
    unstable = {"mu1": 100.0, "alpha1": 2.0, "mu2": -300.0, "alpha2": 8.0}
    assert "negative_initial_modulus" in stability_flags(og, unstable)


def test_law_table_is_shared_with_fem():
    from tissuemech.fem.materials import available_laws

    available_laws.cache_clear()
    laws = available_laws()
    for key in ("neo_hookean", "mooney_rivlin", "reduced_polynomial3", "ogden1", "lopez_pamies2"):
        assert key in HYPERELASTIC_LAWS
        entry = HYPERELASTIC_LAWS[key]
        spec = laws[key]
        fn = entry.get("dW_dI1") or entry.get("dW_dlambda")
        assert fn in (spec.dw_di1, spec.dw_dlambda), key

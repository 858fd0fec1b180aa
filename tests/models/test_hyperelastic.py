"""Hyperelastic closed forms (science.md sections 1.7, 2.1, 2.2)."""
import numpy as np
import pytest

from tissuemech.models.base import bulk_modulus, initial_shear_modulus
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
    assert initial_shear_modulus(og, p) == pytest.approx(150.0, rel=1e-9)
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


# ------------------------------------------------------------------------------------------------------
# Nunes, Amin and the full polynomial: checked against the energy differentiated along the deformation path
# (simple shear sigma12 = dW/dgamma at I1 = I2 = 3 + gamma^2; uniaxial P = dW/dlambda at I1 = lambda^2 + 2/lambda,
# I2 = 2 lambda + lambda^-2), which is independent of the dW/dI1, dW/dI2 implementation.
# ------------------------------------------------------------------------------------------------------
LAM = np.linspace(0.6, 1.6, 21)
SHEAR = np.linspace(0.02, 0.8, 17)


def _path_derivative(energy, x, h=1e-6):
    """Central difference (relative step) of a scalar energy path."""
    return (energy(x + h * x) - energy(x - h * x)) / (2 * h * x)


def _shear_energy(W):
    return lambda g: W(3 + g**2, 3 + g**2)


def _uniaxial_energy(W):
    return lambda lam: W(lam**2 + 2 / lam, 2 * lam + lam**-2)


def _polynomial_energy(coefficients):
    return lambda i1, i2: sum(c * (i1 - 3) ** i * (i2 - 3) ** j for (i, j), c in coefficients.items())


def test_nunes_simple_shear_normal_stress_and_uniaxial_closed_forms():
    m = get_model("nunes")
    c1, c2 = 60.0, 15.0
    p = {"C1": c1, "C2": c2}
    # sigma = 2 gamma (W1 + W2), W1 = C1, W2 = C2 (I2 - 3)^(-1/4) = C2 gamma^(-1/2)
    np.testing.assert_allclose(m.elastic_shear_stress(p, SHEAR), 2 * c1 * SHEAR + 2 * c2 * np.sqrt(SHEAR), rtol=1e-12)
    np.testing.assert_allclose(m.elastic_shear_stress(p, -SHEAR), -m.elastic_shear_stress(p, SHEAR), rtol=1e-12)
    assert m.elastic_shear_stress(p, np.array([0.0]))[0] == 0.0
    n1, n2 = m.normal_stress_differences(p, SHEAR)
    np.testing.assert_allclose(n1, SHEAR * (2 * c1 * SHEAR + 2 * c2 * np.sqrt(SHEAR)), rtol=1e-12)
    np.testing.assert_allclose(n2, -2 * c2 * SHEAR**1.5, rtol=1e-12)
    W = lambda i1, i2: c1 * (i1 - 3) + 4 / 3 * c2 * np.abs(i2 - 3) ** 0.75  # noqa: E731
    np.testing.assert_allclose(m.uniaxial_nominal_stress(p, LAM[LAM != 1.0]),
                               _path_derivative(_uniaxial_energy(W), LAM[LAM != 1.0]), rtol=1e-6)
    np.testing.assert_allclose(m.elastic_shear_stress(p, SHEAR), _path_derivative(_shear_energy(W), SHEAR), rtol=1e-6)
    # square-root start: no finite initial modulus, the secant modulus grows like gamma^(-1/2) as gamma -> 0
    secant = m.elastic_shear_stress(p, np.array([1e-6, 1e-4])) / np.array([1e-6, 1e-4])
    assert secant[0] / secant[1] > 9.0


def test_amin_energy_derivatives_and_yamashita_kawabata_limit():
    m = get_model("amin")
    p = {"C5": 60.0, "C3": 40.0, "C4": 300.0, "C2": 15.0, "N": 0.5, "M": 2.5}

    def W(i1, i2):
        x = i1 - 3
        return (p["C5"] * x + p["C3"] / (p["N"] + 1) * x ** (p["N"] + 1) + p["C4"] / (p["M"] + 1) * x ** (p["M"] + 1)
                + p["C2"] * (i2 - 3))

    np.testing.assert_allclose(m.elastic_shear_stress(p, SHEAR), _path_derivative(_shear_energy(W), SHEAR), rtol=1e-6)
    lam = LAM[LAM != 1.0]
    np.testing.assert_allclose(m.uniaxial_nominal_stress(p, lam), _path_derivative(_uniaxial_energy(W), lam), rtol=1e-6)
    _, n2 = m.normal_stress_differences(p, SHEAR)
    np.testing.assert_allclose(n2, -2 * p["C2"] * SHEAR**2, rtol=1e-12)
    # C4 = 0 is Yamashita-Kawabata; with N = 1 that is Mooney-Rivlin plus C3/2 (I1-3)^2 (a Yeoh-type term)
    yk = {**p, "C4": 0.0, "N": 1.0}
    expected = 2 * SHEAR * (p["C5"] + p["C3"] * SHEAR**2 + p["C2"])
    np.testing.assert_allclose(m.elastic_shear_stress(yk, SHEAR), expected, rtol=1e-12)
    # a negative exponent (low-strain softening) keeps sigma finite and zero at the origin: 2 C3 gamma^(2N+1)
    soft = {**p, "C5": 0.0, "C4": 0.0, "C2": 0.0, "N": -0.3}
    np.testing.assert_allclose(m.elastic_shear_stress(soft, SHEAR), 2 * 40.0 * SHEAR**0.4, rtol=1e-12)
    assert m.elastic_shear_stress(soft, np.array([0.0]))[0] == 0.0


def test_polynomial_order_one_is_mooney_rivlin_and_order_two_matches_polynomial2():
    from tissuemech.models.hyperelastic import polynomial

    p1 = polynomial(1)
    assert p1.param_names == ("C10", "C01")
    mr = get_model("mooney_rivlin")
    p = {"C10": 60.0, "C01": 25.0}
    np.testing.assert_allclose(p1.elastic_shear_stress(p, SHEAR), mr.elastic_shear_stress(p, SHEAR), rtol=1e-14)
    np.testing.assert_allclose(p1.uniaxial_nominal_stress(p, LAM), mr.uniaxial_nominal_stress(p, LAM), rtol=1e-14)
    np.testing.assert_allclose(p1.normal_stress_differences(p, SHEAR)[1], -2 * 25.0 * SHEAR**2, rtol=1e-12)
    q = {"C10": 60.0, "C01": 25.0, "C20": 30.0, "C11": -12.0, "C02": 7.0}
    general, fixed = polynomial(2), get_model("polynomial2")
    assert general.param_names == fixed.param_names
    np.testing.assert_allclose(general.uniaxial_nominal_stress(q, LAM), fixed.uniaxial_nominal_stress(q, LAM),
                               rtol=1e-13)
    np.testing.assert_allclose(general.normal_stress_differences(q, SHEAR)[1],
                               fixed.normal_stress_differences(q, SHEAR)[1], rtol=1e-13)


@pytest.mark.parametrize("order", [3, 4, 5, 6])
def test_full_polynomial_against_its_energy(order):
    m = get_model(f"polynomial{order}")
    # Abaqus order: C10, C01, C20, C11, C02, C30, ... (total degree, then rising power of I2 - 3)
    expected_names = tuple(f"C{t - j}{j}" for t in range(1, order + 1) for j in range(t + 1))
    assert m.param_names == expected_names and len(expected_names) == order * (order + 3) // 2
    rng = np.random.default_rng(order)
    coefficients = {(int(n[1]), int(n[2])): float(v) for n, v in
                    zip(expected_names, rng.uniform(5.0, 60.0, len(expected_names)) / np.arange(1, len(expected_names) + 1))}
    p = {f"C{i}{j}": c for (i, j), c in coefficients.items()}
    W = _polynomial_energy(coefficients)
    np.testing.assert_allclose(m.elastic_shear_stress(p, SHEAR), _path_derivative(_shear_energy(W), SHEAR), rtol=1e-6)
    lam = LAM[LAM != 1.0]
    np.testing.assert_allclose(m.uniaxial_nominal_stress(p, lam), _path_derivative(_uniaxial_energy(W), lam), rtol=1e-6)
    # N2 = -2 gamma^2 W2, W2 = sum j C_ij x^i y^(j-1) at x = y = gamma^2
    w2 = sum(j * c * SHEAR ** (2 * (i + j - 1)) for (i, j), c in coefficients.items() if j > 0)
    np.testing.assert_allclose(m.normal_stress_differences(p, SHEAR)[1], -2 * SHEAR**2 * w2, rtol=1e-12)


@pytest.mark.parametrize("key,params", [
    ("nunes", {"C1": 60.0, "C2": 15.0}),
    ("amin", {"C5": 60.0, "C3": 40.0, "C4": 300.0, "C2": 15.0, "N": 0.5, "M": 2.5}),
    ("polynomial3", {"C10": 40.0, "C01": 15.0, "C20": 60.0, "C11": -10.0, "C02": 20.0, "C30": 50.0, "C21": 10.0,
                     "C12": -5.0, "C03": 8.0}),
])
def test_new_laws_reach_the_fem_material_routine(key, params):
    """The FEM adopts the law table: one material point in simple shear gives the 1-D closed form."""
    from tissuemech.fem import materials as mats
    mats.available_laws.cache_clear()
    assert key in HYPERELASTIC_LAWS and key in mats.available_laws()
    model = get_model(key)
    mu_ref = float(model.elastic_shear_stress(params, np.array([0.05]))[0] / 0.05)
    mat = mats.make_material(key, params, bulk_modulus_pa=1e4 * mu_ref)
    for g in (0.05, 0.3, 0.6):
        F = np.eye(3)
        F[0, 1] = g
        assert mats.cauchy_stress(mat, F)[0, 1] == pytest.approx(model.elastic_shear_stress(params, np.array([g]))[0],
                                                                 rel=2e-3)


def test_nunes_fit_from_default_start_recovers_noisy_truth():
    """Two linear coefficients: a default-start least-squares fit to 1 % noise lands on the truth."""
    from tissuemech import fitting as F

    m = get_model("nunes")
    truth = {"C1": 120.0, "C2": 35.0}
    g = np.linspace(0.01, 0.5, 40)
    rng = np.random.default_rng(4)
    observed = m.elastic_shear_stress(truth, g) * (1 + 0.01 * rng.standard_normal(g.size))
    curve = F.Curve(test="simple_shear", condition="shear", response="elastic_shear", inputs={"shear_strain": g},
                    observed={"shear_stress": observed})
    res = F.fit(F.FitProblem(m, [curve], target="none", model_key="nunes"), n_random=0)
    assert res.params["C1"] == pytest.approx(120.0, rel=0.05) and res.params["C2"] == pytest.approx(35.0, rel=0.05)


def test_bulk_modulus_from_shear_modulus_and_poisson_ratio():
    """K = 2 mu (1 + nu) / (3 (1 - 2 nu)): nu = 0 gives 2 mu / 3, nu = 0.25 gives 5 mu / 3 (= lambda + 2 mu / 3 with
    lambda = mu); nu outside (-1, 0.5) is refused."""
    assert bulk_modulus(300.0, 0.0) == pytest.approx(200.0, rel=1e-15)
    assert bulk_modulus(300.0, 0.25) == pytest.approx(500.0, rel=1e-15)
    assert bulk_modulus(1000.0, 0.49) == pytest.approx(1000.0 * 2 * 1.49 / (3 * 0.02), rel=1e-12)
    for nu in (0.5, 0.6, -1.0):
        with pytest.raises(ValueError, match="poisson_ratio"):
            bulk_modulus(300.0, nu)


def test_one_compiled_shear_and_uniaxial_kernel_serves_every_law():
    # the laws reach the 1-D kernels as C function pointers: one signature (so one on-disk cache entry) for all
    # invariant laws and one for all stretch laws; jitted-dispatcher arguments compiled a kernel per law per process
    from tissuemech.models import hyperelastic as H

    gamma, stretch = np.linspace(0.01, 0.4, 9), np.linspace(0.8, 1.2, 9)
    for key in ("neo_hookean", "mooney_rivlin", "gent", "ogden1", "ogden2"):
        model = get_model(key)
        p = model.default_params()
        assert np.all(np.isfinite(model.elastic_shear_stress(p, gamma)))
        assert np.all(np.isfinite(model.uniaxial_nominal_stress(p, stretch)))
    for kernel in (H._invariant_shear, H._invariant_uniaxial, H._stretch_shear, H._stretch_uniaxial):
        assert len(kernel.signatures) == 1, kernel

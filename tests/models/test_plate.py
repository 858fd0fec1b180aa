"""Parallel-plate forward model against closed forms (science.md sections 2.1, 2.2)."""
import numpy as np
import pytest

from tissuemech.models.base import ConstitutiveModel, ParamSpec
from tissuemech.models.beyond_qlv import MaxwellBranchModel
from tissuemech.models.plate import (apparent_rim_stress, first_harmonic_moduli, forward_plate, gauss_radii,
                                     n_exponent, oscillation_moduli, rabinowitsch_rim_stress,
                                     thrust_normal_force, torque_from_history)
from tissuemech.models.qlv import LinearElasticShear, QLVModel, qlv_params

R = 0.01
TAUS = np.array([0.1, 1.09, 9.91, 100.0])
G = np.array([0.00033, 0.23447, 0.21368, 0.14447])


class MooneyRivlinShear(ConstitutiveModel):
    """W = C1(I1-3) + C2(I2-3): sigma = 2(C1+C2) gamma, N1 = gamma sigma, N2 = -2 C2 gamma^2."""

    def __init__(self):
        super().__init__(name="mr", family="hyperelastic",
                         param_specs=(ParamSpec("C1", "Pa", 1.0), ParamSpec("C2", "Pa", 1.0)),
                         responses=frozenset({"elastic_shear", "normal_stress"}))

    def elastic_shear_stress(self, p, strain):
        return 2 * (p["C1"] + p["C2"]) * np.asarray(strain, float)

    def normal_stress_differences(self, p, strain):
        g = np.asarray(strain, float)
        return g * self.elastic_shear_stress(p, g), -2 * p["C2"] * g ** 2


class PowerLawShear(ConstitutiveModel):
    def __init__(self):
        super().__init__(name="power", family="hyperelastic",
                         param_specs=(ParamSpec("K", "Pa", 1.0), ParamSpec("n", "1", 1.0)),
                         responses=frozenset({"elastic_shear"}))

    def elastic_shear_stress(self, p, strain):
        g = np.asarray(strain, float)
        return p["K"] * np.sign(g) * np.abs(g) ** p["n"]


class OddPolynomialShear(ConstitutiveModel):
    def __init__(self):
        super().__init__(name="poly3", family="hyperelastic",
                         param_specs=tuple(ParamSpec(f"a{k}", "Pa", 1.0) for k in (1, 2, 3)),
                         responses=frozenset({"elastic_shear"}))

    def elastic_shear_stress(self, p, strain):
        g = np.asarray(strain, float)
        return p["a1"] * g + p["a2"] * g ** 3 + p["a3"] * g ** 5


def test_gauss_radii_integrate_r_cubed_exactly():
    r, w = gauss_radii(8, R)
    assert np.all((r > 0) & (r < R))
    assert np.sum(w * r ** 15) == pytest.approx(R ** 16 / 16, rel=1e-13)


def test_neo_hookean_torque_closed_form():
    mu, rim = 160.0, np.linspace(0, 0.5, 11)
    torque = torque_from_history(LinearElasticShear(), {"G0": mu}, np.arange(11.0), rim, R)
    np.testing.assert_allclose(torque, np.pi / 2 * mu * rim * R ** 3, rtol=1e-13, atol=1e-20)


@pytest.mark.parametrize("n", [0.5, 1.5, 2.0, 3.0])
def test_power_law_apparent_stress_factor(n):
    p = {"K": 300.0, "n": n}
    rim = np.array([0.05, 0.2, 0.5])
    app = forward_plate(PowerLawShear(), p, np.arange(3.0), rim, R, target="apparent_stress", n_gauss=16)
    np.testing.assert_allclose(app / (300.0 * rim ** n), 4 / (n + 3), rtol=1e-5)


def test_power_law_n_exponent_and_correction():
    p = {"K": 300.0, "n": 0.5}
    rim = np.geomspace(0.01, 0.5, 40)
    torque = torque_from_history(PowerLawShear(), p, np.arange(40.0), rim, R, n_gauss=16)
    np.testing.assert_allclose(n_exponent(torque, rim), 0.5, atol=1e-5)
    np.testing.assert_allclose(rabinowitsch_rim_stress(torque, rim, R), 300.0 * np.sqrt(rim), rtol=1e-5)


def test_reduced_polynomial_apparent_coefficients_and_correction():
    a = {"a1": 80.0, "a2": 400.0, "a3": 2000.0}
    rim = np.linspace(0.0, 0.5, 101)
    law = OddPolynomialShear()
    app = forward_plate(law, a, np.arange(rim.size), rim, R, target="apparent_stress")
    np.testing.assert_allclose(app, 80 * rim + 400 * 2 / 3 * rim ** 3 + 2000 * 0.5 * rim ** 5, rtol=1e-12, atol=1e-14)
    torque = torque_from_history(law, a, np.arange(rim.size), rim, R)
    corrected = rabinowitsch_rim_stress(torque, rim, R)
    assert law.elastic_shear_stress(a, 0.5) == pytest.approx(152.5)
    assert app[-1] == pytest.approx(104.6, abs=0.05)
    assert corrected[-1] == pytest.approx(152.5, abs=1.0)        # science.md: ~151.8 with a numerical slope
    np.testing.assert_allclose(corrected[20:], law.elastic_shear_stress(a, rim[20:]), rtol=1e-2)
    assert np.isnan(corrected[0])                                  # zero strain: no log-log slope


def test_linear_viscoelastic_apparent_equals_true_rim_stress():
    model = QLVModel(LinearElasticShear(), 4, taus_s=TAUS)
    p = qlv_params(model, {"G0": 200.0}, G)
    t = np.linspace(0, 50, 501)
    rim = np.minimum(0.1 * t, 0.2)
    app = forward_plate(model, p, t, rim, R, gap_m=0.002, target="apparent_stress")
    true = forward_plate(model, p, t, rim, R, target="corrected_stress")
    np.testing.assert_allclose(app, true, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(forward_plate(model, p, t, rim, R, target="torque"), app * np.pi * R ** 3 / 2)
    with pytest.raises(ValueError, match="unknown target"):
        forward_plate(model, p, t, rim, R, target="stress")


def test_first_harmonic_moduli_of_synthetic_signal():
    t = np.linspace(0, 2, 400, endpoint=False)
    w = 2 * np.pi
    strain = 0.01 * np.sin(w * t + 0.3)
    stress = 0.01 * (150 * np.sin(w * t + 0.3) + 40 * np.cos(w * t + 0.3)) + 0.5 + 0.3 * np.sin(3 * w * t)
    gp, gpp = first_harmonic_moduli(t, strain, stress, 1.0)
    assert gp == pytest.approx(150.0, rel=1e-10) and gpp == pytest.approx(40.0, rel=1e-10)


@pytest.mark.parametrize("freq", [0.1, 1.0, 5.0])
def test_oscillation_of_prony_material_matches_analytic(freq):
    model = QLVModel(LinearElasticShear(), 4, taus_s=TAUS)
    p = qlv_params(model, {"G0": 200.0}, [0.1, 0.2, 0.2, 0.1])
    gp, gpp = oscillation_moduli(model, p, freq, [0.001, 0.01], R, n_cycles=12, points_per_cycle=256)
    g_star = model.complex_modulus(p, np.array([2 * np.pi * freq]))[0]
    np.testing.assert_allclose(gp, g_star.real, rtol=5e-4)
    np.testing.assert_allclose(gpp, g_star.imag, rtol=5e-4)


def test_amplitude_sweep_of_stiffening_material():
    """A stiffening instantaneous law: apparent G' grows with amplitude, less than the true rim modulus."""
    model = QLVModel(OddPolynomialShear(), 4, taus_s=TAUS)
    p = qlv_params(model, {"a1": 200.0, "a2": 2000.0, "a3": 0.0}, [0.1, 0.2, 0.2, 0.1])
    amps = [0.001, 0.2]
    gp_app, _ = oscillation_moduli(model, p, 1.0, amps, R)
    gp_true, _ = oscillation_moduli(model, p, 1.0, amps, R, target="corrected_stress")
    assert gp_app[0] == pytest.approx(gp_true[0], rel=1e-3)
    assert gp_true[1] > gp_app[1] > 1.1 * gp_app[0]


def test_maxwell_branch_oscillation_matches_its_complex_modulus():
    model = MaxwellBranchModel(LinearElasticShear(), 2, "neo_hookean", taus_s=[0.05, 0.5])
    p = {"G0": 100.0, "mu_b1": 60.0, "mu_b2": 40.0}
    gp, gpp = oscillation_moduli(model, p, 2.0, 0.01, R, n_cycles=10, points_per_cycle=256)
    g_star = model.complex_modulus(p, np.array([4 * np.pi]))[0]
    assert gp[0] == pytest.approx(g_star.real, rel=1e-3) and gpp[0] == pytest.approx(g_star.imag, rel=1e-3)


def test_mooney_rivlin_thrust_closed_form():
    p = {"C1": 55.0, "C2": 25.0}
    mu = 2 * (p["C1"] + p["C2"])
    rim = np.array([0.1, 0.5])
    force = thrust_normal_force(MooneyRivlinShear(), p, rim, R)
    np.testing.assert_allclose(force, np.pi / 4 * rim ** 2 * R ** 2 * (mu + 2 * p["C2"]), rtol=1e-13)
    assert np.all(force > 0)                                   # positive Poynting: pushes plates apart
    # science.md magnitude: R = 10 mm, gamma_R = 0.5, mu = 160 Pa, C2 = 50 Pa -> ~5 mN... with psi = 50 1/m
    f = thrust_normal_force(MooneyRivlinShear(), {"C1": 30.0, "C2": 50.0}, np.array([0.5]), R)[0]
    assert f == pytest.approx(np.pi / 4 * 50.0 ** 2 * R ** 4 * 260.0, rel=1e-12)


def test_qlv_thrust_relaxes_with_reduced_relaxation_function():
    model = QLVModel(MooneyRivlinShear(), 4, taus_s=TAUS)
    p = qlv_params(model, {"C1": 55.0, "C2": 25.0}, G)
    t = np.linspace(0, 100, 201)
    rim = np.full(t.size, 0.3)
    force = forward_plate(model, p, t, rim, R, target="normal_force")
    g_r = 1 - G.sum() + np.sum(G[:, None] * np.exp(-t / TAUS[:, None]), axis=0)
    np.testing.assert_allclose(force, force[0] * g_r, rtol=1e-12)
    assert force[0] == pytest.approx(np.pi / 4 * 0.09 * R ** 2 * (160 + 50), rel=1e-12)


def test_apparent_rim_stress_units():
    assert apparent_rim_stress(np.pi * R ** 3 / 2, R) == pytest.approx(1.0)


def test_torque_controlled_creep():
    """Linear law: plate creep == homogeneous creep; stiffening law: the rim strains more than a homogeneous
    sample at the same apparent stress would (the apparent stress under-reports the rim stress), and the
    solved rim history reproduces the imposed apparent stress through the forward model."""
    from tissuemech.models.plate import creep_rim_strain
    t = np.concatenate([np.linspace(0, 0.05, 6), np.geomspace(0.05, 50, 150)[1:]])
    stress = np.minimum(t / 0.05, 1.0) * 10.0
    lin = QLVModel(LinearElasticShear(), 4, taus_s=TAUS)
    p = qlv_params(lin, {"G0": 200.0}, G)
    np.testing.assert_allclose(creep_rim_strain(lin, p, t, stress, R), lin.creep_strain(p, t, stress), rtol=1e-9,
                               atol=1e-15)
    model = QLVModel(OddPolynomialShear(), 4, taus_s=TAUS)
    p = qlv_params(model, {"a1": 40.0, "a2": 400.0, "a3": 2000.0}, G)
    rim = creep_rim_strain(model, p, t, stress, R)
    # the forward recursion takes sigma_e linear between samples, the creep the torque: second order apart
    np.testing.assert_allclose(forward_plate(model, p, t, rim, R), stress, atol=2e-3)
    fine_t = np.concatenate([np.linspace(0, 0.05, 6), np.geomspace(0.05, 50, 1200)[1:]])
    fine_stress = np.minimum(fine_t / 0.05, 1.0) * 10.0
    np.testing.assert_allclose(
        forward_plate(model, p, fine_t, creep_rim_strain(model, p, fine_t, fine_stress, R), R), fine_stress, atol=5e-5)
    # exact on the sparse grid: the rim strain at the common samples does not move with the sampling
    np.testing.assert_allclose(np.interp(t, fine_t, creep_rim_strain(model, p, fine_t, fine_stress, R))[5::10],
                               rim[5::10], rtol=1e-6)
    assert rim[-1] > 1.02 * model.creep_strain(p, t, stress)[-1]


def test_inertia_magnitudes_of_science_table():
    from tissuemech.models.plate import apparent_complex_modulus, torsion_geometry_factor
    b = torsion_geometry_factor(0.01, 0.002)
    for f, expected in ((1.0, 50.0), (2.0, 201.0), (10.0, 5027.0), (20.0, 20106.0)):
        assert 1e-5 * (2 * np.pi * f) ** 2 / b == pytest.approx(expected, abs=0.6)
    g = np.array([200.0 + 20.0j])
    f = np.array([20.0])
    # 1 % instrument-inertia error at 20 Hz: -201 Pa on G'
    shifted = apparent_complex_modulus(g, f, 0.01, 0.002, inertia_error_kg_m2=1e-7)
    assert (shifted - g)[0] == pytest.approx(-201.06, abs=0.05)
    # sample inertia: exact wave factors and their small-kh expansions (21.9 Pa at 20 Hz, h = 2 mm)
    moving = apparent_complex_modulus(g, f, 0.01, 0.002, density_kg_m3=1040.0)
    fixed = apparent_complex_modulus(g, f, 0.01, 0.002, density_kg_m3=1040.0, sensing="fixed")
    shift = 1040.0 * (2 * np.pi * 20) ** 2 * 0.002 ** 2
    assert shift / 3 == pytest.approx(21.9, abs=0.05)
    assert (moving - g)[0].real == pytest.approx(-shift / 3, rel=0.1)
    assert (fixed - g)[0].real == pytest.approx(shift / 6, rel=0.1)
    kh = 2 * np.pi * 20 * np.sqrt(1040.0 / g[0]) * 0.002
    assert moving[0] == pytest.approx(g[0] * kh / np.tan(kh), rel=1e-12)
    np.testing.assert_array_equal(apparent_complex_modulus(g, f, 0.01, 0.002), g)


def test_n_exponent_is_robust_to_torque_noise():
    rng = np.random.default_rng(3)
    rim = np.geomspace(0.01, 0.5, 120)
    torque = torque_from_history(PowerLawShear(), {"K": 300.0, "n": 0.5}, np.arange(rim.size), rim, R, n_gauss=16)
    noisy = torque * (1 + 0.005 * rng.standard_normal(rim.size))
    n = n_exponent(noisy, rim, window=21)
    assert abs(np.mean(n) - 0.5) < 0.01 and np.std(n) < 0.05
    # a linear material: n = 1 and the correction leaves the apparent stress unchanged
    lin = torque_from_history(LinearElasticShear(), {"G0": 100.0}, np.arange(rim.size), rim, R)
    np.testing.assert_allclose(rabinowitsch_rim_stress(lin, rim, R), apparent_rim_stress(lin, R), rtol=1e-10)


def test_torque_controlled_creep_generic_model_path():
    """A model without branch drives (Maxwell branches): torque-controlled creep through the generic solver."""
    from tissuemech.models.plate import creep_rim_strain
    model = MaxwellBranchModel(OddPolynomialShear(), 1, "ogden", taus_s=[2.0])
    p = {"a1": 40.0, "a2": 400.0, "a3": 0.0, "mu_b1": 60.0, "alpha_b": -5.0}
    t = np.concatenate([np.linspace(0, 0.05, 4), 0.05 + np.geomspace(0.01, 30, 50)])
    stress = np.minimum(t / 0.05, 1.0) * 10.0
    rim = creep_rim_strain(model, p, t, stress, R)
    np.testing.assert_allclose(forward_plate(model, p, t, rim, R), stress, atol=1e-8)
    assert rim[-1] > rim[4] > 0


def test_rim_normal_stress_difference_inverts_thrust():
    from tissuemech.models.plate import rim_normal_stress_difference
    p = {"C1": 55.0, "C2": 25.0}
    rim = np.linspace(0.02, 0.5, 60)
    force = thrust_normal_force(MooneyRivlinShear(), p, rim, R)
    n1, n2 = MooneyRivlinShear().normal_stress_differences(p, rim)
    np.testing.assert_allclose(rim_normal_stress_difference(force, rim, R), n1 - n2, rtol=1e-6)


def test_a_law_that_softens_beyond_the_data_is_inverted_on_its_rising_branch():
    """A two-term Lopez-Pamies law with negative exponents, as a joint fit returned it for a generated creep
    dataset: the plate's apparent elastic stress rises to ~1 kPa at a rim strain of ~0.3 and falls to zero beyond
    (stress 2 gamma sum mu_i (I1/3)^(alpha_i - 1), I1 = 3 + gamma^2). A creep's rim strain is the root on the rising
    branch from zero strain (the one the sample passes through), found with a table and Newton steps; before, the
    fall at strains the creep never reaches sent every such inversion to 60 bisections over the whole line."""
    from lmfit import Parameters

    from tissuemech.models.plate import apparent_elastic_stress, invert_increasing
    from tissuemech.models.registry import get_model

    model = QLVModel(get_model("lopez_pamies2"), 1)
    p = Parameters()
    for name, value in dict(mu1=9411.0, alpha1=-20.524, mu2=-3918.8, alpha2=-16.623, beta_1=0.76, tau_1=1.0).items():
        p.add(name, value=value)
    calls = []

    def fun(rim):
        calls.append(1)
        return apparent_elastic_stress(model, p, rim)

    target = np.linspace(-900.0, 900.0, 41)
    rim = invert_increasing(fun, target)

    # the oracle: the apparent stress in closed form, Gauss-Legendre-free (4 int_0^1 sigma(x g) x^2 dx by scipy)
    from scipy.integrate import quad

    def apparent(g):
        def sigma(s):
            i1 = 3.0 + s * s
            return s * sum(mu * (i1 / 3.0) ** (a - 1.0) for mu, a in ((9411.0, -20.524), (-3918.8, -16.623)))
        return 4.0 * quad(lambda x: sigma(x * g) * x * x, 0.0, 1.0)[0]

    peak = max(np.linspace(0.0, 1.0, 2001), key=apparent)
    assert np.all(np.abs(rim) < peak)
    np.testing.assert_allclose([apparent(g) for g in rim], target, rtol=1e-6, atol=1e-6)
    assert len(calls) <= 8

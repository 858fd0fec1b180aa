"""Incompressible isotropic hyperelastic laws: simple-shear, normal-stress and uniaxial closed forms.

Each law is defined **once** by its strain-energy derivatives, compiled with numba and shared with the
TLED FEM (:data:`HYPERELASTIC_LAWS`, adopted by :func:`tissuemech.fem.materials.available_laws`):

* invariant laws ``W(I1, I2)``: ``dW_dI1(params, I1, I2)`` and ``dW_dI2(params, I1, I2)``;
* stretch laws (Ogden, Valanis-Landel form ``W = sum_k w(lambda_k)``): ``dW_dlambda(params, lambda) = w'(lambda)``.

Closed forms (incompressible, ``science.md`` sections 1.7 and 2.2; ``fem.md`` section 4):

* simple shear, amount ``gamma``: ``I1 = I2 = 3 + gamma^2``, ``sigma12 = 2 gamma (W1 + W2)``,
  ``N1 = sigma11 - sigma22 = gamma sigma12`` (universal), ``N2 = sigma22 - sigma33 = -2 gamma^2 W2``;
  for stretch laws with principal stretches ``l1 = gamma/2 + sqrt(1 + gamma^2/4)``, ``l2 = 1/l1``, ``l3 = 1`` and
  ``t_k = l_k w'(l_k)``: ``sigma12 = (t1 - t2)/(l1 + l2)``, ``N2 = (t1 + t2 - gamma sigma12)/2 - t3``;
* uniaxial nominal stress: ``P = 2 (lambda - lambda^-2)(W1 + W2/lambda)``, or for stretch laws
  ``P = (t(lambda) - t(lambda^-1/2)) / lambda``.

Laws: neo-Hookean, Mooney-Rivlin, full polynomial (orders 2-6, Abaqus coefficient order), reduced polynomial /
Yeoh, Gent, exponential (Demiray), Arruda-Boyce, Ogden, Lopez-Pamies, Nunes (``W = C1 (I1-3) + 4/3 C2 (I2-3)^(3/4)``) and Amin
(``W = C5 (I1-3) + C3/(N+1) (I1-3)^(N+1) + C4/(M+1) (I1-3)^(M+1) + C2 (I2-3)``); see the factories.

Parameter names follow the Abaqus/FEBio conventions used by :mod:`tissuemech.cards`: ``mu`` (neo-Hookean
shear modulus, ``C10 = mu/2``), ``C10, C01, C20, ...`` (polynomial coefficients, Pa), ``mu1, alpha1, ...``
(Ogden ``W = sum 2 mu_p/alpha_p^2 (l1^a + l2^a + l3^a - 3)`` and Lopez-Pamies
``W = sum 3^(1-a)/(2a) mu (I1^a - 3^a)``; both have initial shear modulus ``sum mu_p``).
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import cfunc, njit, types

from .base import ConstitutiveModel, ParamSpec, Params

# ------------------------------------------------------------------------------------------------------
# scalar laws (numba): the single implementation used by the 1-D closed forms and by the FEM kernels
# ------------------------------------------------------------------------------------------------------

#: numba signatures of the scalar laws: ``dW/dI(params, I1, I2)`` and ``dW/dlambda(params, lambda)``
INVARIANT_SIG = types.float64(types.float64[::1], types.float64, types.float64)
STRETCH_SIG = types.float64(types.float64[::1], types.float64)


@functools.lru_cache(maxsize=None)
def as_cfunc(fn, signature):
    """A numba law compiled into a C function pointer (a first-class function of ``signature``).

    Kernels that take laws as first-class functions are compiled once for every law and can be cached on
    disk; kernels that take jitted dispatchers are compiled again per law in every process (numba#2956).
    """
    py = getattr(fn, "py_func", fn)
    return cfunc(signature, cache=True)(py)


@functools.lru_cache(maxsize=None)
def compiled_law_kernel(kernel, kind: str):
    """The compiled entry point of a 1-D kernel ``kernel(*laws, params, x)`` taking ``kind`` laws as C pointers.

    Calling the entry point skips the dispatcher's type resolution of the function-pointer arguments, which
    costs more than the kernel itself on the short arrays of a fit (``Dispatcher.compile`` loads the disk cache).
    """
    law = types.FunctionType(INVARIANT_SIG if kind == "invariant" else STRETCH_SIG)
    laws = (law, law) if kind == "invariant" else (law,)
    return kernel.compile((*laws, types.float64[::1], types.float64[::1]))



@njit(cache=True)
def zero_dw_di2(p, i1, i2):
    """``dW/dI2 = 0`` of laws without an I2 part (shared with the FEM, which skips it)."""
    return 0.0


@njit(cache=True)
def neo_hookean_dw_di1(p, i1, i2):
    """``W = mu/2 (I1 - 3)``; ``p = [mu]`` (Pa)."""
    return 0.5 * p[0]


@njit(cache=True)
def mooney_rivlin_dw_di1(p, i1, i2):
    """``W = C10 (I1 - 3) + C01 (I2 - 3)``; ``p = [C10, C01]`` (Pa)."""
    return p[0]


@njit(cache=True)
def mooney_rivlin_dw_di2(p, i1, i2):
    return p[1]


@njit(cache=True)
def reduced_polynomial_dw_di1(p, i1, i2):
    """``W = sum_i C_i0 (I1 - 3)^i``; ``p = [C10, C20, ...]`` (Pa)."""
    x = i1 - 3.0
    s = 0.0
    xp = 1.0
    for i in range(p.size):
        s += (i + 1) * p[i] * xp
        xp *= x
    return s


@njit(cache=True)
def polynomial2_dw_di1(p, i1, i2):
    """``W = C10 x + C01 y + C20 x^2 + C11 x y + C02 y^2``, ``x = I1-3, y = I2-3``; ``p = [C10, C01, C20, C11, C02]``."""
    return p[0] + 2.0 * p[2] * (i1 - 3.0) + p[3] * (i2 - 3.0)


@njit(cache=True)
def polynomial2_dw_di2(p, i1, i2):
    return p[1] + p[3] * (i1 - 3.0) + 2.0 * p[4] * (i2 - 3.0)


@njit(cache=True)
def lopez_pamies_dw_di1(p, i1, i2):
    """``W = sum_r 3^(1-a_r)/(2 a_r) mu_r (I1^a_r - 3^a_r)``; ``p = [mu1, alpha1, mu2, alpha2, ...]``."""
    s = 0.0
    for r in range(p.size // 2):
        mu, a = p[2 * r], p[2 * r + 1]
        s += 0.5 * 3.0 ** (1.0 - a) * mu * i1 ** (a - 1.0)
    return s


@njit(cache=True)
def gent_dw_di1(p, i1, i2):
    """``W = -mu Jm/2 ln(1 - (I1 - 3)/Jm)``; ``p = [mu, Jm]``; diverges at the locking stretch."""
    return 0.5 * p[0] / (1.0 - (i1 - 3.0) / p[1])


@njit(cache=True)
def exponential_dw_di1(p, i1, i2):
    """Exponential (Demiray 1972) law ``W = mu/(2 b) (exp(b (I1 - 3)) - 1)``; ``p = [mu, b]``.

    Simple shear: ``sigma12 = mu gamma exp(b gamma^2)`` (initial shear modulus ``mu``; ``b`` > 0 stiffens)."""
    return 0.5 * p[0] * np.exp(p[1] * (i1 - 3.0))


_AB_C = np.array([0.5, 1.0 / 20.0, 11.0 / 1050.0, 19.0 / 7000.0, 519.0 / 673750.0])


@njit(cache=True)
def arruda_boyce_dw_di1(p, i1, i2):
    """Arruda-Boyce (5-term Abaqus series) ``W = mu sum_i C_i / lambda_m^(2i-2) (I1^i - 3^i)``; ``p = [mu, lambda_m]``."""
    s = 0.0
    ip = 1.0
    for i in range(5):
        s += (i + 1) * _AB_C[i] / p[1] ** (2 * i) * ip
        ip *= i1
    return p[0] * s


@njit(cache=True)
def ogden_dw_dlambda(p, lam):
    """``w'(lambda)`` of ``W = sum_p 2 mu_p/a_p^2 (l1^a_p + l2^a_p + l3^a_p - 3)``; ``p = [mu1, alpha1, ...]``."""
    s = 0.0
    for r in range(p.size // 2):
        mu, a = p[2 * r], p[2 * r + 1]
        s += 2.0 * mu / a * lam ** (a - 1.0)
    return s


@njit(cache=True)
def polynomial_dw_di1(p, i1, i2):
    """Full polynomial ``W = sum_{1 <= i+j <= N} C_ij (I1-3)^i (I2-3)^j``; ``p`` in the Abaqus order
    ``[C10, C01, C20, C11, C02, C30, C21, C12, C03, ...]`` (total degree ascending, then rising power of
    ``I2 - 3``), ``N(N+3)/2`` coefficients for order ``N`` (Pa)."""
    x = i1 - 3.0
    y = i2 - 3.0
    s = 0.0
    idx = 0
    total = 1
    while idx < p.size:
        for j in range(total + 1):
            i = total - j
            if i > 0:
                s += i * p[idx] * x ** (i - 1) * y ** j
            idx += 1
        total += 1
    return s


# the I2 twin of polynomial_dw_di1 (as for every law here): the FEM kernels call dW/dI1 and dW/dI2 as two
# separate numba functions of (p, i1, i2)
@njit(cache=True)
def polynomial_dw_di2(p, i1, i2):
    x = i1 - 3.0
    y = i2 - 3.0
    s = 0.0
    idx = 0
    total = 1
    while idx < p.size:
        for j in range(total + 1):
            i = total - j
            if j > 0:
                s += j * p[idx] * x ** i * y ** (j - 1)
            idx += 1
        total += 1
    return s


#: Nunes (2011) ``W = C1 (I1bar - 3) + 4/3 C2 (I2bar - 3)^(3/4)``, ``p = [C1, C2]`` (Pa): its ``dW/dI1 = C1`` is the
#: Mooney-Rivlin first derivative (the first parameter), so the same compiled function serves both laws
nunes_dw_di1 = mooney_rivlin_dw_di1


@njit(cache=True)
def nunes_dw_di2(p, i1, i2):
    # W2 = C2 (I2 - 3)^(-1/4) is singular at the reference state, but every stress it enters is multiplied by
    # a factor vanishing faster (simple shear: 2 gamma W2 = 2 C2 gamma^(1/2)), so the limit 0 is the right
    # value there; round-off can also make I2bar - 3 slightly negative in the FEM
    y = i2 - 3.0
    if y <= 0.0:
        return 0.0
    return p[1] * y ** -0.25


@njit(cache=True)
def _power_term(c, x, e):
    """``c x^e`` for ``x = I1 - 3 >= 0``; 0 at the reference state when ``e < 0`` (same limit as Nunes)."""
    if e == 0.0:
        return c
    if x <= 0.0:
        return 0.0
    return c * x ** e


@njit(cache=True)
def amin_dw_di1(p, i1, i2):
    """Amin ``W = C5 (I1-3) + C3/(N+1) (I1-3)^(N+1) + C4/(M+1) (I1-3)^(M+1) + C2 (I2-3)``;
    ``p = [C5, C3, C4, C2, N, M]``."""
    x = i1 - 3.0
    return p[0] + _power_term(p[1], x, p[4]) + _power_term(p[2], x, p[5])


@njit(cache=True)
def amin_dw_di2(p, i1, i2):
    return p[3]


@njit(cache=True)  # the laws arrive as C function pointers (as_cfunc): one cached compile for every law
def _invariant_shear(dw1, dw2, p, gamma):
    n = gamma.size
    sigma = np.empty(n)
    n2 = np.empty(n)
    for k in range(n):
        g = gamma[k]
        i = 3.0 + g * g
        w1 = dw1(p, i, i)
        w2 = dw2(p, i, i)
        sigma[k] = 2.0 * g * (w1 + w2)
        n2[k] = -2.0 * g * g * w2
    return sigma, n2


@njit(cache=True)  # the laws arrive as C function pointers (as_cfunc): one cached compile for every law
def _invariant_uniaxial(dw1, dw2, p, lam):
    out = np.empty(lam.size)
    for k in range(lam.size):
        l = lam[k]
        i1 = l * l + 2.0 / l
        i2 = 2.0 * l + 1.0 / (l * l)
        out[k] = 2.0 * (l - 1.0 / (l * l)) * (dw1(p, i1, i2) + dw2(p, i1, i2) / l)
    return out


@njit(cache=True)  # the laws arrive as C function pointers (as_cfunc): one cached compile for every law
def _stretch_shear(dwl, p, gamma):
    n = gamma.size
    sigma = np.empty(n)
    n2 = np.empty(n)
    t3 = dwl(p, 1.0)
    for k in range(n):
        g = gamma[k]
        l1 = 0.5 * abs(g) + np.sqrt(1.0 + 0.25 * g * g)
        l2 = 1.0 / l1
        t1 = l1 * dwl(p, l1)
        t2 = l2 * dwl(p, l2)
        s = (t1 - t2) / (l1 + l2)
        if g < 0:
            s = -s
        sigma[k] = s
        n2[k] = 0.5 * (t1 + t2 - g * s) - t3
    return sigma, n2


@njit(cache=True)  # the laws arrive as C function pointers (as_cfunc): one cached compile for every law
def _stretch_uniaxial(dwl, p, lam):
    out = np.empty(lam.size)
    for k in range(lam.size):
        l = lam[k]
        lt = 1.0 / np.sqrt(l)
        out[k] = (l * dwl(p, l) - lt * dwl(p, lt)) / l
    return out


# ------------------------------------------------------------------------------------------------------
# model classes
# ------------------------------------------------------------------------------------------------------
_HYPER_RESPONSES = frozenset({"elastic_shear", "shear_history", "normal_stress", "uniaxial"})


def _modulus(name: str, init: float, description: str = "") -> ParamSpec:
    return ParamSpec(name, "Pa", init, 1e-3, 1e8, log=True, description=description)


def _coefficient(name: str, init: float = 0.0) -> ParamSpec:
    # higher-order polynomial coefficients may be negative (softening); fitted on a linear scale
    return ParamSpec(name, "Pa", init, -1e7, 1e7, log=False, description="polynomial coefficient")


def _exponent(name: str, init: float) -> ParamSpec:
    return ParamSpec(name, "1", init, -60.0, 60.0, log=False, description="stretch exponent")


@dataclass
class HyperelasticModel(ConstitutiveModel):
    """An incompressible hyperelastic law given by numba strain-energy derivatives.

    ``kind`` is ``"invariant"`` (``dw_di1``, ``dw_di2``) or ``"stretch"`` (``dw_dlambda``). The shear history
    response is rate independent (the elastic law evaluated at the current strain).
    """

    family: str = "hyperelastic"
    kind: str = "invariant"
    dw_di1: Callable | None = None
    dw_di2: Callable | None = None
    dw_dlambda: Callable | None = None
    responses: frozenset[str] = field(default_factory=lambda: _HYPER_RESPONSES)

    def _vector(self, p: Params) -> np.ndarray:
        return np.array([float(p[n]) for n in self.param_names], dtype=np.float64)

    def _law_functions(self) -> tuple:
        if self.kind == "invariant":
            return as_cfunc(self.dw_di1, INVARIANT_SIG), as_cfunc(self.dw_di2 or zero_dw_di2, INVARIANT_SIG)
        return (as_cfunc(self.dw_dlambda, STRETCH_SIG),)

    def _shear(self, p: Params, strain) -> tuple[np.ndarray, np.ndarray]:
        g = np.ascontiguousarray(np.asarray(strain, dtype=np.float64))
        kernel = _invariant_shear if self.kind == "invariant" else _stretch_shear
        s, n2 = compiled_law_kernel(kernel, self.kind)(*self._law_functions(), self._vector(p), g.ravel())
        return s.reshape(g.shape), n2.reshape(g.shape)

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        """Simple-shear Cauchy shear stress sigma12 (Pa) at amount of shear ``strain``."""
        return self._shear(p, strain)[0]

    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        return self.elastic_shear_stress(p, strain)

    def normal_stress_differences(self, p: Params, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(N1, N2)`` in Pa: ``N1 = gamma sigma12``, ``N2 = sigma22 - sigma33``."""
        s, n2 = self._shear(p, strain)
        return np.asarray(strain, float) * s, n2

    def uniaxial_nominal_stress(self, p: Params, stretch: np.ndarray) -> np.ndarray:
        """Incompressible uniaxial nominal stress P11 (Pa) at stretch ``lambda``."""
        lam = np.ascontiguousarray(np.asarray(stretch, dtype=np.float64))
        kernel = _invariant_uniaxial if self.kind == "invariant" else _stretch_uniaxial
        out = compiled_law_kernel(kernel, self.kind)(*self._law_functions(), self._vector(p), lam.ravel())
        return out.reshape(lam.shape)


@dataclass
class LinearElasticShear(ConstitutiveModel):
    """Linear elastic shear law ``sigma = G gamma`` (small strain; ``N1 = N2 = 0``; uniaxial ``P = 3G(lambda - 1)``).

    The thesis's choice for strains below about 10 % at rate-independent conditions. The one linear-elastic law
    of the package: the modulus is the model's only parameter, whatever its name (``G`` here, the registry's
    ``linear_elastic``; ``G0`` in the QLV family's small-strain instantaneous law, ``models.qlv.LinearElasticShear``,
    which sets only other defaults).
    """

    name: str = "linear_elastic"
    family: str = "hyperelastic"
    param_specs: tuple[ParamSpec, ...] = (_modulus("G", 200.0, "shear modulus"),)
    responses: frozenset[str] = field(default_factory=lambda: _HYPER_RESPONSES)

    @property
    def modulus_name(self) -> str:
        """Name of the shear modulus parameter (the only one)."""
        return self.param_specs[0].name

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        return float(p[self.modulus_name]) * np.asarray(strain, float)

    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        return self.elastic_shear_stress(p, strain)

    def normal_stress_differences(self, p: Params, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        z = np.zeros_like(np.asarray(strain, float))
        return z, z.copy()

    def uniaxial_nominal_stress(self, p: Params, stretch: np.ndarray) -> np.ndarray:
        return 3.0 * float(p[self.modulus_name]) * (np.asarray(stretch, float) - 1.0)


def neo_hookean() -> HyperelasticModel:
    return HyperelasticModel(name="neo_hookean", param_specs=(_modulus("mu", 200.0, "shear modulus"),),
                             dw_di1=neo_hookean_dw_di1)


def mooney_rivlin() -> HyperelasticModel:
    return HyperelasticModel(name="mooney_rivlin", param_specs=(_modulus("C10", 80.0), _modulus("C01", 20.0)),
                             dw_di1=mooney_rivlin_dw_di1, dw_di2=mooney_rivlin_dw_di2)


def reduced_polynomial(order: int, name: str | None = None) -> HyperelasticModel:
    specs = (_modulus("C10", 100.0),) + tuple(_coefficient(f"C{i}0", 10.0) for i in range(2, order + 1))
    return HyperelasticModel(name=name or f"reduced_polynomial{order}", param_specs=specs,
                             dw_di1=reduced_polynomial_dw_di1, structure={"order": order})


def polynomial2() -> HyperelasticModel:
    specs = (_modulus("C10", 80.0), _modulus("C01", 20.0), _coefficient("C20"), _coefficient("C11"),
             _coefficient("C02"))
    return HyperelasticModel(name="polynomial2", param_specs=specs, dw_di1=polynomial2_dw_di1,
                             dw_di2=polynomial2_dw_di2, structure={"order": 2})


def ogden(n_terms: int) -> HyperelasticModel:
    specs = []
    for r in range(1, n_terms + 1):
        specs += [ParamSpec(f"mu{r}", "Pa", 200.0 / n_terms, -1e7, 1e7, description="Ogden modulus"),
                  _exponent(f"alpha{r}", 2.0 + 4.0 * (r - 1) * (-1) ** r)]
    return HyperelasticModel(name=f"ogden{n_terms}", kind="stretch", param_specs=tuple(specs),
                             dw_dlambda=ogden_dw_dlambda, structure={"terms": n_terms})


def lopez_pamies(n_terms: int) -> HyperelasticModel:
    specs = []
    for r in range(1, n_terms + 1):
        specs += [ParamSpec(f"mu{r}", "Pa", 200.0 / n_terms, -1e7, 1e7, description="Lopez-Pamies modulus"),
                  _exponent(f"alpha{r}", 1.0 + 2.0 * (r - 1))]
    return HyperelasticModel(name=f"lopez_pamies{n_terms}", param_specs=tuple(specs),
                             dw_di1=lopez_pamies_dw_di1, structure={"terms": n_terms})


def gent() -> HyperelasticModel:
    specs = (_modulus("mu", 200.0), ParamSpec("Jm", "1", 5.0, 1e-2, 1e4, log=True, description="locking I1-3"))
    return HyperelasticModel(name="gent", param_specs=specs, dw_di1=gent_dw_di1)


def exponential() -> HyperelasticModel:
    """Exponential (Demiray) law ``W = mu/(2 b) (exp(b (I1 - 3)) - 1)`` (Demiray 1972, J. Biomech. 5:309-311;
    Abaqus has no built-in form: a user material). ``b`` is bounded below by 1e-6 (``b -> 0`` is neo-Hookean)."""
    specs = (_modulus("mu", 200.0), ParamSpec("b", "1", 0.5, 1e-6, 100.0, log=True, description="stiffening exponent"))
    return HyperelasticModel(name="exponential", param_specs=specs, dw_di1=exponential_dw_di1)


def arruda_boyce() -> HyperelasticModel:
    specs = (_modulus("mu", 200.0), ParamSpec("lambda_m", "1", 3.0, 1.01, 100.0, log=True,
                                              description="locking chain stretch"))
    return HyperelasticModel(name="arruda_boyce", param_specs=specs, dw_di1=arruda_boyce_dw_di1)


def polynomial(order: int) -> HyperelasticModel:
    """Full polynomial (generalized Mooney-Rivlin) of order ``order``: ``W = sum_{1<=i+j<=N} C_ij x^i y^j``,
    ``x = I1 - 3``, ``y = I2 - 3``; parameters in the Abaqus ``*HYPERELASTIC, POLYNOMIAL, N=order`` order.

    ``C10`` and ``C01`` are positive moduli (fitted on a log scale, as in Mooney-Rivlin); higher coefficients
    may be negative. Order 1 is Mooney-Rivlin. In simple shear ``x = y = gamma^2``, so only the sums
    ``sum_{i+j=k} C_ij`` are identifiable from shear data alone.
    """
    names = [f"C{t - j}{j}" for t in range(1, order + 1) for j in range(t + 1)]
    specs = tuple(_modulus(n, 80.0 if n == "C10" else 20.0) if n in ("C10", "C01") else _coefficient(n)
                  for n in names)
    return HyperelasticModel(name=f"polynomial{order}", param_specs=specs, dw_di1=polynomial_dw_di1,
                             dw_di2=polynomial_dw_di2, structure={"order": order})


def nunes() -> HyperelasticModel:
    """Nunes law ``W = C1 (I1bar - 3) + 4/3 C2 (I2bar - 3)^(3/4)`` (L.C.S. Nunes 2011, Mater. Sci. Eng. A
    528:1799-1804, PDMS in simple shear): ``sigma12 = 2 C1 gamma + 2 C2 gamma^(1/2)``,
    ``N2 = -2 C2 gamma^(3/2)``. Its initial tangent modulus is infinite (square-root softening from zero).
    """
    specs = (_modulus("C1", 80.0, "I1 modulus"), _modulus("C2", 10.0, "I2 modulus of the (I2-3)^(3/4) term"))
    return HyperelasticModel(name="nunes", param_specs=specs, dw_di1=nunes_dw_di1, dw_di2=nunes_dw_di2)


def amin() -> HyperelasticModel:
    """Amin law ``W = C5 (I1-3) + C3/(N+1) (I1-3)^(N+1) + C4/(M+1) (I1-3)^(M+1) + C2 (I2-3)``.

    Introduced for natural and high-damping rubber by Amin et al. (2002, Mech. Mater. 34:75-95) as an extension of
    Yamashita-Kawabata (1992) by a second power term of ``I1 - 3``. Form checked against Hyperelastics.jl's
    ``Amin`` (citing Amin, Wiraguna, Bhuiyan & Okui 2006, J. Eng. Mech. 132(1):54-64), which writes it
    ``C1 (I1-3) + C2/(N+1) (I1-3)^(N+1) + C3/(M+1) (I1-3)^(M+1) + C4 (I2-3)``: the same law with relabelled
    constants (C1 -> C5, C2 -> C3, C3 -> C4, C4 -> C2 here).
    ``W1 = C5 + C3 x^N + C4 x^M`` (``x = I1 - 3``), ``W2 = C2``. Exponents are bounded
    to ``[-0.45, 10]`` so that ``sigma12 = 2 gamma (W1 + W2)`` tends to 0 at ``gamma -> 0``.
    """
    specs = (_modulus("C5", 80.0, "linear I1 modulus"), _coefficient("C3", 10.0), _coefficient("C4", 10.0),
             _modulus("C2", 20.0, "I2 modulus"),
             ParamSpec("N", "1", 1.0, -0.45, 10.0, log=False, description="exponent of the C3 term"),
             ParamSpec("M", "1", 2.0, -0.45, 10.0, log=False, description="exponent of the C4 term"))
    return HyperelasticModel(name="amin", param_specs=specs, dw_di1=amin_dw_di1, dw_di2=amin_dw_di2)


#: registry key -> factory (every model family's MODELS has this shape; models.registry merges them)
MODELS: dict[str, Callable[[], ConstitutiveModel]] = {
    "linear_elastic": LinearElasticShear,
    "neo_hookean": neo_hookean,
    "mooney_rivlin": mooney_rivlin,
    "polynomial2": polynomial2,
    "yeoh": lambda: reduced_polynomial(3, name="yeoh"),
    "gent": gent,
    "exponential": exponential,
    "arruda_boyce": arruda_boyce,
    "nunes": nunes,
    "amin": amin,
}
for _n in range(3, 7):
    MODELS[f"polynomial{_n}"] = (lambda n=_n: polynomial(n))
for _n in range(2, 7):
    MODELS[f"reduced_polynomial{_n}"] = (lambda n=_n: reduced_polynomial(n))
for _n in (1, 2, 3):
    MODELS[f"ogden{_n}"] = (lambda n=_n: ogden(n))
for _n in (1, 2):
    MODELS[f"lopez_pamies{_n}"] = (lambda n=_n: lopez_pamies(n))


def _law_entry(model: HyperelasticModel) -> dict:
    if model.kind == "stretch":
        return {"kind": "stretch", "dW_dlambda": model.dw_dlambda, "param_names": model.param_names}
    return {"kind": "invariant", "dW_dI1": model.dw_di1, "dW_dI2": model.dw_di2 or zero_dw_di2,
            "param_names": model.param_names}


#: law key -> {kind, dW_dI1/dW_dI2 or dW_dlambda (numba), param_names}: the table the FEM adopts
HYPERELASTIC_LAWS: dict[str, dict] = {
    key: _law_entry(factory()) for key, factory in MODELS.items() if key != "linear_elastic"
}


def stability_flags(model: ConstitutiveModel, p: Params, strain_max: float = 0.5,
                    stretch_range: tuple[float, float] = (0.5, 1.5), n: int = 200) -> list[str]:
    """Material-stability checks of fitted parameters (e.g. Ogden with large |alpha|, negative coefficients).

    Returns flags: ``shear_not_monotone`` (d sigma12/d gamma <= 0 somewhere in [0, strain_max]),
    ``negative_initial_modulus``, ``uniaxial_not_monotone`` (Drucker: dP/d lambda <= 0 in ``stretch_range``),
    ``nonfinite_response``. An empty list means stable over the checked ranges.
    """
    flags = []
    gamma = np.linspace(0.0, strain_max, n)
    s = model.elastic_shear_stress(p, gamma)
    lam = np.linspace(*stretch_range, n)
    pu = model.uniaxial_nominal_stress(p, lam) if model.supports("uniaxial") else np.zeros(n)
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(pu))):
        return ["nonfinite_response"]
    if s[1] <= 0.0:
        flags.append("negative_initial_modulus")
    if np.any(np.diff(s) <= 0.0):
        flags.append("shear_not_monotone")
    if model.supports("uniaxial") and np.any(np.diff(pu) <= 0.0):
        flags.append("uniaxial_not_monotone")
    return flags

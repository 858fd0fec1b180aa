"""Common interface of every constitutive model in the library.

A model is an instance of a :class:`ConstitutiveModel` subclass. Its *structure* (number of Prony terms,
polynomial order, fixed relaxation times, the instantaneous law of a QLV model ...) is fixed at
construction; its *parameters* are plain floats passed as a mapping ``{name: value}`` to every prediction
method, so lmfit, the virtual rheometer, the cards and the FEM all call the same pure functions.

Units: parameters carry their unit in :class:`ParamSpec`; stresses and moduli in Pa, times in s, strains
dimensionless (0.01 = 1 %), rates in 1/s, angular frequency in rad/s.

Response kinds (``ConstitutiveModel.responses``), each a method:

===================  =====================================================================================
``shear_history``    :meth:`shear_stress_history` -- homogeneous simple shear, arbitrary strain history
``oscillation``      :meth:`complex_modulus` -- linear (small-amplitude) G*(omega)
``flow``             :meth:`steady_shear_stress` -- steady flow curve tau(shear rate)
``creep``            :meth:`creep_strain` -- strain under an imposed (piecewise) stress history
``elastic_shear``    :meth:`elastic_shear_stress` -- instantaneous/elastic simple-shear law sigma_e(gamma)
``normal_stress``    :meth:`normal_stress_differences` -- N1, N2 in simple shear (elastic)
``uniaxial``         :meth:`uniaxial_nominal_stress` -- incompressible uniaxial nominal stress P(lambda)
===================  =====================================================================================
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

Params = Mapping[str, float]


@dataclass(frozen=True)
class ParamSpec:
    """One model parameter.

    Attributes
    ----------
    name : lmfit-compatible identifier (``[A-Za-z_][A-Za-z0-9_]*``)
    unit : physical unit, e.g. ``"Pa"``, ``"s"``, ``"Pa s^n"``, ``"1"``
    init : default initial value
    lower, upper : bounds (use ``-inf``/``inf`` when unbounded)
    log : fit on a log scale (moduli, times, viscosities)
    description : one line
    """

    name: str
    unit: str
    init: float
    lower: float = -np.inf
    upper: float = np.inf
    log: bool = False
    description: str = ""


class ResponseNotSupported(NotImplementedError):
    """Raised when a model is asked for a response kind it cannot describe."""


@dataclass
class ConstitutiveModel:
    """Base class. Subclasses set ``name``, ``family``, ``param_specs`` and ``responses`` and implement the
    methods of the responses they support.

    ``family`` is one of ``viscous``, ``linear_viscoelastic``, ``fractional``, ``hyperelastic``, ``qlv``,
    ``beyond_qlv``.
    """

    name: str = "base"
    family: str = "base"
    param_specs: tuple[ParamSpec, ...] = field(default_factory=tuple)
    responses: frozenset[str] = frozenset()
    #: extra structural settings recorded with every fit/card (e.g. fixed taus)
    structure: dict = field(default_factory=dict)
    #: ``shear_stress_histories(p, time_s, strain, restart)`` takes concatenated histories (``restart`` marks
    #: where each starts), so several measurements are evaluated in one compiled pass
    concatenated_histories: ClassVar[bool] = False
    #: the stress is linear in the strain history (linear viscoelastic and fractional models): a history scaled by
    #: x gives the stress scaled by x, so the plate quadrature needs the rim history only
    linear_in_strain: ClassVar[bool] = False

    # --- helpers -----------------------------------------------------------------------------------
    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.param_specs)

    def default_params(self) -> dict[str, float]:
        return {p.name: float(p.init) for p in self.param_specs}

    def supports(self, response: str) -> bool:
        return response in self.responses

    def _unsupported(self, response: str):
        raise ResponseNotSupported(f"model {self.name!r} ({self.family}) does not describe {response!r}")

    # --- responses ---------------------------------------------------------------------------------
    def shear_stress_history(self, p: Params, time_s: np.ndarray, strain: np.ndarray) -> np.ndarray:
        """Shear stress (Pa) for a homogeneous simple-shear strain history ``strain(time_s)``.

        ``time_s`` strictly increasing, ``strain[0]`` is the strain at ``time_s[0]`` reached from a
        virgin state (the history before ``time_s[0]`` is zero strain). Between samples the strain is
        linear in time.
        """
        self._unsupported("shear_history")

    def complex_modulus(self, p: Params, angular_frequency_rad_s: np.ndarray) -> np.ndarray:
        """Complex shear modulus G*(omega) = G' + iG'' (Pa) in the linear (small amplitude) limit."""
        self._unsupported("oscillation")

    def steady_shear_stress(self, p: Params, shear_rate_1_s: np.ndarray) -> np.ndarray:
        """Steady shear stress (Pa) at the given shear rates."""
        self._unsupported("flow")

    def creep_strain(self, p: Params, time_s: np.ndarray, stress_pa: np.ndarray) -> np.ndarray:
        """Shear strain under an imposed stress history ``stress_pa(time_s)`` (stress control)."""
        self._unsupported("creep")

    def elastic_shear_stress(self, p: Params, strain: np.ndarray) -> np.ndarray:
        """Instantaneous (elastic) simple-shear stress sigma_e(gamma) in Pa."""
        self._unsupported("elastic_shear")

    def normal_stress_differences(self, p: Params, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Elastic first and second normal stress differences N1 = s11-s22, N2 = s22-s33 (Pa)."""
        self._unsupported("normal_stress")

    def uniaxial_nominal_stress(self, p: Params, stretch: np.ndarray) -> np.ndarray:
        """Incompressible uniaxial nominal (1st Piola-Kirchhoff) stress P11(lambda) in Pa."""
        self._unsupported("uniaxial")


class InstantaneousLawModel(ConstitutiveModel):
    """A model built on an instantaneous elastic law (QLV, Pipkin-Rogers, fractional QLV).

    Subclasses set ``instantaneous`` (a hyperelastic :class:`ConstitutiveModel`) and implement
    ``instantaneous_params(p)``; the instantaneous (t = 0+) normal stress differences are the law's own.
    """

    def instantaneous_params(self, p: Params) -> dict[str, float]:
        raise NotImplementedError

    def normal_stress_differences(self, p: Params, strain: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Instantaneous (t = 0+) N1, N2 of the instantaneous law (Pa)."""
        if not self.supports("normal_stress"):
            self._unsupported("normal_stress")
        return self.instantaneous.normal_stress_differences(self.instantaneous_params(p), np.asarray(strain, float))


# ----------------------------------------------------------------------------------------------------------
# small-strain elastic constants (the one definition of each; cards, QLV/beyond-QLV models, synth and FEM use them)
# ----------------------------------------------------------------------------------------------------------
#: shear-strain step of the numerical initial slope (:func:`initial_shear_modulus`)
SLOPE_STEP = 1e-6


def initial_shear_modulus(model: ConstitutiveModel, p: Params, step: float = SLOPE_STEP) -> float:
    r"""Initial (small-strain, instantaneous) shear modulus of a model, Pa: the one rule, used by the cards, the
    uncertainty stages (``uq.reference_shear_modulus``), the model families and the FEM (``fem.materials``).

    For a model with an elastic shear law (``elastic_shear`` response: hyperelastic laws, the instantaneous law of
    QLV and beyond-QLV models, a FEM material's simple-shear stress):

    .. math:: \mu_0 = \left.\frac{d\sigma_e}{d\gamma}\right|_{\gamma=0}
              \approx \frac{\sigma_e(h) - \sigma_e(-h)}{2h}

    a central difference of :meth:`ConstitutiveModel.elastic_shear_stress` with step :math:`h` (``step``);
    for an isotropic law :math:`\sigma_e` is odd in :math:`\gamma`, so the error is :math:`O(h^2)`. A law whose
    tangent grows without bound as :math:`\gamma \to 0` gives a step-dependent value (``cards.make_card``
    detects that by comparing two steps). A linear viscoelastic model without an elastic law: its relaxation
    modulus at :math:`t = 0` (``relaxation_modulus``; :math:`G_\infty + \sum G_i` of a Prony series). NaN where
    neither gives a finite value (a fluid, a springpot).

    Parameters
    ----------
    model : a model (``elastic_shear`` response, or a ``relaxation_modulus(p, time_s)`` method)
    p : its parameters
    step : the shear-strain step :math:`h`
    """
    if model.supports("elastic_shear"):
        strain = np.array([-step, step])
        s = np.asarray(model.elastic_shear_stress(p, strain), float).reshape(strain.shape)
        return float((s[1] - s[0]) / (2.0 * step))
    relaxation_modulus = getattr(model, "relaxation_modulus", None)
    if relaxation_modulus is not None:
        with np.errstate(all="ignore"):
            g0 = float(np.asarray(relaxation_modulus(p, np.array([0.0])), float).ravel()[0])
        if np.isfinite(g0):
            return g0
    return float("nan")


def bulk_modulus(mu: float, nu: float) -> float:
    r"""Bulk modulus of an isotropic material from its shear modulus and Poisson's ratio, Pa.

    .. math:: K = \frac{2\mu(1+\nu)}{3(1-2\nu)}

    Parameters
    ----------
    mu : shear modulus :math:`\mu` (Pa); for a hyperelastic law its initial shear modulus
    nu : Poisson's ratio :math:`\nu` in (-1, 0.5); the pipeline's value is the configuration's
        ``fem.poisson_ratio`` (there is no default)

    Raises
    ------
    ValueError : ``nu`` outside (-1, 0.5)
    """
    if not -1.0 < nu < 0.5:
        raise ValueError("poisson_ratio must lie in (-1, 0.5)")
    return 2.0 * mu * (1.0 + nu) / (3.0 * (1.0 - 2.0 * nu))

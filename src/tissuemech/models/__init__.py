"""Constitutive model library (one module per family) and the registry that names them."""
from .base import ConstitutiveModel, ParamSpec, ResponseNotSupported  # noqa: F401

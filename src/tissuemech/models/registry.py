"""Name -> model factory registry.

Each family module exposes ``MODELS: dict[str, Callable[[], ConstitutiveModel]]`` mapping a stable key
(used in config files, file names, cards and regression tables, e.g. ``"prony4"``, ``"reduced_polynomial3"``,
``"qlv_rp3_prony4"``) to a zero-argument factory. The registry merges them; keys must be unique.
"""
from __future__ import annotations

from collections.abc import Callable

from . import beyond_qlv, fractional, hyperelastic, linear, qlv, viscous
from .base import ConstitutiveModel

FAMILY_MODULES = (viscous, linear, fractional, hyperelastic, qlv, beyond_qlv)


def _collect() -> dict[str, Callable[[], ConstitutiveModel]]:
    merged: dict[str, Callable[[], ConstitutiveModel]] = {}
    for mod in FAMILY_MODULES:
        for key, factory in mod.MODELS.items():
            if key in merged:
                raise ValueError(f"duplicate model key {key!r} in {mod.__name__}")
            merged[key] = factory
    return merged


def available_models() -> list[str]:
    """Sorted keys of every registered model."""
    return sorted(_collect())


def get_model(key: str) -> ConstitutiveModel:
    """Instantiate a registered model by key; unknown keys raise ``KeyError`` listing the known ones."""
    models = _collect()
    if key not in models:
        raise KeyError(f"unknown model {key!r}; known models: {', '.join(sorted(models))}")
    return models[key]()

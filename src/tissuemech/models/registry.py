"""Name -> model factory registry.

Each family module exposes ``MODELS: dict[str, Callable[[], ConstitutiveModel]]`` mapping a stable key
(used in config files, file names, cards and regression tables, e.g. ``"prony4"``, ``"reduced_polynomial3"``,
``"qlv_rp3_prony4"``) to a zero-argument factory. The registry merges them; keys must be unique.
"""
from __future__ import annotations

import re
from collections.abc import Callable, Mapping, Sequence

import numpy as np

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


#: keys of the fixed-time models (``qlv_<law>_prony<n>``, ``qlv_<law>_fluid<n>``, ``pr_<law>_prony<n>``, each
#: optionally ``_v<k>`` when one scope fits the same law on two sets of times): family, instantaneous-law tag,
#: solid or fluid, number of branches, variant
FIXED_TIME_KEY = re.compile(r"(qlv|pr)_(.+?)_(prony|fluid)(\d+)(?:_v(\d+))?")


def model_on_times(key: str, taus_s: Sequence[float]) -> ConstitutiveModel:
    """The fixed-time QLV or Pipkin-Rogers model ``key`` built on the relaxation times ``taus_s`` [s].

    ``key`` is ``qlv_<law>_prony<n>`` (solid), ``qlv_<law>_fluid<n>`` (fluid: no equilibrium modulus, the slowest
    branch is the reference) or ``pr_<law>_prony<n>``, with ``<law>`` a tag of
    :func:`tissuemech.models.qlv.instantaneous_law`; the model gets one branch per time (``n`` of the key is the
    number of times the key was made for, not checked) and keeps ``key`` as its name. Any other key is returned
    as registered (free times, fractional or flow models choose their own time scales).
    """
    m = FIXED_TIME_KEY.fullmatch(key)
    taus = np.asarray(taus_s, float)
    if m is None or taus.size == 0:
        return get_model(key)
    family, tag, kind, _, _ = m.groups()
    law = qlv.instantaneous_law(tag)
    if family == "qlv":
        return qlv.QLVModel(law, n_prony=taus.size, taus_s=taus, name=key, fluid=kind == "fluid")
    if kind == "fluid":
        raise KeyError(f"no fluid Pipkin-Rogers model ({key!r})")
    return beyond_qlv.PipkinRogersModel(law, taus.size, taus_s=taus, name=key)


def build_model(key: str, structure: Mapping | None = None) -> ConstitutiveModel:
    """The model a fit record or card was made with: its key and recorded ``structure``.

    A fixed-time QLV or Pipkin-Rogers fit records its relaxation times (``structure["taus_s"]``), which the fit
    stage's ``material`` scope chooses from the data, so the key alone does not rebuild it
    (:func:`model_on_times`); every other model is :func:`get_model` of its key.
    """
    taus = (structure or {}).get("taus_s")
    if taus and FIXED_TIME_KEY.fullmatch(key):
        return model_on_times(key, taus)
    return get_model(key)

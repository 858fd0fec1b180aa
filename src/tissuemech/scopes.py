"""What the fit stage fits on a dataset: its scopes (see :mod:`tissuemech.stages`), and the test kinds that get a
relaxation spectrum.

Kept apart from :mod:`tissuemech.stages` so that the workflow's DAG (``workflow/rules/common.smk``), which asks
this at every Snakemake start, a no-op rerun included, imports the model registry only and not the fitting, FEM
and plotting stack (about 3 CPU seconds per start). ``stages`` re-exports every name.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

from .models.registry import available_models

JOINT_SCOPE = "viscoelastic_joint"
ALL_MODES_SCOPE = "all_modes"
#: test kinds whose averaged curves get a relaxation (or retardation) spectrum, ``stages.run_spectrum``
SPECTRUM_TESTS = ("frequency_sweep", "stress_relaxation", "creep_recovery")


def dataset_scopes(tests: Sequence[str], fit_config: Mapping) -> dict[str, dict]:
    """Scopes of a dataset from its test kinds (see :mod:`tissuemech.stages`). Unknown model keys raise ``KeyError``."""
    known = set(available_models())
    tests = set(tests)
    scopes: dict[str, dict] = {}

    def check(keys):
        missing = sorted(set(keys) - known)
        if missing:
            raise KeyError(f"config names unknown models {missing}")
        return list(keys)

    for test, models in fit_config.get("models", {}).items():
        if test in tests and models:
            scopes[test] = {"tests": [test], "models": check(models)}
    joint = fit_config.get("joint_models", [])
    if joint and {"constant_shear_rate", "stress_relaxation"} <= tests:
        scopes[JOINT_SCOPE] = {"tests": ["constant_shear_rate", "stress_relaxation"], "models": check(joint)}
    if {"simple_shear", "uniaxial"} <= tests:
        models = [m for m in fit_config.get("models", {}).get("uniaxial", []) if m != "linear_elastic"]
        if models:
            scopes[ALL_MODES_SCOPE] = {"tests": ["simple_shear", "uniaxial"], "models": check(models)}
    return scopes


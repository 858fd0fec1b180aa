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
#: frequency sweeps at >= 2 temperatures: the shifted sweeps as one curve at Tref (``tts.mastercurve_curve``)
MASTERCURVE_SCOPE = "mastercurve"


def dataset_scopes(tests: Sequence[str], fit_config: Mapping, tts: bool = False) -> dict[str, dict]:
    """Scopes of a dataset from its test kinds (see :mod:`tissuemech.stages`). Unknown model keys raise ``KeyError``.

    ``tts``: the dataset's frequency sweeps carry >= 2 temperatures (the workflow's ``has_tts``: rule ``tts`` writes
    its ``tts.nc``). Then the sweeps are not fitted as if they were one temperature: the plain
    ``frequency_sweep`` scope is left out and the :data:`MASTERCURVE_SCOPE` scope fits the shifted sweeps, one
    curve at the reference temperature, with ``fit.models.mastercurve`` (default: the ``frequency_sweep`` list).
    Its spec carries ``"mastercurve": True``; the fit stage then needs the ``tts.nc`` of the dataset.
    """
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
    if tts and "frequency_sweep" in scopes:
        plain = scopes.pop("frequency_sweep")
        models = fit_config.get("models", {}).get(MASTERCURVE_SCOPE) or plain["models"]
        scopes[MASTERCURVE_SCOPE] = {"tests": ["frequency_sweep"], "models": check(models), "mastercurve": True}
    joint = fit_config.get("joint_models", [])
    if joint and {"constant_shear_rate", "stress_relaxation"} <= tests:
        scopes[JOINT_SCOPE] = {"tests": ["constant_shear_rate", "stress_relaxation"], "models": check(joint)}
    if {"simple_shear", "uniaxial"} <= tests:
        models = [m for m in fit_config.get("models", {}).get("uniaxial", []) if m != "linear_elastic"]
        if models:
            scopes[ALL_MODES_SCOPE] = {"tests": ["simple_shear", "uniaxial"], "models": check(models)}
    return scopes


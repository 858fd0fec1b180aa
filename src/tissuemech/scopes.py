"""What the fit stage fits on a dataset: its scopes (see :mod:`tissuemech.stages`), and the test kinds that get a
relaxation spectrum.

Kept apart from :mod:`tissuemech.stages` so that the workflow's DAG (``workflow/rules/common.smk``), which asks
this at every Snakemake start, a no-op rerun included, imports the model registry only and not the fitting, FEM
and plotting stack (about 3 CPU seconds per start). ``stages`` re-exports every name.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

from .models.registry import available_models

#: one QLV-family model fitted jointly to every viscoelastic shear test of a dataset (:mod:`tissuemech.material`)
MATERIAL_SCOPE = "material"
#: the test kinds the material model describes (flow curves of fluids stay in their own scope)
MATERIAL_TESTS = ("constant_shear_rate", "stress_relaxation", "creep_recovery", "frequency_sweep", "amplitude_sweep")
#: instantaneous-law tags (:func:`tissuemech.models.qlv.instantaneous_law`) the material model's law is chosen among
#: by AICc: neo-Hookean, reduced polynomial 2 and 3, one-term Ogden (either sign of alpha), Gent, two-term
#: Lopez-Pamies, exponential (Demiray)
MATERIAL_LAWS = ("neo_hookean", "rp2", "rp3", "ogden1", "gent", "lp2", "exp")
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

    The :data:`MATERIAL_SCOPE` scope (every dataset with at least one of :data:`MATERIAL_TESTS`; config
    ``fit.material``: ``enabled``, ``laws``) fits one QLV model to all of them (:func:`tissuemech.material.fit_material`);
    its spec has ``"material": True``, the ``laws`` and no ``models`` (the candidates are built on the relaxation
    times the data resolve), and ``"mastercurve": True`` when its sweeps are at several temperatures (the sweeps
    enter shifted to Tref).
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
    material = fit_config.get("material", {})
    shear = [t for t in MATERIAL_TESTS if t in tests]
    if shear and material.get("enabled", True):
        laws = list(material.get("laws") or MATERIAL_LAWS)
        unknown = sorted(set(laws) - set(MATERIAL_LAWS))
        if unknown:
            raise KeyError(f"config fit.material.laws names unknown laws {unknown}; known: {list(MATERIAL_LAWS)}")
        # the candidates' keys follow from the relaxation times the data resolve, so they are not listed here
        scopes[MATERIAL_SCOPE] = {"tests": shear, "models": [], "laws": laws, "material": True,
                                  "points_per_curve": material.get("points_per_curve"),
                                  "mastercurve": bool(tts and "frequency_sweep" in shear)}
    if {"simple_shear", "uniaxial"} <= tests:
        models = [m for m in fit_config.get("models", {}).get("uniaxial", []) if m != "linear_elastic"]
        if models:
            scopes[ALL_MODES_SCOPE] = {"tests": ["simple_shear", "uniaxial"], "models": check(models)}
    return scopes


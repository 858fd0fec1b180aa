"""Diagnosis: what a fitted model gets wrong, the named cause, the fix and its held-out gain.

Modules: :mod:`.evidence` (residual tables, cross-test consistency), the statistics (cluster regression,
Holm) are in :mod:`tissuemech.stats`, below; :mod:`.catalogue` (named causes, detectors, fixes), :mod:`.temperature` (temperature dependence, TTS fix),
:mod:`.inertia` (inertia-dominated oscillation points), :mod:`.causes` (registry of every named cause),
:mod:`.generic` (unnamed structure, confounded covariates),
:mod:`.baseline` (fitted models on runs, extension fits), :mod:`.homogeneous` (simple shear + uniaxial
specimens: cross-mode prediction, tension-compression asymmetry, I2 identifiability), :mod:`.report`
(``diagnose``, ``run_diagnosis``, JSON/netCDF/figures).
"""
from .catalogue import CATALOGUE_IDS  # noqa: F401
from .causes import CAUSE_IDS  # noqa: F401

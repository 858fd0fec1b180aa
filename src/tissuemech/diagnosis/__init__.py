"""Diagnosis: what a fitted model gets wrong, the named cause, the fix and its held-out gain.

Modules: :mod:`.evidence` (residual tables, cross-test consistency), :mod:`.stats` (residual-structure
statistics, Holm), :mod:`.catalogue` (named causes, detectors, fixes), :mod:`.generic` (unnamed structure),
:mod:`.baseline` (fitted models on runs, extension fits), :mod:`.homogeneous` (simple shear + uniaxial
specimens: cross-mode prediction, tension-compression asymmetry, I2 identifiability), :mod:`.report`
(``diagnose``, ``run_diagnosis``, JSON/netCDF/figures).
"""
from .catalogue import CATALOGUE_IDS  # noqa: F401

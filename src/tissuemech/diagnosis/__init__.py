"""Diagnosis: what a fitted model gets wrong, the named cause, the fix and its held-out gain.

One module a stage: :mod:`.baseline` (fitted models on the runs, extension fits) -> :mod:`.noise` (the noise of the
data) -> :mod:`.evidence` (residual tables, cross-test consistency) -> detectors (:mod:`.levels`,
:mod:`.oscillation`, :mod:`.time_domain`, :mod:`.inertia`, :mod:`.temperature`; unnamed structure in
:mod:`.generic` and :mod:`.covariates`; the shared finding records in :mod:`.findings`, the contract in
:mod:`.catalogue`) registered once in :mod:`.causes` -> :mod:`.decision` (the one rule) -> :mod:`.fixes` (fixes
that refit the baseline) -> :mod:`.report` (``diagnose``, ``run_diagnosis``, JSON/netCDF) and :mod:`.figures`.
:mod:`.homogeneous` diagnoses simple shear + uniaxial specimens (cross-mode prediction, tension-compression
asymmetry, I2 identifiability) under the same rule. The statistics (cluster regression, mixed models, Holm) are
in :mod:`tissuemech.stats`, below.
"""
from .causes import CATALOGUE_IDS, CAUSE_IDS  # noqa: F401

"""The catalogue of named causes of model-data discrepancy (``science.md`` sections 2, 3 and 4.4): the finding
contract every detector follows, and the detectors' public names in one place.

The causes themselves -- ids, detectors, signatures and what to do -- are registered once, in :mod:`.causes`;
how a cause is named is :mod:`.decision`'s one rule. Every detector ``detect_<id>(ctx) -> dict`` returns a
*finding*:

``effect``            the cause id (:data:`~tissuemech.diagnosis.causes.CAUSE_IDS`)
``tested``            False when the data cannot test it (e.g. no frequency sweep); then p_value is NaN and the
                      evidence says what is missing
``statistic``         the test statistic (t, F, ... named in ``statistic_name``)
``p_value``/``log10_p`` the uncorrected p-value
``effect_size``       physical size of the effect in ``effect_size_unit``
``practical``         True when the effect size exceeds the practical threshold of the cause (dense curves make
                      tiny misfits significant)
``evidence``          a sentence naming tests, conditions and covariates, with bounded wording
``fix``               ``{model, metric, before, after, gain, cv, parameters}`` -- the correction or extension that
                      removes the cause, scored on held-out data; ``gain`` is ``(before - after) / before``;
                      ``parameters.n_held_out_points`` the held-out values its metric pools
``baseline_free``     (optional) True when test and fix do not use the baseline's predictions

The current rule (:data:`tissuemech.diagnosis.decision.DECISION_RULE`, written into every ``diagnosis.json`` as
``decision_rule``, the same for parallel-plate and multi-mode data): a cause is named only when its test is
significant after Holm at the family-wise alpha (alpha/2 to the named causes, alpha/2 to the scan for unnamed
structure), its effect is practically relevant, *and* its fix, scored on held-out data, lowers the held-out error
by more than the noise margin z_(1-alpha) eps/sqrt(2 n). A significant, relevant cause whose fix was not scored
is listed in ``significant_fix_not_evaluated`` and not named; a scored fix that does not beat the margin does not
name it either. The decision adds ``p_holm``, ``significant``, ``detected``, ``decision`` and ``what_to_do``.

The signature matrix of ``science.md`` 4.4 is built into the detectors: the within-ramp residual
regressions of non-separability (strain^2 x log-rate) and wall slip (stress threshold / gap) share one design
with the rim-error (strain^2, strain^3) and offset (1/stress) signatures as controls and each other's
covariate as a control; drift is read from curve levels within samples, else within specimens, with specimen and
sample as random effects (:func:`~tissuemech.diagnosis.levels.within_test`), never from a fixed test order or
from the specimens' differences; preconditioning by the model-free paired comparison of
whatever test came first on each sample with later repeats of a comparable measurement and by the first-load
indicator within samples; amplitude softening and large-strain yield or slip from the amplitude sweeps themselves
(the raw phase tells a sample that yields at low frequency from inertia at high frequency); inertial ringing in
relaxations and creep. Curve-level detectors assume no test order, specimen or sample count: the order of the
tests on a sample comes from ``order``, else ``started_at``, else ``total_time``; where the design cannot
separate a covariate from the test sequence, the first load, the logged temperature or the condition the finding
lists them in ``confounded_with`` with the design that would separate them in ``separating_design``
(:data:`~tissuemech.diagnosis.findings.SEPARATING_DESIGN`).

Homogeneous multi-mode data (simple shear + uniaxial compression/tension) are diagnosed by
:mod:`.homogeneous`, which adds ``tension_compression_asymmetry`` and tests ``unidentified_i2_dependence`` from
the mode combination instead of the normal force.

Inputs (:class:`~tissuemech.diagnosis.findings.DiagnosisContext`): the canonical runs, the residual table of the
baseline model (:func:`tissuemech.diagnosis.evidence.residual_table`) and ``fit_info`` -- how the baseline was
fitted: ``target`` (the plate targets of :mod:`tissuemech.fitting`: ``"thesis"``: reported 2M/(pi R^3) taken as
rim stress; ``"apparent_stress"``/``"torque"``: plate forward model; ``"corrected_stress"``: Rabinowitsch),
``relaxation`` (``"step"`` or ``"ramp"``/``"measured"``) and optionally ``correlations`` ({"p1|p2": rho}).
"""
from __future__ import annotations

from .causes import CATALOGUE_IDS, CAUSE_IDS, DETECTORS, explains
from .findings import DiagnosisContext, curve_levels
from .inertia import detect_inertia_dominated_points, detect_inertial_ringing, detect_yield_or_slip
from .levels import (detect_elapsed_time_drift, detect_outlier_specimen, detect_preconditioning, paired_first_load_test,
                     within_test)
from .oscillation import detect_amplitude_softening, detect_instrument_inertia, raw_phase_inertia
from .temperature import detect_temperature_dependence
from .time_domain import (detect_finite_rise_time, detect_nonseparable_relaxation, detect_rim_stress_nonlinearity,
                          detect_torque_offset, detect_unidentified_i2_dependence, detect_wall_slip)

__all__ = ["CATALOGUE_IDS", "CAUSE_IDS", "DETECTORS", "DiagnosisContext", "curve_levels",
           "detect_amplitude_softening", "detect_elapsed_time_drift", "detect_finite_rise_time",
           "detect_inertia_dominated_points", "detect_inertial_ringing", "detect_instrument_inertia",
           "detect_nonseparable_relaxation", "detect_outlier_specimen", "detect_preconditioning",
           "detect_rim_stress_nonlinearity", "detect_temperature_dependence", "detect_torque_offset",
           "detect_unidentified_i2_dependence", "detect_wall_slip", "detect_yield_or_slip", "explains",
           "paired_first_load_test", "raw_phase_inertia", "within_test"]

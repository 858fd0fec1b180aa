"""Catalogue of named causes of model-data discrepancy (``science.md`` sections 2, 3 and 4.4).

Every cause has one detector ``detect_<id>(ctx) -> dict`` that returns a *finding*:

``effect``            the catalogue id (:data:`CATALOGUE_IDS`)
``tested``            False when the data cannot test it (e.g. no frequency sweep); then p_value is NaN
``statistic``         the test statistic (t, F, ... named in ``statistic_name``)
``p_value``/``log10_p`` the uncorrected p-value (Holm across all tests is applied in :mod:`.report`)
``effect_size``       physical size of the effect in ``effect_size_unit``
``practical``         True when the effect size exceeds the practical threshold of the cause (a finding
                      needs statistical *and* practical significance; dense curves make tiny misfits
                      significant)
``evidence``          a sentence naming tests, conditions and covariates
``fix``               ``{model, metric, before, after, gain, cv, parameters}`` -- the correction or
                      extension that removes the cause, scored on held-out data; ``gain`` is the relative
                      reduction ``(before - after) / before``

The signature matrix of ``science.md`` 4.4 is built into the detectors: the within-ramp residual
regressions of non-separability (strain^2 x log-rate) and wall slip (stress threshold / gap) share one design
with the rim-error (strain^2, strain^3) and offset (1/stress) signatures as controls and each other's
covariate as a control; drift is read from curve levels within samples (sample + condition fixed effects)
and between samples (two-stage on sample means, :func:`between_sample_test`), never from a fixed test order
alone; preconditioning by the model-free paired comparison of whatever test came first on each sample with
later repeats of a comparable measurement (:func:`paired_first_load_test`) and by the first-load indicator
within samples. Curve-level detectors assume no test order, specimen or sample count: the order of the tests
on a sample comes from ``order``, else ``started_at``, else ``total_time`` (:func:`curve_levels`); drift and
first load are each controlled for the other, and where the design cannot separate a covariate from the
test sequence, the first load, the logged temperature or the condition (a fixed order) the finding lists
them in ``confounded_with`` with the design that would separate them in ``separating_design``. A cause is
named (in :mod:`.report`) only when it passes Holm, is practically relevant and its fix does not lose on
held-out data.

Homogeneous multi-mode data (simple shear + uniaxial compression/tension) are diagnosed by
:mod:`.homogeneous`, which adds the cross-mode id ``tension_compression_asymmetry`` and tests
``unidentified_i2_dependence`` from the mode combination instead of the normal force.

Inputs (:class:`DiagnosisContext`): the canonical runs, the residual table of the baseline model
(:func:`tissuemech.diagnosis.evidence.residual_table`) and ``fit_info`` -- how the baseline was fitted:
``target`` (the plate targets of :mod:`tissuemech.fitting`: ``"thesis"``: reported 2M/(pi R^3) taken as rim
stress; ``"apparent_stress"``/``"torque"``: plate forward model; ``"corrected_stress"``: Rabinowitsch), ``relaxation`` (``"step"`` or ``"ramp"``) and
optionally ``correlations`` ({"p1|p2": rho}) of the fitted parameters.
"""
from __future__ import annotations

from collections.abc import Callable

from .findings import (CATALOGUE_IDS, DISTORTS, DiagnosisContext, EXPLAINS, TIME_DOMAIN, curve_levels,
                       cv_group_column, demean_by, explains, fix_record, fixed_effect_design, group_cv,
                       make_finding, primary_rows, rms, untested_finding)
from .levels import (CONFOUND_CORRELATION, FIXED_EFFECT_SETS, SEPARATING_DESIGN, TIME_TEMPERATURE_R2,
                     between_sample_test, detect_elapsed_time_drift, detect_outlier_specimen,
                     detect_preconditioning, level_regression, paired_first_load_test, specimen_levels)
from .oscillation import (detect_amplitude_softening, detect_instrument_inertia,
                          raw_phase_inertia, spectrum_shape_basis)
from .time_domain import (RIM_BIASED_TARGETS, detect_finite_rise_time, detect_nonseparable_relaxation,
                          detect_rim_stress_nonlinearity, detect_torque_offset, detect_unidentified_i2_dependence,
                          detect_wall_slip)

DETECTORS: dict[str, Callable[[DiagnosisContext], dict]] = {
    "nonseparable_relaxation": detect_nonseparable_relaxation,
    "rim_stress_nonlinearity": detect_rim_stress_nonlinearity,
    "wall_slip": detect_wall_slip,
    "elapsed_time_drift": detect_elapsed_time_drift,
    "preconditioning": detect_preconditioning,
    "instrument_inertia": detect_instrument_inertia,
    "torque_offset": detect_torque_offset,
    "outlier_specimen": detect_outlier_specimen,
    "amplitude_softening": detect_amplitude_softening,
    "finite_rise_time": detect_finite_rise_time,
    "unidentified_i2_dependence": detect_unidentified_i2_dependence,
}
assert tuple(DETECTORS) == CATALOGUE_IDS

__all__ = ['CATALOGUE_IDS', 'CONFOUND_CORRELATION', 'DETECTORS', 'DISTORTS', 'DiagnosisContext', 'EXPLAINS',
           'FIXED_EFFECT_SETS', 'RIM_BIASED_TARGETS', 'SEPARATING_DESIGN', 'TIME_DOMAIN',
           'TIME_TEMPERATURE_R2', 'between_sample_test', 'curve_levels', 'cv_group_column', 'demean_by',
           'detect_amplitude_softening', 'detect_elapsed_time_drift', 'detect_finite_rise_time',
           'detect_instrument_inertia', 'detect_nonseparable_relaxation', 'detect_outlier_specimen',
           'detect_preconditioning', 'detect_rim_stress_nonlinearity', 'detect_torque_offset',
           'detect_unidentified_i2_dependence', 'detect_wall_slip', 'explains', 'fix_record', 'fixed_effect_design',
           'group_cv', 'level_regression', 'make_finding', 'paired_first_load_test', 'primary_rows',
           'raw_phase_inertia', 'rms', 'specimen_levels', 'spectrum_shape_basis', 'untested_finding']

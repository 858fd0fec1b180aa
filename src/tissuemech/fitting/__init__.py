"""Least-squares fitting of constitutive models to rheometer curves (lmfit).

A package of small private modules, each re-exported here (``__all__``), so ``from tissuemech.fitting import X``
and ``fitting.X`` are the only names to use: ``_data`` (:class:`Curve`, builders and selectors), ``_problem``
(plate targets, :func:`predict`, :class:`NoiseModel`, :class:`FitProblem`), ``_fit`` (:func:`fit`,
:class:`FitResult`, flags, the fit-record netCDF and ``fits.csv`` row) and ``_prony`` (:func:`prony_nnls`,
:func:`prony_start`).

Three layers:

1. **Data selection** -- :class:`Curve` is one curve to fit (one test at one condition, an average over
   samples or a single run) with the inputs the model needs (a strain history, angular frequencies, shear
   rates, an imposed stress history, strains or stretches), the observed values, their sample SD and the
   bookkeeping (test, condition, specimen, geometry). Builders turn canonical runs
   (:func:`curve_from_run`) or averaged curves (:func:`curves_from_averages`) into curves; selectors
   restrict the strain range or thin dense curves to log-spaced points (dense rheometer curves have
   autocorrelated residuals; thinning keeps the information criteria honest, ``science.md`` section 4.2).
2. **Problem** -- :class:`FitProblem` joins any number of curves for one model (joint fits across tests and
   conditions, e.g. QLV on every CSR rate plus relaxation), the parallel-plate *target* (how a model
   prediction is compared with rim data, recorded with every fit) and the noise model. Residuals are
   weighted by ``max(sample SD, noise floor)``; oscillation and flow curves use log residuals because they
   span decades.
3. **Fit** -- :func:`fit` runs lmfit (``least_squares``/TRF with bounds) on log10-transformed moduli and times,
   from the model's start, an optional supplied start (e.g. :func:`prony_nnls`) and seeded random starts,
   keeps the best, and returns a :class:`FitResult` with parameters, propagated standard errors,
   correlation matrix, identifiability and convergence flags, chi-square, RMSE, AIC/AICc/BIC (with n and
   with the effective n from lag-1 residual autocorrelation), residuals and the data selection.

Plate targets (``science.md`` section 2.1) for curves measured between parallel plates (the choice is
recorded with every fit):

``thesis``
    the thesis method: the reported apparent rim stress 2M/(pi R^3) is taken as the true rim stress and
    compared with the homogeneous model at the rim strain. Exact for linear materials only; biases
    stiffening terms (C20 -> 2/3, C30 -> 1/2 of the truth).
``apparent_stress``
    the reported apparent rim stress is compared with the model's apparent rim stress 2M/(pi R^3), M from
    the radial integral (``models.plate.forward_plate``, every radius with its own history). Unbiased.
``corrected_stress``
    the homogeneous model at the rim strain is compared with the Rabinowitsch-corrected data
    sigma_R = M/(2 pi R^3) (3 + d ln M / d ln gamma_R) (``models.plate.rabinowitsch_rim_stress``; needs a
    monotone strain or rate sweep).
``torque``
    the model's torque through the radial integral is compared with the measured torque (or the reported
    stress x pi R^3 / 2 when the export has no torque).
``none``
    homogeneous tests (simple shear/uniaxial specimens, e.g. Budday): no plate.

Oscillation (linear: the apparent stress is exact), creep and homogeneous tests do not depend on the
target.
"""
from __future__ import annotations

from ..records import FitRecord
from ..spectra import log_spaced_taus
from ._data import (TEST_RESPONSE, Curve, amplitude_sweep_curve, amplitude_sweep_lve_curve, curve_and_rows, curve_from_run, curve_ranges,
                    curves_from_averages, geometry_from_runs, loading_phases, relaxation_history, select_strain, thin,
                    with_relaxation_history)
from ._fit import (CORRELATION_FLAG, EQUIVALENT_CHISQR_RTOL, FITS_CSV_ATTRS, FitResult, at_bound_parameters, evaluate,
                   fit, fit_to_dataset, fits_csv_row, has_covariance, weights_at_upper_bound, write_fit_netcdf)
from ._problem import (AMPLITUDE_SWEEP_CYCLES, LOG_RESPONSES, PLATE_TARGETS, FitProblem, NoiseModel, describes,
                       oscillation_window_bounds, plate_factor, predict, target_observations)
from ._prony import prony_nnls, prony_start


__all__ = [
    "PLATE_TARGETS", "TEST_RESPONSE", "LOG_RESPONSES", "CORRELATION_FLAG", "EQUIVALENT_CHISQR_RTOL",
    "AMPLITUDE_SWEEP_CYCLES", "describes", "amplitude_sweep_curve",
    "Curve", "amplitude_sweep_lve_curve", "curve_from_run", "curve_and_rows", "curves_from_averages",
    "geometry_from_runs", "loading_phases", "relaxation_history", "thin", "select_strain", "with_relaxation_history", "curve_ranges",
    "plate_factor", "target_observations", "predict", "oscillation_window_bounds",
    "NoiseModel", "FitProblem", "FitResult", "fit", "evaluate", "log_spaced_taus",
    "prony_nnls", "prony_start", "FitRecord", "fit_to_dataset", "write_fit_netcdf", "fits_csv_row", "FITS_CSV_ATTRS",
    "at_bound_parameters", "has_covariance", "weights_at_upper_bound",
]

"""The reported optimum is the optimum, not where the solver's default tolerances stopped.

Oracle: the optimality of the result itself. A further least-squares run from the reported parameters with much
tighter tolerances must lower chi-square by no more than 1e-3 and move no parameter by more than 1e-3 of its standard
error. Measured on the bundled
brain (28 Nov 2026): with the polish 6e-6 (Prony stress relaxation) and 3e-6 (Burgers creep); with scipy's default
1e-8 tolerances alone 3.2e-4 and 1.9e-4, and the flat Burgers valley stopped at machine-dependent points 1e-3
standard errors apart on a Zen 4 and a Zen 5 CPU (tests/regression).
"""
import tempfile
import warnings

import lmfit
import numpy as np
import pytest

from tissuemech import ranking as R
from tissuemech import regression as REG
from tissuemech.fitting import FitProblem, NoiseModel


@pytest.fixture(scope="module")
def brain_scopes(repo_root):
    settings = REG.fit_settings(repo_root / "config" / "config.yaml")
    with tempfile.TemporaryDirectory() as work:
        averages, tests = REG.dataset_averages(repo_root / "raw" / "porcine_brain_thesis", work, exclude_flagged=True)
    return settings, averages, REG.dataset_scopes(tests, settings)


@pytest.mark.parametrize("scope, model", [("stress_relaxation", "prony3"), ("creep_recovery", "burgers")])
def test_a_tighter_refit_does_not_move_the_reported_optimum(brain_scopes, scope, model):
    settings, averages, scopes = brain_scopes
    curves = REG.scope_curves(averages, scopes[scope]["tests"])
    factory = R.RegistryFactory(model)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        result = R.fit_candidate(R.Candidate(model, factory), curves, settings["plate_target"], scope,
                                 n_random=int(settings["multistart"]), seed=int(settings["seed"]))
        problem = FitProblem(model=factory(), curves=list(curves), target=settings["plate_target"],
                             noise=NoiseModel(), scope=scope)
        refit = lmfit.minimize(problem.residual, problem.make_params(result.params), method="least_squares",
                               xtol=1e-15, ftol=1e-15, gtol=1e-15)
    moved = {k: abs(v - result.params[k]) / result.stderr[k] for k, v in problem.natural(refit.params).items()
             if np.isfinite(result.stderr[k]) and result.stderr[k] > 0}
    # the optimum: a tighter solver lowers chi-square by no more than 1e-3 (a standard error is where it rises by 1),
    # and moves no parameter by a measurable fraction of its standard error (the flat Burgers valley lets it wander
    # 4e-4 SE on a Zen 4 CPU for a 4e-7 chi-square gain; without the polish the reported point sat 1e-3 SE from where
    # another machine stopped)
    assert float(refit.chisqr) >= result.chisqr - 1e-3, (float(refit.chisqr), result.chisqr)
    assert moved and max(moved.values()) < 1e-3, moved

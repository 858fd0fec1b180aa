"""A misfit shape along log omega that every predicted frequency sweep shares is a statement about the
baseline's spectrum: reported in baseline.cross_test_shape, removed before the covariate scan of those curves.
Structure that differs between the curves is still found."""
import numpy as np
import pandas as pd

from tissuemech.diagnosis.generic import shared_shape, structure_tests


def _sweeps(seed, slope_with_level=0.0, n_curves=6, common_shape=lambda z: 0.15 * np.sin(1.3 * z) + 0.05 * z):
    rng = np.random.default_rng(seed)
    w = np.logspace(-1, 2, 16)                                  # rad/s
    rows = []
    for c in range(n_curves):
        level = 1000.0 * np.exp(rng.normal(0, 0.2))
        z = np.log10(w)
        common = common_shape(z)                                 # the baseline's spectrum misfit, same for all
        own = slope_with_level * (c - n_curves / 2) * z          # a shape that differs between curves
        lr = common + own + rng.normal(0, 0.01, w.size)
        pred = level * w ** 0.2
        for k in range(w.size):
            rows.append({"curve": f"c{c}", "test": "frequency_sweep", "quantity": "storage_modulus",
                         "log_ratio": lr[k], "predicted_abs": pred[k], "sigma": 0.01 * pred[k],
                         "frequency_sq": w[k] ** 2, "log_time": np.log10(10.0 * (k + 1)),
                         "specimen": f"s{c}", "sample": f"s{c}a", "condition": "fs"})
    return pd.DataFrame(rows)


def test_a_shared_spectrum_misfit_is_a_baseline_statement_not_structure():
    table = _sweeps(1)
    # scanned as if the baseline had been fitted to the sweeps: the shared shape is structure along frequency
    fitted = structure_tests(table)
    assert any(g["covariate"] == "frequency_sq" and g["p_value"] < 1e-4 and g["practical"] for g in fitted)
    shapes = []
    predicted = structure_tests(table, ["frequency_sweep"], shapes)
    assert not any(g["p_value"] < 1e-3 and g["practical"] for g in predicted)
    assert len(shapes) == 1 and shapes[0]["test"] == "frequency_sweep" and shapes[0]["degree"] >= 3  # a sine over 3.9 rad
    # the true shape spans 0.15 (sin over 1.3*3 rad covers its full range) + 0.05*3: at least 0.3 in log
    assert shapes[0]["range_log"] > 0.3 and shapes[0]["wald_p"] < 1e-3


def test_structure_that_differs_between_predicted_sweeps_is_still_tested():
    table = _sweeps(2, slope_with_level=0.03)
    shape, summary = shared_shape(table, "frequency_sq")
    assert np.allclose(pd.Series(shape).groupby(table["curve"].to_numpy()).mean(), 0.0, atol=1e-12)  # levels kept
    residual = table["log_ratio"] - shape
    # what is left after the shared shape still carries the curve-specific slope: its size is what was put in
    slopes = [np.polyfit(np.log10(np.sqrt(g["frequency_sq"])), residual[g.index], 1)[0]
              for _, g in table.groupby("curve")]
    assert np.ptp(slopes) > 0.1                                  # 0.03 x 5 curves apart = 0.15 put in
    assert summary["n_curves"] == 6


def test_the_shared_shapes_degree_is_chosen_by_the_data():
    """BIC picks the degree: a straight line in log omega stays degree 1, a sigmoid step of the loss modulus
    over the last decade (a fast mode outside the fitted tests' window) needs more than a cubic, and after
    removing it nothing is left to scan."""
    _, line = shared_shape(_sweeps(3, common_shape=lambda z: 0.1 * z), "frequency_sq")
    assert line["degree"] == 1
    step = _sweeps(4, common_shape=lambda z: 2.8 / (1 + np.exp(-4 * (z - 1.5))))
    shapes = []
    found = structure_tests(step, ["frequency_sweep"], shapes)
    assert shapes[0]["degree"] > 3
    assert not any(g["p_value"] < 1e-3 and g["practical"] for g in found)

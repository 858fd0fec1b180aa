"""The diagnose stage on virtual-rheometer data: synth dataset -> canonical runs -> baseline fit -> diagnosis.

The canonical runs are built from the generator's own channels and samples.csv rows (what ingest returns
for these files; the round trip of the export is the ingest tests' business), the baseline is fitted with
:func:`tissuemech.diagnosis.baseline.fit_runs` (lmfit through :mod:`tissuemech.fitting`) to the ramps and
relaxations, and every run is predicted with it.
"""
from __future__ import annotations

import warnings

import numpy as np

from tissuemech.canonical import make_run_dataset
from tissuemech.diagnosis.baseline import fit_runs, predict_runs
from tissuemech.diagnosis.evidence import residual_table
from tissuemech.diagnosis.report import diagnose, with_model_fixes
from tissuemech.synth.generator import generate_dataset

TAUS = [0.1, 1.0, 10.0, 100.0]
#: small thesis-like design: every sample runs AS, FS, three CSR rates and four relaxations in order
TESTS = ([{"test": "amplitude_sweep", "settings": {"n_points": 12, "strain_max": 0.05}},
          {"test": "frequency_sweep", "settings": {"n_points": 10}}]
         + [{"test": "constant_shear_rate", "settings": {"shear_rate_1_s": r, "n_points": 16}} for r in (0.001, 0.01, 0.1)]
         + [{"test": "stress_relaxation", "settings": {"strain": s, "n_points": 16, "hold_s": 100.0}}
            for s in (0.01, 0.1, 0.2, 0.4)])

#: 6 specimens x 2 samples, test order shuffled per sample after the leading amplitude sweep
DESIGN = {"specimens": 6, "samples": 2, "order": "shuffled"}
#: how the baseline is fitted for an effect (default: linear QLV through the torque, measured strain history)
ANALYSIS = {
    "finite_rise_time": {"relaxation": "step"},   # data with a 0.5 s ramp, analysed as a step
    # a stiffening law fitted the thesis way: homogeneous law at the rim strain vs the reported 2M/(pi R^3)
    "rim_stress_nonlinearity": {"baseline": "qlv_rp2_prony4", "target": "thesis"},
}


def config(effect: str | None, magnitude: float = 1.0, specimens: int = 4, samples: int = 2,
           specimen_log_sd: float = 0.25, pause_s: float = 120.0, order: str = "fixed") -> dict:
    from tissuemech.synth.effects import DEFAULTS

    effects = {}
    if effect:
        # scale the magnitude parameter of the effect (the first default is its size)
        params = dict(DEFAULTS[effect])
        key = next(iter(params))
        if effect == "outlier_specimen":
            params[key] = 1.0 + (params[key] - 1.0) * magnitude
        else:
            params[key] = params[key] * magnitude
        effects[effect] = params
    return {"name": f"hidden_{effect or 'null'}", "temperature_c": 37.0,
            "geometry": {"radius_mm": 12.5, "gap_mm": [2.0, 4.0]},
            "truth": {"model": {"kind": "qlv", "instantaneous": "linear", "taus_s": TAUS},
                      "params": {"G0": 200.0, "beta_1": 0.3, "beta_2": 0.5, "beta_3": 0.4, "beta_4": 0.2}},
            "variability": {"specimen_log_sd": specimen_log_sd, "sample_log_sd": 0.1},
            "effects": effects, "session": {"pause_between_tests_s": pause_s, "loading_time_s": 300.0},
            "sequence": {"specimens": specimens, "samples_per_specimen": samples, "tests": TESTS, "order": order}}


def synth_runs(cfg: dict, seed: int, out_dir) -> list:
    gen = generate_dataset(cfg, seed, out_dir)
    runs = []
    for fname, item in gen["runs"].items():
        meta = item["meta"]
        attrs = {"dataset": cfg["name"], "run": fname, "test": meta["test"], "specimen": meta["specimen"],
                 "sample": meta["sample"], "order": int(meta["order"]), "source_file": fname,
                 "source_sha256": "synthetic", "radius_m": meta["radius_mm"] * 1e-3, "gap_m": meta["gap_mm"] * 1e-3,
                 "temperature_c": meta["temperature_c"], "started_at": meta["started_at"]}
        for k in ("shear_rate_1_per_s", "strain_pct", "stress_pa", "frequency_hz"):
            if meta.get(k) is not None:
                attrs[k] = float(meta[k])
        runs.append(make_run_dataset({k: np.asarray(v, float) for k, v in item["channels"].items()}, attrs))
    return runs


def diagnose_synthetic(effect: str | None, seed: int, out_dir, magnitude: float = 1.0, baseline="qlv_linear_prony4",
                       target="torque", relaxation="measured", **design):
    """Generate, fit the baseline to the ramps and relaxations, diagnose. Returns (runs, table, result, fit).

    ``design``: ``specimens``, ``samples`` (per specimen) of :func:`config`."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cfg = config(effect, magnitude, **design)
        runs = synth_runs(cfg, seed, out_dir)
        shear = [r for r in runs if r.attrs["test"] in ("constant_shear_rate", "stress_relaxation")]
        fit = fit_runs(baseline, shear, target, relaxation, n_points=16)
        from tissuemech.models.registry import get_model
        preds = predict_runs(get_model(baseline), fit.params, runs, target, relaxation)
        keep = [i for i, p in enumerate(preds) if p]
        table = residual_table([runs[i] for i in keep], [preds[i] for i in keep], baseline)
        fit_info = {"target": target, "relaxation": relaxation, "correlations": {},
                    "fitted_tests": ["constant_shear_rate", "stress_relaxation"]}
        result = diagnose([runs[i] for i in keep], table, baseline, fit_info)
        # model-level fixes (refits) are scored as run_diagnosis does, so the decision rule is the pipeline's
        result = with_model_fixes(result, [runs[i] for i in keep], table, fit_info)
    return runs, table, result, fit

"""Dataset generator: a config (YAML mapping) + a seed -> a dataset folder as a lab would drop it.

Config keys (see ``config/synth/*.yaml`` for complete examples):

``name``, ``material``, ``species``, ``tissue``, ``temperature_c``, ``license``, ``citation``
    dataset metadata (dataset.yaml)
``geometry``
    ``radius_mm`` and ``gap_mm`` (a number, or ``[min, max]``: each sample's gap drawn uniformly)
``truth``
    ``model``: a registry key (``tissuemech.models.registry``) or a structure
    ``{kind: qlv|pipkin_rogers, instantaneous: <tag>, taus_s: [...], per_branch: bool}``; ``params``: the
    population parameters; ``by_test``: optional ``{test kind: {model, params}}`` overriding the truth for one
    test kind (e.g. a viscous law for the flow curve of a yielded gel). The material-model effects are
    applied on top (:func:`tissuemech.synth.effects.modify_truth`).
``variability``
    ``specimen_log_sd``, ``sample_log_sd``: log-normal factors on every Pa-valued parameter
``instrument``
    fields of :class:`tissuemech.synth.instrument.InstrumentSettings`
``effects``
    ``{effect id: {magnitude parameters}}`` (empty: null configuration)
``session``
    ``start`` (ISO 8601), ``pause_between_tests_s``, ``loading_time_s``, ``specimen_prefix``
``groups``
    list of ``{test, samples, specimens, settings}``: independent samples (one test each) spread over the
    first ``specimens`` specimens of the pool; and/or ``sequence``:
    ``{specimens, samples_per_specimen, tests: [{test, settings}, ...], order}``: every sample runs the list in
    order (``order: fixed``, the default) or, with ``order: shuffled``, runs the first test first (the LVE
    amplitude check) and the others in a random order of its own, so that elapsed time and test condition
    are not confounded
``provenance``
    ``truth_choice`` and ``departures`` texts copied to dataset.yaml
"""
from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import yaml

from ..models.base import ConstitutiveModel
from . import effects as fx
from .instrument import Geometry, InstrumentSettings, run_protocol
from .protocols import build_protocol
from .writer import RESULT_NAMES, write_json, write_rheocompass_csv, write_samples_csv, write_yaml
from ..models.beyond_qlv import PipkinRogersModel
from ..models.plate import gauss_radii
from ..models.qlv import QLVModel, instantaneous_law
from ..models.registry import get_model

GENERATOR = "tissuemech.synth virtual rheometer 1"


def build_model(spec) -> ConstitutiveModel:
    """Truth model from a registry key or a structure mapping (see module docstring)."""
    if isinstance(spec, str):
        return get_model(spec)
    kind = spec.get("kind")
    law = instantaneous_law(spec.get("instantaneous", "linear"))
    taus = spec.get("taus_s")
    n = len(taus) if taus is not None else int(spec.get("n_prony", 4))
    if kind == "qlv":
        return QLVModel(law, n, taus_s=taus, name=spec.get("name"))
    if kind == "pipkin_rogers":
        return PipkinRogersModel(law, n, taus_s=taus, per_branch=bool(spec.get("per_branch", False)),
                                 name=spec.get("name"))
    raise ValueError(f"unknown truth model kind {kind!r}: use a registry key or kind qlv/pipkin_rogers")


def instantaneous_rim_ratio(model: ConstitutiveModel, params: Mapping[str, float], rim_strain: float = 0.5) -> float | None:
    """Apparent-to-true rim stress ratio ``(2M/(pi R^3))/sigma_e(gamma_R)`` of the model's instantaneous law at
    ``rim_strain`` (1 for a linear law; < 1 for stiffening laws: the rim-stress error inherent in the data)."""
    if not model.supports("elastic_shear"):
        return None
    r, w = gauss_radii(16, 1.0)
    sigma = np.asarray(model.elastic_shear_stress(params, rim_strain * r), float)
    apparent = 4.0 * np.sum(w * r * r * sigma)          # 2M/(pi R^3) with M = 2 pi int sigma r^2 dr, R = 1
    true = float(np.asarray(model.elastic_shear_stress(params, np.array([rim_strain])), float)[0])
    return float(apparent / true)


def _check_params(model: ConstitutiveModel, params: Mapping[str, float], where: str) -> dict[str, float]:
    missing = set(model.param_names) - set(params)
    extra = set(params) - set(model.param_names)
    if missing or extra:
        raise ValueError(f"{where}: parameters of {model.name!r} are {list(model.param_names)}; "
                         f"missing {sorted(missing)}, unknown {sorted(extra)}")
    return {k: float(v) for k, v in params.items()}


@dataclasses.dataclass
class PlannedRun:
    """One test on one sample, in session order."""

    test: str
    settings: dict
    specimen_index: int
    specimen: str
    sample: str
    order: int
    gap_m: float = 0.0
    start_s: float = 0.0          # session time of the specimen when the test starts


def plan_runs(config: Mapping, rng: np.random.Generator) -> list[PlannedRun]:
    """Design of the dataset: which sample runs which test, in which order and when."""
    session = config.get("session", {})
    prefix = session.get("specimen_prefix", "specimen")
    groups = list(config.get("groups", []))
    seq = config.get("sequence")
    n_spec = max([int(g.get("specimens", 1)) for g in groups] + [int(seq["specimens"]) if seq else 0]
                 + [int(config.get("n_specimens", 0))])
    spec_names = [f"{prefix}{i + 1:02d}" for i in range(n_spec)]
    counters = [0] * n_spec
    planned: list[PlannedRun] = []

    def new_sample(si: int) -> str:
        counters[si] += 1
        return f"s{counters[si]:02d}"
    for gi, g in enumerate(groups):
        k = int(g.get("specimens", 1))
        pool = [(gi + j) % n_spec for j in range(k)]
        for s in range(int(g["samples"])):
            si = pool[s % k]
            planned.append(PlannedRun(g["test"], dict(g.get("settings", {})), si, spec_names[si], new_sample(si), 1))
    if seq:
        for si in range(int(seq["specimens"])):
            for _ in range(int(seq["samples_per_specimen"])):
                name = new_sample(si)
                tests = list(seq["tests"])
                if seq.get("order", "fixed") == "shuffled":
                    tests = tests[:1] + [tests[i + 1] for i in rng.permutation(len(tests) - 1)]
                elif seq.get("order", "fixed") != "fixed":
                    raise ValueError(f"sequence.order must be 'fixed' or 'shuffled', not {seq['order']!r}")
                for order, t in enumerate(tests, start=1):
                    planned.append(PlannedRun(t["test"], dict(t.get("settings", {})), si, spec_names[si], name, order))
    # gaps per sample and session timing: each specimen is tested in one session, sample after sample
    gap = config.get("geometry", {}).get("gap_mm", 3.0)
    gaps: dict[tuple[int, str], float] = {}
    for r in planned:
        key = (r.specimen_index, r.sample)
        if key not in gaps:
            gaps[key] = (rng.uniform(gap[0], gap[1]) if isinstance(gap, (list, tuple)) else float(gap)) * 1e-3
        r.gap_m = gaps[key]
    planned.sort(key=lambda r: (r.specimen_index, r.sample, r.order))
    return planned


def generate_dataset(config: Mapping, seed: int, out_dir: str | Path, header: str = "simple") -> dict:
    """Generate a dataset folder (RheoCompass CSVs, samples.csv, dataset.yaml, truth.json).

    Returns
    -------
    dict with ``runs`` (per file: the generated canonical channels in SI and the run metadata) and
    ``truth`` (the truth.json content).
    """
    out_dir = Path(out_dir)
    rng = np.random.default_rng(seed)
    effects = fx.resolve(config.get("effects"))
    truth_cfg = config["truth"]
    base_model = build_model(truth_cfg["model"])
    base_params = _check_params(base_model, {**({"kappa": 0.0, "gamma_s": 0.2} if "kappa" in base_model.param_names
                                                and "kappa" not in truth_cfg["params"] else {}),
                                             **truth_cfg["params"]}, "truth")
    model, params, derived = fx.modify_truth(base_model, base_params, effects)
    planned = plan_runs(config, rng)
    kinds = {r.test for r in planned}
    by_test = {}
    for kind, sub in (truth_cfg.get("by_test") or {}).items():
        if kind not in kinds:            # a truth override of a test that is not in the design
            continue
        m = build_model(sub["model"])
        by_test[kind] = (m, _check_params(m, sub["params"], f"truth.by_test.{kind}"))
    instrument = InstrumentSettings(**config.get("instrument", {}))
    artefacts = fx.build_artefacts(effects, instrument.motor_inertia_kg_m2)
    geometry_cfg = config.get("geometry", {})
    radius_m = float(geometry_cfg.get("radius_mm", 12.5)) * 1e-3
    temperature_c = float(config.get("temperature_c", 20.0))
    var = config.get("variability", {})
    session = config.get("session", {})
    start = dt.datetime.fromisoformat(str(session.get("start", "2026-01-12T09:00:00")))
    pause = float(session.get("pause_between_tests_s", 120.0))
    loading = float(session.get("loading_time_s", 300.0))

    n_spec = 1 + max(r.specimen_index for r in planned)
    spec_log = rng.normal(size=n_spec) * float(var.get("specimen_log_sd", 0.0))
    sample_log: dict[tuple[int, str], float] = {}
    clock = np.zeros(n_spec)
    seen_samples: set = set()
    rows, runs_truth, generated = [], [], {}
    for idx, run in enumerate(planned):
        key = (run.specimen_index, run.sample)
        if key not in sample_log:
            sample_log[key] = rng.normal() * float(var.get("sample_log_sd", 0.0))
        if key not in seen_samples:
            clock[run.specimen_index] += loading
            seen_samples.add(key)
        settings = {**run.settings, **fx.protocol_overrides(run.test, effects)}
        protocol = build_protocol(run.test, **settings)
        run.start_s = float(clock[run.specimen_index])
        elapsed_h = run.start_s / 3600.0
        first = run.order == 1
        m, p = by_test.get(run.test, (model, params))
        factor = float(np.exp(spec_log[run.specimen_index] + sample_log[key])) * fx.modulus_factor(
            effects, elapsed_h, first, run.specimen_index)
        p_run = fx.scale_moduli(m, p, factor)
        run_rng = np.random.default_rng([seed, idx])
        channels = run_protocol(protocol, m, p_run, Geometry(radius_m, run.gap_m), instrument, artefacts,
                                temperature_c, run_rng)
        # elapsed session time of every point: the specimen's session clock at the test start + test time
        channels = {"total_time": run.start_s + channels["time"], **channels}
        clock[run.specimen_index] += protocol.duration_s + pause
        cond = protocol.condition
        tag = {"constant_shear_rate": f"csr{cond.get('shear_rate_1_per_s', 0):g}",
               "stress_relaxation": f"sr{cond.get('strain_pct', 0):g}pct",
               "creep_recovery": f"cr{cond.get('stress_pa', 0):g}Pa",
               "frequency_sweep": "fs", "amplitude_sweep": "as", "flow_curve": "fc"}[run.test]
        fname = f"{run.specimen}_{run.sample}_{run.order:02d}_{tag}.csv"
        write_rheocompass_csv(out_dir / fname, channels, f"{config['name']}_{run.specimen}_{run.sample}_{tag}",
                              RESULT_NAMES[run.test], header=header)
        started = start + dt.timedelta(days=run.specimen_index, seconds=run.start_s)
        rows.append({"file": fname, "specimen": run.specimen, "sample": run.sample, "test": run.test,
                     "order": run.order, "shear_rate_1_per_s": cond.get("shear_rate_1_per_s"),
                     "strain_pct": cond.get("strain_pct"), "stress_pa": cond.get("stress_pa"),
                     "frequency_hz": cond.get("frequency_hz"), "radius_mm": radius_m * 1e3,
                     "gap_mm": round(run.gap_m * 1e3, 4), "temperature_c": temperature_c,
                     "started_at": started.isoformat(timespec="seconds"),
                     # covariate: hours since the specimen's session started (post-mortem/handling time proxy)
                     "session_elapsed_h": round(elapsed_h, 6)})
        runs_truth.append({"file": fname, "specimen": run.specimen, "sample": run.sample, "test": run.test,
                           "order": run.order, "model": m.name, "modulus_factor": factor,
                           "elapsed_h": elapsed_h, "gap_m": run.gap_m, "radius_m": radius_m,
                           "rise_time_s": protocol.rise_time_s, "params": p_run})
        generated[fname] = {"channels": channels, "meta": rows[-1]}

    write_samples_csv(out_dir / "samples.csv", rows)
    truth = {
        "dataset": config["name"], "seed": int(seed), "generator": GENERATOR,
        "config_sha256": hashlib.sha256(yaml.safe_dump(dict(config), sort_keys=True).encode()).hexdigest(),
        "truth_model": {"spec": truth_cfg["model"], "name": model.name, "family": model.family,
                        "structure": model.structure, "params": params,
                        "units": {s.name: s.unit for s in model.param_specs}},
        "by_test": {k: {"name": m.name, "params": p} for k, (m, p) in by_test.items()},
        "variability": {"specimen_log_sd": float(var.get("specimen_log_sd", 0.0)),
                        "sample_log_sd": float(var.get("sample_log_sd", 0.0)),
                        "scaled": "every parameter with a unit in Pa"},
        "specimens": {f"{config.get('session', {}).get('specimen_prefix', 'specimen')}{i + 1:02d}":
                      {"log_factor": float(spec_log[i])} for i in range(n_spec)},
        "effects": {k: {**v, **derived.get(k, {})} for k, v in effects.items()},
        "inherent": {"rim_stress_ratio_at_50pct": instantaneous_rim_ratio(model, params),
                     "note": "apparent 2M/(pi R^3) over true rim stress of the instantaneous law at a 50 % rim "
                             "strain; the rim-stress error of any nonlinear truth is in the data even when "
                             "rim_stress_nonlinearity is not injected"},
        "instrument": dataclasses.asdict(instrument),
        "runs": runs_truth,
    }
    write_json(out_dir / "truth.json", truth)
    prov = config.get("provenance", {})
    dataset_yaml = {
        "name": config["name"], "material": config.get("material", ""), "species": config.get("species", ""),
        "tissue": config.get("tissue", ""), "temperature_c": temperature_c,
        "geometry": {"type": "parallel plate", "radius_mm": radius_m * 1e3, "gap_mm": geometry_cfg.get("gap_mm")},
        "instrument": "virtual Anton Paar MCR-type rheometer (RheoCompass CSV export)",
        "provenance": {"type": "synthetic", "generator": GENERATOR, "seed": int(seed),
                       "config": config.get("config_path", ""), "truth_model": model.name,
                       "effects": sorted(effects), "truth_choice": prov.get("truth_choice", ""),
                       "departures": prov.get("departures", "")},
        "license": config.get("license", "CC0-1.0"), "citation": config.get("citation", ""),
    }
    write_yaml(out_dir / "dataset.yaml", dataset_yaml)
    return {"runs": generated, "truth": truth}


def load_config(path: str | Path) -> dict:
    """Read a generator config (YAML)."""
    with open(path, encoding="utf-8") as fh:
        cfg = yaml.safe_load(fh)
    cfg.setdefault("config_path", str(path))
    return cfg

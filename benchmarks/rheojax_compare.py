"""Peer benchmark (a script, not a test): the same fits with tissuemech and, when it is importable, RheoJAX.

Data, read in place from ``../shared/data/real`` (the real exports of issue 15; nothing is copied):

* ``lims``  -- one frequency sweep of the TA LIMS cooling series (``--temperature``, default 30 degC);
* ``trios`` -- the TRIOS fungi frequency sweep, points with a raw phase <= 90 deg (the inertia-dominated ones
  left out, as the ingest quality flag does);
* ``cnf``   -- the mean relaxation modulus of the ten CNF relaxations for t >= ``--t-min`` (default 1 s: before
  about 0.5 s the exported modulus rings through zero after the step), fitted as an ideal step of unit strain.

Then the shift factors of all 20 LIMS sweeps at Tref = ``--temperature`` (tissuemech's automatic shift with
standard errors beside RheoJAX's ``Mastercurve(auto_shift=True)``; the issue's RheoJAX run gave +8.55 .. -3.98).

Models (tissuemech key -> RheoJAX class): prony3/prony4 -> GeneralizedMaxwell(n_modes=3/4), sls1 -> Zener,
fractional_zener -> FractionalZenerSolidSolid, prony2 -> GeneralizedMaxwell(n_modes=2). Both sides are scored by
the same relative RMSE, sqrt(mean(((model - data)/data)^2)) over G' and G'' (sweeps) or G(t) (relaxation), from
each side's own predictions. Times are wall seconds of the second (warm) fit. RheoJAX needs Python >= 3.12 and
is optional: without it the script prints tissuemech's side and says RheoJAX is absent.

    PYTHONPATH=src .venv/bin/python benchmarks/rheojax_compare.py [--temperature 30] [--t-min 1]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from tissuemech import fitting as F
from tissuemech.io.dispatch import read_export
from tissuemech.models.registry import get_model

REAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "real"
SWEEP_MODELS = ("prony3", "prony4", "sls1", "fractional_zener")
RELAXATION_MODELS = ("sls1", "prony2")
RHEOJAX = {"prony2": ("GeneralizedMaxwell", {"n_modes": 2}), "prony3": ("GeneralizedMaxwell", {"n_modes": 3}),
           "prony4": ("GeneralizedMaxwell", {"n_modes": 4}), "sls1": ("Zener", {}),
           "fractional_zener": ("FractionalZenerSolidSolid", {})}


def lims_sweep(temperature_c: float):
    blocks = read_export(REAL / "ta_lims" / "ares_g2_frequency_sweep_tts.txt")
    b = min(blocks, key=lambda b: abs(np.nanmedian(b.data["temperature"]) - temperature_c))
    d = b.data
    return d["angular_frequency"].to_numpy(float), d["storage_modulus"].to_numpy(float), d["loss_modulus"].to_numpy(float)


def trios_sweep():
    b = next(b for b in read_export(REAL / "trios" / "hr20_fungi_frequency_sweep.xls") if b.name == "Frequency sweep - 2")
    d = b.data[b.data["raw_phase"] <= np.pi / 2]
    return d["angular_frequency"].to_numpy(float), d["storage_modulus"].to_numpy(float), d["loss_modulus"].to_numpy(float)


def cnf_relaxation(t_min: float):
    folder = REAL / "rheocompass_cnf_hydrogel"
    runs = [read_export(p)[0].data for p in sorted(folder.glob("HC1_stressrelaxation_20C_*.csv"))]
    n = min(len(r) for r in runs)
    t = runs[0]["time"].to_numpy(float)[:n]
    g = np.mean([r["relaxation_modulus"].to_numpy(float)[:n] for r in runs], axis=0)
    keep = t >= t_min
    return t[keep], g[keep]


def ours(key: str, kind: str, x, y):
    """tissuemech fit (lmfit, multistart as in the pipeline); returns params, relative RMSE, warm seconds."""
    model = get_model(key)
    if kind == "oscillation":
        curve = F.Curve("frequency_sweep", "bench", "oscillation", {"angular_frequency": x},
                        {"storage_modulus": y[0], "loss_modulus": y[1]})
    else:   # ideal step of unit strain: the stress is G(t)
        th = np.r_[0.0, x]
        curve = F.Curve("stress_relaxation", "bench", "shear_history",
                        {"time": th, "shear_strain": np.ones(th.size)}, {"shear_stress": y},
                        obs_index=np.arange(1, th.size))
    problem = F.FitProblem(model, [curve], model_key=key)
    F.fit(problem, n_random=3, seed=0)                       # warm-up (numba, caches)
    t0 = time.perf_counter()
    res = F.fit(problem, n_random=3, seed=0)
    seconds = time.perf_counter() - t0
    if kind == "oscillation":
        g = model.complex_modulus(res.params, x)
        rel = np.r_[(g.real - y[0]) / y[0], (g.imag - y[1]) / y[1]]
    else:
        rel = (model.relaxation_modulus(res.params, x) - y) / y
    return res.params, float(np.sqrt(np.mean(rel ** 2))), seconds


def theirs(rheojax, key: str, kind: str, x, y):
    """RheoJAX fit of the matching model; returns params, relative RMSE, warm seconds (or raises)."""
    name, kwargs = RHEOJAX[key]
    cls = getattr(rheojax.models, name)
    data = np.column_stack(y) if kind == "oscillation" else y
    mode = "oscillation" if kind == "oscillation" else "relaxation"
    cls(**kwargs).fit(x, data, test_mode=mode)                # warm-up (JIT)
    model = cls(**kwargs)
    t0 = time.perf_counter()
    model.fit(x, data, test_mode=mode)
    seconds = time.perf_counter() - t0
    pred = np.asarray(model.predict(x))
    if kind == "oscillation":
        pred = np.column_stack([pred.real, pred.imag]) if np.iscomplexobj(pred) else pred.reshape(-1, 2)
        rel = np.r_[(pred[:, 0] - y[0]) / y[0], (pred[:, 1] - y[1]) / y[1]]
    else:
        rel = (pred.ravel() - y) / y
    params = model.parameters
    names = list(params.keys()) if hasattr(params, "keys") else list(getattr(params, "names", []))
    return {n: float(params.get_value(n)) for n in names}, float(np.sqrt(np.mean(rel ** 2))), seconds


def tts_comparison(rheojax, t_ref_c: float) -> None:
    """Shift factors of the 20 LIMS sweeps at ``t_ref_c``: tissuemech (with standard errors) and, when present,
    RheoJAX's automatic shift (``Mastercurve(auto_shift=True)``, temperatures in K)."""
    from tissuemech import tts

    blocks = read_export(REAL / "ta_lims" / "ares_g2_frequency_sweep_tts.txt")
    sweeps = [tts.Sweep(float(np.nanmedian(b.data["temperature"])), b.data["angular_frequency"],
                        b.data["storage_modulus"], b.data["loss_modulus"], b.name) for b in blocks]
    t0 = time.perf_counter()
    res = tts.shift_factors(sweeps, t_ref_c=t_ref_c)
    ours_s = time.perf_counter() - t0
    theirs_at, theirs_s, note = {}, float("nan"), "RheoJAX absent"
    if rheojax is not None:
        try:
            from rheojax.core.data import RheoData
            from rheojax.transforms.mastercurve import Mastercurve

            data = [RheoData(x=s.omega, y=np.column_stack([s.storage, s.loss]), domain="frequency",
                             metadata={"temperature": s.temperature_c + 273.15}) for s in sweeps]
            t0 = time.perf_counter()
            mc = Mastercurve(reference_temp=float(res.t_ref_c) + 273.15, auto_shift=True)
            mc.transform(data)
            theirs_s = time.perf_counter() - t0
            temps_k, log_at = mc.get_auto_shift_factors()
            theirs_at = {round(float(t) - 273.15): float(v) for t, v in zip(temps_k, log_at)}
            note = "RheoJAX Mastercurve(auto_shift=True)"
        except Exception as exc:  # noqa: BLE001 - reported, the table still prints our side
            note = f"RheoJAX failed: {type(exc).__name__}: {exc}"
    print(f"\nTTS of the LIMS series at Tref = {res.t_ref_c:.1f} degC: tissuemech {ours_s:.2f} s, {note}"
          + (f" {theirs_s:.2f} s" if np.isfinite(theirs_s) else ""))
    print(f"{'T [degC]':>9} {'log aT (ours)':>14} {'se':>7} {'log aT (RheoJAX)':>17} {'difference':>11}")
    for t, la, se in zip(res.temperatures_c, res.log_aT, res.log_aT_stderr):
        other = theirs_at.get(round(float(t)), float("nan"))
        print(f"{t:>9.1f} {la:>14.3f} {se:>7.3f} {other:>17.3f} {la - other:>11.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--temperature", type=float, default=30.0, help="LIMS sweep temperature [degC]")
    ap.add_argument("--t-min", type=float, default=1.0, help="start of the CNF relaxation window [s]")
    args = ap.parse_args()
    if not REAL.is_dir():
        raise SystemExit(f"real data folder {REAL} not found")
    try:
        import rheojax
        import rheojax.models  # noqa: F401
    except ImportError as exc:
        rheojax = None
        print(f"RheoJAX is absent ({exc}); printing tissuemech's side only. It needs Python >= 3.12: install it "
              "in a separate environment and run this script there with PYTHONPATH=src.\n")
    cases = [(f"lims {args.temperature:g} degC", "oscillation", *split(lims_sweep(args.temperature)), SWEEP_MODELS),
             ("trios fungi", "oscillation", *split(trios_sweep()), SWEEP_MODELS),
             (f"cnf t >= {args.t_min:g} s", "relaxation", *cnf_relaxation(args.t_min), RELAXATION_MODELS)]
    print(f"{'data':<18} {'model':<17} {'side':<10} {'rel. RMSE':>10} {'time [s]':>9}  parameters")
    for label, kind, x, y, models in cases:
        for key in models:
            sides = [("tissuemech", ours)] + ([("RheoJAX", lambda *a: theirs(rheojax, *a))] if rheojax else [])
            for side, run in sides:
                try:
                    params, rmse, seconds = run(key, kind, x, y)
                    text = ", ".join(f"{k}={v:.4g}" for k, v in params.items())
                    print(f"{label:<18} {key:<17} {side:<10} {rmse:>10.4f} {seconds:>9.3f}  {text}")
                except Exception as exc:  # noqa: BLE001 - one failed fit is a line of the table, not the end
                    print(f"{label:<18} {key:<17} {side:<10} {'failed':>10} {'':>9}  {type(exc).__name__}: {exc}")
    tts_comparison(rheojax, args.temperature)


def split(sweep):
    w, g1, g2 = sweep
    return w, (g1, g2)


if __name__ == "__main__":
    main()

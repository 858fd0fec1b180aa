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
each side's own predictions. Times are wall seconds of the second (warm) fit.

RheoJAX needs Python >= 3.12, tissuemech's environment is 3.11: RheoJAX's side runs in its own interpreter,
``benchmarks/rheojax_side.py`` started as a subprocess (data in and results out as JSON on its standard streams),
named by ``--rheojax-python`` or the environment variable ``RHEOJAX_PYTHON``. It is optional: without one the
script prints tissuemech's side and says so. A throwaway environment outside the repository, e.g.::

    PYENV_VERSION=3.12.1 python3.12 -m venv /tmp/rjx-venv && /tmp/rjx-venv/bin/pip install rheojax
    PYTHONPATH=src .venv/bin/python benchmarks/rheojax_compare.py --rheojax-python /tmp/rjx-venv/bin/python \
        [--temperature 30] [--t-min 1]

The output is Markdown (the tables of ``docs/peers_benchmark.md``), headed by the machine it ran on (CPU model,
cores, load average: timings on a shared, loaded machine compare only side by side).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
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


def relative_rmse(kind: str, prediction, y) -> float:
    """sqrt(mean(((model - data)/data)^2)) over G' and G'' (sweeps) or G(t): the score of both sides."""
    if kind == "oscillation":
        p = np.asarray(prediction, float)
        rel = np.r_[(p[0] - y[0]) / y[0], (p[1] - y[1]) / y[1]]
    else:
        rel = (np.asarray(prediction, float) - y) / y
    return float(np.sqrt(np.mean(rel ** 2)))


def lims_sweeps():
    from tissuemech import tts

    blocks = read_export(REAL / "ta_lims" / "ares_g2_frequency_sweep_tts.txt")
    return [tts.Sweep(float(np.nanmedian(b.data["temperature"])), b.data["angular_frequency"],
                      b.data["storage_modulus"], b.data["loss_modulus"], b.name) for b in blocks]


def run_rheojax(python: str, request: dict, timeout_s: float) -> tuple[dict | None, str]:
    """RheoJAX's side in its own interpreter (``rheojax_side.py``); (reply, "") or (None, why not)."""
    worker = Path(__file__).with_name("rheojax_side.py")
    try:
        proc = subprocess.run([python, str(worker)], input=json.dumps(request), capture_output=True, text=True,
                              timeout=timeout_s, env={**os.environ, "JAX_PLATFORMS": "cpu"})
    except (OSError, subprocess.TimeoutExpired) as exc:
        return None, f"{type(exc).__name__}: {exc}"
    if proc.returncode != 0:
        tail = proc.stderr.strip().splitlines()[-3:]
        return None, f"{python} exited with {proc.returncode}: {' | '.join(tail)}"
    try:
        return json.loads(proc.stdout), ""
    except json.JSONDecodeError as exc:
        return None, f"unreadable reply ({exc})"


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return (f"{model}, {os.cpu_count()} cores, load average {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} "
            f"(1/5/15 min) at the start; Python {sys.version.split()[0]}")


def fmt_params(params: dict) -> str:
    return ", ".join(f"{k}={v:.4g}" for k, v in params.items())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--temperature", type=float, default=30.0, help="LIMS sweep temperature [degC]")
    ap.add_argument("--t-min", type=float, default=1.0, help="start of the CNF relaxation window [s]")
    ap.add_argument("--rheojax-python", default=os.environ.get("RHEOJAX_PYTHON"),
                    help="interpreter with rheojax installed (default: $RHEOJAX_PYTHON; none: tissuemech only)")
    ap.add_argument("--timeout", type=float, default=3600.0, help="limit of RheoJAX's side [s]")
    args = ap.parse_args()
    if not REAL.is_dir():
        raise SystemExit(f"real data folder {REAL} not found")
    print(f"Machine: {machine()}\n")
    cases = [(f"lims {args.temperature:g} degC", "oscillation", *split(lims_sweep(args.temperature)), SWEEP_MODELS),
             ("trios fungi", "oscillation", *split(trios_sweep()), SWEEP_MODELS),
             (f"cnf t >= {args.t_min:g} s", "relaxation", *cnf_relaxation(args.t_min), RELAXATION_MODELS)]
    rows, jobs = [], []
    for label, kind, x, y, models in cases:
        for key in models:
            try:
                params, rmse, seconds = ours(key, kind, x, y)
                rows.append((label, key, "tissuemech", f"{rmse:.4f}", f"{seconds:.3f}", fmt_params(params)))
            except Exception as exc:  # noqa: BLE001 - one failed fit is a line of the table, not the end
                rows.append((label, key, "tissuemech", "failed", "", f"{type(exc).__name__}: {exc}"))
            name, kwargs = RHEOJAX[key]
            jobs.append({"id": f"{label}|{key}", "model": name, "kwargs": kwargs, "kind": kind,
                         "x": np.asarray(x, float).tolist(),
                         "y": [np.asarray(v, float).tolist() for v in y] if kind == "oscillation"
                         else np.asarray(y, float).tolist(), "_label": label, "_key": key, "_y": y})
    sweeps = lims_sweeps()
    from tissuemech import tts

    t0 = time.perf_counter()
    res = tts.shift_factors(sweeps, t_ref_c=args.temperature)
    ours_tts_s = time.perf_counter() - t0
    reply, why = None, "no --rheojax-python / RHEOJAX_PYTHON given"
    if args.rheojax_python:
        request = {"fits": [{k: v for k, v in j.items() if not k.startswith("_")} for j in jobs],
                   "tts": {"t_ref_c": float(res.t_ref_c),
                           "sweeps": [{"temperature_c": s.temperature_c, "omega": s.omega.tolist(),
                                       "storage": s.storage.tolist(), "loss": s.loss.tolist()} for s in sweeps]}}
        reply, why = run_rheojax(args.rheojax_python, request, args.timeout)
    if reply is None:
        print(f"RheoJAX side not run: {why}. Printing tissuemech's side only.\n")
    else:
        print(f"RheoJAX {reply['rheojax']} (JAX {reply['jax']}, Python {reply['python']}, CPU) via "
              f"{args.rheojax_python}\n")
        by_id = {f["id"]: f for f in reply["fits"]}
        for j in jobs:
            f = by_id.get(j["id"], {"error": "no reply"})
            if f.get("error"):
                row = (j["_label"], j["_key"], "RheoJAX", "failed", "", f["error"][:200])
            else:
                rmse = relative_rmse(j["kind"], f["prediction"], j["_y"])
                row = (j["_label"], j["_key"], "RheoJAX", f"{rmse:.4f}", f"{f['seconds']:.3f}", fmt_params(f["params"]))
            i = max(k for k, r in enumerate(rows) if r[0] == j["_label"] and r[1] == j["_key"])
            rows.insert(i + 1, row)
    print("| data | model | side | rel. RMSE | warm time [s] | parameters |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print("| " + " | ".join(r) + " |")
    theirs_at, theirs_s, note = {}, float("nan"), "RheoJAX not run"
    if reply is not None and reply.get("tts"):
        t = reply["tts"]
        if t.get("error"):
            note = f"RheoJAX failed: {t['error'][:200]}"
        else:
            theirs_at = {round(tc): v for tc, v in zip(t["temperatures_c"], t["log_aT"])}
            theirs_s, note = t["seconds"], "RheoJAX Mastercurve(auto_shift=True)"
    print(f"\nTTS of the 20 LIMS sweeps at Tref = {res.t_ref_c:.1f} degC: tissuemech {ours_tts_s:.2f} s; {note}"
          + (f" {theirs_s:.2f} s" if np.isfinite(theirs_s) else "") + "\n")
    print("| T [degC] | log aT tissuemech | se | log aT RheoJAX | difference |")
    print("|---|---|---|---|---|")
    for t, la, se in zip(res.temperatures_c, res.log_aT, res.log_aT_stderr):
        other = theirs_at.get(round(float(t)), float("nan"))
        print(f"| {t:.1f} | {la:.3f} | {se:.3f} | {other:.3f} | {la - other:.3f} |")


def split(sweep):
    """(omega, (G', G'')) sorted by increasing omega (the TRIOS export runs from high to low frequency; RheoJAX
    requires a non-decreasing axis, tissuemech does not care)."""
    w, g1, g2 = (np.asarray(v, float) for v in sweep)
    order = np.argsort(w, kind="stable")
    return w[order], (g1[order], g2[order])


if __name__ == "__main__":
    main()

"""RheoJAX's side of ``benchmarks/rheojax_compare.py``, run in RheoJAX's own interpreter (Python >= 3.12).

Not a test and not part of the package: it imports only numpy and rheojax, never tissuemech, so it runs in a
separate environment (e.g. ``/tmp/rjx-venv``). ``rheojax_compare.py`` starts it as a subprocess, writes one JSON
document to its standard input and reads one JSON document from its standard output:

input  ``{"fits": [{"id", "model", "kwargs", "kind": "oscillation" | "relaxation", "x": [...],
         "y": [[G'...], [G''...]] | [G(t)...]}], "tts": {"t_ref_c", "sweeps": [{"temperature_c", "omega",
         "storage", "loss"}]} | null}``
output ``{"rheojax": version, "jax": version, "python": version, "fits": [{"id", "params", "prediction",
         "seconds", "error"}], "tts": {"temperatures_c", "log_aT", "seconds", "error"} | null}``

Every fit is run twice and the second (warm: JAX compiled) is timed; ``prediction`` is the model's G', G''
(sweeps) or G(t) (relaxation) at ``x``, scored by the caller with the same formula as tissuemech's fits.
Temperatures go to RheoJAX in K.
"""
from __future__ import annotations

import json
import sys
import time
import warnings

import numpy as np


def _params(model) -> dict:
    ps = model.parameters
    names = list(ps.keys()) if hasattr(ps, "keys") else list(getattr(ps, "names", []))
    out = {}
    for n in names:
        try:
            out[n] = float(ps.get_value(n))
        except Exception:  # noqa: BLE001 - a parameter RheoJAX cannot report is left out
            continue
    return out


def _prediction(model, x, kind: str) -> list:
    pred = np.asarray(model.predict(x))
    if kind == "oscillation":
        if np.iscomplexobj(pred):
            return [pred.real.tolist(), pred.imag.tolist()]
        pred = pred.reshape(x.size, -1) if pred.size == 2 * x.size else pred
        if pred.ndim == 2 and pred.shape == (x.size, 2):
            return [pred[:, 0].tolist(), pred[:, 1].tolist()]
        raise ValueError(f"unexpected oscillation prediction shape {pred.shape}")
    return np.ravel(pred).tolist()


def fit_one(models, job: dict) -> dict:
    cls = getattr(models, job["model"])
    x = np.asarray(job["x"], float)
    kind = job["kind"]
    y = np.asarray(job["y"], float)
    data = y[0] + 1j * y[1] if kind == "oscillation" else y
    mode = "oscillation" if kind == "oscillation" else "relaxation"
    out = {"id": job["id"], "params": {}, "prediction": None, "seconds": float("nan"), "error": ""}
    try:
        cls(**job.get("kwargs", {})).fit(x, data, test_mode=mode)       # warm-up: JAX compilation
        model = cls(**job.get("kwargs", {}))
        t0 = time.perf_counter()
        model.fit(x, data, test_mode=mode)
        out["seconds"] = time.perf_counter() - t0
        out["params"] = _params(model)
        out["prediction"] = _prediction(model, x, kind)
    except Exception as exc:  # noqa: BLE001 - one failed fit is one line of the caller's table
        out["error"] = f"{type(exc).__name__}: {exc}"
    return out


def shift(tts: dict) -> dict:
    out = {"temperatures_c": [], "log_aT": [], "seconds": float("nan"), "error": ""}
    try:
        from rheojax.core.data import RheoData
        from rheojax.transforms.mastercurve import Mastercurve

        data = [RheoData(x=np.asarray(s["omega"], float),
                         y=np.asarray(s["storage"], float) + 1j * np.asarray(s["loss"], float), domain="frequency",
                         metadata={"temperature": float(s["temperature_c"]) + 273.15}) for s in tts["sweeps"]]
        t0 = time.perf_counter()
        mc = Mastercurve(reference_temp=float(tts["t_ref_c"]) + 273.15, auto_shift=True)
        mc.transform(data)
        out["seconds"] = time.perf_counter() - t0
        temps_k, log_at = mc.get_auto_shift_factors()
        out["temperatures_c"] = [float(t) - 273.15 for t in np.ravel(temps_k)]
        out["log_aT"] = [float(v) for v in np.ravel(log_at)]
    except Exception as exc:  # noqa: BLE001 - reported to the caller
        out["error"] = f"{type(exc).__name__}: {exc}"
    return out


def main() -> None:
    request = json.load(sys.stdin)
    reply_to, sys.stdout = sys.stdout, sys.stderr     # whatever RheoJAX prints must not corrupt the JSON reply
    warnings.simplefilter("ignore")
    import jax
    import rheojax
    import rheojax.models as models

    reply = {"rheojax": rheojax.__version__, "jax": jax.__version__, "python": sys.version.split()[0],
             "fits": [fit_one(models, job) for job in request.get("fits", [])],
             "tts": shift(request["tts"]) if request.get("tts") else None}
    json.dump(reply, reply_to)


if __name__ == "__main__":
    main()

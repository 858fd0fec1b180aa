"""Power study of the diagnosis (not a test): detection rate vs effect magnitude.

For every catalogue cause, designs with that single effect at 0.5x, 1x and 2x its typical magnitude
(``science.md`` section 3) are generated over several seeds and diagnosed; a run counts as a detection
when the cause is the *top* finding (correct naming), and the table also shows how often anything at all
was named and how often the null design raised a false alarm (alpha = 0.01, Holm).

The designs are the constructed homogeneous-shear QLV designs of ``tests/diagnosis/constructed.py``
(6 specimens x 3 samples, specimen SD 25 %, sample SD 10 %, 1 % + 0.03 Pa noise).

Usage::

    NUMBA_CACHE_DIR=.numba_cache .venv/bin/python benchmarks/power_study.py --seeds 5
"""
from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "diagnosis"))

from constructed import make_design  # noqa: E402

from tissuemech.diagnosis import CATALOGUE_IDS  # noqa: E402
from tissuemech.diagnosis.evidence import residual_table  # noqa: E402
from tissuemech.diagnosis.report import diagnose, top_finding  # noqa: E402


def one(effect, magnitude, seed, design):
    kw = dict(design)
    if effect == "unidentified_i2_dependence":
        kw["with_normal_force"] = True
    runs, preds, fit_info = make_design(effect, magnitude=magnitude, seed=seed, **kw)
    res = diagnose(runs, residual_table(runs, preds, "qlv"), "qlv", fit_info)
    gain = next((f["fix"] or {}).get("gain") for f in res["findings"] if f["effect"] == effect) if effect else None
    return top_finding(res), any(f["detected"] for f in res["findings"]) or bool(res["unexplained"]), gain


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--magnitudes", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    ap.add_argument("--effects", nargs="+", default=list(CATALOGUE_IDS))
    ap.add_argument("--small", action="store_true", help="the CI test design (4 specimens x 2 samples, 16 points)")
    args = ap.parse_args(argv)
    design = ({"n_specimens": 4, "n_samples": 2, "n_points": 16} if args.small
              else {"n_specimens": 6, "n_samples": 3, "n_points": 30})
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    false_alarms = sum(one(None, 1.0, 1000 + s, design)[1] for s in range(args.seeds))
    print(f"design {design}, {args.seeds} seeds; null design: {false_alarms}/{args.seeds} runs with any finding")
    header = "effect".ljust(28) + "".join(f"{m:>5g}x correct  (gain>0)" for m in args.magnitudes)
    print(header)
    for eff in args.effects:
        cells = []
        for m in args.magnitudes:
            hits, gains = 0, 0
            for s in range(args.seeds):
                top, _, gain = one(eff, m, s, design)
                hits += top == eff
                gains += top == eff and (gain is None or gain > 0)
            cells.append(f"{hits:>6d}/{args.seeds}     ({gains}/{args.seeds})  ")
        print(eff.ljust(28) + "".join(cells), flush=True)
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()

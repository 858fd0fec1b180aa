"""CPU seconds of the diagnosis of finished datasets, through the `diagnose` rule's own function.

Runs :func:`tissuemech.diagnosis.report.run_diagnosis` on ``<results>/<dataset>`` (its runs, its material fits and
its ranking, as the rule does; outputs to a temporary folder) and prints the process CPU seconds, the baseline and
the named causes with their held-out gains. Run it with one BLAS thread, as Snakemake runs a one-thread job; this
machine's speed may drift, so compare two code versions interleaved (``PYTHONPATH=<other checkout>/src``)::

    OPENBLAS_NUM_THREADS=1 python benchmarks/diagnosis_speed.py results porcine_brain_thesis ta_lims
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from tissuemech.diagnosis.report import run_diagnosis


def gain_of(finding: dict) -> float:
    gain = (finding.get("fix") or {}).get("gain")
    return float("nan") if gain is None else float(gain)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, help="a finished run's results folder")
    ap.add_argument("datasets", nargs="+")
    ap.add_argument("--alpha", type=float, default=0.01)
    ap.add_argument("--poisson-ratio", type=float, required=True, help="the configuration's fem.poisson_ratio")
    args = ap.parse_args()
    for name in args.datasets:
        folder = args.results / name
        with tempfile.TemporaryDirectory() as out:
            cpu, wall = time.process_time(), time.perf_counter()
            result = run_diagnosis(folder / "runs", folder / "fits" / "material", f"{out}/f.json", f"{out}/r.nc",
                                   f"{out}/fig", dataset=name, alpha=args.alpha, ranking=folder / "ranking.csv",
                                   extension_cards_dir=f"{out}/cards", poisson_ratio=args.poisson_ratio)
            cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        named = [f"{f['effect']} (gain {gain_of(f):.4f})" for f in result.get("findings", []) if f.get("detected")]
        print(f"{name}: {cpu:.1f} CPU s, {wall:.1f} wall s, baseline {result.get('model')}; "
              f"named: {', '.join(named) or 'nothing'}", flush=True)


if __name__ == "__main__":
    main()

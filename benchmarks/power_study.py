"""Power study of the diagnosis (not a test): detection rate vs effect magnitude.

Rheometer designs: for every catalogue cause, designs with that single effect at 0.5x, 1x and 2x its
typical magnitude (``science.md`` section 3) are generated over several seeds and diagnosed; a run counts
as a detection when the cause is the *top* finding (correct naming); ``(gain>0)`` counts those whose fix
also improved the held-out metric. The designs are the constructed homogeneous-shear QLV designs of
``tests/diagnosis/constructed.py`` (6 specimens x 3 samples, specimen SD 25 %, sample SD 10 %, 1 % + 0.03 Pa
noise; ``--small``: 4 x 2, 16 points, the CI design). The null design counts runs with any finding.

Multi-mode designs (``--multimode-seeds``): the Budday-like design of
``tests/diagnosis/constructed_homogeneous.py`` (simple shear to gamma = 0.2, compression to lambda = 0.9,
tension to 1.1; Mooney-Rivlin truth with C10 + C01 = 600 Pa, 1 % + 0.03 Pa noise), I2 share
C01/(C10 + C01) = 0.4 x magnitude, diagnosed by :func:`tissuemech.diagnosis.homogeneous.diagnose_homogeneous`.
Both ``unidentified_i2_dependence`` (the cause) and ``tension_compression_asymmetry`` (its symptom) may be
named for the same truth, so a detection there is "named", not "top"; the null truth is C01 = 0.

Virtual-rheometer designs (``--synth-seeds``): the issue-5 suite design of ``tests/diagnosis/synth_pipeline.py``
(:mod:`tissuemech.synth`, 6 specimens x 2 samples, AS first then FS, three CSR rates and four relaxations in
an order shuffled per sample; baseline fitted with lmfit as in ``synth_pipeline.ANALYSIS``), each effect's
first magnitude parameter scaled by 0.5/1/2 (the outlier factor as 1 + (2.5 - 1) x magnitude); diagnosed over
``--jobs`` processes.

Usage::

    NUMBA_CACHE_DIR=.numba_cache .venv/bin/python benchmarks/power_study.py --seeds 5
    .venv/bin/python benchmarks/power_study.py --small --seeds 3 --multimode-seeds 10 --markdown docs/power_study.md
    .venv/bin/python benchmarks/power_study.py --seeds 0 --synth-seeds 2 --jobs 2 --markdown docs/power_study_synth.md
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
import warnings
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "diagnosis"))

from constructed import make_design  # noqa: E402
from constructed_homogeneous import TYPICAL_SHARE, make_multimode  # noqa: E402

from tissuemech.diagnosis import CATALOGUE_IDS  # noqa: E402
from tissuemech.diagnosis.evidence import residual_table  # noqa: E402
from tissuemech.diagnosis.homogeneous import ASYMMETRY_ID, I2_ID, diagnose_homogeneous  # noqa: E402
from tissuemech.diagnosis.report import diagnose, top_finding  # noqa: E402


def one(effect, magnitude, seed, design):
    kw = dict(design)
    if effect == "unidentified_i2_dependence":
        kw["with_normal_force"] = True
    runs, preds, fit_info = make_design(effect, magnitude=magnitude, seed=seed, **kw)
    res = diagnose(runs, residual_table(runs, preds, "qlv"), "qlv", fit_info)
    gain = next((f["fix"] or {}).get("gain") for f in res["findings"] if f["effect"] == effect) if effect else None
    return top_finding(res), any(f["detected"] for f in res["findings"]) or bool(res["unexplained"]), gain


def one_multimode(magnitude, seed):
    """Named findings (id -> fix gain) and whether anything unexplained was reported."""
    res, _ = diagnose_homogeneous(make_multimode(TYPICAL_SHARE * magnitude, seed=seed), n_random=2, n_grid=15)
    named = {f["effect"]: (f["fix"] or {}).get("gain") for f in res["findings"] if f["detected"]}
    return named, bool(res["unexplained"])


def one_synth(job):
    """(effect, magnitude, seed) on the virtual rheometer -> (top finding, anything raised, fix gain)."""
    import tempfile

    from synth_pipeline import ANALYSIS, DESIGN, diagnose_synthetic

    effect, magnitude, seed = job
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as tmp:
        _, _, res, _ = diagnose_synthetic(effect, seed, tmp, magnitude=magnitude, **DESIGN,
                                          **ANALYSIS.get(effect, {}))
    gain = next(((f["fix"] or {}).get("gain") for f in res["findings"] if f["effect"] == effect), None)
    return top_finding(res), any(f["detected"] for f in res["findings"]) or bool(res["unexplained"]), gain


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="seeds per rheometer cell (0 skips the rheometer part)")
    ap.add_argument("--multimode-seeds", type=int, default=0, help="seeds per multi-mode cell (0 skips it)")
    ap.add_argument("--magnitudes", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    ap.add_argument("--effects", nargs="+", default=list(CATALOGUE_IDS))
    ap.add_argument("--synth-seeds", type=int, default=0,
                    help="seeds per virtual-rheometer cell (0 skips it; synth_pipeline.DESIGN)")
    ap.add_argument("--jobs", type=int, default=1, help="processes for the virtual-rheometer cells")
    ap.add_argument("--small", action="store_true", help="the CI test design (4 specimens x 2 samples, 16 points)")
    ap.add_argument("--markdown", type=Path, help="also write the tables as Markdown to this file")
    args = ap.parse_args(argv)
    design = ({"n_specimens": 4, "n_samples": 2, "n_points": 16} if args.small
              else {"n_specimens": 6, "n_samples": 3, "n_points": 30})
    warnings.simplefilter("ignore")
    t0 = time.perf_counter()
    mags = args.magnitudes
    def flush(lines):
        # written after every row so that a run cut short keeps what it measured
        if args.markdown:
            args.markdown.parent.mkdir(parents=True, exist_ok=True)
            args.markdown.write_text("\n".join(lines + [""]))

    md = [f"Generated by `benchmarks/power_study.py {' '.join(sys.argv[1:] if argv is None else argv)}` "
          f"({time.strftime('%Y-%m-%d')}, Python {platform.python_version()}); alpha = 0.01 family-wise (Holm).", ""]
    if args.multimode_seeds:
        n = args.multimode_seeds
        null = [one_multimode(0.0, 1000 + s) for s in range(n)]
        alarms = sum(bool(named) or unexpl for named, unexpl in null)
        head = (f"Multi-mode designs (Mooney-Rivlin truth, 1x = C01/(C10 + C01) = {TYPICAL_SHARE}), seeds 0..{n - 1} "
                f"(null C01 = 0: seeds 1000..{999 + n}): null design {alarms}/{n} runs with any finding")
        print(head)
        md += [head + ".", "", "Cell: runs where the effect is named / seeds (of those, fix gain > 0).", "",
               "| effect | " + " | ".join(f"{m:g}x" for m in mags) + " |", "|---|" + "---|" * len(mags)]
        results = {m: [one_multimode(m, s) for s in range(n)] for m in mags}
        for eff in (I2_ID, ASYMMETRY_ID):
            cells, md_cells = [], []
            for m in mags:
                hits = sum(eff in named for named, _ in results[m])
                gains = sum(eff in named and (named[eff] is None or named[eff] > 0) for named, _ in results[m])
                cells.append(f"{hits:>6d}/{n}     ({gains}/{n})  ")
                md_cells.append(f"{hits}/{n} ({gains})")
            print((eff + " [multimode]").ljust(40) + "".join(cells), flush=True)
            md.append(f"| {eff} (multi-mode) | " + " | ".join(md_cells) + " |")
            flush(md)
        md.append("")
    if args.seeds:
        false_alarms = sum(one(None, 1.0, 1000 + s, design)[1] for s in range(args.seeds))
        head = (f"Rheometer designs {design}, seeds 0..{args.seeds - 1} (null design seeds 1000..{999 + args.seeds}): "
                f"null design {false_alarms}/{args.seeds} runs with any finding")
        print(head)
        print("effect".ljust(28) + "".join(f"{m:>5g}x correct  (gain>0)" for m in mags))
        md += [head + ".", "", "Cell: runs where the effect is the top finding / seeds (of those, fix gain > 0).", "",
               "| effect | " + " | ".join(f"{m:g}x" for m in mags) + " |", "|---|" + "---|" * len(mags)]
        for eff in args.effects:
            cells, md_cells = [], []
            for m in mags:
                hits, gains = 0, 0
                for s in range(args.seeds):
                    top, _, gain = one(eff, m, s, design)
                    hits += top == eff
                    gains += top == eff and (gain is None or gain > 0)
                cells.append(f"{hits:>6d}/{args.seeds}     ({gains}/{args.seeds})  ")
                md_cells.append(f"{hits}/{args.seeds} ({gains})")
            print(eff.ljust(28) + "".join(cells), flush=True)
            md.append(f"| {eff} | " + " | ".join(md_cells) + " |")
            flush(md)
        md.append("")
    if args.synth_seeds:
        from concurrent.futures import ProcessPoolExecutor

        from synth_pipeline import DESIGN

        n = args.synth_seeds
        jobs = [(None, 1.0, 1000 + s) for s in range(n)] + [(e, m, s) for e in args.effects for m in mags
                                                           for s in range(n)]
        with ProcessPoolExecutor(args.jobs) as pool:
            out = dict(zip(jobs, pool.map(one_synth, jobs)))
        alarms = sum(out[(None, 1.0, 1000 + s)][1] for s in range(n))
        head = (f"Virtual-rheometer designs {DESIGN}, seeds 0..{n - 1} (null design seeds 1000..{999 + n}): "
                f"null design {alarms}/{n} runs with any finding")
        print(head)
        md += [head + ".", "", "Cell: runs where the effect is the top finding / seeds (of those, fix gain > 0); "
               "misses: magnitude, seed and what was on top instead (none: nothing named).", "",
               "| effect | " + " | ".join(f"{m:g}x" for m in mags) + " | misses |", "|---|" + "---|" * (len(mags) + 1)]
        for eff in args.effects:
            md_cells, misses = [], []
            for m in mags:
                cell = [out[(eff, m, s)] for s in range(n)]
                hits = sum(top == eff for top, _, _ in cell)
                gains = sum(top == eff and (g is None or g > 0) for top, _, g in cell)
                md_cells.append(f"{hits}/{n} ({gains})")
                misses += [f"{m:g}x s{s}: {top or 'none'}" for s, (top, _, _) in enumerate(cell) if top != eff]
            print(eff.ljust(28) + "  ".join(md_cells) + "  " + "; ".join(misses), flush=True)
            md.append(f"| {eff} | " + " | ".join(md_cells) + f" | {'; '.join(misses)} |")
        md.append("")
    total = f"total {time.perf_counter() - t0:.0f} s wall"
    print(total)
    flush(md + [total + "."])


if __name__ == "__main__":
    main()

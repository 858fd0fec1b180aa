"""CPU seconds a pipeline job spends before and after its work: the imports of its workflow script and the
interpreter's teardown (issue 17, per-job start-up).

For every script in ``workflow/scripts`` its top-level import lines run in a fresh interpreter (``--repeats``
times, the variants interleaved; medians printed). Variants:

* ``baseline``: the package at ``--baseline-src`` (e.g. a worktree of an older commit), bytecode precompiled,
  normal exit (teardown included);
* ``no-bytecode``: this checkout's package compiled from source in every process (what a job paid where
  ``PYTHONDONTWRITEBYTECODE`` is set and nothing was precompiled), normal exit;
* ``teardown``: this checkout, bytecode precompiled, normal exit;
* ``current``: this checkout, bytecode precompiled, the process ended with ``os._exit`` after the imports (what
  ``job_log(end_process=True)`` does after a job).

Each figure is the process's CPU time (user + system, from the parent's ``RUSAGE_CHILDREN``). Each variant imports
a copy of its ``src`` folder in a temporary folder (compiled there or not), so the checkout is not touched. Usage::

    git worktree add /tmp/base <commit>
    python benchmarks/job_startup.py --baseline-src /tmp/base/src
"""
from __future__ import annotations

import argparse
import compileall
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def import_lines(script: Path) -> str:
    return "".join(line for line in script.read_text().splitlines(keepends=True)
                   if line.startswith(("import ", "from ")))


def child_cpu_s(code: str, src: Path, exit_at_end: bool) -> float:
    env = {**os.environ, "PYTHONPATH": str(src), "PYTHONDONTWRITEBYTECODE": "1", "MPLBACKEND": "Agg"}
    body = code + ("import os\nos._exit(0)\n" if exit_at_end else "")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-c", body], env=env, check=True, cwd=ROOT)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline-src", type=Path, default=None, help="the src folder of the code to compare with")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        def copy(src: Path, name: str, compiled: bool) -> Path:
            target = Path(tmp, name)
            shutil.copytree(src, target, ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
            if compiled:
                compileall.compile_dir(target, quiet=1)
            return target

        compiled = copy(ROOT / "src", "compiled", True)
        variants = {"no-bytecode": (copy(ROOT / "src", "plain", False), False), "teardown": (compiled, False),
                    "current": (compiled, True)}
        if args.baseline_src is not None:
            variants = {"baseline": (copy(args.baseline_src, "baseline", True), False), **variants}
        scripts = sorted((ROOT / "workflow" / "scripts").glob("*.py"))
        print(f"# {sys.platform}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}; median CPU s of "
              f"{args.repeats} fresh processes")
        print(f"{'script':24s}" + "".join(f"{name:>13s}" for name in variants))
        totals = dict.fromkeys(variants, 0.0)
        for script in scripts:
            code = import_lines(script)
            samples = {name: [] for name in variants}
            for _ in range(args.repeats):
                for name, (src, exit_at_end) in variants.items():
                    samples[name].append(child_cpu_s(code, src, exit_at_end))
            medians = {name: statistics.median(v) for name, v in samples.items()}
            for name, value in medians.items():
                totals[name] += value
            print(f"{script.name:24s}" + "".join(f"{medians[name]:13.2f}" for name in variants))
        print(f"{'sum over scripts':24s}" + "".join(f"{totals[name]:13.2f}" for name in variants))
        print(f"# load after {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()

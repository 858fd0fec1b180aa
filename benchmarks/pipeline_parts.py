"""Pipeline-time parts of issue 17, each timed side by side against what it replaced (synthetic inputs).

* ``netcdf``: one run-like file (15 variables of 16 points) written and read through xarray with the h5netcdf
  engine (before) and the netCDF4 engine (``canonical.NETCDF_ENGINE``, after); ms per file.
* ``plate``: ``--curves`` parallel-plate histories of 100-400 samples predicted one by one
  (``forward_plate``, before) and in one compiled pass (``forward_plate_batch``, after) for a QLV and a
  Pipkin-Rogers model; and a linear model's torque from 8 Gauss-radius histories (before) against the rim history
  alone (``torque_from_history`` for ``linear_in_strain`` models, after); ms per call.
* ``figures``: ``--figures`` log-log figures written as PNG + SVG with matplotlib's mathtext tick labels (before)
  and with ``plots.PowerOfTenFormatter`` (after); CPU s.

Before/after alternate ``--repeats`` times; the best of each is printed with the ratio and the 1-minute load.
Usage::

    python benchmarks/pipeline_parts.py --parts netcdf,plate,figures
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from tissuemech.numba_cache import use_source_keyed_cache  # noqa: E402 (before anything imports numba)

use_source_keyed_cache(Path(__file__).resolve().parents[1] / ".numba_cache")
sys.path.insert(0, str(Path(__file__).resolve().parent))
os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np  # noqa: E402
import xarray as xr  # noqa: E402
from fem_timing import machine  # noqa: E402

from tissuemech import plots  # noqa: E402
from tissuemech.models.plate import (PlateHistories, forward_plate, forward_plate_batch, gauss_radii,  # noqa: E402
                                     stress_histories, torque_from_history)
from tissuemech.models.registry import get_model  # noqa: E402


def best_of(repeats: int, before, after) -> tuple[float, float]:
    """Best CPU seconds of ``before()`` and ``after()``, called alternately ``repeats`` times each."""
    t_before, t_after = [], []
    for _ in range(repeats):
        for fn, out in ((before, t_before), (after, t_after)):
            t0 = time.process_time()
            fn()
            out.append(time.process_time() - t0)
    return min(t_before), min(t_after)


def report(name: str, before_s: float, after_s: float, unit: float, unit_name: str) -> None:
    print(f"{name:48s} before {before_s * unit:9.3f} {unit_name}  after {after_s * unit:9.3f} {unit_name}  "
          f"ratio {before_s / after_s:5.2f}x  (load {os.getloadavg()[0]:.2f})", flush=True)


def part_netcdf(repeats: int, n_files: int = 20) -> None:
    t = np.linspace(0.0, 1.0, 16)
    ds = xr.Dataset({f"v{i}": ("point", np.sin(t * (i + 1))) for i in range(14)} | {"time": ("point", t)},
                    attrs={"test": "stress_relaxation", "sample": "s1"})
    with tempfile.TemporaryDirectory() as tmp:
        def write(engine):
            for k in range(n_files):
                ds.to_netcdf(Path(tmp) / f"{engine}_{k}.nc", engine=engine)

        def read(engine):
            for k in range(n_files):
                with xr.open_dataset(Path(tmp) / f"{engine}_{k}.nc", engine=engine) as f:
                    f.load()
        before, after = best_of(repeats, lambda: write("h5netcdf"), lambda: write("netcdf4"))
        report("netCDF write, per file (h5netcdf -> netcdf4)", before / n_files, after / n_files, 1e3, "ms")
        before, after = best_of(repeats, lambda: read("h5netcdf"), lambda: read("netcdf4"))
        report("netCDF read, per file (h5netcdf -> netcdf4)", before / n_files, after / n_files, 1e3, "ms")


def _histories(n_curves: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_curves):
        n = int(rng.integers(100, 400))
        t = np.cumsum(rng.uniform(0.01, 0.5, n))
        t -= t[0]
        out.append((t, np.minimum(t / 2.0, 1.0) * rng.uniform(0.01, 0.3), rng.uniform(0.01, 0.025)))
    return out


def part_plate(repeats: int, n_curves: int) -> None:
    histories = _histories(n_curves)
    batch = PlateHistories.of(histories)
    for key in ("qlv_rp3_prony4", "pr_rp3_prony4"):
        model = get_model(key)
        p = model.default_params()
        forward_plate_batch(model, p, batch)  # compile
        before, after = best_of(repeats, lambda: [forward_plate(model, p, t, g, r) for t, g, r in histories],
                                lambda: forward_plate_batch(model, p, batch))
        report(f"{key}: {n_curves} plate histories", before, after, 1e3, "ms")
    model = get_model("prony4")
    p = model.default_params()
    t, rim, radius = histories[0]
    r, w = gauss_radii(8, radius)

    def every_radius():
        sigma = stress_histories(model, p, t, (r / radius)[:, None] * rim[None, :])
        return 2.0 * np.pi * np.sum((w * r * r)[:, None] * sigma, axis=0)
    before, after = best_of(repeats, lambda: [every_radius() for _ in range(50)],
                            lambda: [torque_from_history(model, p, t, rim, radius) for _ in range(50)])
    report("prony4 torque: 8 radii -> rim history", before / 50, after / 50, 1e3, "ms")


def part_figures(repeats: int, n_figures: int) -> None:
    x = np.geomspace(1e-3, 1e3, 60)
    plain = plots.plain_text_log_ticks

    def draw(tick_labels, out):
        plots.plain_text_log_ticks = tick_labels
        try:
            for k in range(n_figures):
                fig, (ax,) = plots.new_figure()
                ax.loglog(x, 100 * x ** -0.2 * (1 + 0.01 * k), "o-", ms=3, label="mean")
                ax.set_xlabel(plots.axis_label("time"))
                ax.set_ylabel(plots.axis_label("relaxation_modulus"))
                ax.legend()
                plots.save_figure(fig, Path(out) / f"fig{k}")
        finally:
            plots.plain_text_log_ticks = plain
    with tempfile.TemporaryDirectory() as tmp:
        before, after = best_of(repeats, lambda: draw(lambda fig: None, tmp), lambda: draw(plain, tmp))
        report(f"{n_figures} log-log figures, PNG + SVG (mathtext -> Unicode)", before, after, 1.0, "s ")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", default="netcdf,plate,figures")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--curves", type=int, default=84)
    ap.add_argument("--figures", type=int, default=10)
    args = ap.parse_args(argv)
    print(machine())
    parts = args.parts.split(",")
    if "netcdf" in parts:
        part_netcdf(args.repeats)
    if "plate" in parts:
        part_plate(args.repeats, args.curves)
    if "figures" in parts:
        part_figures(args.repeats, args.figures)


if __name__ == "__main__":
    main()

"""Snakemake adapter: amplitude/frequency sweeps -> lve.nc, lve.csv (+ LVE figures)."""
from pathlib import Path

from tissuemech.canonical import read_netcdf
from tissuemech.lve import lve_summary, write_lve
from tissuemech.pipeline import job_log, load_runs
from tissuemech.plots import plot_all_lve

with job_log(snakemake.log[0]) as log:
    runs = load_runs(snakemake.input.runs)
    averages = read_netcdf(snakemake.input.averages)
    summary = lve_summary(runs, averages)
    write_lve(summary, snakemake.output.lve, snakemake.output.summary)
    Path(snakemake.output.figures).mkdir(parents=True, exist_ok=True)
    figures = plot_all_lve(summary, runs, averages, snakemake.output.figures)
    log.info("LVE analysis of %d sweeps; %d figures", summary.sizes.get("sweep", 0), len(figures))

"""Snakemake adapter: canonical runs -> averages.nc, lve.nc/lve.csv, spectrum.nc (+ raw-vs-average and LVE figures)."""
from pathlib import Path

from tissuemech.canonical import read_netcdf
from tissuemech.curves import average_runs, write_averages
from tissuemech.lve import lve_summary, write_lve
from tissuemech.pipeline import job_log, load_runs
from tissuemech.plots import plot_all_averages, plot_all_lve
from tissuemech.spectra import run_spectrum

with job_log(snakemake.log[0], end_process=True) as log:
    out = snakemake.output
    runs = load_runs(snakemake.input.runs)
    averages = average_runs(runs, exclude_flagged=snakemake.params.exclude_flagged)
    write_averages(averages, out.averages)
    figures = plot_all_averages(averages, runs, out.figures)
    log.info("averaged %d runs into %d curves; %d figures", len(runs), averages.sizes.get("curve", 0), len(figures))
    averages = read_netcdf(out.averages)  # the LVE limits read the file every later stage reads
    summary = lve_summary(runs, averages)
    write_lve(summary, out.lve, out.lve_summary)
    Path(out.lve_figures).mkdir(parents=True, exist_ok=True)
    figures = plot_all_lve(summary, runs, averages, out.lve_figures)
    log.info("LVE analysis of %d sweeps; %d figures", summary.sizes.get("sweep", 0), len(figures))
    spectra = run_spectrum(out.averages, out.spectrum)
    log.info("relaxation spectra of %d averaged curves", spectra.sizes.get("curve", 0))

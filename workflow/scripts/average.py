"""Snakemake adapter: canonical runs -> averages.nc (+ raw-vs-average figures)."""
from tissuemech.curves import average_runs, write_averages
from tissuemech.pipeline import job_log, load_runs
from tissuemech.plots import plot_all_averages

with job_log(snakemake.log[0]) as log:
    runs = load_runs(snakemake.input.runs)
    averages = average_runs(runs, exclude_flagged=snakemake.config["fit"].get("exclude_flagged", True))
    write_averages(averages, snakemake.output.averages)
    figures = plot_all_averages(averages, runs, snakemake.output.figures)
    log.info("averaged %d runs into %d curves; %d figures", len(runs), averages.sizes.get("curve", 0), len(figures))

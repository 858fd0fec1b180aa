"""Snakemake adapter: every dataset's results -> results/summary.html."""
from tissuemech.pipeline import job_log
from tissuemech.summary import build_summary

with job_log(snakemake.log[0]):
    build_summary("results", snakemake.params.datasets, snakemake.output.html)

"""Snakemake adapter: averages + fit records of one scope -> one figure per model (linear and log axes)."""
from tissuemech.pipeline import job_log
from tissuemech.summary import plot_scope_fits

with job_log(snakemake.log[0]) as log:
    written = plot_scope_fits(snakemake.input.averages, snakemake.input.fits, snakemake.params.tests,
                              snakemake.output.figures)
    log.info("%s/%s: %d fit figures", snakemake.wildcards.dataset, snakemake.wildcards.scope, len(written))

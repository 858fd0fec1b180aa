"""Snakemake adapter: recommended fit of one scope -> posterior (InferenceData netCDF) + credible-interval table."""
from tissuemech.pipeline import job_log
from tissuemech.uq import run_posterior

with job_log(snakemake.log[0]) as log:
    p = snakemake.params
    table = run_posterior(snakemake.input.ranking, snakemake.input.averages, snakemake.input.fits,
                          snakemake.wildcards.scope, p.tests, snakemake.output.idata, snakemake.output.table,
                          walkers=p.walkers, steps=p.steps, burn=p.burn, seed=p.seed,
                          dataset=snakemake.wildcards.dataset, figure_path=snakemake.output.figure)
    log.info("\n%s", table.to_string())
    for warning in set(table.get("warnings", [])):
        if warning:
            log.warning("posterior diagnostics: %s", warning)

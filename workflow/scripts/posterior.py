"""Snakemake adapter: one fit record of a scope -> posterior (InferenceData netCDF), credible-interval table and
the fit figure with its posterior-predictive band. The model ``baseline`` is the scope's baseline model
(``ranking/<scope>.csv``; the material scope's candidates are named after the data)."""
from pathlib import Path

from tissuemech.pipeline import job_log
from tissuemech.ranking import scope_model
from tissuemech.summary import plot_posterior_fit
from tissuemech.uq import run_posterior

with job_log(snakemake.log[0], end_process=True) as log:
    p, w = snakemake.params, snakemake.wildcards
    model = scope_model(snakemake.input.ranking, w.model)
    table = run_posterior(snakemake.input.averages, snakemake.input.fits, w.scope, model, p.spec,
                          snakemake.output.idata, snakemake.output.table, walkers=p.walkers, steps=p.steps,
                          burn=p.burn, seed=p.seed, dataset=w.dataset)
    log.info("%s:\n%s", model, table.to_string())
    for warning in set(table.get("warnings", [])):
        if warning:
            log.warning("posterior diagnostics: %s", warning)
    plot_posterior_fit(snakemake.input.averages, Path(snakemake.input.fits) / f"{model}.nc",
                       snakemake.output.idata, p.spec, snakemake.output.figure)

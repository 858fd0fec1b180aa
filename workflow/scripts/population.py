"""Snakemake adapter: recommended fit of one scope + its runs -> per-piece levels and the mixed-effects population
distribution of the log initial shear modulus, written into a copy of the recommended card."""
from tissuemech.pipeline import job_log
from tissuemech.uq import run_population

with job_log(snakemake.log[0], end_process=True) as log:
    p = snakemake.params
    pop = run_population(snakemake.input.ranking, snakemake.input.runs, snakemake.input.fits,
                         snakemake.input.cards, snakemake.wildcards.scope, p.tests, snakemake.output.card,
                         snakemake.output.levels, dataset=snakemake.wildcards.dataset,
                         exclude_flagged=p.exclude_flagged)
    log.info("population: %s", pop)

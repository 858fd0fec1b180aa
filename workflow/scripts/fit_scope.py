"""Snakemake adapter: averaged curves -> fits, cards and ranking of one scope, and its fit figures."""
from tissuemech.pipeline import job_log
from tissuemech.summary import fit_scope_job

with job_log(snakemake.log[0], end_process=True) as log:
    table = fit_scope_job(
        snakemake.input.averages, snakemake.wildcards.scope, snakemake.params.spec,
        target=snakemake.params.target, seed=snakemake.params.seed, multistart=snakemake.params.multistart,
        fits_dir=snakemake.output.fits, cards_dir=snakemake.output.cards, ranking_path=snakemake.output.ranking,
        dataset=snakemake.wildcards.dataset, poisson_ratio=snakemake.params.poisson_ratio,
        tts_path=snakemake.input.get("tts"), figures_dir=snakemake.output.figures,
    )
    log.info("scope %s: ranked %d models", snakemake.wildcards.scope, len(table))

"""Snakemake adapter: averaged curves -> fits, cards and ranking of one scope, and one figure per fitted model."""
from tissuemech.pipeline import job_log
from tissuemech.stages import run_fit_scope
from tissuemech.summary import plot_scope_fits

with job_log(snakemake.log[0], end_process=True) as log:
    table = run_fit_scope(
        snakemake.input.averages, snakemake.wildcards.scope, snakemake.params.spec,
        target=snakemake.params.target, seed=snakemake.params.seed, multistart=snakemake.params.multistart,
        fits_dir=snakemake.output.fits, cards_dir=snakemake.output.cards, ranking_path=snakemake.output.ranking,
        dataset=snakemake.wildcards.dataset, poisson_ratio=snakemake.params.poisson_ratio,
        tts_path=snakemake.input.get("tts"),
    )
    log.info("scope %s: ranked %d models", snakemake.wildcards.scope, len(table))
    shown = None
    if snakemake.params.spec.get("material") and not table.empty and "baseline" in table:
        shown = set(table.loc[table["baseline"].astype(bool) | table["recommended"].astype(bool), "model"])
    written = plot_scope_fits(snakemake.input.averages, snakemake.output.fits, snakemake.params.spec,
                              snakemake.output.figures, tts_path=snakemake.input.get("tts"), models=shown)
    log.info("%s/%s: %d fit figures", snakemake.wildcards.dataset, snakemake.wildcards.scope, len(written))

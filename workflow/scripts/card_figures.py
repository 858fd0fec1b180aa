"""Snakemake adapter: material cards of a dataset -> cards.csv and one table figure per scope."""
from tissuemech.pipeline import job_log
from tissuemech.summary import plot_cards

with job_log(snakemake.log[0]) as log:
    written = plot_cards(snakemake.params.cards_root, snakemake.input.ranking, snakemake.output.figures,
                         snakemake.output.table)
    log.info("%s: %d card figures", snakemake.wildcards.dataset, len(written))

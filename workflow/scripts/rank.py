"""Snakemake adapter: per-scope rankings -> ranking.csv, ranking figure; material cards -> cards.csv and one
table figure per scope (fits.csv: rule fits_table)."""
from tissuemech.pipeline import job_log
from tissuemech.stages import collect_scopes
from tissuemech.summary import plot_cards

with job_log(snakemake.log[0]) as log:
    ranking = collect_scopes(snakemake.input.rankings, snakemake.output.ranking, figure_out=snakemake.output.figure)
    log.info("ranking with %d rows", len(ranking))
    written = plot_cards(snakemake.params.cards_root, snakemake.output.ranking, snakemake.output.card_figures,
                         snakemake.output.cards_table)
    log.info("%s: %d card figures", snakemake.wildcards.dataset, len(written))

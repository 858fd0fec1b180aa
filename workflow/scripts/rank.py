"""Snakemake adapter: per-scope rankings -> ranking.csv, ranking figure; fit records + posterior credible-interval
tables -> the tidy fits.csv; cross-test tables -> cross_test.csv and its figure; material cards -> cards.csv and one
table figure per scope."""
from tissuemech.pipeline import job_log
from tissuemech.stages import collect_cross_tests, collect_scopes, write_fits_table
from tissuemech.summary import plot_cards

with job_log(snakemake.log[0], end_process=True) as log:
    ranking = collect_scopes(snakemake.input.rankings, snakemake.output.ranking, figure_out=snakemake.output.figure)
    log.info("ranking with %d rows", len(ranking))
    cross = collect_cross_tests(snakemake.input.rankings, snakemake.wildcards.dataset, snakemake.output.cross_test,
                                figure_out=snakemake.output.cross_test_figure)
    log.info("cross_test.csv: %d rows", len(cross))
    table = write_fits_table(snakemake.input.fits, snakemake.wildcards.dataset, snakemake.output.fits,
                             posterior_tables=snakemake.input.posterior)
    log.info("fits.csv: %d records, %d with credible intervals", len(table),
             int(table["posterior_rhat_max"].notna().sum()) if "posterior_rhat_max" in table else 0)
    written = plot_cards(snakemake.params.cards_root, snakemake.output.ranking, snakemake.output.card_figures,
                         snakemake.output.cards_table)
    log.info("%s: %d card figures", snakemake.wildcards.dataset, len(written))

"""Snakemake adapter: per-scope rankings and fit records -> ranking.csv, fits.csv, ranking figure."""
from tissuemech.pipeline import job_log
from tissuemech.stages import collect_scopes

with job_log(snakemake.log[0]) as log:
    ranking = collect_scopes(snakemake.input.rankings, snakemake.input.fits, snakemake.wildcards.dataset,
                             snakemake.output.ranking, snakemake.output.fits, snakemake.output.figure)
    log.info("ranking with %d rows", len(ranking))

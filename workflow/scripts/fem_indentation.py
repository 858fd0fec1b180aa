"""Snakemake adapter: recommended cards (ranking.csv) -> TLED flat-punch indentation (8 and 15 mm punches)."""
from pathlib import Path

from tissuemech.pipeline import job_log
from tissuemech.stages import run_fem_indentation, select_cards

with job_log(snakemake.log[0], end_process=True) as log:
    cards = select_cards(snakemake.input.ranking, snakemake.params.cards_root)
    log.info("indentation with cards: %s", [str(c) for c in cards])
    Path(snakemake.output.vtu).mkdir(parents=True, exist_ok=True)
    run_fem_indentation(cards, snakemake.output.data, snakemake.output.figure,
                        element_size_m=snakemake.params.element_size_m, vtu_dir=snakemake.output.vtu,
                        n_threads=snakemake.threads)

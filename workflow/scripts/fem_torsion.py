"""Snakemake adapter: recommended cards (ranking.csv) -> TLED torsion of the rheometer sample vs measured torque."""
from tissuemech.pipeline import job_log
from tissuemech.stages import run_fem_torsion, select_cards

with job_log(snakemake.log[0], end_process=True) as log:
    cards = select_cards(snakemake.input.ranking, snakemake.params.cards_root)
    log.info("torsion with cards: %s", [str(c) for c in cards])
    table = run_fem_torsion(cards, snakemake.input.averages, snakemake.output.data, snakemake.output.table,
                            snakemake.output.figure, element_size_m=snakemake.params.element_size_m,
                            vtu_dir=snakemake.output.vtu, n_threads=snakemake.threads)
    log.info("\n%s", table.to_string())

"""Snakemake adapter: baseline and extension cards -> TLED replay of the dataset's measured tests (replay.csv)."""
from tissuemech.pipeline import job_log
from tissuemech.stages import replay_cards, run_fem_replay

with job_log(snakemake.log[0], end_process=True) as log:
    cards = replay_cards(snakemake.input.ranking, snakemake.params.cards_root, snakemake.input.get("diagnosis"),
                         snakemake.input.get("extension_cards"))
    log.info("replay with cards: %s", [(c.name, c.role, c.reason) for c in cards])
    table = run_fem_replay(cards, snakemake.input.averages, snakemake.output.table, snakemake.output.points,
                           snakemake.output.figure, element_size_m=snakemake.params.element_size_m,
                           n_threads=snakemake.threads, extension_cards_dir=snakemake.input.get("extension_cards"),
                           fix_json=snakemake.output.fix_simulation)
    log.info("\n%s", table.to_string())

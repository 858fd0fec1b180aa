"""Snakemake adapter: baseline and extension cards -> TLED replay of the dataset's measured tests (replay.csv).

Rule fem_replay_baseline replays the baseline card alone (no diagnosis needed); rule fem_replay adds the extension
cards of the diagnosis to that table and draws the figure."""
from tissuemech.pipeline import job_log
from tissuemech.stages import replay_cards, run_fem_replay

with job_log(snakemake.log[0], end_process=True) as log:
    inputs, outputs = snakemake.input, snakemake.output
    cards = replay_cards(inputs.ranking, snakemake.params.cards_root, inputs.get("diagnosis"),
                         inputs.get("extension_cards"))
    log.info("replay with cards: %s", [(c.name, c.role, c.reason) for c in cards])
    replayed = (inputs.replayed_table, inputs.replayed_points) if "replayed_table" in inputs.keys() else None
    table = run_fem_replay(cards, inputs.averages, outputs.table, outputs.points, outputs.get("figure"),
                           element_size_m=snakemake.params.element_size_m, n_threads=snakemake.threads,
                           extension_cards_dir=inputs.get("extension_cards"), fix_json=outputs.get("fix_simulation"),
                           replayed=replayed)
    log.info("\n%s", table.to_string())

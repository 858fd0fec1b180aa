# Uncertainty (issue 16): posteriors of the recommended fit of each scope (config `posterior`).

POSTERIOR = config.get("posterior", {})


def posterior_scopes_of(name):
    """Scopes of a dataset whose recommended fit gets a posterior (config posterior.datasets / .scopes)."""
    if name not in POSTERIOR.get("datasets", []):
        return []
    wanted = POSTERIOR.get("scopes") or []
    return [s for s in dataset_scopes_of(name) if not wanted or s in wanted]


def uq_targets():
    """Posterior files of every enabled dataset and scope (added to the default target in the Snakefile)."""
    return [
        f"results/{name}/posterior/{scope}.nc"
        for name in DATASETS
        for scope in posterior_scopes_of(name)
    ]


rule posterior:
    input:
        ranking="results/{dataset}/ranking.csv",
        averages="results/{dataset}/averages.nc",
        fits="results/{dataset}/fits/{scope}",
    output:
        idata="results/{dataset}/posterior/{scope}.nc",
        table=report(
            "results/{dataset}/posterior/{scope}.csv",
            caption="../report/posterior_table.rst",
            category="{dataset}",
            subcategory="3 fits: {scope}",
            labels={"scope": "{scope}", "model": "posterior (credible intervals)"},
        ),
    log:
        "logs/{dataset}/posterior_{scope}.log",
    benchmark:
        "benchmarks/runs/{dataset}/posterior_{scope}.tsv"
    params:
        tests=lambda wildcards: scope_spec(wildcards)["tests"],
        walkers=POSTERIOR.get("walkers"),
        steps=POSTERIOR.get("steps", 1600),
        burn=POSTERIOR.get("burn", 200),
        seed=POSTERIOR.get("seed", 0),
        pkg=script_hash("workflow/scripts/posterior.py"),
    script:
        "../scripts/posterior.py"

# Uncertainty (issue 16): posteriors of the fits of each enabled scope (config `posterior`), specimen variability
# and FEM bands of the recommended model. Target and input functions (posterior_models_of, uq_targets ...) are in
# common.smk, as fit.smk's rule rank reads the posterior tables (for fits.csv).


rule posterior:
    input:
        averages="results/{dataset}/averages.nc",
        fits="results/{dataset}/fits/{scope}",
        ranking="results/{dataset}/ranking/{scope}.csv",
    output:
        idata="results/{dataset}/posterior/{scope}/{model}.nc",
        table=report(
            "results/{dataset}/posterior/{scope}/{model}.csv",
            caption="../report/posterior_table.rst",
            category="{dataset}",
            subcategory="3 fits: {scope}",
            labels={
                "scope": "{scope}",
                "model": "{model}: posterior (credible intervals)",
            },
        ),
        figure=report(
            "results/{dataset}/figures/posterior/{scope}/{model}.png",
            caption="../report/posterior_predictive.rst",
            category="{dataset}",
            subcategory="3 fits: {scope}",
            labels={
                "scope": "{scope}",
                "model": "{model} with posterior-predictive band",
            },
        ),
    log:
        "logs/{dataset}/posterior_{scope}_{model}.log",
    benchmark:
        "benchmarks/runs/{dataset}/posterior_{scope}_{model}.tsv"
    priority: critical_chain_priority
    params:
        spec=scope_spec,
        walkers=POSTERIOR.get("walkers"),
        steps=POSTERIOR.get("steps", 1400),
        burn=POSTERIOR.get("burn", 400),
        seed=POSTERIOR.get("seed", 0),
        pkg=script_hash("workflow/scripts/posterior.py"),
    script:
        "../scripts/posterior.py"


rule population:
    input:
        ranking="results/{dataset}/ranking.csv",
        runs="results/{dataset}/runs",
        fits="results/{dataset}/fits/{scope}",
        cards="results/{dataset}/cards/{scope}",
    output:
        card="results/{dataset}/population/{scope}.card.json",
        levels=report(
            "results/{dataset}/population/{scope}.levels.csv",
            caption="../report/population_levels.rst",
            category="{dataset}",
            subcategory="3 fits: {scope}",
            labels={
                "scope": "{scope}",
                "model": "specimen variability (per-piece levels)",
            },
        ),
    log:
        "logs/{dataset}/population_{scope}.log",
    benchmark:
        "benchmarks/runs/{dataset}/population_{scope}.tsv"
    params:
        tests=lambda wildcards: scope_spec(wildcards)["tests"],
        exclude_flagged=config["fit"].get("exclude_flagged", True),
        pkg=script_hash("workflow/scripts/population.py"),
    script:
        "../scripts/population.py"


rule uq_indentation:
    input:
        posterior=posterior_files,
        population="results/{dataset}/population/{scope}.card.json",
        fits="results/{dataset}/fits/{scope}",
        compiled=NUMBA_COMPILED,
    output:
        data="results/{dataset}/uq/indentation_{scope}.nc",
        figure=report(
            "results/{dataset}/figures/uq_indentation_{scope}.png",
            caption="../report/uq_indentation.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "indentation bands", "item": "{scope}"},
        ),
    log:
        "logs/{dataset}/uq_indentation_{scope}.log",
    benchmark:
        "benchmarks/runs/{dataset}/uq_indentation_{scope}.tsv"
    threads: FEM_THREADS
    params:
        n_draws=POSTERIOR.get("fem_draws", 32),
        element_size_m=config["fem"]["block_element_size_m"],
        seed=POSTERIOR.get("seed", 0),
        pkg=script_hash("workflow/scripts/uq_fem.py"),
    script:
        "../scripts/uq_fem.py"


rule uq_torsion:
    input:
        posterior=posterior_files,
        population="results/{dataset}/population/{scope}.card.json",
        fits="results/{dataset}/fits/{scope}",
        compiled=NUMBA_COMPILED,
        averages="results/{dataset}/averages.nc",
    output:
        data="results/{dataset}/uq/torsion_{scope}.nc",
        figure=report(
            "results/{dataset}/figures/uq_torsion_{scope}.png",
            caption="../report/uq_torsion.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "torsion bands", "item": "{scope}"},
        ),
    log:
        "logs/{dataset}/uq_torsion_{scope}.log",
    benchmark:
        "benchmarks/runs/{dataset}/uq_torsion_{scope}.tsv"
    threads: FEM_THREADS
    params:
        n_draws=POSTERIOR.get("fem_draws", 32),
        element_size_m=config["fem"]["cylinder_element_size_m"],
        seed=POSTERIOR.get("seed", 0),
        pkg=script_hash("workflow/scripts/uq_fem.py"),
    script:
        "../scripts/uq_fem.py"


def extension_indentation_inputs(wildcards):
    """The bands, the simulation cards and, for the brain-indentation dataset, the MNI brain mesh (both cards
    are pressed into it too)."""
    inputs = {
        "bands": f"results/{wildcards.dataset}/uq/indentation_material.nc",
        "cards": f"results/{wildcards.dataset}/diagnosis/simulation_cards",
        "compiled": NUMBA_COMPILED,
    }
    if BRAIN_INDENTATION and wildcards.dataset == BRAIN_DATASET:
        inputs["brain_mesh"] = BRAIN_FILES["brain_mesh"]
    return inputs


rule uq_extension_indentation:
    # the named extensions' full-data cards beside their baseline on the flat punch of the bands above (and in the
    # MNI brain)
    input:
        unpack(extension_indentation_inputs),
    output:
        table="results/{dataset}/uq/extension_indentation.csv",
    log:
        "logs/{dataset}/uq_extension_indentation.log",
    benchmark:
        "benchmarks/runs/{dataset}/uq_extension_indentation.tsv"
    threads: FEM_THREADS
    params:
        pkg=script_hash("workflow/scripts/uq_extension.py"),
    script:
        "../scripts/uq_extension.py"

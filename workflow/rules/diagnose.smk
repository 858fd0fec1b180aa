# What the model gets wrong, why, the extension that fixes it and the held-out gain. The baseline is the first
# adequate fit in the order of ranking.csv (QLV family first); see README "Reading a diagnosis". The extension of a
# named cause is fitted to all runs and per fold; its cards (diagnosis/simulation_cards) are replayed by rule
# fem_replay, and rule diagnosis adds the simulator's held-out gain (fix.simulation) to diagnosis.json.
# Homogeneous multi-mode datasets (simple shear + compression + tension, e.g. Budday) are dispatched to the
# cross-mode diagnosis, which refits its I1/I2 laws per mode combination; their fits input only orders the job.


rule diagnose:
    input:
        runs="results/{dataset}/runs",
        fits=diagnosis_fits,
        ranking="results/{dataset}/ranking.csv",
    output:
        # the findings before the simulator scored their extensions (rule diagnosis writes diagnosis.json)
        json="results/{dataset}/diagnosis/findings.json",
        extension_cards=directory("results/{dataset}/diagnosis/simulation_cards"),
        residuals="results/{dataset}/residuals.nc",
        figures=report(
            directory("results/{dataset}/figures/diagnosis"),
            patterns=["{figure}.png"],
            caption="../report/diagnosis.rst",
            category="{dataset}",
            subcategory="5 diagnosis",
            labels={"figure": "{figure}"},
        ),
    log:
        "logs/{dataset}/diagnose.log",
    benchmark:
        "benchmarks/runs/{dataset}/diagnose.tsv"
    priority: critical_chain_priority
    params:
        alpha=config["diagnosis"]["alpha"],
        poisson_ratio=config["fem"]["poisson_ratio"],
        pkg=script_hash("workflow/scripts/diagnose.py"),
    script:
        "../scripts/diagnose.py"


rule diagnosis:
    # the findings with the simulator's score of each named extension (fix.simulation), where the tests are replayed
    input:
        unpack(diagnosis_inputs),
    output:
        json=report(
            "results/{dataset}/diagnosis.json",
            caption="../report/diagnosis_json.rst",
            category="{dataset}",
            subcategory="5 diagnosis",
            labels={"figure": "diagnosis record"},
        ),
    log:
        "logs/{dataset}/diagnosis.log",
    benchmark:
        "benchmarks/runs/{dataset}/diagnosis.tsv"
    priority: critical_chain_priority
    params:
        pkg=script_hash("workflow/scripts/diagnosis.py"),
    script:
        "../scripts/diagnosis.py"

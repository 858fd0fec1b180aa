# What the model gets wrong, why, the extension that fixes it and the held-out gain. The baseline is the first
# adequate fit in the order of ranking.csv (QLV family first); see README "Reading a diagnosis".
# Homogeneous multi-mode datasets (simple shear + compression + tension, e.g. Budday) are dispatched to the
# cross-mode diagnosis, which refits its I1/I2 laws per mode combination; their fits input only orders the job.


rule diagnose:
    input:
        runs="results/{dataset}/runs",
        fits=diagnosis_fits,
        ranking="results/{dataset}/ranking.csv",
    output:
        json=report(
            "results/{dataset}/diagnosis.json",
            caption="../report/diagnosis_json.rst",
            category="{dataset}",
            subcategory="5 diagnosis",
            labels={"figure": "diagnosis record"},
        ),
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
    params:
        alpha=config["diagnosis"]["alpha"],
        pkg=script_hash("workflow/scripts/diagnose.py"),
    script:
        "../scripts/diagnose.py"

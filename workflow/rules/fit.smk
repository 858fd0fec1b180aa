# Model fits per dataset and scope (joint test kinds), cross-validated ranking, material cards.


rule fit_scope:
    input:
        averages="results/{dataset}/averages.nc",
    output:
        fits=directory("results/{dataset}/fits/{scope}"),
        cards=directory("results/{dataset}/cards/{scope}"),
        ranking="results/{dataset}/ranking/{scope}.csv",
    log:
        "logs/{dataset}/fit_{scope}.log",
    benchmark:
        "benchmarks/runs/{dataset}/fit_{scope}.tsv"
    group:
        "fits"
    params:
        spec=scope_spec,
        target=config["fit"]["plate_target"],
        seed=config["fit"]["seed"],
        multistart=config["fit"]["multistart"],
        poisson_ratio=config["fem"]["poisson_ratio"],
        pkg=script_hash("workflow/scripts/fit_scope.py"),
    script:
        "../scripts/fit_scope.py"


rule rank:
    input:
        rankings=scope_rankings,
        fits=scope_fit_dirs,
    output:
        ranking=report(
            "results/{dataset}/ranking.csv",
            caption="../report/ranking_table.rst",
            category="{dataset}",
            subcategory="4 ranking",
            labels={"item": "ranking table"},
        ),
        fits="results/{dataset}/fits.csv",
        figure=report(
            "results/{dataset}/figures/ranking.png",
            caption="../report/ranking.rst",
            category="{dataset}",
            subcategory="4 ranking",
            labels={"item": "ranking figure"},
        ),
    log:
        "logs/{dataset}/rank.log",
    benchmark:
        "benchmarks/runs/{dataset}/rank.tsv"
    params:
        pkg=script_hash("workflow/scripts/rank.py"),
    script:
        "../scripts/rank.py"

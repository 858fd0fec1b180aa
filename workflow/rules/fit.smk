# Model fits per dataset and scope (joint test kinds), cross-validated ranking, material cards, and their figures
# (drawn in the same jobs: a separate figure job per scope paid the Python and package start-up again).
# The mastercurve scope (sweeps at >= 2 temperatures) also reads tts.nc: its sweeps are fitted shifted to Tref.


rule fit_scope:
    input:
        unpack(fit_scope_inputs),
    output:
        fits=directory("results/{dataset}/fits/{scope}"),
        cards=directory("results/{dataset}/cards/{scope}"),
        ranking="results/{dataset}/ranking/{scope}.csv",
        figures=report(
            directory("results/{dataset}/figures/fits/{scope}"),
            patterns=["{model}.png"],
            caption="../report/fits.rst",
            category="{dataset}",
            subcategory="3 fits: {scope}",
            labels={"scope": "{scope}", "model": "{model}"},
        ),
    log:
        "logs/{dataset}/fit_{scope}.log",
    benchmark:
        "benchmarks/runs/{dataset}/fit_{scope}.tsv"
    priority: critical_chain_priority
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
    # fits.csv waits for the posterior tables of the dataset (none for most datasets; rule posterior reads the fits,
    # not the ranking) so that it carries their credible intervals next to the lmfit standard errors
    input:
        rankings=scope_rankings,
        cards=scope_card_dirs,
        fits=scope_fit_dirs,
        posterior=posterior_tables,
    output:
        fits="results/{dataset}/fits.csv",
        ranking=report(
            "results/{dataset}/ranking.csv",
            caption="../report/ranking_table.rst",
            category="{dataset}",
            subcategory="4 ranking",
            labels={"item": "ranking table"},
        ),
        figure=report(
            "results/{dataset}/figures/ranking.png",
            caption="../report/ranking.rst",
            category="{dataset}",
            subcategory="4 ranking",
            labels={"item": "ranking figure"},
        ),
        cross_test=report(
            "results/{dataset}/cross_test.csv",
            caption="../report/cross_test_table.rst",
            category="{dataset}",
            subcategory="4 ranking",
            labels={"item": "cross-test table"},
        ),
        cross_test_figure=report(
            "results/{dataset}/figures/cross_test.png",
            caption="../report/cross_test.rst",
            category="{dataset}",
            subcategory="4 ranking",
            labels={"item": "cross-test figure"},
        ),
        cards_table=report(
            "results/{dataset}/cards.csv",
            caption="../report/cards_table.rst",
            category="{dataset}",
            subcategory="6 material cards",
            labels={"table": "all cards"},
        ),
        card_figures=report(
            directory("results/{dataset}/figures/cards"),
            patterns=["{scope}.png"],
            caption="../report/cards.rst",
            category="{dataset}",
            subcategory="6 material cards",
            labels={"table": "{scope}"},
        ),
    log:
        "logs/{dataset}/rank.log",
    benchmark:
        "benchmarks/runs/{dataset}/rank.tsv"
    priority: critical_chain_priority
    params:
        cards_root="results/{dataset}/cards",
        pkg=script_hash("workflow/scripts/rank.py"),
    script:
        "../scripts/rank.py"

# TLED experiments driven by the material cards: rheometer torsion, the replay of the measured tests,
# flat-punch indentation, timing.

# the MNI brain geometry (nilearn wheel data, fTetWild): the timing rule always uses the mesh; flat-punch
# indentation of it runs with the best card of the first selected indentation dataset, when one is selected
BRAIN_MESH = bool(config["fem"].get("brain_mesh", False))
BRAIN_DATASET = next(
    (d for d in config["fem"].get("indentation_datasets", []) if d in DATASETS), None
)
BRAIN_INDENTATION = BRAIN_MESH and BRAIN_DATASET is not None
# numba threads of one FEM job (Snakemake schedules jobs by these threads)
FEM_THREADS = int(config["fem"].get("threads", 1))
BRAIN_FILES = {
    "brain_mesh": "results/fem/brain_mesh.vtu",
    "brain_indentation": "results/fem/brain_indentation.nc",
}
# every TLED job waits for rule fem_compile, which fills numba's cache once (a cold process compiles the loops
# for ~1.5 CPU minutes, ~90 CPU s; FEM jobs that started together each did)
NUMBA_COMPILED = "results/fem/numba_compiled.json"


rule fem_compile:
    output:
        stamp=NUMBA_COMPILED,
    log:
        "logs/fem_compile.log",
    benchmark:
        "benchmarks/runs/fem_compile.tsv"
    params:
        pkg=script_hash("workflow/scripts/fem_compile.py"),
    script:
        "../scripts/fem_compile.py"


rule fem_torsion:
    input:
        compiled=NUMBA_COMPILED,
        ranking="results/{dataset}/ranking.csv",
        averages="results/{dataset}/averages.nc",
    output:
        table=report(
            "results/{dataset}/fem/torsion.csv",
            caption="../report/fem_torsion_table.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "torsion", "item": "error table"},
        ),
        data="results/{dataset}/fem/torsion.nc",
        figure=report(
            "results/{dataset}/figures/fem_torsion.png",
            caption="../report/fem_torsion.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "torsion", "item": "torque vs rim strain"},
        ),
        vtu=directory("results/{dataset}/fem/torsion_vtu"),
    log:
        "logs/{dataset}/fem_torsion.log",
    benchmark:
        "benchmarks/runs/{dataset}/fem_torsion.tsv"
    threads: FEM_THREADS
    params:
        cards_root="results/{dataset}/cards",
        element_size_m=config["fem"]["cylinder_element_size_m"],
        pkg=script_hash("workflow/scripts/fem_torsion.py"),
    script:
        "../scripts/fem_torsion.py"


rule fem_replay_baseline:
    # the baseline card needs no diagnosis: it is replayed while the diagnosis runs (rule fem_replay adds the
    # extension cards the diagnosis names)
    input:
        compiled=NUMBA_COMPILED,
        ranking="results/{dataset}/ranking.csv",
        averages="results/{dataset}/averages.nc",
    output:
        table="results/{dataset}/fem/replay_baseline.csv",
        points="results/{dataset}/fem/replay_baseline_points.csv",
    log:
        "logs/{dataset}/fem_replay_baseline.log",
    benchmark:
        "benchmarks/runs/{dataset}/fem_replay_baseline.tsv"
    priority: critical_chain_priority
    threads: FEM_THREADS
    params:
        cards_root="results/{dataset}/cards",
        element_size_m=config["fem"]["cylinder_element_size_m"],
        pkg=script_hash("workflow/scripts/fem_replay.py"),
    script:
        "../scripts/fem_replay.py"


def fem_replay_inputs(wildcards):
    """The replay's inputs: its cards (through ranking.csv), the averages, the baseline card's replay, and
    diagnosis.json where the dataset has one (the named causes whose extension cards are replayed beside the
    baseline card).
    """
    inputs = {
        "compiled": NUMBA_COMPILED,
        "ranking": f"results/{wildcards.dataset}/ranking.csv",
        "averages": f"results/{wildcards.dataset}/averages.nc",
        "replayed_table": f"results/{wildcards.dataset}/fem/replay_baseline.csv",
        "replayed_points": f"results/{wildcards.dataset}/fem/replay_baseline_points.csv",
    }
    if has_diagnosis(wildcards.dataset):
        inputs["diagnosis"] = f"results/{wildcards.dataset}/diagnosis/findings.json"
        inputs["extension_cards"] = (
            f"results/{wildcards.dataset}/diagnosis/simulation_cards"
        )
    return inputs


rule fem_replay:
    input:
        unpack(fem_replay_inputs),
    output:
        table=report(
            "results/{dataset}/fem/replay.csv",
            caption="../report/fem_replay_table.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "replay", "item": "error table"},
        ),
        points="results/{dataset}/fem/replay_points.csv",
        fix_simulation="results/{dataset}/fem/fix_simulation.json",
        figure=report(
            "results/{dataset}/figures/fem_replay.png",
            caption="../report/fem_replay.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "replay", "item": "measured vs simulated"},
        ),
    log:
        "logs/{dataset}/fem_replay.log",
    benchmark:
        "benchmarks/runs/{dataset}/fem_replay.tsv"
    priority: critical_chain_priority
    threads: FEM_THREADS
    params:
        cards_root="results/{dataset}/cards",
        element_size_m=config["fem"]["cylinder_element_size_m"],
        pkg=script_hash("workflow/scripts/fem_replay.py"),
    script:
        "../scripts/fem_replay.py"


rule fem_indentation:
    input:
        compiled=NUMBA_COMPILED,
        ranking="results/{dataset}/ranking.csv",
    output:
        data="results/{dataset}/fem/indentation.nc",
        figure=report(
            "results/{dataset}/figures/fem_indentation.png",
            caption="../report/fem_indentation.rst",
            category="{dataset}",
            subcategory="7 FEM experiments",
            labels={"experiment": "indentation", "item": "force vs depth"},
        ),
        vtu=directory("results/{dataset}/fem/indentation_vtu"),
    log:
        "logs/{dataset}/fem_indentation.log",
    benchmark:
        "benchmarks/runs/{dataset}/fem_indentation.tsv"
    threads: FEM_THREADS
    params:
        cards_root="results/{dataset}/cards",
        element_size_m=config["fem"]["block_element_size_m"],
        pkg=script_hash("workflow/scripts/fem_indentation.py"),
    script:
        "../scripts/fem_indentation.py"


rule fem_brain_mesh:
    output:
        mesh=BRAIN_FILES["brain_mesh"],
        quality="results/fem/brain_mesh_quality.json",
    log:
        "logs/fem_brain_mesh.log",
    benchmark:
        "benchmarks/runs/fem_brain_mesh.tsv"
    params:
        pkg=script_hash("workflow/scripts/fem_brain_mesh.py"),
    script:
        "../scripts/fem_brain_mesh.py"


rule fem_brain_indentation:
    input:
        compiled=NUMBA_COMPILED,
        ranking=f"results/{BRAIN_DATASET}/ranking.csv",
        brain_mesh=BRAIN_FILES["brain_mesh"],
    output:
        data=BRAIN_FILES["brain_indentation"],
        vtu=directory("results/fem/brain_indentation_vtu"),
    log:
        "logs/fem_brain_indentation.log",
    benchmark:
        "benchmarks/runs/fem_brain_indentation.tsv"
    threads: FEM_THREADS
    params:
        cards_root=f"results/{BRAIN_DATASET}/cards",
        pkg=script_hash("workflow/scripts/fem_brain_indentation.py"),
    script:
        "../scripts/fem_brain_indentation.py"


rule fem_timing:
    input:
        unpack(
            lambda wildcards: {"compiled": NUMBA_COMPILED}
            | ({"brain_mesh": BRAIN_FILES["brain_mesh"]} if BRAIN_MESH else {})
        ),
    output:
        table=report(
            "results/fem/timing.csv",
            caption="../report/timing_table.rst",
            category="FEM timing",
            labels={"figure": "table"},
        ),
    log:
        "logs/fem_timing.log",
    benchmark:
        "benchmarks/runs/fem_timing.tsv"
    params:
        python=sys.executable,
        pkg=script_hash("benchmarks/fem_timing.py"),
        brain=f"--brain-mesh {BRAIN_FILES['brain_mesh']}" if BRAIN_MESH else "",
    shell:
        "{params.python} benchmarks/fem_timing.py --threads 1 --max-elements 20000 --kernels auto,generic --precisions float64 --updates 2e6 {params.brain}"
        " --out {output.table} > {log} 2>&1"

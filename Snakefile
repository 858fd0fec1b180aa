# tissuemech: rheometer exports -> canonical runs -> averages/LVE -> fits -> ranking -> cards -> diagnosis -> FEM
from snakemake.utils import min_version, validate

min_version("9.0")


configfile: "config/config.yaml"


report: "workflow/report/workflow.rst"


validate(config, schema="workflow/schemas/config.schema.yaml")


include: "workflow/rules/common.smk"
include: "workflow/rules/ingest.smk"
include: "workflow/rules/curves.smk"
include: "workflow/rules/fit.smk"
include: "workflow/rules/diagnose.smk"
include: "workflow/rules/fem.smk"
include: "workflow/rules/report.smk"
include: "workflow/rules/uq.smk"


rule all:
    default_target: True
    input:
        all_targets() + uq_targets(),

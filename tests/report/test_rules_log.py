"""Every rule of the workflow writes a log file per job under logs/ and a benchmark under benchmarks/runs/."""
from __future__ import annotations

import re

import pytest


def _rules(repo_root):
    """rule name -> its block of text, for the Snakefile and every workflow/rules/*.smk."""
    files = [repo_root / "Snakefile", *sorted((repo_root / "workflow" / "rules").glob("*.smk"))]
    blocks = {}
    for path in files:
        text = path.read_text()
        for match in re.finditer(r"^rule (\w+):\n((?:[ \t]+.*\n|\n)*)", text, re.M):
            blocks[match.group(1)] = (path.name, match.group(2))
    return blocks


def test_the_parser_sees_the_rules(repo_root):
    rules = _rules(repo_root)
    assert {"ingest", "average", "fit_scope", "rank", "summary", "mesh_figures", "all"} <= set(rules)


@pytest.mark.parametrize("directive,prefix", [("log", "logs/"), ("benchmark", "benchmarks/runs/")])
def test_every_rule_has_a_log_and_a_benchmark(repo_root, directive, prefix):
    missing = []
    for name, (filename, block) in _rules(repo_root).items():
        if name == "all":
            continue
        match = re.search(rf"^\s+{directive}:\n\s+\"([^\"]+)\"", block, re.M)
        if match is None or not match.group(1).startswith(prefix):
            missing.append(f"{filename}: rule {name}")
    assert not missing, f"rules without a {directive}: under {prefix}: {missing}"


def test_job_logs_are_unique_per_job(repo_root):
    """Two rules writing the same log path would overwrite each other's logs."""
    seen = {}
    for name, (_, block) in _rules(repo_root).items():
        match = re.search(r"^\s+log:\n\s+\"([^\"]+)\"", block, re.M)
        if match:
            assert match.group(1) not in seen, f"rules {seen.get(match.group(1))} and {name} share a log path"
            seen[match.group(1)] = name

"""Rerun-trigger hashes: every package module a script reaches through imports (static, transitive)."""
from pathlib import Path

from tissuemech.sourcehash import package_sources, source_hash


def _package(tmp_path: Path) -> Path:
    src = tmp_path / "src"
    pkg = src / "tissuemech"
    (pkg / "sub" / "schemas").mkdir(parents=True)
    (pkg / "other").mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from .helpers import x  # noqa\n")
    (pkg / "sub" / "helpers.py").write_text("x = 1\n")
    (pkg / "sub" / "leaf.py").write_text("def f():\n    from ..deep import g\n    return g()\n")
    (pkg / "sub" / "schemas" / "a.schema.json").write_text("{}")
    (pkg / "deep.py").write_text("import numpy\n\ndef g():\n    return 2\n")
    (pkg / "other" / "__init__.py").write_text("")
    (pkg / "other" / "unused.py").write_text("y = 2\n")
    (pkg / "other" / "data.json").write_text("{}")
    (tmp_path / "script.py").write_text("from tissuemech.sub import leaf\n")
    return src


def test_sources_are_transitive_and_include_function_level_imports_and_package_data(tmp_path):
    src = _package(tmp_path)
    names = {p.relative_to(src / "tissuemech").as_posix() for p in package_sources(tmp_path / "script.py", src)}
    assert names == {"__init__.py", "sub/__init__.py", "sub/helpers.py", "sub/leaf.py", "deep.py",
                     "sub/schemas/a.schema.json"}


def test_hash_changes_with_a_reached_module_only(tmp_path):
    src = _package(tmp_path)
    script = tmp_path / "script.py"
    before = source_hash(script, src)
    (src / "tissuemech" / "other" / "unused.py").write_text("y = 3\n")
    assert source_hash(script, src) == before
    (src / "tissuemech" / "deep.py").write_text("def g():\n    return 3\n")
    assert source_hash(script, src) != before


def test_real_fit_script_reaches_every_model_family():
    root = Path(__file__).resolve().parents[2]
    names = {p.name for p in package_sources(root / "workflow" / "scripts" / "fit_scope.py", root / "src")}
    assert {"_data.py", "_problem.py", "_fit.py", "_prony.py", "ranking.py", "registry.py", "hyperelastic.py",
            "beyond_qlv.py", "viscous.py", "pipeline.py"} <= names

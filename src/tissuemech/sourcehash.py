"""Source hashes of the package code a workflow script runs (Snakemake rerun triggers).

Snakemake reruns a job when its script, shell command or params change, but not when a module the script imports
changes. Each rule therefore passes ``source_hash(script)`` as a param: a digest of every ``tissuemech`` source
file the script can reach through imports, found statically (``ast``) and transitively, including imports inside
functions and the package ``__init__`` files that importing a submodule executes. Data files shipped inside a
reached package folder (e.g. the JSON schemas of ``tissuemech.io``) are part of the digest.

Only the standard library is used, so the Snakefile can call it at parse time without importing the science.
"""
from __future__ import annotations

import ast
import functools
import hashlib
from collections.abc import Iterable
from pathlib import Path

PACKAGE = "tissuemech"
#: non-Python files inside package folders that change results
DATA_SUFFIXES = (".json",)


def _module_name(path: Path, src_dir: Path) -> str | None:
    try:
        parts = list(path.relative_to(src_dir).with_suffix("").parts)
    except ValueError:
        return None  # a script outside the package
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _module_file(name: str, src_dir: Path) -> Path | None:
    base = src_dir.joinpath(*name.split("."))
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def _imported_names(path: Path, src_dir: Path) -> Iterable[str]:
    """Absolute module names a source file may import (``from a import b`` yields ``a`` and ``a.b``).

    Parsed once per process and file version: a Snakefile hashes every rule script at parse time, and the
    scripts share most of the package (16 scripts re-parsed the same ~100 modules, ~7 s of CPU per start)."""
    stat = path.stat()
    return _imported_names_cached(str(path), stat.st_mtime_ns, stat.st_size, str(src_dir))


@functools.lru_cache(maxsize=4096)
def _imported_names_cached(path_str: str, mtime_ns: int, size: int, src_dir_str: str) -> tuple[str, ...]:
    return tuple(_parse_imported_names(Path(path_str), Path(src_dir_str)))


def _parse_imported_names(path: Path, src_dir: Path) -> Iterable[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    own = _module_name(path, src_dir)
    package = (own if path.name == "__init__.py" else own.rpartition(".")[0]) if own else None
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                if package is None:
                    continue
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            yield base
            yield from (f"{base}.{alias.name}" for alias in node.names if alias.name != "*")


def _package_data(folder: Path) -> list[Path]:
    """Data files of a package folder and of its plain (non-package) subfolders."""
    files = [p for p in folder.iterdir() if p.is_file() and p.suffix in DATA_SUFFIXES]
    for sub in folder.iterdir():
        if sub.is_dir() and not (sub / "__init__.py").exists():
            files += [p for p in sub.rglob("*") if p.is_file() and p.suffix in DATA_SUFFIXES]
    return files


def package_sources(script: str | Path, src_dir: str | Path) -> list[Path]:
    """Every package source file reachable by imports from ``script`` (sorted; the script itself excluded).

    Parameters
    ----------
    script : a workflow script or a package module
    src_dir : the folder that holds the ``tissuemech`` package (``<repo>/src``)
    """
    src_dir = Path(src_dir).resolve()
    script = Path(script).resolve()
    found: set[Path] = set()
    queue = [script]
    while queue:
        current = queue.pop()
        for name in _imported_names(current, src_dir):
            if name != PACKAGE and not name.startswith(PACKAGE + "."):
                continue
            parts = name.split(".")
            # importing a.b.c runs a/__init__, a/b/__init__ and a/b/c
            for depth in range(1, len(parts) + 1):
                target = _module_file(".".join(parts[:depth]), src_dir)
                if target is not None and target not in found:
                    found.add(target)
                    queue.append(target)
    for folder in {p.parent for p in found if p.name == "__init__.py"}:
        found.update(_package_data(folder))
    found.discard(script)
    return sorted(found)


def source_hash(script: str | Path, src_dir: str | Path, length: int = 16) -> str:
    """SHA-256 (hex, first ``length`` digits) over the relative paths and bytes of :func:`package_sources`."""
    src_dir = Path(src_dir).resolve()
    digest = hashlib.sha256()
    for path in package_sources(script, src_dir):
        digest.update(path.relative_to(src_dir).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:length]

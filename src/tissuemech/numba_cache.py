"""A numba cache folder keyed by the numba-compiled sources of the package.

numba keys a cached function on its own source file only, while the TLED loops of ``fem/_kernels.py`` compile in
functions of other modules (the material laws, ``fem.kinematics.symmetric_eigen3``, ``models``): one cache folder
kept across edits serves a kernel compiled from older sources of those modules. The Makefile sets
``NUMBA_CACHE_DIR`` to :func:`source_keyed_cache_dir`; the test suite and the benchmarks, which also run outside
``make``, call :func:`use_source_keyed_cache`. This module imports only the standard library (nothing that imports
numba, so it can run before numba reads its configuration, and any ``python3`` can run it before the install).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

#: the package folders whose modules the compiled kernels reach
KERNEL_SOURCE_FOLDERS = ("fem", "models")


def source_keyed_cache_dir(base: str | Path, package: str | Path | None = None) -> Path:
    """``base / "src-<sha1 of fem/*.py and models/*.py of the package>"`` (16 hex digits); ``package``: the package
    folder (default: this one's)."""
    package = Path(__file__).resolve().parent if package is None else Path(package)
    digest = hashlib.sha1()
    for folder in KERNEL_SOURCE_FOLDERS:
        for source in sorted((package / folder).glob("*.py")):
            digest.update(f"{folder}/{source.name}".encode())
            digest.update(source.read_bytes())
    return Path(base) / f"src-{digest.hexdigest()[:16]}"


def use_source_keyed_cache(base: str | Path) -> None:
    """Set ``NUMBA_CACHE_DIR`` to :func:`source_keyed_cache_dir` of ``base``, unless it is set (e.g. by the Makefile).
    Call it before anything imports numba."""
    os.environ.setdefault("NUMBA_CACHE_DIR", str(source_keyed_cache_dir(base)))

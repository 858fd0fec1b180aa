"""Shared pytest fixtures."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED_REAL = Path(os.environ.get("TISSUEMECH_SHARED_REAL", ROOT.parent / "shared" / "data" / "real"))


@pytest.fixture(scope="session")
def shared_real() -> Path:
    """The read-only folder of real instrument exports; tests using it skip when it is absent."""
    if not SHARED_REAL.is_dir():
        pytest.skip(f"real data folder {SHARED_REAL} not available")
    return SHARED_REAL


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return ROOT

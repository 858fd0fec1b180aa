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


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """Make ``--dist loadgroup`` honour ``xdist_group`` under pytest >= 9.

    pytest-xdist (3.8) sends the tests of a group to one worker by appending ``@<group>`` to each item's
    nodeid on the workers, and it does so by assigning ``item._nodeid``; pytest 9 derives ``nodeid`` from
    ``item._id``, so the suffix is lost and every group is spread over both workers (each worker then
    builds the group's module-scoped fixtures: the regression refits, the workflow runs ...). This hook
    sets the suffix where pytest reads it; it does nothing where xdist's own suffix already took effect.
    """
    if not getattr(config.option, "loadgroup", False):  # set by xdist on its workers
        return
    try:
        from _pytest.nodeid import NodeId
    except ImportError:  # pytest < 9: xdist's own suffix works
        return
    for item in items:
        names = sorted({str(m.args[0] if m.args else m.kwargs.get("name", "default"))
                        for m in item.iter_markers("xdist_group")})
        if not names or not isinstance(getattr(item, "_id", None), NodeId):
            continue
        suffix = "@" + "_".join(names)
        if not item.nodeid.endswith(suffix):
            item._id = NodeId.parse(item.nodeid + suffix)

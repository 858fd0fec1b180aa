"""Shared fixtures of the FEM tests; analytic helpers live in ``fem_reference``."""
from __future__ import annotations

import pytest


@pytest.fixture(autouse=True)
def _single_numba_thread():
    """Run the kernels on one thread: on the shared 2-core CI machine parallel regions that wait for a
    descheduled thread make small problems several times slower (results do not depend on it)."""
    from tissuemech.fem.tled import numba_threads

    with numba_threads(1):
        yield

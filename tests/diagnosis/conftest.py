"""Fixtures of the diagnosis tests: constructed designs (see constructed.py) diagnosed once per module."""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))


@pytest.fixture(scope="session")
def diagnosed():
    """Cache: (effect, kwargs) -> (runs, table, result) so each constructed design is diagnosed once."""
    from constructed import make_design
    from tissuemech.diagnosis.evidence import residual_table
    from tissuemech.diagnosis.report import diagnose

    cache = {}

    def get(effect, **kw):
        key = (effect, tuple(sorted(kw.items())))
        if key not in cache:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                runs, preds, fit_info = make_design(effect, **kw)
                table = residual_table(runs, preds, "qlv_constructed")
                cache[key] = (runs, table, diagnose(runs, table, "qlv_constructed", fit_info))
        return cache[key]

    return get

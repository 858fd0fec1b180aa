"""Shared pytest fixtures."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from tissuemech.numba_cache import use_source_keyed_cache

ROOT = Path(__file__).resolve().parents[1]
# a plain pytest run (not make test) gets a cache folder named after the kernel sources too: numba's own __pycache__
# cache would serve the TLED loops compiled from older material laws or kinematics (tissuemech.numba_cache)
use_source_keyed_cache(ROOT / ".numba_cache")
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


@pytest.fixture(scope="module")
def qlv_rp3_fit():
    """A QLV (RP3 x Prony 4) fit to its own noise-free 0.01 1/s ramp: ``(model, FitResult)`` (the uncertainty and
    the card-file tests start from it)."""
    import numpy as np

    from tissuemech import fitting as F
    from tissuemech.models.qlv import qlv_params
    from tissuemech.models.registry import get_model

    key = "qlv_rp3_prony4"
    model = get_model(key)
    truth = qlv_params(model, {"C10": 150.0, "C20": 50.0, "C30": 200.0}, [0.3, 0.2, 0.15, 0.05])
    t = np.linspace(0.0, 50.0, 41)
    g = 0.01 * t
    curve = F.Curve(test="constant_shear_rate", condition="rate=0.01/s", response="shear_history",
                    inputs={"time": t, "shear_strain": g},
                    observed={"shear_stress": model.shear_stress_history(truth, t, g)[1:]},
                    obs_index=np.arange(1, 41), nominal={"shear_rate_1_per_s": 0.01})
    return model, F.fit(F.FitProblem(model, [curve], target="none", model_key=key), starts=[truth], n_random=0)


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

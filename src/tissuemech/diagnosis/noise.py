"""The second stage of the diagnosis, after the baseline and before the detectors: the noise model of the
measured quantities, read from the data themselves. It is :mod:`tissuemech.noise`, the one model that the LVE
limit and the ingest's quality flags use too; re-exported here so that the diagnosis package reads as its
pipeline.
"""
from collections.abc import Mapping

import numpy as np

from .. import fitting
from ..noise import (ABOVE_NOISE_SIGMAS, COMPARED_QUANTITIES, INPUT_QUANTITIES, MODULI, OSCILLATORY_TESTS,
                     estimate_noise, is_response, measured_torque_modulus, noise_sd, points_above_floor,
                     relative_noise_level, robust_noise_sd)

__all__ = ["ABOVE_NOISE_SIGMAS", "COMPARED_QUANTITIES", "INPUT_QUANTITIES", "MODULI", "OSCILLATORY_TESTS",
           "estimate_noise", "fit_noise", "is_response", "measured_torque_modulus", "noise_sd", "points_above_floor", "relative_noise_level", "robust_noise_sd"]


#: fit observables whose noise block is the run quantity of the same name; a torque observable has the relative
#: scatter of the rim stress it is proportional to (its absolute floor needs the plate radius: the fit's default)
_FIT_OBSERVABLE_OF = {"torque": "shear_stress"}


def fit_noise(noise: Mapping) -> fitting.NoiseModel:
    """The weights of a fit under :func:`estimate_noise`'s model: per fit observable the within-curve relative SD
    and, where it is in the observable's own unit, the absolute floor (median over the test blocks of that
    quantity), so that a refit weighs its points as the residual tests do (a point ten times below the fit's
    default floor but well above the measured one counts). Observables without an estimate, and estimates of zero
    (noise-free data), keep the defaults of :class:`tissuemech.fitting.NoiseModel`."""
    default = fitting.NoiseModel()
    blocks = noise.get("blocks", {})
    relative, absolute = {}, dict(default.absolute)
    for observable in set(default.absolute) | set(_FIT_OBSERVABLE_OF):
        quantity = _FIT_OBSERVABLE_OF.get(observable, observable)
        # only the tests that respond in the quantity: an imposed strain or creep stress has no response noise
        entries = [b for k, b in blocks.items() if k.partition("|")[2] == quantity and is_response(k)]
        rel = [float(b["relative"]) for b in entries if float(b["relative"]) > 0]
        if rel:
            relative[observable] = float(np.median(rel))
        own = [float(b["absolute"]) for b in entries if "absolute_units" not in b and float(b["absolute"]) > 0]
        if own and observable == quantity:
            absolute[observable] = float(np.median(own))
    return fitting.NoiseModel(relative=default.relative, absolute=absolute, relative_by=relative)

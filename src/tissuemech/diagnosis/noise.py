"""The second stage of the diagnosis, after the baseline and before the detectors: the noise model of the
measured quantities, read from the data themselves. It is :mod:`tissuemech.noise`, the one model that the LVE
limit and the ingest's quality flags use too; re-exported here so that the diagnosis package reads as its
pipeline.
"""
from ..noise import (ABOVE_NOISE_SIGMAS, COMPARED_QUANTITIES, INPUT_QUANTITIES, MODULI, OSCILLATORY_TESTS,
                     estimate_noise, noise_sd, points_above_floor, relative_noise_level, robust_noise_sd)

__all__ = ["ABOVE_NOISE_SIGMAS", "COMPARED_QUANTITIES", "INPUT_QUANTITIES", "MODULI", "OSCILLATORY_TESTS",
           "estimate_noise", "noise_sd", "points_above_floor", "relative_noise_level", "robust_noise_sd"]

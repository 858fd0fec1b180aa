"""Constructed multi-mode homogeneous data (Budday-like design) with a known Mooney-Rivlin truth.

Simple shear gamma in [-0.2, 0.2] (P12), uniaxial compression lambda 1 -> 0.9 and tension 1 -> 1.1 (P11),
generated through the closed forms of :mod:`tissuemech.models.hyperelastic` (``W = C10 (I1-3) + C01 (I2-3)``)
with 1 % relative + 0.03 Pa Gaussian noise: P12 = 2 gamma (C10 + C01), P11 = 2 (lambda - lambda^-2)(C10 + C01/lambda).
"""
from __future__ import annotations

import numpy as np

from tissuemech.canonical import make_run_dataset
from tissuemech.models.registry import get_model

#: C10 + C01 held at the initial shear modulus / 2 of cortex (mu0 = 2 (C10 + C01) ~ 1.2 kPa)
C_SUM = 600.0
#: the typical I2 share C01 / (C10 + C01) of magnitude 1 (0.5x and 2x in the power study)
TYPICAL_SHARE = 0.4


def make_multimode(c01_share: float = TYPICAL_SHARE, seed: int = 0, rel_noise: float = 0.01,
                   n_shear: int = 23, n_compression: int = 30, n_tension: int = 18) -> list:
    """Canonical runs (simple shear, compression, tension) of a Mooney-Rivlin truth with
    C01 = c01_share * C_SUM and C10 = C_SUM - C01."""
    rng = np.random.default_rng(seed)
    model = get_model("mooney_rivlin")
    c01 = c01_share * C_SUM
    p = {"C10": C_SUM - c01, "C01": c01}

    def noisy(y):
        return y + rng.normal(0.0, 1.0, y.shape) * np.sqrt((rel_noise * y) ** 2 + 0.03 ** 2)

    gamma = np.linspace(-0.2, 0.2, n_shear)
    lam_c = np.linspace(1.0, 0.9, n_compression)
    lam_t = np.linspace(1.0, 1.1, n_tension)
    common = {"dataset": "constructed_multimode", "specimen": "s1", "sample": "mean", "source_file": "none",
              "source_sha256": "0", "truth_C10_pa": p["C10"], "truth_C01_pa": p["C01"]}
    return [
        make_run_dataset({"shear_strain": gamma, "shear_stress": noisy(model.elastic_shear_stress(p, gamma))},
                         {**common, "run": "s1_shear", "test": "simple_shear", "order": 1, "covariate_mode": "shear"}),
        make_run_dataset({"stretch": lam_c, "nominal_stress": noisy(model.uniaxial_nominal_stress(p, lam_c))},
                         {**common, "run": "s1_compression", "test": "uniaxial", "order": 2,
                          "covariate_mode": "compression"}),
        make_run_dataset({"stretch": lam_t, "nominal_stress": noisy(model.uniaxial_nominal_stress(p, lam_t))},
                         {**common, "run": "s1_tension", "test": "uniaxial", "order": 3, "covariate_mode": "tension"}),
    ]

"""Cross-checks of the redundant columns an instrument writes, as an integrity check of what was read.

Oscillation exports carry more columns than they have degrees of freedom: the loss factor is
:math:`\\tan\\delta = G''/G'` and the complex viscosity is :math:`|\\eta^*| = \\sqrt{G'^2 + G''^2}/\\omega`.
When a file's bytes are damaged (a binary ``.xls`` has no checksum) or a column is mislabelled, the
redundant columns stop agreeing. The allowed disagreement is what the printed precision of each cell permits
(a cell written as ``0.17`` may be anything in [0.165, 0.175]), plus a relative floor for instruments that
compute the derived column from unrounded values.
"""
from __future__ import annotations

import numpy as np

from .blocks import Block
from .errors import IngestError

#: relative disagreement always allowed (instruments derive tan δ from the unrounded phase; measured on the real
#: TRIOS and LIMS exports: up to 7e-6)
DERIVED_RTOL = 1e-4
#: the significant digits of a parsed value are read from its shortest representation at this many digits
_MAX_SIGNIFICANT = 12


def printed_relative_precision(values) -> np.ndarray:
    """Half a unit in the last printed significant digit, relative to the value (NaN where the value is 0 or NaN).

    The digits are those of the shortest decimal representation of the value rounded to 12 significant digits,
    so a value read from text keeps the digits it was printed with (``0.17`` -> 2 digits -> 2.9e-2) and a value
    stored as a binary double gets ~1e-12. Trailing zeros count as not significant, which errs on the lenient side.
    """
    x = np.abs(np.asarray(values, dtype=float))
    out = np.full(x.shape, np.nan)
    for i, v in np.ndenumerate(x):
        if not np.isfinite(v) or v == 0.0:
            continue
        digits = np.format_float_scientific(v, precision=_MAX_SIGNIFICANT - 1, unique=False, trim="-")
        mantissa = digits.split("e")[0].replace(".", "").rstrip("0") or "0"
        k = max(1, len(mantissa))
        exponent = int(np.floor(np.log10(v)))
        out[i] = 0.5 * 10.0 ** (exponent - k + 1) / v
    return out


def _disagreement(path, block: Block, measured: str, computed: np.ndarray, precision: np.ndarray) -> None:
    observed = block.data[measured].to_numpy(float)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.abs(computed / observed - 1.0)
    allowed = 1.5 * precision + DERIVED_RTOL
    bad = np.flatnonzero(np.isfinite(rel) & np.isfinite(allowed) & (rel > allowed))
    if bad.size:
        k = int(bad[0])
        line = block.meta.get("first_data_line")
        raise IngestError(
            path,
            f"block {block.name!r}, point {k + 1}: {measured} {observed[k]:.6g} disagrees with the value the other "
            f"columns give ({computed[k]:.6g}, relative {rel[k]:.2g} > {allowed[k]:.2g} allowed by the printed "
            f"precision); {bad.size} point(s) disagree: damaged file or mislabelled column",
            line=None if line is None else int(line) + k, column=measured)


def check_redundant_columns(path, blocks: list[Block]) -> list[Block]:
    """Raise :class:`IngestError` where tan δ or |η*| disagrees with G′, G″ and ω beyond the printed precision.

    Returns the blocks unchanged, so a reader can end with ``return check_redundant_columns(path, blocks)``.
    """
    for block in blocks:
        d = block.data
        if not {"storage_modulus", "loss_modulus"} <= set(d.columns):
            continue
        g1, g2 = d["storage_modulus"].to_numpy(float), d["loss_modulus"].to_numpy(float)
        r1, r2 = printed_relative_precision(g1), printed_relative_precision(g2)
        if "loss_factor" in d.columns:
            with np.errstate(divide="ignore", invalid="ignore"):
                computed = g2 / g1
            _disagreement(path, block, "loss_factor", computed,
                          r1 + r2 + printed_relative_precision(d["loss_factor"]))
        if {"complex_viscosity", "angular_frequency"} <= set(d.columns):
            w = d["angular_frequency"].to_numpy(float)
            with np.errstate(divide="ignore", invalid="ignore"):
                computed = np.hypot(g1, g2) / w
            _disagreement(path, block, "complex_viscosity", computed,
                          np.fmax(r1, r2) + printed_relative_precision(w)
                          + printed_relative_precision(d["complex_viscosity"]))
    return blocks

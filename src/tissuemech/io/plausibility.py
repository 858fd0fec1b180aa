"""Plausibility checks of what a person typed (sample sheet, ``dataset.yaml``), with the likely mistake named.

These are checks, not physical defaults: nothing here fills in a missing value. A value outside its range is an
error whose message says what the value looks like (``looks like metres``, ``looks like kelvin``) and how to
widen the range when the value is right (``dataset.yaml`` ``plausible_ranges``). The bounds and the reason for
each are listed in ``docs/ingest.md`` ("Plausibility checks").

* :data:`PLAUSIBLE_RANGES` and :func:`range_problem`: one value against its range;
* :func:`diameter_problem`: a stated plate radius twice the export's (a diameter typed as the radius);
* :func:`temperature_problem`: a stated temperature against the temperature the export logged (kelvin typed as
  degrees Celsius is an error, another difference a warning).
"""
from __future__ import annotations

import math
from collections.abc import Mapping

#: key -> (low, high) in the key's unit. Reasons (docs/ingest.md): radius 1-50 mm spans commercial plates (8-60 mm
#: diameter) with margin; gap 0.01-20 mm from the plate parallelism of a few µm to the thickest specimens loaded;
#: temperature -150-250 degC spans the coldest convection ovens and Peltier/electrical plates (to 200 degC) and
#: stays below 273: a kelvin value of any temperature above 0 degC falls above it; |strain| 1e-4-5000 % from
#: the deflection-angle resolution to a strain no plate specimen survives.
PLAUSIBLE_RANGES: dict[str, tuple[float, float]] = {
    "radius_mm": (1.0, 50.0),
    "gap_mm": (0.01, 20.0),
    "temperature_c": (-150.0, 250.0),
    "strain_pct": (1e-4, 5000.0),
}
UNITS = {"radius_mm": "mm", "gap_mm": "mm", "temperature_c": "°C", "strain_pct": "%"}
KELVIN_OFFSET = 273.15
#: a stated temperature this far (degC) from the export's logged median is a report warning: well above the
#: regulation accuracy of rheometer temperature control (about 0.1 degC)
TEMPERATURE_WARN_C = 2.0
#: a stated temperature whose kelvin reading lies this close (degC) to the logged one is taken as kelvin
KELVIN_MATCH_C = 2.0


def ranges_with(overrides: Mapping | None) -> dict[str, tuple[float, float]]:
    """:data:`PLAUSIBLE_RANGES` with ``dataset.yaml``'s ``plausible_ranges`` replacing the ranges it names."""
    out = dict(PLAUSIBLE_RANGES)
    for key, pair in (overrides or {}).items():
        low, high = sorted(float(v) for v in pair)
        out[key] = (low, high)
    return out


def range_problem(key: str, value: float, ranges: Mapping[str, tuple[float, float]] | None = None) -> str | None:
    """Why ``value`` of ``key`` (``radius_mm``, ``gap_mm``, ``temperature_c``, ``strain_pct``) is implausible,
    with the likely mistake; None when it is within its range (or ``key`` has none).

    ``strain_pct`` is checked by magnitude (a compression may be written negative).
    """
    ranges = PLAUSIBLE_RANGES if ranges is None else ranges
    if key not in ranges or value is None:
        return None
    low, high = ranges[key]
    unit = UNITS[key]
    checked = abs(value) if key == "strain_pct" else value
    if low <= checked <= high:
        return None
    text = f"{key} {value:g} {unit} is outside the plausible range {low:g} to {high:g} {unit}"
    hint = ""
    if key in ("radius_mm", "gap_mm") and checked < low and low <= checked * 1e3 <= high:
        hint = f": looks like metres ({value:g} m = {value * 1e3:g} mm); write {value * 1e3:g}"
    elif key in ("radius_mm", "gap_mm") and checked > high and low <= checked * 1e-3 <= high:
        hint = f": looks like micrometres ({value:g} µm = {value * 1e-3:g} mm); write {value * 1e-3:g}"
    elif key == "temperature_c" and checked > high and low <= checked - KELVIN_OFFSET <= high:
        hint = (f": looks like kelvin ({value:g} K = {value - KELVIN_OFFSET:g} °C); write "
                f"{value - KELVIN_OFFSET:g}")
    return (text + hint + f". If the value is right, widen the range in dataset.yaml: "
            f"plausible_ranges: {{{key}: [low, high]}}")


def diameter_problem(stated_radius_m: float | None, export_radius_m: float | None, source: str,
                     rel: float) -> str | None:
    """A stated radius twice the export's (within ``rel``): the plate diameter typed as the radius."""
    if not stated_radius_m or not export_radius_m:
        return None
    if abs(stated_radius_m - 2.0 * export_radius_m) <= rel * 2.0 * export_radius_m:
        return (f"{source} radius {stated_radius_m * 1e3:g} mm is twice the export's plate radius "
                f"{export_radius_m * 1e3:g} mm: looks like a diameter; write the radius "
                f"{stated_radius_m * 0.5e3:g} mm (half the diameter)")
    return None


def temperature_problem(stated_c: float | None, logged_c: float | None, source: str) -> tuple[str | None, str | None]:
    """``(error, warning)`` of a stated temperature against the export's logged one (median, degC).

    Error: the stated value read as kelvin matches the logged one (within :data:`KELVIN_MATCH_C`) and the
    value as degrees Celsius does not. Warning: any other difference above :data:`TEMPERATURE_WARN_C`.
    """
    if stated_c is None or logged_c is None or not (math.isfinite(stated_c) and math.isfinite(logged_c)):
        return None, None
    diff = abs(stated_c - logged_c)
    if diff <= TEMPERATURE_WARN_C:
        return None, None
    if abs(stated_c - KELVIN_OFFSET - logged_c) <= KELVIN_MATCH_C:
        return (f"temperature_c {stated_c:g} against the export's logged {logged_c:.4g} °C: looks like kelvin "
                f"({stated_c:g} K = {stated_c - KELVIN_OFFSET:.4g} °C); write {stated_c - KELVIN_OFFSET:.4g}"), None
    return None, (f"temperature: {source} {stated_c:g} °C, the export logs {logged_c:.4g} °C (median); "
                  f"{source} used")


__all__ = ["KELVIN_MATCH_C", "KELVIN_OFFSET", "PLAUSIBLE_RANGES", "TEMPERATURE_WARN_C", "UNITS",
           "diameter_problem", "range_problem", "ranges_with", "temperature_problem"]

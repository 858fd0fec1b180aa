"""Registry of every named cause the diagnosis tests: the catalogue of :mod:`.catalogue` plus the causes
met on real data that live in their own modules (:mod:`.temperature`: ``temperature_dependence``;
:mod:`.inertia`: ``inertia_dominated_points``, ``inertial_ringing``).

:data:`CAUSE_IDS` (ordered) and :data:`DETECTORS` ({id: detector(ctx) -> finding}) are what
:func:`tissuemech.diagnosis.report.diagnose` runs; the finding contract is the one of :mod:`.catalogue`.
"""
from __future__ import annotations

from collections.abc import Callable

from . import catalogue
from .inertia import EFFECT as INERTIA_POINTS_ID
from .inertia import RINGING as RINGING_ID
from .inertia import detect_inertia_dominated_points, detect_inertial_ringing
from .temperature import EFFECT as TEMPERATURE_ID
from .temperature import detect_temperature_dependence

CAUSE_IDS: tuple[str, ...] = catalogue.CATALOGUE_IDS + (TEMPERATURE_ID, INERTIA_POINTS_ID, RINGING_ID)

DETECTORS: dict[str, Callable[[catalogue.DiagnosisContext], dict]] = {
    **catalogue.DETECTORS,
    TEMPERATURE_ID: detect_temperature_dependence,
    INERTIA_POINTS_ID: detect_inertia_dominated_points,
    RINGING_ID: detect_inertial_ringing,
}
assert tuple(DETECTORS) == CAUSE_IDS

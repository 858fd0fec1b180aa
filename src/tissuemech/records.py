"""Typed records at stage boundaries (issue 14): what one stage writes and the next reads.

:class:`FitRecord` is the fit record ``results/<dataset>/fits/<scope>/<model>.nc``: everything the fit stage
keeps about one fit, with the one writer (:meth:`FitRecord.to_dataset` / :meth:`FitRecord.to_netcdf`) and the
one reader (:meth:`FitRecord.from_dataset` / :meth:`FitRecord.from_netcdf`). ``fitting.fit_to_dataset`` and
``fitting.write_fit_netcdf`` write through it, and every reader of a fit record (``fitting.fits_csv_row``,
``summary`` fit figures, ``diagnosis.baseline.read_fit_record``) reads through it.

:class:`MaterialCard` is a material card ``results/<dataset>/cards/<scope>/<model>.json`` as read, validated:
the one card reader.

:class:`Finding` is one entry of ``diagnosis.json``'s ``findings`` (a named cause: its test, effect size and
held-out fix), validated where the diagnosis writes it and read through it by the report.

On disk (the layout every existing record has): dims ``param``/``param_b`` (variables ``value``, ``stderr``,
``varying``, ``unit``, ``correlation``), ``point`` (``observed``, ``predicted``, ``weighted_residual``,
``curve_index``, ``observable``) and ``curve`` (``curve_label``, ``curve_rmse``, ``curve_nrmse``); scalar
attributes (:data:`SCALAR_ATTRS`, ``success`` as 0/1, ``condition_number``) and JSON attributes (``flags``,
``selection``, ``ranges``, ``structure``, ``sloppy_direction``, ``start_chisqr`` with failed starts as null).

Schema versions: every fit record (netCDF attribute ``schema_version``) and every card (JSON ``schema_version``)
states the ``"major.minor"`` version of its layout (:data:`FIT_RECORD_SCHEMA_VERSION`, :data:`CARD_SCHEMA_VERSION`);
a file without one is version 0 (written before versions existed) and reads with the field defaults, a file of a
newer major version than this code knows is refused with :class:`SchemaVersionError` (:func:`schema_major`).

This module sits just above ``canonical`` (it imports nothing else of the package), so every layer may use it.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from .canonical import read_netcdf, to_jsonable, write_netcdf, write_text

#: layout version of the fit records this code writes ("major.minor"; a reader refuses a newer major version)
FIT_RECORD_SCHEMA_VERSION = "1.0"
#: layout version of the material cards this code writes ("major.minor"; a reader refuses a newer major version).
#: 1.0: ``schema_version`` itself, the Pipkin-Rogers block ``pipkin_rogers``, ``abaqus_reason`` and the MARLOW table
#: in the card (``abaqus_marlow_table``), so that every format is written from the card alone
CARD_SCHEMA_VERSION = "1.0"
#: the index file of a dataset's simulation cards (:mod:`tissuemech.diagnosis.simulation_cards` writes it, the FEM
#: replay and the uncertainty stage read it)
SIMULATION_CARDS_INDEX = "index.json"


class SchemaVersionError(ValueError):
    """A record or card of a layout version this code cannot read (a newer major version, or not a version)."""


def schema_major(value, kind: str, known: str, source: str = "") -> int:
    """The major version of a file's ``schema_version`` (``value``; None or absent: 0, a file written before
    versions existed), checked against the version this code writes (``known``).

    Raises :class:`SchemaVersionError` naming the file (``source``), the kind of file and both versions when the
    file's major version is newer than ``known``'s or the value is not a ``"major.minor"`` version."""
    where = f" {source}" if source else ""
    if value is None:
        return 0
    text = str(value).strip()
    head = text.split(".", 1)[0]
    if not head.isdigit():
        raise SchemaVersionError(f"{kind}{where}: schema_version {value!r} is not a 'major.minor' version")
    major, known_major = int(head), int(str(known).split(".", 1)[0])
    if major > known_major:
        raise SchemaVersionError(f"{kind}{where} has schema_version {text}, newer than {known} (the newest this "
                                 f"tissuemech reads): update tissuemech to read it")
    return major


#: scalar attributes of a fit record, in the order they are written (``success`` and ``condition_number`` follow)
SCALAR_ATTRS = ("model_key", "family", "scope", "target", "relaxation", "message", "chisqr", "redchi", "rmse",
                "nrmse", "n", "n_eff", "k", "aic", "aicc", "bic", "aicc_eff", "bic_eff", "nfev", "n_starts")
_INT_ATTRS = ("n", "k", "nfev", "n_starts")
_STR_ATTRS = ("model_key", "family", "scope", "target", "relaxation", "message")


def _json_attr(ds: xr.Dataset, name: str, default):
    text = ds.attrs.get(name, "")
    return json.loads(text) if text else default


@dataclass(eq=False)
class FitRecord:
    """One fit record: parameters, uncertainties, flags, criteria, residuals and the data selection.

    ``params``/``stderr``/``units`` are ordered by the model's parameters; ``correlation`` is the
    ``len(params)`` square matrix of the fitted (internal) parameters, NaN in rows/columns of fixed ones. The
    per-point arrays (``observed``, ``predicted``, ``weighted_residual``, ``curve_index``, ``observable``) are
    the residual terms of every curve concatenated (curve by curve, observable by observable).
    ``start_chisqr`` is inf for a start that failed. Compare records field by field (``eq=False``: arrays).
    """

    model_key: str
    family: str = ""
    scope: str = ""
    target: str = ""
    #: strain-history treatment of relaxation curves (``fitting.relaxation_history``)
    relaxation: str = "measured"
    params: dict[str, float] = field(default_factory=dict)
    stderr: dict[str, float] = field(default_factory=dict)
    units: dict[str, str] = field(default_factory=dict)
    varying: list[str] = field(default_factory=list)
    correlation: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    flags: list[str] = field(default_factory=list)
    success: bool = True
    message: str = ""
    chisqr: float = float("nan")
    redchi: float = float("nan")
    rmse: float = float("nan")
    nrmse: float = float("nan")
    n: int = 0
    n_eff: float = float("nan")
    k: int = 0
    aic: float = float("nan")
    aicc: float = float("nan")
    bic: float = float("nan")
    aicc_eff: float = float("nan")
    bic_eff: float = float("nan")
    nfev: int = 0
    n_starts: int = 0
    condition_number: float = float("nan")
    sloppy_direction: dict[str, float] = field(default_factory=dict)
    start_chisqr: list[float] = field(default_factory=list)
    curve_labels: list[str] = field(default_factory=list)
    curve_rmse: dict[str, float] = field(default_factory=dict)
    curve_nrmse: dict[str, float] = field(default_factory=dict)
    observed: np.ndarray = field(default_factory=lambda: np.zeros(0))
    predicted: np.ndarray = field(default_factory=lambda: np.zeros(0))
    weighted_residual: np.ndarray = field(default_factory=lambda: np.zeros(0))
    curve_index: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    observable: np.ndarray = field(default_factory=lambda: np.zeros(0, str))
    selection: list[dict] = field(default_factory=list)
    ranges: dict[str, float] = field(default_factory=dict)
    structure: dict = field(default_factory=dict)
    #: layout version of the file the record was read from ("0": written before versions existed); the writer
    #: always writes :data:`FIT_RECORD_SCHEMA_VERSION`
    schema_version: str = FIT_RECORD_SCHEMA_VERSION

    # ------------------------------------------------------------------ derived views
    @property
    def converged(self) -> bool:
        """The optimiser reported success (``success``)."""
        return bool(self.success)

    @property
    def correlations(self) -> dict[str, float]:
        """``{"a|b": rho}`` for every pair a before b (parameter order) with a finite correlation."""
        names = list(self.params)
        c = np.asarray(self.correlation, float)
        out = {}
        if c.shape != (len(names), len(names)):
            return out
        for i, a in enumerate(names):
            for j in range(i + 1, len(names)):
                if np.isfinite(c[i, j]):
                    out[f"{a}|{names[j]}"] = float(c[i, j])
        return out

    @property
    def tests(self) -> list[str]:
        """The test kinds of the curves the fit saw (from ``selection``), sorted."""
        return sorted({str(s.get("test", "")) for s in self.selection})

    # ------------------------------------------------------------------ from a fit
    @classmethod
    def from_result(cls, result: Any) -> FitRecord:
        """The record of a ``fitting.FitResult`` (``residuals`` flattened to points, ``correlation`` widened
        from the varying parameters to all parameters)."""
        names = list(result.params)
        kv = len(result.varying)
        corr = np.full((len(names), len(names)), np.nan)
        pos = {n: names.index(n) for n in result.varying}
        full = np.shape(result.correlation) == (kv, kv)
        for i, a in enumerate(result.varying):
            for j, b in enumerate(result.varying):
                corr[pos[a], pos[b]] = result.correlation[i, j] if full else np.nan
        obs, pred, wres, cidx, oname = [], [], [], [], []
        for ci, terms in enumerate(result.residuals):
            for name, (y, f, w) in terms.items():
                obs.append(np.asarray(y, float))
                pred.append(np.asarray(f, float))
                wres.append(np.asarray(w, float))
                cidx.append(np.full(np.size(y), ci))
                oname.extend([name] * np.size(y))
        cat = (lambda xs: np.concatenate(xs) if xs else np.array([]))
        return cls(
            model_key=result.model_key, family=result.family, scope=result.scope, target=result.target,
            relaxation=result.relaxation, params=dict(result.params), stderr={n: result.stderr[n] for n in names},
            units={n: result.units[n] for n in names}, varying=list(result.varying), correlation=corr,
            flags=list(result.flags), success=bool(result.success), message=str(result.message),
            chisqr=result.chisqr, redchi=result.redchi, rmse=result.rmse, nrmse=result.nrmse, n=result.n,
            n_eff=result.n_eff, k=result.k, aic=result.aic, aicc=result.aicc, bic=result.bic,
            aicc_eff=result.aicc_eff, bic_eff=result.bic_eff, nfev=result.nfev, n_starts=result.n_starts,
            condition_number=float(result.condition_number), sloppy_direction=dict(result.sloppy_direction),
            start_chisqr=list(result.start_chisqr), curve_labels=list(result.curve_labels),
            curve_rmse={c: result.curve_rmse[c] for c in result.curve_labels},
            curve_nrmse={c: result.curve_nrmse[c] for c in result.curve_labels},
            observed=cat(obs), predicted=cat(pred), weighted_residual=cat(wres), curve_index=cat(cidx).astype(int),
            observable=np.array(oname, dtype=str), selection=result.selection, ranges=result.ranges,
            structure=result.structure)

    # ------------------------------------------------------------------ the one writer
    def to_dataset(self) -> xr.Dataset:
        """The record as an xarray Dataset (dims ``param``, ``param_b``, ``point``, ``curve``; module docstring)."""
        names = list(self.params)
        ds = xr.Dataset(
            {"value": ("param", [self.params[n] for n in names], {"long_name": "fitted value (natural units)"}),
             "stderr": ("param", [self.stderr[n] for n in names], {"long_name": "standard error (delta method)"}),
             "varying": ("param", [int(n in self.varying) for n in names]),
             "unit": ("param", [self.units[n] for n in names]),
             "correlation": (("param", "param_b"), np.asarray(self.correlation, float),
                             {"long_name": "correlation of the fitted (internal) parameters"}),
             "observed": ("point", np.asarray(self.observed, float)),
             "predicted": ("point", np.asarray(self.predicted, float)),
             "weighted_residual": ("point", np.asarray(self.weighted_residual, float),
                                   {"long_name": "(prediction - observation) / sigma (log for G*, flow)"}),
             "curve_index": ("point", np.asarray(self.curve_index).astype(int)),
             "observable": ("point", np.asarray(self.observable, dtype=str)),
             "curve_label": ("curve", np.array(self.curve_labels, dtype=str)),
             "curve_rmse": ("curve", [self.curve_rmse[c] for c in self.curve_labels]),
             "curve_nrmse": ("curve", [self.curve_nrmse[c] for c in self.curve_labels])},
            coords={"param": names, "param_b": names})
        scalars = {name: getattr(self, name) for name in SCALAR_ATTRS}
        scalars["success"] = int(self.success)
        ds.attrs.update({k: (float(v) if isinstance(v, (float, np.floating)) else v) for k, v in scalars.items()})
        ds.attrs["flags"] = json.dumps(list(self.flags))
        ds.attrs["selection"] = json.dumps(to_jsonable(self.selection, nonfinite_as_null=False))
        ds.attrs["ranges"] = json.dumps(to_jsonable(self.ranges, nonfinite_as_null=False))
        ds.attrs["structure"] = json.dumps(self.structure)
        ds.attrs["condition_number"] = float(self.condition_number)
        ds.attrs["sloppy_direction"] = json.dumps(self.sloppy_direction)
        ds.attrs["start_chisqr"] = json.dumps([c if np.isfinite(c) else None for c in self.start_chisqr])
        ds.attrs["schema_version"] = FIT_RECORD_SCHEMA_VERSION
        return ds

    def to_netcdf(self, path: str | os.PathLike) -> None:
        """Atomically write the record (``results/<dataset>/fits/<scope>/<model>.nc``)."""
        write_netcdf(self.to_dataset(), path)

    # ------------------------------------------------------------------ the one reader
    @classmethod
    def from_dataset(cls, ds: xr.Dataset, default_key: str = "", source: str = "") -> FitRecord:
        """A record from its Dataset (:meth:`to_dataset`, or a file read back). Variables or attributes an
        older or partial record lacks take the field defaults (``varying``: every parameter; ``relaxation``:
        ``"measured"``; ``success``: true); a record without ``schema_version`` is version 0, one of a newer major
        version than :data:`FIT_RECORD_SCHEMA_VERSION` raises :class:`SchemaVersionError` (naming ``source``)."""
        a = ds.attrs
        version = a.get("schema_version")
        schema_major(version, "fit record", FIT_RECORD_SCHEMA_VERSION, source)
        names = [str(n) for n in ds["param"].values] if "param" in ds.coords else []

        def per_param(var, cast, default):
            return {n: cast(v) for n, v in zip(names, ds[var].values)} if var in ds else dict.fromkeys(names, default)

        def per_point(var, dtype):
            return np.asarray(ds[var].values, dtype) if var in ds else np.zeros(0, dtype)

        labels = [str(c) for c in ds["curve_label"].values] if "curve_label" in ds else []

        def per_curve(var):
            return ({c: float(v) for c, v in zip(labels, ds[var].values)} if var in ds
                    else dict.fromkeys(labels, float("nan")))

        kwargs: dict[str, Any] = {}
        for name in SCALAR_ATTRS + ("condition_number",):
            if name in a:
                v = a[name]
                kwargs[name] = str(v) if name in _STR_ATTRS else int(v) if name in _INT_ATTRS else float(v)
        kwargs.setdefault("model_key", default_key)
        return cls(
            **kwargs, success=bool(int(a.get("success", 1))),
            params=per_param("value", float, float("nan")), stderr=per_param("stderr", float, float("nan")),
            units=per_param("unit", str, ""),
            varying=[n for n, v in zip(names, ds["varying"].values) if int(v)] if "varying" in ds else names,
            correlation=(np.asarray(ds["correlation"].values, float) if "correlation" in ds
                         else np.full((len(names), len(names)), np.nan)),
            flags=[str(f) for f in _json_attr(ds, "flags", [])],
            sloppy_direction=_json_attr(ds, "sloppy_direction", {}),
            start_chisqr=[float("inf") if c is None else float(c) for c in _json_attr(ds, "start_chisqr", [])],
            curve_labels=labels, curve_rmse=per_curve("curve_rmse"), curve_nrmse=per_curve("curve_nrmse"),
            observed=per_point("observed", float), predicted=per_point("predicted", float),
            weighted_residual=per_point("weighted_residual", float), curve_index=per_point("curve_index", int),
            observable=per_point("observable", str), selection=_json_attr(ds, "selection", []),
            ranges=_json_attr(ds, "ranges", {}), structure=_json_attr(ds, "structure", {}),
            schema_version="0" if version is None else str(version))

    @classmethod
    def from_netcdf(cls, path: str | os.PathLike) -> FitRecord:
        """Read a fit record file (the model key falls back to the file's stem)."""
        return cls.from_dataset(read_netcdf(path), default_key=os.path.splitext(os.path.basename(path))[0],
                                source=str(path))


#: elastic-law keys of a linear elastic shear law (``models.hyperelastic.LinearElasticShear``): a card written
#: before schema 1.0 may name one; :func:`finite_strain_law` is the one place it becomes the neo-Hookean law
LINEAR_ELASTIC_LAWS = ("linear_elastic_shear", "linear_elastic")


def finite_strain_law(law: str | None, params: dict, initial_shear_modulus: float | None) -> tuple[str | None, dict]:
    """The elastic law a card states and the FEM runs: a linear elastic shear law (:data:`LINEAR_ELASTIC_LAWS`) as
    the neo-Hookean law with mu = G0 (``initial_shear_modulus``, else the law's ``G0``/``G``) -- identical in simple
    shear at any strain, and a finite-strain law every FE code knows; any other law unchanged. The one rename, used
    by the card builder (``cards.material_fields``) and by :class:`MaterialCard` for cards written before it."""
    if law not in LINEAR_ELASTIC_LAWS:
        return law, params
    g0 = initial_shear_modulus if initial_shear_modulus is not None else params.get("G0", params.get("G"))
    return "neo_hookean", {"mu": float(g0)}


class CardError(ValueError):
    """A material card that does not have the shape :class:`MaterialCard` reads."""


def _is_number(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, (bool, np.bool_))


def _numbers(x) -> bool:
    return isinstance(x, (list, tuple)) and all(_is_number(v) for v in x)


def _check_pipkin_rogers(model: str, block, prony) -> None:
    """Validation of a card's ``pipkin_rogers`` block (:class:`MaterialCard`)."""
    def bad(why):
        raise CardError(f"card {model}: 'pipkin_rogers' {why}, not {block!r}")

    if not isinstance(block, dict):
        bad("must be an object with 'beta', 'kappa' and 'gamma_s'")
    beta, kappa, gamma_s = block.get("beta"), block.get("kappa"), block.get("gamma_s")
    if not _numbers(beta) or not _numbers(kappa) or len(beta) != len(kappa):
        bad("needs as many numbers 'beta' as 'kappa'")
    if any(b < 0 for b in beta) or any(k <= -1 for k in kappa):
        bad("needs beta_i >= 0 and kappa_i > -1")
    if not _is_number(gamma_s) or not gamma_s > 0:
        bad("needs a positive number 'gamma_s'")
    if not isinstance(prony, dict) or len(prony.get("tau") or ()) != len(beta):
        bad(f"needs a 'prony' series with one time per term ({len(beta)})")


@dataclass(frozen=True, eq=False)
class MaterialCard:
    """A material card ``results/<dataset>/cards/<scope>/<model>.json``: the one card reader (:meth:`from_json`,
    :meth:`from_dict`) and the one JSON writer (:meth:`json_text`, :meth:`write_json`), used by the FEM stages
    (``stages.select_cards``, ``stages.card_for_fem``), the card table (``summary.card_table``), the uncertainty
    stages and the solver (``fem.materials.material_from_card`` reads a card through it). ``cards.make_card``
    builds the card's content (the fit -> card conversions need the model library, a layer above this module) and
    ``cards.write_card_files`` validates it through :meth:`from_dict` before it writes the JSON and the Abaqus,
    FEBio and NiftySim files, each from the card's content alone.

    The typed fields are what the readers use; ``data`` is the whole card as plain JSON values (no model objects).
    Validation (:class:`CardError`): ``model`` a non-empty string, ``elastic_law`` a string or absent,
    ``elastic_parameters`` numbers by name, ``prony`` absent or with as many ``g`` as ``tau`` (numbers, positive
    times), ``poisson_ratio``/``bulk_modulus``/``initial_shear_modulus`` numbers or absent, ``pipkin_rogers`` absent
    or ``beta``/``kappa`` per Prony term with ``beta >= 0``, ``kappa > -1`` and a positive ``gamma_s``,
    ``time_temperature_shift`` absent or an object; ``schema_version`` (:func:`schema_major`; absent: "0") not newer
    than :data:`CARD_SCHEMA_VERSION`. NaN is a number (a fluid-like model's card has NaN moduli). Compare cards by
    ``data`` (``eq=False``).

    ``pipkin_rogers`` (the nonseparable extension, ``models.beyond_qlv.PipkinRogersModel``): the card's Prony series
    holds the small-strain weights ``g_i = beta_i / (1 + sum beta)`` and the times; the block holds the fitted
    ``beta_i``, ``kappa_i`` and ``gamma_s`` unchanged, the weights at a strain being ``g_i = beta_i m_i / (1 + sum_j
    beta_j m_j)``, ``m_i = 1 + kappa_i s``, ``s = x / (x + gamma_s^2)`` with ``x = I1bar - 3`` of the isochoric
    deformation (``gamma^2`` in simple shear).
    """

    model: str
    elastic_law: str | None = None
    elastic_parameters: dict[str, float] = field(default_factory=dict)
    initial_shear_modulus: float | None = None
    poisson_ratio: float | None = None
    bulk_modulus: float | None = None
    prony: dict | None = None
    pipkin_rogers: dict | None = None
    time_temperature_shift: dict | None = None
    schema_version: str = CARD_SCHEMA_VERSION
    data: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        if not isinstance(self.model, str) or not self.model:
            raise CardError(f"card 'model' must be a non-empty string, not {self.model!r}")
        if self.elastic_law is not None and not isinstance(self.elastic_law, str):
            raise CardError(f"card {self.model}: 'elastic_law' must be a string, not {self.elastic_law!r}")
        if not isinstance(self.elastic_parameters, dict) or not all(
                isinstance(k, str) and _is_number(v) for k, v in self.elastic_parameters.items()):
            raise CardError(f"card {self.model}: 'elastic_parameters' must map names to numbers, "
                            f"not {self.elastic_parameters!r}")
        for name in ("initial_shear_modulus", "poisson_ratio", "bulk_modulus"):
            value = getattr(self, name)
            if value is not None and not _is_number(value):
                raise CardError(f"card {self.model}: {name!r} must be a number, not {value!r}")
        if self.prony is not None:
            g, tau = (self.prony.get("g"), self.prony.get("tau")) if isinstance(self.prony, dict) else (None, None)
            if (not _numbers(g) or not _numbers(tau) or len(g) != len(tau) or any(t <= 0 for t in tau)):
                raise CardError(f"card {self.model}: 'prony' needs as many numbers 'g' as positive times 'tau', "
                                f"not {self.prony!r}")
        if self.pipkin_rogers is not None:
            _check_pipkin_rogers(self.model, self.pipkin_rogers, self.prony)
        if self.time_temperature_shift is not None and not isinstance(self.time_temperature_shift, dict):
            raise CardError(f"card {self.model}: 'time_temperature_shift' must be an object, not "
                            f"{self.time_temperature_shift!r}")

    @classmethod
    def from_dict(cls, card: dict, source: str = "") -> MaterialCard:
        """A card from its dict (as ``json.loads`` or ``cards.make_card`` gives it); ``source`` names the file in
        errors. A dict without ``schema_version`` is a card of version 0."""
        if not isinstance(card, dict):
            raise CardError(f"a card is a JSON object, not {type(card).__name__}")
        version = card.get("schema_version")
        schema_major(version, "material card", CARD_SCHEMA_VERSION, source)
        return cls(model=card.get("model"), elastic_law=card.get("elastic_law"),
                   elastic_parameters=card.get("elastic_parameters") or {},
                   initial_shear_modulus=card.get("initial_shear_modulus"), poisson_ratio=card.get("poisson_ratio"),
                   bulk_modulus=card.get("bulk_modulus"), prony=card.get("prony"),
                   pipkin_rogers=card.get("pipkin_rogers"), time_temperature_shift=card.get("time_temperature_shift"),
                   schema_version="0" if version is None else str(version), data=card)

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> MaterialCard:
        """Read a card file (``<model>.json``)."""
        with open(path, encoding="utf-8") as f:
            return cls.from_dict(json.load(f), source=str(path))

    # ------------------------------------------------------------------ the one JSON writer
    def json_text(self) -> str:
        """Canonical JSON text of the card (sorted keys, NaN kept as NaN, ``schema_version`` set to the version
        this code writes)."""
        clean = {**self.data, "schema_version": CARD_SCHEMA_VERSION}
        return json.dumps(to_jsonable(clean, nonfinite_as_null=False), indent=2, sort_keys=True, allow_nan=True)

    def write_json(self, path: str | os.PathLike):
        """Atomically write the card's JSON (:meth:`json_text`) to ``path``; returns the path."""
        return write_text(self.json_text() + "\n", path)

    # ------------------------------------------------------------------ the solver's view
    @property
    def fem_law(self) -> str:
        """The law key the FEM runs: ``elastic_law`` (else ``model``), a linear elastic shear law as its
        finite-strain extension ``neo_hookean`` (:func:`finite_strain_law`)."""
        law = self.elastic_law or self.model
        return finite_strain_law(law, {}, 0.0)[0]

    @property
    def fem_parameters(self) -> dict[str, float]:
        """The parameters of :attr:`fem_law`: ``elastic_parameters`` (a linear law's as ``{"mu": G0}``), or for a
        minimal card without ``elastic_law`` its ``parameters``."""
        if not self.elastic_law:
            return dict(self.data.get("parameters") or {})
        return finite_strain_law(self.elastic_law, self.elastic_parameters, self.initial_shear_modulus)[1]

    def for_fem(self) -> dict:
        """The card as the FEM takes it (``fem.experiments.card_material``): unchanged, except that a linear
        elastic shear law is written as the neo-Hookean law with mu = G0 (:func:`finite_strain_law`)."""
        card = dict(self.data)
        if self.elastic_law in LINEAR_ELASTIC_LAWS:
            card["elastic_law"], card["elastic_parameters"] = self.fem_law, self.fem_parameters
        return card


class FindingError(ValueError):
    """A diagnosis finding that does not have the shape :class:`Finding` reads."""


def _number_or_null(x) -> bool:
    return x is None or _is_number(x)


#: fields of a finding that are numbers, or null where not computed (NaN is written as null)
FINDING_NUMBERS = ("statistic", "p_value", "p_holm", "log10_p", "effect_size")
#: fields of a finding that are booleans where present
FINDING_FLAGS = ("tested", "detected", "significant", "practical")


@dataclass(frozen=True, eq=False)
class Finding:
    """One named-cause finding of ``diagnosis.json`` as written and read: the diagnosis validates each finding
    through :meth:`from_dict` before it writes the file (``diagnosis.findings.write_diagnosis_json``), and the
    report reads them through it (``summary``).

    Typed fields: ``effect`` (the cause id, a non-empty string), the flags ``tested``, ``detected``,
    ``significant``, ``practical`` (booleans; absent -> False, except ``significant``, None when not judged),
    the statistics ``statistic`` (its name in ``statistic_name``), ``p_value``, ``p_holm`` (Holm-adjusted over
    the family), ``log10_p`` and ``effect_size`` (in ``effect_size_unit``), each a float, NaN where not computed
    (null on disk); ``evidence`` (the sentence the report prints) and ``fix`` (None, or the held-out score of
    the cause's fix: ``model`` and ``metric`` strings, ``before``/``after``/``gain`` numbers or null). ``data``
    is the whole finding as plain JSON values, detector-specific keys included; compare findings by ``data``.
    Validation errors (:class:`FindingError`) name the finding's effect and the field.
    """

    effect: str
    tested: bool = False
    detected: bool = False
    significant: bool | None = None
    practical: bool = False
    statistic: float = np.nan
    statistic_name: str = ""
    p_value: float = np.nan
    p_holm: float = np.nan
    log10_p: float = np.nan
    effect_size: float = np.nan
    effect_size_unit: str = ""
    evidence: str = ""
    fix: dict | None = None
    data: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_dict(cls, finding: dict) -> Finding:
        """A finding from its dict (as the diagnosis makes it, or as ``json.load`` reads it back)."""
        if not isinstance(finding, dict):
            raise FindingError(f"a finding is a JSON object, not {type(finding).__name__}")
        effect = finding.get("effect")
        if not isinstance(effect, str) or not effect:
            raise FindingError(f"finding 'effect' must be a non-empty string, not {effect!r}")
        for name in FINDING_FLAGS:
            value = finding.get(name)
            if value is not None and not isinstance(value, (bool, np.bool_)):
                raise FindingError(f"finding {effect}: {name!r} must be true or false, not {value!r}")
        for name in FINDING_NUMBERS:
            if not _number_or_null(finding.get(name)):
                raise FindingError(f"finding {effect}: {name!r} must be a number or null, not {finding[name]!r}")
        for name in ("statistic_name", "effect_size_unit", "evidence"):
            if not isinstance(finding.get(name, ""), str):
                raise FindingError(f"finding {effect}: {name!r} must be a string, not {finding[name]!r}")
        fix = finding.get("fix")
        if fix is not None:
            if not isinstance(fix, dict) or not isinstance(fix.get("model"), str) or \
                    not isinstance(fix.get("metric"), str) or \
                    not all(_number_or_null(fix.get(k)) for k in ("before", "after", "gain")):
                raise FindingError(f"finding {effect}: 'fix' must hold 'model' and 'metric' strings and "
                                   f"'before'/'after'/'gain' numbers, not {fix!r}")

        def number(name):
            value = finding.get(name)
            return np.nan if value is None else float(value)

        significant = finding.get("significant")
        return cls(effect=effect, tested=bool(finding.get("tested", False)),
                   detected=bool(finding.get("detected", False)),
                   significant=None if significant is None else bool(significant),
                   practical=bool(finding.get("practical", False)),
                   statistic_name=finding.get("statistic_name", ""),
                   effect_size_unit=finding.get("effect_size_unit", ""),
                   evidence=finding.get("evidence", ""), fix=fix, data=finding,
                   **{name: number(name) for name in FINDING_NUMBERS})

    @property
    def fix_gain(self) -> float:
        """Held-out gain of the fix (NaN without a scored fix)."""
        gain = (self.fix or {}).get("gain")
        return np.nan if gain is None else float(gain)


__all__ = ["FitRecord", "SCALAR_ATTRS", "MaterialCard", "CardError", "LINEAR_ELASTIC_LAWS", "finite_strain_law",
           "Finding", "FindingError", "FINDING_NUMBERS", "FINDING_FLAGS", "FIT_RECORD_SCHEMA_VERSION",
           "CARD_SCHEMA_VERSION", "SchemaVersionError", "schema_major"]

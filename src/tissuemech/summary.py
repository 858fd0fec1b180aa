"""A self-contained HTML summary of the pipeline results (tables and figures of every dataset).

Complements ``snakemake --report`` (provenance, runtimes, DAG): this page is what a rheologist reads first.
"""
from __future__ import annotations

import base64
import html
import json
from pathlib import Path

import pandas as pd

from .canonical import write_text

_STYLE = """body{font-family:sans-serif;margin:2em;max-width:1200px}table{border-collapse:collapse;font-size:12px}
td,th{border:1px solid #ccc;padding:2px 6px}h2{border-bottom:2px solid #345}img{max-width:560px;margin:4px}
.finding{background:#fff3e0;padding:4px;margin:4px 0}"""


def _table(path: Path, columns: list[str] | None = None, rows: int = 25) -> str:
    if not path.is_file() or path.stat().st_size == 0:
        return f"<p><i>{html.escape(path.name)} not produced</i></p>"
    frame = pd.read_csv(path)
    if columns:
        frame = frame[[c for c in columns if c in frame]]
    return frame.head(rows).to_html(index=False, float_format=lambda v: f"{v:.4g}", na_rep="")


def _img(path: Path) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    return f'<img alt="{html.escape(path.stem)}" title="{html.escape(path.stem)}" src="data:image/png;base64,{data}">'


def _diagnosis(path: Path) -> str:
    if not path.is_file():
        return "<p><i>no diagnosis</i></p>"
    d = json.loads(path.read_text())
    out = []
    for f in d.get("findings", []):
        if not f.get("detected"):
            continue
        fix = f.get("fix") or {}
        gain = fix.get("gain")
        out.append(f'<div class="finding"><b>{html.escape(f["effect"])}</b> (p = {f.get("p_value")}, effect size '
                   f'{f.get("effect_size")}): {html.escape(str(f.get("evidence", "")))}'
                   + (f"<br>fix: {html.escape(str(fix.get('model')))} — {html.escape(str(fix.get('metric')))} "
                      f"{fix.get('before')} → {fix.get('after')} (gain {gain})" if fix else "") + "</div>")
    for s in d.get("not_identifiable", []):
        out.append(f'<div class="finding">{html.escape(str(s))}</div>')
    for u in d.get("unexplained", [])[:10]:
        out.append(f"<div>unexplained structure vs <b>{html.escape(str(u.get('covariate')))}</b> "
                   f"(p = {u.get('p_value')}, effect {u.get('effect_size')})</div>")
    return "".join(out) or "<p>no named cause and no unexplained structure at the family-wise α</p>"


def build_summary(results_dir, datasets: list[str], out_html, max_figures: int = 12) -> Path:
    """Write ``out_html`` summarising every dataset's ingest, LVE, ranking, diagnosis, FEM and figures."""
    root = Path(results_dir)
    parts = [f"<html><head><meta charset='utf-8'><title>tissuemech results</title><style>{_STYLE}</style></head><body>",
             "<h1>tissuemech results</h1>"]
    for name in datasets:
        d = root / name
        parts.append(f"<h2>{html.escape(name)}</h2>")
        parts.append("<h3>Ingest</h3>" + _table(d / "ingest_report.csv", ["run", "file", "test", "status", "reason"], 12))
        parts.append("<h3>LVE limits</h3>" + _table(d / "lve.csv"))
        parts.append("<h3>Ranking</h3>" + _table(d / "ranking.csv", ["scope", "model", "family", "rank", "aicc",
                                                                     "delta_aicc", "bic", "rmse", "nrmse", "cv_nrmse",
                                                                     "flags", "recommended"], 40))
        rec = d / "ranking.csv"
        if rec.is_file() and rec.stat().st_size:
            frame = pd.read_csv(rec)
            if "recommendation" in frame:
                for scope, text in frame.groupby("scope")["recommendation"].first().items():
                    parts.append(f"<p><b>{html.escape(str(scope))}</b>: {html.escape(str(text))}</p>")
        parts.append("<h3>Diagnosis</h3>" + _diagnosis(d / "diagnosis.json"))
        parts.append("<h3>FEM torsion vs measured torque</h3>" + _table(d / "fem" / "torsion.csv"))
        figures = sorted((d / "figures").rglob("*.png")) if (d / "figures").is_dir() else []
        parts.append("<h3>Figures</h3>" + "".join(_img(p) for p in figures[:max_figures]))
    parts.append("<h2>TLED timing</h2>" + _table(root / "fem" / "timing.csv", rows=60))
    parts.append("</body></html>")
    return write_text("\n".join(parts), out_html)

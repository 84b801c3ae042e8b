"""The stress-test report: one self-contained HTML file of ``cbox stress``'s table.

Like the main report (:mod:`cornell_harness.reports.html`) it works offline: the style sheet
(``templates/report.css``, shared with the main report so both look alike)
is inlined, and there is no script, font or image to fetch. It shows

1. the **results table**, one row per (variant, renderer), each check's cell
   coloured pass or fail with its bound or tolerance beside the value
   (time, peak memory, NaN/Inf/negative pixels, mean radiance, linearity);
2. the **checks in detail**: every row's one-line check summary, where its
   expected value comes from and why its tolerance is what it is;
3. the **variants**: what each stresses, its spp, resolution and bounds;
4. **provenance**: versions, machine, date, seed, the command line.

Entry point: :func:`write_stress_report`. The report is built from the table
alone (e.g. as read back from ``stress.csv``), plus provenance.
"""

from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path
from typing import Any, Mapping

import jinja2
import pandas as pd
from markupsafe import Markup

from cornell_harness.store.atomic import write_text_atomic
from cornell_harness.reports.numbers import is_missing

#: Badge class (from report.css) of each row status.
_BADGE = {"pass": "ok", "fail": "failed", "error": "failed", "skipped": "skipped"}


def _environment() -> jinja2.Environment:
    return jinja2.Environment(loader=jinja2.PackageLoader("cornell_harness.reports", "templates"), autoescape=True,
                              trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)


def _css(env: jinja2.Environment) -> Markup:
    text = env.loader.get_source(env, "report.css")[0]
    if "</style" in text.lower():
        raise ValueError("report.css must not contain a closing style tag")
    return Markup(text)



def _num(x: Any, digits: int = 4) -> str:
    if is_missing(x):
        return "—"
    x = float(x)
    if math.isinf(x):
        return "∞" if x > 0 else "−∞"
    return f"{x:.{digits}g}"


def _check_class(outcome: Any) -> str:
    """CSS class of a check's cell: pass, fail, or none (n/a, not run)."""
    text = "" if is_missing(outcome) else str(outcome)
    if text == "pass":
        return "pass"
    if text == "fail" or text.startswith("error"):
        return "fail"
    return ""


def _cell(text: str, check: Any = None, title: str = "", num: bool = True) -> dict:
    return {"text": text, "cls": " ".join(c for c in ("num" if num else "", _check_class(check)) if c),
            "title": title or ("" if is_missing(check) else str(check))}


def _row(r: Mapping) -> dict:
    def pair(value: str, bound: str) -> str:
        return value if value == "—" else f"{value} ≤ {bound}"

    counts = "—" if is_missing(r.get("nan_count")) else \
        f"{int(r['nan_count'])} / {int(r['inf_count'])} / {int(r['negative_count'])}"
    rel = "—" if is_missing(r.get("rel_error")) else f"{float(r['rel_error']):+.3%}"
    z = "—" if is_missing(r.get("z")) else f"{float(r['z']):+.2f}"
    tol = "—" if is_missing(r.get("tolerance")) else f"± {_num(r['tolerance'], 3)}"
    lin = "—" if is_missing(r.get("linearity_rel_error")) else f"{float(r['linearity_rel_error']):+.1e}"
    mean_check = "" if is_missing(r.get("mean_check")) else str(r["mean_check"])
    cells = [
        _cell(str(r.get("spp", "—"))),
        _cell(str(r.get("resolution", "—")), num=False),
        _cell(pair(_num(r.get("time_s"), 3), f"{_num(r.get('time_bound_s'))} s"), r.get("time_check")),
        _cell(pair(_num(r.get("peak_rss_mb"), 4), f"{_num(r.get('rss_bound_mb'))} MB"), r.get("rss_check")),
        _cell(counts, r.get("finite_check"), "NaN / Inf / negative pixels, bound 0"),
        _cell(_num(r.get("mean"), 6), r.get("mean_check"), mean_check),
        _cell(_num(r.get("expected"), 6), r.get("mean_check"), mean_check),
        _cell(tol, r.get("mean_check"), mean_check),
        _cell(rel, r.get("mean_check"), mean_check),
        _cell(z, r.get("mean_check"), mean_check),
        _cell(lin, r.get("linearity_check")),
    ]
    status = str(r.get("status", ""))
    return {
        "variant": str(r.get("variant", "")),
        "renderer": str(r.get("renderer", "")),
        "status": status,
        "badge": _BADGE.get(status, "unavailable"),
        "cells": cells,
        "message": "" if is_missing(r.get("message")) else str(r["message"]),
        "mean_note": mean_check if mean_check.startswith("n/a") else "",
        "checks": "" if is_missing(r.get("checks")) else str(r["checks"]),
        "expected_source": "" if is_missing(r.get("expected_source")) else str(r["expected_source"]),
        "tolerance_basis": "" if is_missing(r.get("tolerance_basis")) else str(r["tolerance_basis"]),
        "not_run": status == "skipped",
    }


def _variants(table: pd.DataFrame) -> list[dict]:
    out = []
    for name, g in table.groupby("variant", sort=False):
        first = g.iloc[0]
        ran = g[g["status"] != "skipped"]
        src = ran.iloc[0] if len(ran) else first
        out.append({
            "name": str(name),
            "stresses": "" if is_missing(first.get("stresses")) else str(first["stresses"]),
            "spp": str(first.get("spp", "—")),
            "resolution": str(first.get("resolution", "—")),
            "time_bound": f"{_num(first.get('time_bound_s'))} s",
            "rss_bound": f"{_num(first.get('rss_bound_mb'))} MB",
            "expected": "" if is_missing(src.get("expected_source")) else str(src["expected_source"]),
            "basis": "" if is_missing(src.get("tolerance_basis")) else str(src["tolerance_basis"]),
        })
    return out


def _harness_version() -> str:
    try:
        from importlib.metadata import version

        return version("cornell-harness")
    except Exception:
        return "unknown"


def render_stress_html(table: pd.DataFrame, provenance: Mapping | None = None, command: str = "") -> str:
    """The report's HTML text (see :func:`write_stress_report`)."""
    provenance = dict(provenance or {})
    records = table.to_dict("records") if len(table) else []
    rows = [_row(r) for r in records]
    counts = {s: int((table["status"] == s).sum()) if len(table) else 0 for s in ("pass", "fail", "error", "skipped")}
    versions = provenance.pop("versions", {}) or {}
    other = [(str(k), ", ".join(map(str, v)) if isinstance(v, (list, tuple)) else str(v))
             for k, v in provenance.items() if not is_missing(v) and v != ""]
    env = _environment()
    return env.get_template("stress.html.j2").render(
        title="Stress test — numerical stability at the extremes",
        rows=rows,
        counts=counts,
        verdict="fail" if counts["fail"] or counts["error"] else "pass",
        variants=_variants(table) if len(table) else [],
        versions=sorted(versions.items()),
        provenance=other,
        command=command,
        generated=_dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        harness_version=_harness_version(),
        css=_css(env),
    )


def write_stress_report(path, table: pd.DataFrame, provenance: dict, command: str) -> Path:
    """Write the self-contained stress report to ``path`` (atomically) and return the path."""
    path = Path(path)
    write_text_atomic(path, render_stress_html(table, provenance, command))
    return path

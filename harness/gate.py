"""The CI quality gate: expectations per (scene, renderer, budget), checked with stated error rates.

A gate config (TOML) lists expectations::

    alpha = 0.01                      # family-wise false-alarm rate of each agreement test
    baseline = "gate-baseline.json"   # optional, relative to this file
    regression_margin = 0.05          # relative; a metric worse than baseline by more fails
    regression_metrics = ["delta_e2000_mean", "rel_mse_trimmed", "ssim"]

    [[expect]]
    scene = "cornell-box"             # stored name or path
    renderer = "pathtracer"           # registered name or package.module:Class
    spp = 256                         # budget: spp, or time = "10s" (spp is then calibrated)
    seed = 0                          # fixed: the same commit gives the same verdict
    unbiased = true                   # tiled z-test against the reference (harness.agreement)
    tile = 16
    slope = [-0.55, -0.45]            # optional: RMSE-vs-spp slope over checkpoints spp/64 .. spp
    max = { delta_e2000_mean = 3.0 }  # optional budgets on any harness metric
    min = { ssim = 0.7 }
    abs_max = { mean_radiance_rel_error = 0.3 }

Every expectation also checks that the image has no NaN and no Inf pixel.
Baseline checks compare runs at the seed the baseline was recorded with
only (a metric's spread between seeds can exceed any useful margin).
Each check becomes one JUnit test case; the Markdown summary and the HTML
report say which expectation failed, by how much, and where in the image.
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from harness import agreement, convergence, runner
from harness.adapter import RendererEntry, resolve
from harness.reference import Reference, load_reference, resolve_scene

#: Metrics where larger is better; every other metric is an error (smaller is better).
HIGHER_IS_BETTER = frozenset({"ssim", "psnr"})
DEFAULT_REGRESSION_METRICS = ("delta_e2000_mean", "rel_mse_trimmed", "ssim")


class GateConfigError(ValueError):
    """Bad gate config; ``str()`` names the file and the field."""

    def __init__(self, file, field: str, message: str):
        super().__init__(f"{file}: {field}: {message}")


@dataclass
class Expectation:
    name: str
    scene: str
    renderer: str
    spp: int | None = None
    time_s: float | None = None
    seed: int = 0
    unbiased: bool = False
    tile: int = 16
    slope: tuple[float, float] | None = None
    max: dict = field(default_factory=dict)
    min: dict = field(default_factory=dict)
    abs_max: dict = field(default_factory=dict)


@dataclass
class GateConfig:
    path: Path
    alpha: float
    expectations: list[Expectation]
    baseline: Path | None = None
    regression_margin: float = 0.05
    regression_metrics: tuple[str, ...] = DEFAULT_REGRESSION_METRICS


def load_config(path: str | Path) -> GateConfig:
    """Parse and validate a gate config; GateConfigError names the file and field of any problem."""
    path = Path(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise GateConfigError(path, "(file)", "no such file") from None
    except tomllib.TOMLDecodeError as e:
        raise GateConfigError(path, "(syntax)", f"invalid TOML: {e}") from None

    def num(table, key, where, default, kind=(int, float)):
        v = table.get(key, default)
        if isinstance(v, bool) or not isinstance(v, kind) or (isinstance(v, float) and not math.isfinite(v)):
            raise GateConfigError(path, f"{where}{key}", f"expected a finite number, got {v!r}")
        return v

    alpha = float(num(doc, "alpha", "", 0.01))
    if not 0 < alpha < 1:
        raise GateConfigError(path, "alpha", f"must be in (0, 1), got {alpha}")
    margin = float(num(doc, "regression_margin", "", 0.05))
    if margin < 0:
        raise GateConfigError(path, "regression_margin", "must be >= 0")
    reg = doc.get("regression_metrics", list(DEFAULT_REGRESSION_METRICS))
    if not isinstance(reg, list) or not all(isinstance(m, str) for m in reg):
        raise GateConfigError(path, "regression_metrics", "expected a list of metric names")
    baseline = doc.get("baseline")
    if baseline is not None and not isinstance(baseline, str):
        raise GateConfigError(path, "baseline", "expected a file name")
    raw = doc.get("expect")
    if not isinstance(raw, list) or not raw:
        raise GateConfigError(path, "expect", "a gate needs at least one [[expect]] table")
    exps, names = [], set()
    for i, t in enumerate(raw):
        w = f"expect[{i}]."
        for key in ("scene", "renderer"):
            if not isinstance(t.get(key), str):
                raise GateConfigError(path, f"{w}{key}", "missing or not a string")
        if ("spp" in t) == ("time" in t):
            raise GateConfigError(path, f"{w}spp", "give exactly one budget: spp = N or time = \"10s\"")
        spp = time_s = None
        if "spp" in t:
            spp = num(t, "spp", w, None, int)
            if spp < 1:
                raise GateConfigError(path, f"{w}spp", "must be >= 1")
        else:
            from harness.experiments import parse_duration
            try:
                time_s = parse_duration(str(t["time"]))
            except ValueError as e:
                raise GateConfigError(path, f"{w}time", str(e)) from None
        slope = t.get("slope")
        if slope is not None:
            if not (isinstance(slope, list) and len(slope) == 2 and all(isinstance(x, (int, float)) for x in slope)
                    and slope[0] < slope[1]):
                raise GateConfigError(path, f"{w}slope", "expected [low, high] with low < high")
            slope = (float(slope[0]), float(slope[1]))
        budgets = {}
        for key in ("max", "min", "abs_max"):
            b = t.get(key, {})
            if not isinstance(b, dict) or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                  for v in b.values()):
                raise GateConfigError(path, f"{w}{key}", "expected a table of metric = number")
            budgets[key] = {k: float(v) for k, v in b.items()}
        unbiased = t.get("unbiased", False)
        if not isinstance(unbiased, bool):
            raise GateConfigError(path, f"{w}unbiased", "expected true or false")
        budget = f"{spp}spp" if spp else f"{time_s:g}s"
        name = t.get("name") or f"{t['scene']}/{t['renderer']}@{budget}"
        if name in names:
            raise GateConfigError(path, f"{w}name", f"two expectations are named {name!r}; give one a name")
        names.add(name)
        tile = num(t, "tile", w, 16, int)
        if tile < 1:
            raise GateConfigError(path, f"{w}tile", "must be >= 1")
        exps.append(Expectation(name, t["scene"], t["renderer"], spp, time_s, num(t, "seed", w, 0, int), unbiased,
                                tile, slope, budgets["max"], budgets["min"], budgets["abs_max"]))
    return GateConfig(path, alpha, exps, path.parent / baseline if baseline else None, margin, tuple(reg))


# -- checks -----------------------------------------------------------------------------

@dataclass
class Check:
    expectation: str
    name: str
    passed: bool
    message: str
    value: float | None = None
    limit: float | None = None


@dataclass
class Outcome:
    """One expectation: its run, checks, and the agreement test when there was one."""

    expectation: Expectation
    record: runner.RunRecord
    checks: list[Check]
    agreement: agreement.Agreement | None = None

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)


def _budget_checks(exp: Expectation, m: dict) -> list[Check]:
    out = []
    for kind, table in (("max", exp.max), ("min", exp.min), ("abs_max", exp.abs_max)):
        for metric, limit in table.items():
            if metric not in m:
                out.append(Check(exp.name, f"{kind}.{metric}", False, f"unknown metric {metric!r}"))
                continue
            v = float(m[metric])
            shown = abs(v) if kind == "abs_max" else v
            ok = shown >= limit if kind == "min" else shown <= limit
            if not math.isfinite(v):
                ok = False
            word = {"max": "≤", "min": "≥", "abs_max": "|·| ≤"}[kind]
            by = "" if ok else f", off by {shown - limit:+.4g} ({(shown - limit) / limit:+.1%})" if limit else ""
            out.append(Check(exp.name, f"{kind}.{metric}", ok, f"{metric} = {v:.5g}, budget {word} {limit:g}{by}",
                             v, limit))
    return out


def _regression_checks(exp: Expectation, m: dict, base: dict | None, cfg: GateConfig) -> list[Check]:
    if not base:
        return []
    out = []
    for metric in cfg.regression_metrics:
        if metric not in base or metric not in m:
            continue
        b, v = float(base[metric]), float(m[metric])
        if metric in HIGHER_IS_BETTER:
            limit = b - abs(b) * cfg.regression_margin
            ok = v >= limit
        else:
            limit = b + abs(b) * cfg.regression_margin
            ok = v <= limit
        change = (v - b) / abs(b) if b else math.inf
        out.append(Check(exp.name, f"baseline.{metric}", ok and math.isfinite(v),
                         f"{metric} = {v:.5g}, baseline {b:.5g} ({change:+.1%}; margin {cfg.regression_margin:.0%})",
                         v, limit))
    return out


def _slope_check(exp: Expectation, rec: runner.RunRecord, ref: Reference) -> Check:
    spp = rec.spp
    shots = {c.spp: c.image for c in rec.checkpoints}
    shots[spp] = rec.image
    xs = sorted(s for s in shots if s >= max(1, spp // 64))
    rmse = [float(np.sqrt(np.mean((np.nan_to_num(shots[s].astype(np.float64)) - ref.image) ** 2))) for s in xs]
    slope = convergence.loglog_slope(xs, rmse)
    lo, hi = exp.slope
    ok = lo <= slope <= hi
    return Check(exp.name, "slope.rmse_spp", ok, f"RMSE-vs-spp slope {slope:.3f} over spp {xs[0]}..{xs[-1]}, "
                 f"expected in [{lo:g}, {hi:g}]", slope, None)


def evaluate(exp: Expectation, rec: runner.RunRecord, ref: Reference, cfg: GateConfig,
             baseline: dict | None = None) -> Outcome:
    """All checks of one expectation on its run (no rendering)."""
    if rec.status != "ok":
        return Outcome(exp, rec, [Check(exp.name, "run", False, f"{rec.status}: {rec.reason}")])
    m = rec.metrics
    bad = int(m["nan_count"]) + int(m["inf_count"])
    checks = [Check(exp.name, "finite", bad == 0,
                    "no NaN or Inf pixel" if bad == 0 else
                    f"{m['nan_count']} NaN and {m['inf_count']} Inf pixels" + _first_bad_pixel(rec.image), bad, 0)]
    agr = None
    if exp.unbiased:
        var = rec.variance if rec.variance is not None else ref.variance * (ref.spp / rec.spp)
        clean = np.where(np.isfinite(rec.image), rec.image, 0.0)
        agr = agreement.agreement_test(clean, var, ref.image, ref.variance, exp.tile, cfg.alpha)
        checks.append(Check(exp.name, "agreement", agr.passed, agr.message(), agr.p_min, agr.level))
    checks += _budget_checks(exp, m)
    if exp.slope:
        checks.append(_slope_check(exp, rec, ref))
    checks += _regression_checks(exp, m, baseline, cfg)
    return Outcome(exp, rec, checks, agr)


def _first_bad_pixel(image) -> str:
    bad = np.argwhere(~np.all(np.isfinite(image), axis=-1))
    return f"; first at pixel (x {bad[0][1]}, y {bad[0][0]})" if len(bad) else ""


# -- running ----------------------------------------------------------------------------

def _checkpoints(exp: Expectation, spp: int) -> list[int]:
    if not exp.slope:
        return []
    out, s = [], max(1, spp // 64)
    while s < spp:
        out.append(s)
        s *= 2
    return out + [spp]


def run_gate(cfg: GateConfig, overrides: dict[str, RendererEntry] | None = None, seed_offset: int = 0,
             on_start: Callable[[Expectation], None] | None = None) -> list[Outcome]:
    """Render every expectation and check it. ``overrides`` replaces renderers by name (tests use it).

    ``seed_offset`` shifts every expectation's seed (false-alarm measurements
    run the same gate over many seeds).
    """
    baseline = load_baseline(cfg)
    metrics, seeds = baseline.get("expectations", {}), baseline.get("seeds", {})
    outcomes = []
    for exp in cfg.expectations:
        if on_start:
            on_start(exp)
        scene = resolve_scene(exp.scene)
        ref = load_reference(scene)
        entry = (overrides or {}).get(exp.renderer) or resolve([exp.renderer])[0]
        seed = exp.seed + seed_offset
        spp = exp.spp
        if spp is None:
            from harness.experiments import spp_for_time_budget
            spp = spp_for_time_budget(entry, scene, exp.time_s, seed) if entry.available else 1
        rec = runner.run_one(entry, scene, spp, seed, ref, checkpoints=_checkpoints(exp, spp))
        # A baseline compares like with like: the same seed, so the same noise. Runs at other seeds
        # (false-alarm measurements) are not compared: a metric's spread between seeds can exceed the margin.
        same_seed = seeds.get(exp.name, seed) == seed
        outcomes.append(evaluate(exp, rec, ref, cfg, metrics.get(exp.name) if same_seed else None))
    return outcomes


def load_baseline(cfg: GateConfig) -> dict:
    if cfg.baseline is None or not cfg.baseline.exists():
        return {}
    try:
        data = json.loads(cfg.baseline.read_text())
        return {"expectations": data["expectations"], "seeds": data.get("seeds", {})}
    except (json.JSONDecodeError, KeyError, TypeError) as e:
        raise GateConfigError(cfg.baseline, "(file)", f"not a gate baseline ({e}); rerun with --update-baseline")


def write_baseline(cfg: GateConfig, outcomes: Sequence[Outcome]) -> Path:
    from harness.atomic import write_json_atomic

    if cfg.baseline is None:
        raise GateConfigError(cfg.path, "baseline", "set baseline = \"FILE.json\" to record a baseline")
    data = {"expectations": {o.expectation.name: runner.json_safe(o.record.metrics) for o in outcomes
                             if o.record.status == "ok"},
            "seeds": {o.expectation.name: o.record.seed for o in outcomes}}
    write_json_atomic(cfg.baseline, data)
    return cfg.baseline


# -- outputs ----------------------------------------------------------------------------

def junit_xml(outcomes: Sequence[Outcome], suite: str = "cbox gate") -> str:
    """JUnit XML: one test case per check, named expectation::check."""
    checks = [c for o in outcomes for c in o.checks]
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(checks)),
                       failures=str(sum(not c.passed for c in checks)), errors="0")
    for o in outcomes:
        t = f"{o.record.time_s:.3f}" if o.record.time_s else "0"
        for c in o.checks:
            case = ET.SubElement(ts, "testcase", classname=o.expectation.name, name=c.name, time=t)
            if not c.passed:
                ET.SubElement(case, "failure", message=c.message).text = c.message
            else:
                ET.SubElement(case, "system-out").text = c.message
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def markdown_summary(outcomes: Sequence[Outcome], alpha: float) -> str:
    """A Markdown verdict for a CI step summary."""
    failed = [c for o in outcomes for c in o.checks if not c.passed]
    verdict = "✅ **gate passed**" if not failed else f"❌ **gate failed**: {len(failed)} check(s)"
    lines = [f"## cbox gate: {verdict}", "",
             f"Agreement tests at family-wise α = {alpha:g} (Šidák over tiles and channels).", "",
             "| expectation | spp | seed | check | result | detail |", "|---|---|---|---|---|---|"]
    for o in outcomes:
        for c in o.checks:
            detail = c.message.replace("|", "\\|")
            lines.append(f"| {o.expectation.name} | {o.record.spp} | {o.record.seed} | {c.name} | "
                         f"{'pass' if c.passed else '**FAIL**'} | {detail} |")
    return "\n".join(lines) + "\n"

"""The checks of one expectation on its run: finite pixels, agreement, budgets, slope, baseline.

Pure evaluation: nothing here renders. :mod:`harness.gate.run` renders and
calls :func:`evaluate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness.evaluate import agreement, convergence, metrics, noise
from harness.evaluate.registry import HIGHER_IS_BETTER
from harness.gate.config import Expectation, GateConfig
from harness.store.references import Reference
from harness.workflows import runner


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
    rmse = [metrics.rmse(metrics.zero_broken_pixels(np.asarray(shots[s], np.float64)), ref.image) for s in xs]
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
        var = rec.variance if rec.variance is not None else noise.render_variance(ref.variance, ref.spp, rec.spp)
        clean = metrics.zero_broken_pixels(rec.image)
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

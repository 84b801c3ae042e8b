"""The checks of one expectation on its run: finite pixels, agreement, variance, outliers, budgets, slope, baseline.

Pure evaluation: nothing here renders. :mod:`harness.gate.run` renders and
calls :func:`evaluate`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness.evaluate import agreement, convergence, metrics, noise, outliers, variance_check
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
    error: bool = False  # the check could not be made (the renderer crashed): a JUnit <error>, not a <failure>


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


#: The statistical tests of an ``unbiased`` expectation; they share its family-wise ``alpha`` (Šidák).
STATISTICAL_TESTS = ("agreement", "variance", "outliers")


def statistical_alpha(alpha: float) -> float:
    """Each statistical test's level, 1 − (1 − α)^(1/3): together they fail a correct renderer at rate ≤ α."""
    return agreement.sidak_level(alpha, len(STATISTICAL_TESTS))


def _alpha_note(alpha: float) -> str:
    return (f" [α = {alpha:g} per expectation, Šidák-split over {', '.join(STATISTICAL_TESTS)}: "
            f"{statistical_alpha(alpha):.3g} each]")


def _variance_check(exp: Expectation, rec: runner.RunRecord, clean: np.ndarray, ref: Reference,
                    alpha: float) -> Check:
    """The renderer's own variance against its residuals (harness.evaluate.variance_check); skipped without one."""
    if rec.variance is None:
        return Check(exp.name, "variance", True, "skipped: the renderer reports no variance, so the agreement and "
                     "outlier tests use the reference renderer's noise model, not a variance it could misstate"
                     + _alpha_note(alpha))
    v = variance_check.variance_check(clean, rec.variance, ref.image, ref.variance, rec.spp,
                                      statistical_alpha(alpha))
    return Check(exp.name, "variance", v.passed, v.message() + _alpha_note(alpha), v.scale, None)


def _outlier_check(exp: Expectation, rec: runner.RunRecord, clean: np.ndarray, ref: Reference,
                   alpha: float) -> Check:
    """One z-test per pixel, threshold calibrated on the reference's noise batch (harness.evaluate.outliers)."""
    o = outliers.outlier_test(clean, rec.variance, ref.image, ref.variance, ref.noise, ref.spp, ref.noise_spp,
                              rec.spp, statistical_alpha(alpha))
    return Check(exp.name, "outliers", o.passed, o.message() + _alpha_note(alpha), o.worst, o.threshold.value)


def evaluate(exp: Expectation, rec: runner.RunRecord, ref: Reference, cfg: GateConfig,
             baseline: dict | None = None) -> Outcome:
    """All checks of one expectation on its run (no rendering)."""
    if rec.status != "ok":
        if rec.info.get("timed_out"):  # a failed check with its time, not a crash
            return Outcome(exp, rec, [Check(exp.name, "time_limit", False, f"{rec.reason}", rec.time_s,
                                            exp.time_limit_s)])
        return Outcome(exp, rec, [Check(exp.name, "run", False, f"{rec.status}: {rec.reason}", error=True)])
    m = rec.metrics
    bad = int(m["nan_count"]) + int(m["inf_count"])
    checks = [Check(exp.name, "finite", bad == 0,
                    "no NaN or Inf pixel" if bad == 0 else
                    f"{m['nan_count']} NaN and {m['inf_count']} Inf pixels" + _first_bad_pixel(rec.image), bad, 0)]
    agr = None
    if exp.unbiased:
        var = rec.variance if rec.variance is not None else noise.render_variance(ref.variance, ref.spp, rec.spp)
        clean = metrics.zero_broken_pixels(rec.image)
        share = statistical_alpha(cfg.alpha)
        agr = agreement.agreement_test(clean, var, ref.image, ref.variance, exp.tile, share)
        checks.append(Check(exp.name, "agreement", agr.passed, agr.message() + _alpha_note(cfg.alpha),
                            agr.p_min, agr.level))
        checks.append(_variance_check(exp, rec, clean, ref, cfg.alpha))
        checks.append(_outlier_check(exp, rec, clean, ref, cfg.alpha))
    checks += _budget_checks(exp, m)
    if exp.slope:
        checks.append(_slope_check(exp, rec, ref))
    checks += _regression_checks(exp, m, baseline, cfg)
    return Outcome(exp, rec, checks, agr)


def _first_bad_pixel(image) -> str:
    bad = np.argwhere(~np.all(np.isfinite(image), axis=-1))
    return f"; first at pixel (x {bad[0][1]}, y {bad[0][0]})" if len(bad) else ""

"""The checks of one expectation on its run: finite pixels, agreement, variance, outliers, budgets, slope,
consistency, baseline.

Pure evaluation: nothing here renders. :mod:`cornell_harness.gate.run` renders (the
expectation's run, and the smaller-budget run of a ``max_ratio``
consistency check) and calls :func:`evaluate`.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from cornell_harness.evaluate import agreement, bias_extrapolation, convergence, metrics, outliers, variance_check
from cornell_harness.evaluate.equivalence import FAIL, INCONCLUSIVE, PASS, interval_verdicts, resolving_half_width
from cornell_harness.evaluate.registry import HIGHER_IS_BETTER, METRICS
from cornell_harness.evaluate.sequential import doubling
from cornell_harness.evaluate.score import lookup, metric_value
from cornell_harness.gate.config import Expectation, GateConfig
from cornell_harness.gate.consistency import Consistency
from cornell_harness.gate.margins import BiasTable, bias_table, equivalence_message
from cornell_harness.store.references import Reference
from cornell_harness.workflows import runner


@dataclass
class Check:
    expectation: str
    name: str
    passed: bool
    message: str
    value: float | None = None
    limit: float | None = None
    error: bool = False  # the check could not be made (the renderer crashed): a JUnit <error>, not a <failure>
    # Not made, and not a failure (the renderer reports no variance to check): passed stays True, so the
    # verdict is unchanged, but JUnit says <skipped/> and the summaries "skipped", never "pass".
    skipped: bool = False
    traceback: str = ""  # a crashed render's traceback (the sandbox child's own), for the log, JUnit and report
    # Neither shown to hold nor to fail (an interval straddles its margin): not passed, but no failure either
    # (exit 3); passed as well where the expectation says inconclusive = "pass".
    inconclusive: bool = False

    @property
    def word(self) -> str:
        """``pass``, ``skipped``, ``FAIL``, ``ERROR``, ``INCONCLUSIVE`` (or ``inconclusive``, counted as a pass):
        the result as every output names it."""
        if self.inconclusive:
            return "inconclusive" if self.passed else "INCONCLUSIVE"
        return "skipped" if self.skipped else "pass" if self.passed else "ERROR" if self.error else "FAIL"

    @property
    def failed(self) -> bool:
        """Failed, not merely inconclusive."""
        return not self.passed and not self.inconclusive


@dataclass
class Outcome:
    """One expectation: its run, checks, and the agreement test when there was one."""

    expectation: Expectation
    record: runner.RunRecord
    checks: list[Check]
    agreement: agreement.Agreement | None = None
    bias: BiasTable | None = None  # an unbiased expectation's relative-bias intervals

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    @property
    def verdict(self) -> str:
        """``fail`` (a check failed), ``inconclusive`` (none failed, one is inconclusive) or ``pass``."""
        return FAIL if any(c.failed for c in self.checks) else INCONCLUSIVE if not self.passed else PASS


def recorded_metric(rec: runner.RunRecord, key: str) -> float | None:
    """A metric of the run: image-wide from ``rec.metrics``, ``region.<region>.<metric>`` from ``rec.regions``."""
    return lookup(rec.metrics, rec.regions, key)


def _budget_checks(exp: Expectation, rec: runner.RunRecord) -> list[Check]:
    out = []
    for kind, table in (("max", exp.max), ("min", exp.min), ("abs_max", exp.abs_max)):
        for metric, limit in table.items():
            v = recorded_metric(rec, metric)
            if v is None:
                out.append(Check(exp.name, f"{kind}.{metric}", False, f"unknown metric {metric!r}"))
                continue
            shown = abs(v) if kind == "abs_max" else v
            ok = shown >= limit if kind == "min" else shown <= limit
            if not math.isfinite(v):
                ok = False
            word = {"max": "≤", "min": "≥", "abs_max": "|·| ≤"}[kind]
            by = "" if ok else f", off by {shown - limit:+.4g} ({(shown - limit) / limit:+.1%})" if limit else ""
            meaning = METRICS[metric].infinite if metric in METRICS and math.isinf(v) else ""
            if meaning:  # a verdict, not an overflow: say it instead of an infinite excess
                by = f" ({meaning})"
            out.append(Check(exp.name, f"{kind}.{metric}", ok, f"{metric} = {v:.5g}, budget {word} {limit:g}{by}",
                             v, limit))
    return out


def _regression_checks(exp: Expectation, m: dict, base: dict | str | None, cfg: GateConfig) -> list[Check]:
    """One ``baseline.<metric>`` check per regression metric; ``base`` a string: why there is no baseline to
    compare with, one skipped ``baseline`` check that says so."""
    if isinstance(base, str):
        return [Check(exp.name, "baseline", True, f"skipped: {base}", skipped=True)]
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


def _shots(rec: runner.RunRecord, first: int) -> tuple[list[int], dict]:
    """The doubling spps from ``first`` to the run's spp that the run has an image of, and the images by spp."""
    shots = {c.spp: c.image for c in rec.checkpoints}
    shots[rec.spp] = rec.image
    return [s for s in doubling(first, rec.spp) if s in shots], shots


def _slope_check(exp: Expectation, rec: runner.RunRecord, ref: Reference) -> Check:
    xs, shots = _shots(rec, max(1, rec.spp // 64))
    rmse = [metric_value(shots[s], ref, s, "rmse") for s in xs]
    slope = convergence.loglog_slope(xs, rmse)
    lo, hi = exp.slope
    ok = lo <= slope <= hi
    return Check(exp.name, "slope.rmse_spp", ok, f"RMSE-vs-spp slope {slope:.3f} over spp {xs[0]}..{xs[-1]}, "
                 f"expected in [{lo:g}, {hi:g}]", slope, None)


def _budget_text(spp: int, settings: str, keys) -> str:
    """``spp 16, global_photons=50000``: a run's spp and the settings a smaller render replaced."""
    values = json.loads(settings or "{}")
    return ", ".join([f"spp {spp}"] + [f"{k}={values.get(k)}" for k in keys])


def _consistency_slope(exp: Expectation, c: Consistency, rec: runner.RunRecord, ref: Reference,
                       masks: Mapping[str, np.ndarray] | None) -> Check:
    """The log-log slope of the metric (by magnitude) against spp over the render's own checkpoints."""
    name, (lo, hi) = f"consistency.{c.metric}", c.slope
    xs, shots = _shots(rec, c.first_spp(rec.spp))
    if len(xs) < 2:
        return Check(exp.name, name, False, f"no checkpoints from spp {c.first_spp(rec.spp)} below {rec.spp}: "
                     "the slope form needs a progressive renderer (or use max_ratio with smaller)")
    ys = [abs(metric_value(shots[s], ref, s, c.metric, masks)) for s in xs]
    slope = convergence.loglog_slope(xs, ys)
    ok = lo <= slope <= hi  # False for NaN (an error of 0 or not finite)
    return Check(exp.name, name, ok, f"{c.metric}-vs-spp slope {slope:.3f} over spp {xs[0]}..{xs[-1]} "
                 f"({c.metric} {ys[0]:.4g} → {ys[-1]:.4g}), expected in [{lo:g}, {hi:g}]", slope, None)


def _consistency_ratio(exp: Expectation, c: Consistency, rec: runner.RunRecord,
                       smaller: runner.RunRecord | None) -> Check:
    """metric(full) ≤ max_ratio · metric(smaller), by magnitude."""
    name, keys = f"consistency.{c.metric}", sorted(c.smaller_settings)
    if smaller is None or smaller.status != "ok":
        why = "was not rendered" if smaller is None else f"{smaller.status}: {smaller.reason}"
        return Check(exp.name, name, False, f"the smaller-budget render {why}", error=True)
    full, small = recorded_metric(rec, c.metric), recorded_metric(smaller, c.metric)
    if full is None or small is None:
        return Check(exp.name, name, False, f"unknown metric {c.metric!r}")
    full, small = abs(full), abs(small)
    ratio = 0.0 if full == 0 else full / small if small > 0 else math.inf
    ok = math.isfinite(ratio) and ratio <= c.max_ratio
    return Check(exp.name, name, ok, f"{c.metric} {full:.4g} at {_budget_text(rec.spp, rec.settings, keys)} "
                 f"against {small:.4g} at {_budget_text(smaller.spp, smaller.settings, keys)}: ratio {ratio:.3f}, "
                 f"limit ≤ {c.max_ratio:g}", ratio, c.max_ratio)


def _bias_limit_checks(exp: Expectation, errors: Mapping[str, np.ndarray] | str | None,
                       alpha: float) -> list[Check]:
    """One check per ``bias_limit`` metric: each seed's error extrapolated to infinite effort, the limits
    t-tested against 0 over seeds (:mod:`cornell_harness.evaluate.bias_extrapolation`), Šidák-split over the metrics."""
    b = exp.bias_limit
    if errors is None or isinstance(errors, str):
        why = errors or "the bias limit's renders were not made"
        return [Check(exp.name, f"bias_limit.{m}", False, why, error=True) for m in b.metrics]
    level = agreement.sidak_level(alpha, len(b.metrics))
    out = []
    for m in b.metrics:
        tol = b.tolerance.get(m, 0.0)
        r = bias_extrapolation.limit_test(errors[m], b.efforts, b.rate, level, tol)
        k, effort = r.seeds, f"{'/'.join(b.setting) or 'spp'} {', '.join(map(str, b.efforts))}"
        # Against 0 the signed t; with a tolerance, how far beyond it the limit lies in standard errors.
        against, t = (f"(|limit| − {tol:.3%}) / se", r.t) if tol else ("t", r.limit.t)
        message = (f"{m} extrapolated to infinite effort (rate {b.rate:g}, {effort}; {k} seeds): limit "
                   f"{r.limit.text()} ({1 - level:.4g} t-interval), {against} = {t:+.2f}, critical ±"
                   f"{r.t_critical:.2f} (level {level:.3g}: α = {alpha:g} Šidák-split over {len(b.metrics)}); "
                   f"bias at the first effort above the limit {r.coefficient.text()} (95%)")
        margin = b.margin.get(m)
        if margin is None or not r.passed:  # no margin: pass or fail; beyond the tolerance: fail either way
            out.append(Check(exp.name, f"bias_limit.{m}", r.passed, message, t, r.t_critical))
            continue
        verdict = str(interval_verdicts(r.limit.low, r.limit.high, margin, tol))
        out.append(three_way(exp, f"bias_limit.{m}", verdict == PASS,
                              f"{message}; {_limit_resolution(r, margin, tol, verdict)}", t, r.t_critical))
    return out


def _limit_resolution(r: bias_extrapolation.LimitTest, margin: float, tol: float, verdict: str) -> str:
    """A bias limit's interval against its margin: inside, or straddling it and about how many seeds would
    resolve it (the interval's half-width falls as 1/√seeds)."""
    if verdict == PASS:
        return f"inside the margin ±{margin:.3%}"
    half, target = (r.limit.high - r.limit.low) / 2, float(resolving_half_width(r.limit.mean, margin, tol))
    more = (f"about {math.ceil(r.seeds * (half / target) ** 2)} seeds would resolve it"
            if target > 0 and math.isfinite(half) else "no number of seeds resolves it")
    return f"inconclusive: the interval straddles the margin ±{margin:.3%} ({more})"


#: The statistical tests of an ``unbiased`` expectation; they share its family-wise ``alpha`` (Šidák).
STATISTICAL_TESTS = ("agreement", "variance", "outliers")


def statistical_alpha(alpha: float) -> float:
    """Each statistical test's level, 1 − (1 − α)^(1/3): together they fail a correct renderer at rate ≤ α."""
    return agreement.sidak_level(alpha, len(STATISTICAL_TESTS))


def _alpha_note(alpha: float) -> str:
    return (f" [α = {alpha:g} per expectation, Šidák-split over {', '.join(STATISTICAL_TESTS)}: "
            f"{statistical_alpha(alpha):.3g} each]")


def _equivalence_check(exp: Expectation, table: BiasTable) -> Check:
    """Every region's bias interval inside its margin (pass), or not (inconclusive; a significant bias is the
    agreement test's failure)."""
    ok = not table.unresolved
    return three_way(exp, "equivalence", ok, equivalence_message(table), len(table.unresolved), 0)


def three_way(exp: Expectation, name: str, ok: bool, message: str, value, limit) -> Check:
    """A check that passes or is inconclusive (counted as a pass where the expectation says so)."""
    if ok:
        return Check(exp.name, name, True, message, value, limit)
    return Check(exp.name, name, exp.inconclusive == "pass", message, value, limit, inconclusive=True)


def variance_of_render_check(exp: Expectation, variance: np.ndarray | None, spp: int, clean: np.ndarray,
                             ref: Reference, level: float, note: str) -> Check:
    """The renderer's own ``variance`` of ``clean`` (at ``spp``) against its residuals, at ``level``
    (cornell_harness.evaluate.variance_check); skipped without one. ``note`` ends its message (the level's
    origin)."""
    if variance is None:
        return Check(exp.name, "variance", True, "skipped: the renderer reports no variance, so the agreement and "
                     "outlier tests use the reference renderer's noise model, not a variance it could misstate"
                     + note, skipped=True)
    v = variance_check.variance_check(clean, variance, ref.image, ref.variance, spp, level)
    return Check(exp.name, "variance", v.passed, v.message() + note, v.scale, None)


def outlier_check(exp: Expectation, variance: np.ndarray | None, spp: int, clean: np.ndarray, ref: Reference,
                  level: float, note: str) -> Check:
    """One z-test per pixel of ``clean`` (at ``spp``), threshold calibrated on the reference's noise batch, at
    ``level`` (cornell_harness.evaluate.outliers); ``note`` ends its message."""
    o = outliers.outlier_test(clean, variance, ref.image, ref.variance, ref.noise, ref.spp, ref.noise_spp, spp,
                              level)
    return Check(exp.name, "outliers", o.passed, o.message() + note, o.worst, o.threshold.value)


def evaluate(exp: Expectation, rec: runner.RunRecord, ref: Reference, cfg: GateConfig,
             baseline: dict | str | None = None, smaller: runner.RunRecord | None = None,
             masks: Mapping[str, np.ndarray] | None = None,
             bias: Mapping[str, np.ndarray] | str | None = None) -> Outcome:
    """All checks of one expectation on its run (no rendering).

    ``baseline`` the metrics recorded for it, or why it is not compared with any (a string: a skipped check);
    ``smaller`` is the smaller-budget run of a ``max_ratio`` consistency check;
    ``masks`` the scene's region masks (:func:`cornell_harness.evaluate.regions.region_masks`): each region is a test of
    an ``unbiased`` expectation's agreement test, and a consistency slope on a region metric needs its mask;
    ``bias`` a ``bias_limit``'s errors per metric ((seeds, efforts) arrays,
    :func:`cornell_harness.gate.run.render_bias_efforts`), or why they are missing.
    """
    if rec.status != "ok":
        if rec.info.get("timed_out"):  # a failed check with its time, not a crash
            return Outcome(exp, rec, [Check(exp.name, "time_limit", False, f"{rec.reason}", rec.time_s,
                                            exp.time_limit_s)])
        return Outcome(exp, rec, [Check(exp.name, "run", False, f"{rec.status}: {rec.reason}", error=True,
                                        traceback=rec.info.get("traceback") or "")])
    m = rec.metrics
    bad = int(m["nan_count"]) + int(m["inf_count"])
    checks = [Check(exp.name, "finite", bad == 0,
                    "no NaN or Inf pixel" if bad == 0 else
                    f"{m['nan_count']} NaN and {m['inf_count']} Inf pixels" + _first_bad_pixel(rec.image), bad, 0)]
    agr = table = None
    if exp.unbiased:
        # The renderer's own variance floored at the noise model (as the outlier test does: render_agreement).
        clean = metrics.zero_broken_pixels(rec.image)
        share = statistical_alpha(cfg.alpha)
        agr = agreement.render_agreement(rec.image, rec.variance, rec.spp, ref.image, ref.variance, ref.spp,
                                         exp.tile, share, masks)
        checks.append(Check(exp.name, "agreement", agr.passed, agr.message() + _alpha_note(cfg.alpha),
                            agr.p_min, agr.level))
        level, note = statistical_alpha(cfg.alpha), _alpha_note(cfg.alpha)
        checks.append(variance_of_render_check(exp, rec.variance, rec.spp, clean, ref, level, note))
        checks.append(outlier_check(exp, rec.variance, rec.spp, clean, ref, level, note))
        table = bias_table(rec.image, rec.variance, rec.spp, ref, masks, cfg.alpha, exp.margins)
        if exp.margins is not None:
            checks.append(_equivalence_check(exp, table))
    checks += _budget_checks(exp, rec)
    if exp.slope:
        checks.append(_slope_check(exp, rec, ref))
    if (c := exp.consistency) is not None:
        checks.append(_consistency_slope(exp, c, rec, ref, masks) if c.slope else
                      _consistency_ratio(exp, c, rec, smaller))
    if exp.bias_limit is not None:
        checks += _bias_limit_checks(exp, bias, cfg.alpha)
    checks += _regression_checks(exp, m, baseline, cfg)
    return Outcome(exp, rec, checks, agr, table if exp.unbiased else None)


def _first_bad_pixel(image) -> str:
    bad = np.argwhere(~np.all(np.isfinite(image), axis=-1))
    return f"; first at pixel (x {bad[0][1]}, y {bad[0][0]})" if len(bad) else ""

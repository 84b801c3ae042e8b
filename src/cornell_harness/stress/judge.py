"""Judging one sandboxed run of a stress variant: its row of the stress table.

A row passes when every check passes:

1. **finite**: no NaN, Inf or negative pixel anywhere in the image
   (:func:`cornell_harness.evaluate.metrics.invalid_pixel_counts`);
2. **time**: the process's wall time is within the variant's bound (the
   sandbox kills it at the bound: :mod:`cornell_harness.workflows.sandbox`);
3. **memory**: the process's peak resident set (``VmHWM``) is within the
   variant's bound (it is killed when its resident set passes it);
4. **mean radiance** (mean over pixels and channels, float64) within the
   tolerance of the expected value (:mod:`cornell_harness.stress.expectations`). It
   is ``n/a (approximates: …)`` for a renderer that declares approximations
   (pyrender: direct light only), whose finiteness, time and memory are still
   checked, and ``n/a`` where no finite value exists (albedo 1);
5. **linearity** (radiance-1e6 only): the image mean equals the same seed's
   unscaled render times the scale within
   :data:`~cornell_harness.stress.variants.LINEARITY_TOLERANCE`.

A row's ``status`` is pass, fail, skipped (set by the suite: unavailable, or
does not model a feature) or error (the renderer raised, gave an image of the
wrong shape, or the expected value could not be made). Every check's outcome,
bound or tolerance goes into the row (:data:`COLUMNS`), and ``checks`` says
them all in one line.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from cornell_harness.adapters.api import attribute
from cornell_harness.evaluate import metrics
from cornell_harness.scenes.model import Scene
from cornell_harness.stress.expectations import FLOAT_FLOOR, Z_CRIT, Expectation, pixel_var
from cornell_harness.workflows.sandbox import SandboxOutcome
from cornell_harness.stress.variants import LINEARITY_TOLERANCE, SEED, Variant

#: Columns of the stress table, in order.
COLUMNS = (
    "variant", "renderer", "status", "message", "spp", "resolution", "seed",
    "time_s", "time_bound_s", "render_time_s", "peak_rss_mb", "rss_bound_mb",
    "nan_count", "inf_count", "negative_count",
    "mean", "expected", "tolerance", "rel_error", "z", "se",
    "finite_check", "time_check", "rss_check", "mean_check", "linearity_check", "linearity_rel_error",
    "checks", "expected_source", "tolerance_basis", "stresses", "version",
)

STATUSES = ("pass", "fail", "skipped", "error")


def new_row(variant: Variant, renderer: str, scene: Scene, status: str, message: str = "") -> dict:
    row = dict.fromkeys(COLUMNS)
    cam = scene.camera
    row.update(variant=variant.name, renderer=renderer, status=status, message=message, spp=variant.spp,
               resolution=f"{cam.width}x{cam.height}", seed=SEED, time_bound_s=variant.time_bound_s,
               rss_bound_mb=variant.rss_bound_mb, stresses=variant.stresses)
    return row


def _approximation_note(approximations: Sequence[str]) -> str:
    """The first clause of each approximation: 'direct lighting only; ...'."""
    return "; ".join(a.split(":")[0].split(" (")[0].strip() for a in approximations)


def _region_mean(image: np.ndarray, keep: np.ndarray | None) -> tuple[float, np.ndarray]:
    """(mean over finite pixels of the region of the channel mean, the selection used)."""
    pix = np.asarray(image, np.float64).mean(axis=-1)
    sel = np.isfinite(pix)
    if keep is not None:
        sel &= keep
    return (float(pix[sel].mean()) if sel.any() else math.nan), sel


def judge_run(variant: Variant, renderer, name: str, scene: Scene, outcome: SandboxOutcome,
              exp: Expectation) -> dict:
    """The row of one run: every check, its bound or tolerance, pass or fail."""
    row = new_row(variant, name, scene, "pass")
    row.update(time_s=round(outcome.time_s, 3), peak_rss_mb=round(outcome.peak_rss_mb, 1), version=outcome.version,
               render_time_s=round(sum(outcome.render_times), 3) if outcome.render_times else None)
    fails = _check_bounds(row, variant, outcome)
    if _without_image(row, outcome, fails):
        row["checks"] = _checks_text(row)
        return row
    image = outcome.images[0]
    _check_finite(row, image, fails)
    _check_mean(row, image, outcome.variances[0], exp, variant.spp, renderer, fails)
    if variant.linearity and len(outcome.images) > 1 and exp.scale:
        _check_linearity(row, image, outcome.images[1], exp.scale, fails)
    else:
        row["linearity_check"] = "n/a (radiance-1e6 only)"
    if row["mean_check"].startswith("error"):
        row.update(status="error", message=exp.error)
    elif fails:
        row.update(status="fail", message="; ".join(fails))
    row["checks"] = _checks_text(row)
    return row


def _check_bounds(row: dict, variant: Variant, outcome: SandboxOutcome) -> list[str]:
    """The time and memory checks into ``row``; the failures' messages."""
    fails: list[str] = []
    time_ok = outcome.ended != "timeout" and outcome.time_s <= variant.time_bound_s
    rss_ok = outcome.ended != "memory" and outcome.peak_rss_mb <= variant.rss_bound_mb
    row["time_check"] = "pass" if time_ok else "fail"
    row["rss_check"] = "pass" if rss_ok else "fail"
    if not time_ok:
        fails.append(outcome.message if outcome.ended == "timeout" else
                     f"took {outcome.time_s:.1f} s, bound {variant.time_bound_s:g} s")
    if not rss_ok:
        fails.append(outcome.message if outcome.ended == "memory" else
                     f"peak RSS {outcome.peak_rss_mb:.0f} MB, bound {variant.rss_bound_mb:.0f} MB")
    return fails


def _without_image(row: dict, outcome: SandboxOutcome, fails: list[str]) -> bool:
    """Finish ``row`` when the run left no usable image (error, crash, wrong shape, killed); True if it did."""
    problem = outcome.problem() if outcome.ended in ("ok", "error", "crashed") else None
    if outcome.ended in ("error", "crashed") or (problem and outcome.ended == "ok"):
        row.update(status="error", message=problem or outcome.message)
        for k in ("finite_check", "mean_check", "linearity_check"):
            row[k] = "n/a (no image)"
        return True
    if outcome.ended != "ok":  # killed at a bound: nothing else to judge
        for k in ("finite_check", "mean_check", "linearity_check"):
            row[k] = "n/a (killed)"
        row.update(status="fail", message="; ".join(fails))
        return True
    return False


def _check_finite(row: dict, image: np.ndarray, fails: list[str]) -> None:
    counts = metrics.invalid_pixel_counts(image)
    row.update(counts)
    finite_ok = not any(counts.values())
    row["finite_check"] = "pass" if finite_ok else "fail"
    if not finite_ok:
        fails.append(f"{counts['nan_count']} NaN, {counts['inf_count']} Inf, "
                     f"{counts['negative_count']} negative pixels")


def _check_mean(row: dict, image: np.ndarray, variance, exp: Expectation, spp: int, renderer,
                fails: list[str]) -> None:
    """The mean-radiance z-test into ``row`` (or why it does not apply)."""
    keep = exp.keep if exp.keep is not None and exp.keep.shape == image.shape[:2] else None
    mean, sel = _region_mean(image, keep)
    row.update(mean=mean, expected_source=exp.source, tolerance_basis=exp.basis)
    approximations = attribute(renderer, "approximations")
    if approximations:
        row["mean_check"] = f"n/a (approximates: {_approximation_note(approximations)})"
        row["expected"] = exp.value
        return
    if exp.error:
        row["mean_check"] = f"error ({exp.error})"
        return
    if exp.value is None:
        row["mean_check"] = f"n/a ({exp.source})"
        return
    se_run = _run_se(image, variance, sel, exp, spp)
    row["expected"] = exp.value
    if se_run is None:
        row["mean_check"] = "n/a (no noise estimate for this render)"
        return
    se = math.hypot(se_run, exp.se)
    tol = Z_CRIT * se + (exp.allowance + FLOAT_FLOOR) * abs(exp.value)
    diff = mean - exp.value
    row.update(se=se, tolerance=tol, rel_error=diff / exp.value if exp.value else math.nan,
               z=diff / se if se > 0 else (0.0 if diff == 0 else math.copysign(math.inf, diff)))
    ok = bool(abs(diff) <= tol)  # NaN mean fails
    row["mean_check"] = "pass" if ok else "fail"
    if not ok:
        fails.append(f"mean {mean:.6g} differs from {exp.value:.6g} by {diff / exp.value:+.3%} "
                     f"(tolerance ±{tol / abs(exp.value):.3%}, z = {row['z']:+.1f})")


def _check_linearity(row: dict, image: np.ndarray, base: np.ndarray, scale: float, fails: list[str]) -> None:
    """Linearity in the emitted radiance: ``image`` against the same seed's unscaled render ``base``."""
    scaled_mean = float(np.asarray(image, np.float64).mean())
    rel = scaled_mean / (scale * float(np.asarray(base, np.float64).mean())) - 1.0
    row["linearity_rel_error"] = rel
    ok = bool(abs(rel) <= LINEARITY_TOLERANCE)
    row["linearity_check"] = "pass" if ok else "fail"
    if not ok:
        fails.append(f"image mean / (scale × same-seed unscaled mean) - 1 = {rel:+.2e} "
                     f"(tolerance ±{LINEARITY_TOLERANCE:g})")


def _run_se(image, variance, sel: np.ndarray, exp: Expectation, spp: int) -> float | None:
    """Standard error of a render's region mean: pixel spread, its own variance, or the reference model."""
    n = int(sel.sum())
    if n == 0:
        return None
    if exp.pixel_spread:
        if n < 2:
            return None
        pix = np.asarray(image, np.float64).mean(axis=-1)[sel]
        return float(pix.std(ddof=1) / math.sqrt(n))
    if variance is not None and np.shape(variance) == np.shape(image) and np.all(np.isfinite(variance)):
        return float(np.sqrt(pixel_var(variance)[sel].sum()) / n)
    if exp.model_se_1spp is not None:
        # Under the reference noise model a render's variance falls as 1/spp.
        return exp.model_se_1spp / math.sqrt(spp)
    return None


def fmt_value(x, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    return f"{x:.{digits}g}"


def _checks_text(row: dict) -> str:
    """One line with every check of a row, its bound or tolerance and its outcome."""
    parts = []
    if row.get("time_s") is not None:
        parts.append(f"time {row['time_s']:.1f} s ≤ {row['time_bound_s']:g} s: {row['time_check']}")
    if row.get("peak_rss_mb") is not None:
        parts.append(f"peak RSS {row['peak_rss_mb']:.0f} MB ≤ {row['rss_bound_mb']:.0f} MB: {row['rss_check']}")
    if row.get("nan_count") is not None:
        parts.append(f"NaN/Inf/negative pixels {row['nan_count']}/{row['inf_count']}/{row['negative_count']} "
                     f"= 0: {row['finite_check']}")
    else:
        parts.append(f"finite: {row['finite_check']}")
    if row.get("tolerance") is not None:
        parts.append(f"mean {fmt_value(row['mean'], 6)} vs {fmt_value(row['expected'], 6)} "
                     f"± {fmt_value(row['tolerance'], 3)} (z {row['z']:+.2f}): {row['mean_check']}")
    else:
        parts.append(f"mean: {row['mean_check']}")
    if row.get("linearity_check") and not row["linearity_check"].startswith("n/a"):
        rel = row.get("linearity_rel_error")
        parts.append(f"linearity {'-' if rel is None else f'{rel:+.1e}'} within ±{LINEARITY_TOLERANCE:g}: "
                     f"{row['linearity_check']}")
    return " · ".join(parts)

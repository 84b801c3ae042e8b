"""The gate's variance check and outlier test (issue 9): what they catch, and the whole gate's false alarms.

Run (13 minutes on the shared 2-core machine, most of it the 20 clean runs of the whole gate)::

    .venv/bin/python -m benchmarks.gate_checks --seeds 20 --markdown docs/gate-detection.md

(1) Variance check: ``LyingVariance`` (``tests/user_renderers.py``: the
    reference plus noise of the reference's own model, 1% too dark, reporting
    F times its variance) on ``cornell-box`` at 256 spp, F = 100, 10 and 2,
    over ``--seeds`` seeds: how often the variance check fails it, its ŝ, and
    how often the agreement test alone would.
(2) Outlier test: ``HotPixel`` (the same noise, one pixel ×2 in every
    channel) on ``cornell-box`` at 256 spp at a few pixels (bright walls,
    edges, dark ones), over ``--seeds`` seeds: how often the outlier test
    fails it (and at that pixel), against the pixel's expected z, and how
    often the tiled agreement test would.
(3) False alarms of the whole gate: every expectation of ``gate.toml``, every
    check, at seed offsets 0 .. seeds-1 (baseline checks at offset 0 only,
    as :func:`cornell_harness.gate.run.run_gate` does), with the margins of the new
    checks on correct renderers (ŝ against its tolerance, the largest
    pixel |z| against the outlier threshold).
(4) The spread ŝ of our path tracer's z at 8-64 spp (256 comes from (3)),
    which sets the variance check's tolerance.
(5) ``--budgets-only``: the clean runs of (3) for the budget expectations
    alone (those without ``unbiased``: budgets, slopes, consistency), their
    ``bias_limit`` left out (``benchmarks/biased_gate.py`` counts its false
    alarms over disjoint seed sets), written to the block
    ``gate_checks.py#budgets``; the whole gate's 20 runs take two hours since
    the bias limits (issue 29), these about half an hour::

        .venv/bin/python -m benchmarks.gate_checks --seeds 20 --budgets-only --markdown docs/gate-detection.md

Tests (1)-(2) and (4) call ``runner.run_one`` and ``cornell_harness.gate.checks.evaluate``
directly (``run_gate`` minus the image metrics, which these checks do not
use); (3) is ``run_gate`` itself, in this process (``sandbox=False``: the
same images as the CLI's child processes). With ``--markdown``, the file
keeps everything outside the generated block ``gate_checks.py`` (between its
markers; ``benchmarks/markdown_blocks.py``); a file without it gets the block
appended.
"""

from __future__ import annotations

import argparse
import dataclasses
import platform
import sys
import time
from collections import defaultdict
from datetime import date
from pathlib import Path

import numpy as np
from scipy.stats import binom

from benchmarks import markdown_blocks
from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate import outliers, variance_check
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.gate.checks import STATISTICAL_TESTS, evaluate, statistical_alpha
from cornell_harness.gate.config import Expectation, load_config
from cornell_harness.gate.run import run_gate
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows import runner

ROOT = Path(__file__).resolve().parent.parent

BLOCK = "gate_checks.py"  # the block of docs/gate-detection.md this writes (benchmarks/markdown_blocks.py)
BUDGETS_BLOCK = "gate_checks.py#budgets"  # the block --budgets-only writes
GATE = ROOT / "gate.toml"
SPP = 256
FACTORS = (100.0, 10.0, 2.0)
#: (label, x, y): hot pixels on cornell-box, from the brightest walls to the darkest floor.
PIXELS = (("red wall", 20, 128), ("green wall", 236, 128), ("back wall", 128, 128),
          ("edge of the tall box", 69, 150), ("top edge of the short box", 160, 172),
          ("dark: the short box's front face", 150, 200), ("darkest: floor in the short box's shadow", 170, 240))
LOW_SPP = (8, 16, 32, 64)


def _expectation(renderer: str, settings: dict, seed: int, scene: str = "cornell-box", spp: int = SPP):
    return Expectation(name=f"{renderer}@{seed}", scene=scene, renderer=renderer, spp=spp, seed=seed, unbiased=True,
                       tile=16, settings=settings)


def _run(cfg, exp: Expectation):
    """One expectation as run_gate runs it, without the image metrics: (record, outcome)."""
    scene = resolve_scene(exp.scene)
    entry = resolve([exp.renderer])[0]
    entry = entry.with_settings(exp.settings) if exp.settings else entry
    rec = runner.run_one(entry, scene, exp.spp, exp.seed, None)
    return rec, evaluate(exp, rec, load_reference(scene), cfg, masks=region_masks(scene))  # regions: agreement tests


def _check(outcome, name):
    return next(c for c in outcome.checks if c.name == name)


def variance_part(cfg, seeds: int) -> list[str]:
    share = statistical_alpha(cfg.alpha)
    lo, hi = variance_check.spread_bounds(variance_check.TOLERANCE, SPP)
    out = [f"**Variance check** (`LyingVariance`: cornell-box at {SPP} spp, 1% too dark, reporting F × its "
           f"variance; {seeds} seeds; tolerance on ŝ [{lo:.3f}, {hi:.3f}], α = {share:.3g}):", "",
           "| F | variance check fails | ŝ (min-max) | 1/ŝ² (mean) | agreement fails | expectation fails |",
           "|---|---|---|---|---|---|"]
    for f in FACTORS:
        fails = agr = whole = 0
        scales = []
        for s in range(seeds):
            _, o = _run(cfg, _expectation("tests.user_renderers:LyingVariance", {"variance_factor": f}, s))
            v = _check(o, "variance")
            fails += not v.passed
            agr += not _check(o, "agreement").passed
            whole += not o.passed
            scales.append(v.value)
        out.append(f"| {f:g} | **{fails} of {seeds}** | {min(scales):.3f}-{max(scales):.3f} | "
                   f"{np.mean([1 / x**2 for x in scales]):.3g} | {agr} of {seeds} | {whole} of {seeds} |")
    return out


def outlier_part(cfg, seeds: int) -> list[str]:
    share = statistical_alpha(cfg.alpha)
    ref = load_reference(resolve_scene("cornell-box"))
    r, v = ref.image.astype(np.float64), ref.variance.astype(np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        z0 = np.median(np.where(v > 0, r / np.sqrt(v * ref.spp / SPP + v), 0.0), axis=-1)  # a ×2 pixel's z
    thr = outliers.calibrate(r, v, ref.noise, ref.spp, ref.noise_spp, SPP, share)
    out = [f"**Outlier test** (`HotPixel`: cornell-box at {SPP} spp, one pixel ×2 in every channel; {seeds} seeds; "
           f"threshold |z| > {thr.value:.2f}, {thr.describe()}; α = {share:.3g}):", "",
           "| pixel (x, y) | radiance (R, G, B) | expected z of the ×2 pixel | outlier test fails there | "
           "agreement fails | expectation fails |", "|---|---|---|---|---|---|"]
    lit = r.sum(axis=-1) > 0
    detectable = float(np.mean(z0[lit] > thr.value))
    out[0] = out[0][:-2] + (f"; a ×2 pixel's expected z exceeds the threshold on {detectable:.0%} of the image's "
                            f"{int(lit.sum())} non-black pixels):")
    for label, x, y in PIXELS:
        found = agr = whole = 0
        for s in range(seeds):
            _, o = _run(cfg, _expectation("tests.user_renderers:HotPixel", {"x": x, "y": y, "factor": 2.0}, s))
            c = _check(o, "outliers")
            found += (not c.passed) and f"pixel x {x}, y {y}," in c.message
            agr += not _check(o, "agreement").passed
            whole += not o.passed
        rgb = ", ".join(f"{c:.3f}" for c in r[y, x])
        out.append(f"| {label} ({x}, {y}) | {rgb} | {z0[y, x]:.1f} | **{found} of {seeds}** | {agr} of {seeds} | "
                   f"{whole} of {seeds} |")
    return out


def low_spp_part(cfg) -> list[str]:
    out = ["**Spread of our path tracer's z against spp** (seed 0; the variance check's tolerance is "
           "[1/(1+δ), 1 + δ + 1/√spp], δ = 0.1):", "",
           "| scene | " + " | ".join(f"{n} spp" for n in LOW_SPP) + " |", "|---|" + "---|" * len(LOW_SPP)]
    for scene in ("cornell-box", "furnace", "light-panel"):
        cells = []
        for n in LOW_SPP:
            _, o = _run(cfg, _expectation("pathtracer", {}, 0, scene, n))
            c = _check(o, "variance")
            lo, hi = variance_check.spread_bounds(variance_check.TOLERANCE, n)
            cells.append(f"{c.value:.3f} in [{lo:.3f}, {hi:.3f}]{'' if c.passed else ' **FAIL**'}")
        out.append(f"| {scene} | " + " | ".join(cells) + " |")
    return out


def clean_part(seeds: int) -> tuple[list[str], list[float]]:
    cfg = load_config(GATE)
    share = statistical_alpha(cfg.alpha)
    fails = defaultdict(list)  # expectation -> [(offset, check, message)]
    runs_failed = 0
    scale = defaultdict(list)  # expectation -> ŝ over seeds
    ratio = defaultdict(list)  # expectation -> worst |z| / threshold over seeds
    wall = []
    for off in range(seeds):
        t0 = time.perf_counter()
        outcomes = run_gate(cfg, seed_offset=off, sandbox=False)
        wall.append(time.perf_counter() - t0)
        bad = False
        for o in outcomes:
            name = o.expectation.name
            for c in o.checks:
                if not c.passed:
                    fails[name].append((off, c.name, c.message))
                    bad = True
                if c.name == "variance" and c.value is not None:
                    scale[name].append(c.value)
                if c.name == "outliers":
                    ratio[name].append(c.value / c.limit)
        runs_failed += bad
        print(f"  clean gate run, seed offset {off}: {'FAIL' if bad else 'pass'} ({wall[-1]:.0f} s)", file=sys.stderr)
    unbiased = [e for e in cfg.expectations if e.unbiased]
    per_run = 1 - (1 - cfg.alpha) ** len(unbiased)
    out = [f"**False alarms of the whole gate** (`gate.toml`: all {len(cfg.expectations)} expectations, all checks; "
           f"seed offsets 0-{seeds - 1}; baseline checks at offset 0 only): **{runs_failed} of {seeds} gate runs "
           f"failed**. Stated rate: α = {cfg.alpha:g} per unbiased expectation (its {', '.join(STATISTICAL_TESTS)} "
           f"tests at {share:.3g} each), so at most 1 − (1 − α)^{len(unbiased)} = {per_run:.4f} per gate run from "
           f"the statistical tests, {seeds * per_run:.2f} expected in {seeds} runs"
           + (f" (P(≥ {runs_failed}) = {binom.sf(runs_failed - 1, seeds, per_run):.2g})" if runs_failed else
              f" (P(0) = {binom.pmf(0, seeds, per_run):.2f})")
           + "; budget expectations have no stated rate.", "",
           "| expectation | runs failed | failing checks | ŝ of the variance check (min-max) | "
           "largest pixel \\|z\\| / outlier threshold (max) |", "|---|---|---|---|---|"]
    for e in cfg.expectations:
        f = fails.get(e.name, [])
        offs = sorted({off for off, _, _ in f})
        checks = "; ".join(f"offset {off}: {c}" for off, c, _ in f) or "none"
        sc = (f"{min(scale[e.name]):.3f}-{max(scale[e.name]):.3f}" if scale[e.name] else
              ("skipped (no variance reported)" if e.unbiased else "-"))
        rt = f"{max(ratio[e.name]):.2f}" if ratio[e.name] else "-"
        out.append(f"| {e.name} | {len(offs)} of {seeds} | {checks} | {sc} | {rt} |")
    for e in cfg.expectations:
        for off, c, msg in fails.get(e.name, []):
            out.append(f"- {e.name}, offset {off}, `{c}`: {msg}")
    return out, wall


def budgets_part(seeds: int) -> list[str]:
    """(5): every budget expectation (no ``unbiased``), its bias limit left out, at seed offsets 0 .. seeds-1."""
    cfg = load_config(GATE)
    chosen = [dataclasses.replace(e, bias_limit=None) for e in cfg.expectations if not e.unbiased]
    cfg = dataclasses.replace(cfg, expectations=chosen)
    fails, worst, wall = defaultdict(list), defaultdict(dict), []
    for off in range(seeds):
        t0 = time.perf_counter()
        outcomes = run_gate(cfg, seed_offset=off, sandbox=False)
        wall.append(time.perf_counter() - t0)
        for o in outcomes:
            for c in o.checks:
                if not c.passed:
                    fails[o.expectation.name].append((off, c.name))
                kind = c.name.split(".")[0]
                if kind in ("max", "abs_max", "min") and c.value and c.limit:  # the share of its budget used
                    use = abs(c.value) / abs(c.limit) if kind != "min" else abs(c.limit) / abs(c.value)
                    worst[o.expectation.name][c.name] = max(use, worst[o.expectation.name].get(c.name, 0.0))
        print(f"  budget expectations, seed offset {off}: {sum(len(v) for v in fails.values())} failures so far "
              f"({wall[-1]:.0f} s)", file=sys.stderr)
    out = [f"**Clean runs of the budget expectations** (`gate.toml`: the {len(chosen)} without `unbiased`, every "
           f"check but the bias limit, which `biased_gate.py` counts; seed offsets 0-{seeds - 1}; baseline checks "
           f"at offset 0 only). Budgets have no stated false-alarm rate: the column *most used* is the largest "
           f"share of its budget a budget check used over the seeds (|value| / |limit|; limit / value for a "
           f"`min`).", "",
           "| expectation | runs failed | failing checks | most used (check: share) |", "|---|---|---|---|"]
    for e in chosen:
        f = fails.get(e.name, [])
        top = sorted(worst[e.name].items(), key=lambda kv: -kv[1])[:2]
        out.append(f"| {e.name} | {len({off for off, _ in f})} of {seeds} | "
                   f"{'; '.join(f'offset {off}: {c}' for off, c in f) or 'none'} | "
                   f"{', '.join(f'{c}: {v:.2f}' for c, v in top) or '-'} |")
    out += ["", f"Time per run of these expectations: median {np.median(wall):.0f} s, max {max(wall):.0f} s."]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--markdown", type=Path, help="write the results into this file (between the markers)")
    ap.add_argument("--skip-clean", action="store_true", help="leave out (3), the clean gate runs (slow)")
    ap.add_argument("--budgets-only", action="store_true",
                    help="only (5): the budget expectations' clean runs, into the block gate_checks.py#budgets")
    args = ap.parse_args(argv)
    if args.budgets_only:
        t0 = time.perf_counter()
        lines = [f"Measured {date.today().isoformat()} on {platform.machine()}.", ""] + budgets_part(args.seeds)
        lines += ["", f"Command: `.venv/bin/python -m benchmarks.gate_checks --seeds {args.seeds} --budgets-only "
                      f"--markdown docs/gate-detection.md` ({(time.perf_counter() - t0) / 60:.0f} min)."]
        print("\n".join(lines), flush=True)
        if args.markdown:
            markdown_blocks.write_blocks([args.markdown], {BUDGETS_BLOCK: "\n".join(lines)})
        return 0
    cfg = dataclasses.replace(load_config(GATE), baseline=None)
    t0 = time.perf_counter()
    lines = [f"Measured {date.today().isoformat()} on {platform.machine()}, α = {cfg.alpha:g} per expectation "
             f"(`gate.toml`).", ""]
    lines += variance_part(cfg, args.seeds) + [""]
    print("\n".join(lines), flush=True)
    part = outlier_part(cfg, args.seeds) + [""]
    print("\n".join(part), flush=True)
    lines += part
    part = low_spp_part(cfg) + [""]
    print("\n".join(part), flush=True)
    lines += part
    if not args.skip_clean:
        part, wall = clean_part(args.seeds)
        part += ["", f"Time per whole gate run: median {np.median(wall):.0f} s, max {max(wall):.0f} s."]
        print("\n".join(part), flush=True)
        lines += part
    lines += ["", f"Command: `.venv/bin/python -m benchmarks.gate_checks --seeds {args.seeds} --markdown "
                  f"docs/gate-detection.md` ({(time.perf_counter() - t0) / 60:.0f} min)."]
    if args.markdown:
        markdown_blocks.write_blocks([args.markdown], {BLOCK: "\n".join(lines)})
    return 0


if __name__ == "__main__":
    sys.exit(main())

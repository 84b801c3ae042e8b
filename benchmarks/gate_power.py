"""The CI gate's power and false-alarm rate on our path tracer, in one run.

Everything runs the ``pathtracer`` expectations of ``gate.toml`` (their
scenes, spp, seeds, tiles, α and baseline; the other renderers' expectations
are left out) through :func:`cornell_harness.gate.run.run_gate`.

(1) False alarms: the unmutated path tracer, with ``--seeds`` seed offsets
    (0, 1, ...). A gate run has several expectations, each a family-wise
    α-level test, so a run is a false alarm with probability at most
    1 - (1 - α)^E for E expectations; the count over seeds is binomial.
(2) Power: every mutant of ``tests/mutants/`` (a realistic bug patched into
    a copy of ``src/cornell_harness/renderers/pathtracer.py``) at the gate's seeds, which must
    fail. For each: detected or not, the failing checks, the smallest
    p-value or the margin, and where.
(3) Effect size, with common random numbers: a mutant and the unmutated
    render at the same seed draw the same random numbers, so their difference
    is the bug's bias with little noise. Divided by the noise the gate assumes
    (the render's variance at the CI budget plus the reference's) it gives the
    mutant's expected |z| on its most affected test, the gate's power at the
    CI budget over fresh seeds (not only the gate's own), and the budget
    multiple at which the power reaches 99% ("never" when the reference's own
    noise hides the bias at any spp).

Run (about 8 minutes on an idle 2-core machine)::

    .venv/bin/python -m benchmarks.gate_power --seeds 20 --markdown docs/gate-detection.md

With ``--markdown``, the file keeps everything outside the generated block
``gate_power.py`` (between its markers; ``benchmarks/markdown_blocks.py``).
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import sys
import tempfile
import time
from dataclasses import dataclass
from datetime import date
from pathlib import Path

import numpy as np
from scipy.stats import binom, norm

from benchmarks import markdown_blocks
from tests import mutants
from cornell_harness.evaluate.agreement import region_sums, tile_sums
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.evaluate.registry import HIGHER_IS_BETTER
from cornell_harness.gate.run import load_baseline, run_gate
from cornell_harness.store.references import load_reference
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.adapters.api import default_threads

ROOT = Path(__file__).resolve().parent.parent

POWER = 0.99
#: The checks with a stated false-alarm rate: agreement, variance and outliers share the expectation's alpha.
STATISTICAL = {"agreement", "variance", "outliers", "finite"}
HANG_TIMEOUT_S = 120  # ~10 gate runs: a mutant of mutants.ISOLATED that has not ended by then never will
MULTIPLES = [2.0 ** k for k in range(-8, 17)]  # budget multiples searched for 99% power

BLOCK = "gate_power.py"  # the block of docs/gate-detection.md this writes (benchmarks/markdown_blocks.py)


@dataclass
class Tests:
    """One expectation's agreement tests for a mutant: bias d, render variance and reference variance per test."""

    d: np.ndarray
    v_img: np.ndarray
    v_ref: np.ndarray
    r_sum: np.ndarray
    names: list[str]


def _tests(label: str, mut_image, clean_image, clean_var, ref, tile: int, masks: dict) -> Tests:
    """The agreement test's tests (tiles, the scene's named regions, the whole image; its order of names)."""
    mut = np.where(np.isfinite(mut_image), mut_image, 0.0).astype(np.float64)  # as the gate cleans it
    diff = mut - clean_image.astype(np.float64)
    vi, vr, r = clean_var.astype(np.float64), ref.variance.astype(np.float64), ref.image.astype(np.float64)
    regions = list(region_sums(diff, masks))  # the non-empty ones

    def flat(a):
        sums = region_sums(a, masks)
        return np.concatenate([tile_sums(a, tile).ravel(), *(sums[n] for n in regions), a.sum(axis=(0, 1))])

    h, w, _ = diff.shape
    rows, cols = -(-h // tile), -(-w // tile)
    names = [f"{label}: pixels x {c * tile}-{min(c * tile + tile, w) - 1}, "
             f"y {r_ * tile}-{min(r_ * tile + tile, h) - 1}, channel {ch}"
             for r_ in range(rows) for c in range(cols) for ch in "RGB"]
    names += [f"{label}: region {n} ({int(np.count_nonzero(masks[n]))} pixels), channel {ch}"
              for n in regions for ch in "RGB"]
    names += [f"{label}: whole image, channel {ch}" for ch in "RGB"]
    return Tests(flat(diff), flat(vi), flat(vr), flat(r), names)


def _mu(d: np.ndarray, var: np.ndarray) -> np.ndarray:
    """|d|/√var; 0 where both are 0, inf where only the variance is (as cornell_harness.evaluate.agreement does)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        mu = np.abs(d) / np.sqrt(var)
    mu[(var <= 0) & (d == 0)] = 0.0
    return mu


def _power(t: Tests, z_crit: float, multiple: float) -> float:
    """P(at least one test rejects) at ``multiple`` × the budget: test i is N(d_i / sd_i, 1)."""
    mu = _mu(t.d, t.v_img / multiple + t.v_ref if math.isfinite(multiple) else t.v_ref)
    p = norm.sf(z_crit - mu) + norm.cdf(-z_crit - mu)
    return float(1.0 - np.prod(1.0 - p))


@dataclass
class Effect:
    z_expected: float  # |bias| / noise on the most affected test at the CI budget
    where: str  # that test
    rel: float  # its relative change of the tile (or image) mean
    power: float  # P(the gate's agreement tests fail) at the CI budget over fresh seeds, from the bias alone
    multiple_99: float | None  # smallest budget multiple (power of 2) with power >= POWER; None: unreachable
    nonfinite: int  # NaN/Inf pixels in the mutant's images: the finite check fails whatever the bias


def effect(tests: list[Tests], z_crit: float, nonfinite: int) -> Effect:
    """Expected z, power and budget for 99% power of a mutant over all expectations (module docstring, (3))."""
    z = [_mu(t.d, t.v_img + t.v_ref) for t in tests]
    e = int(np.argmax([zi.max() for zi in z]))
    k = int(np.argmax(z[e]))
    t = tests[e]

    def family(m):
        return 1.0 - math.prod(1.0 - _power(x, z_crit, m) for x in tests)

    multiple = None
    if family(math.inf) >= POWER:
        multiple = next((m for m in MULTIPLES if family(m) >= POWER), None)
    rel = float(t.d[k] / t.r_sum[k]) if t.r_sum[k] != 0 else math.nan  # nan: the reference is 0 there
    return Effect(float(z[e][k]), t.names[k], rel, family(1.0), multiple, nonfinite)


def _cell(s: str) -> str:
    return s.replace("|", "\\|").replace("\n", " ")


def _multiple(m: float | None, spp: dict) -> str:
    """A budget multiple as spp (one figure per distinct budget of the expectations)."""
    if m is None:
        return "never (reference noise)"
    floor = "≤ " if m == MULTIPLES[0] else ""
    return ", ".join(f"{floor}{max(1, round(s * m))} spp" for s in dict.fromkeys(spp.values()))


def _rel(rel: float) -> str:
    return "reference 0 there" if math.isnan(rel) else f"{rel:+.2%}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=20, help="seed offsets for the unmutated path tracer (default 20)")
    ap.add_argument("--mutant", action="append", help="only these mutants (repeatable; default: all)")
    ap.add_argument("--gate", default=str(mutants.GATE_TOML), help="gate config (default: gate.toml)")
    ap.add_argument("--work", help="folder for the mutants' modules (default: a fresh temporary folder)")
    ap.add_argument("--markdown", help="write the detection table and false-alarm line to this file")
    args = ap.parse_args(argv)
    if args.seeds < 1:
        ap.error("--seeds must be >= 1 (seed offset 0 is the baseline of the effect sizes)")

    cfg = mutants.pathtracer_gate_config(args.gate)
    exps = cfg.expectations
    refs = {e.name: load_reference(resolve_scene(e.scene)) for e in exps}
    masks = {e.name: region_masks(resolve_scene(e.scene)) for e in exps}  # each region is an agreement test
    spp = {e.name: e.spp for e in exps}
    work = Path(args.work) if args.work else Path(tempfile.mkdtemp(prefix="cbox-mutants-"))
    names = args.mutant or [m.name for m in mutants.MUTANTS]
    budget = "; ".join(f"{mutants.label(e)} (seed {e.seed}, tile {e.tile})" for e in exps)
    print(f"gate {args.gate}: {budget}; alpha {cfg.alpha}, baseline {cfg.baseline.name if cfg.baseline else None}; "
          f"{default_threads()} threads", flush=True)

    # (1) false alarms; seed offset 0 is also the common-random-numbers baseline of (3)
    alarms, wall, render, clean_p, clean0, clean_z = [], [], [], [], {}, {e.name: [] for e in exps}
    alarms_by_exp = {e.name: 0 for e in exps}  # runs where a STATISTICAL check failed
    # The gate compares with its baseline at the recorded seed only; what a margin would say at other seeds
    # (a renderer change that alters its random numbers is a new seed to it) is computed here.
    base_change = {}  # (expectation, metric) -> relative changes against the baseline, one per seed
    baseline = load_baseline(cfg)
    base_exceed = [False] * args.seeds  # runs where some metric is worse than its baseline by more than the margin
    for off in range(args.seeds):
        t0 = time.perf_counter()
        outcomes = run_gate(cfg, seed_offset=off, sandbox=False)  # same images as the CLI's child process
        v = mutants.verdict(outcomes)
        wall.append(time.perf_counter() - t0)
        render.append(v.time_s)
        clean_p.append(v.p_min)
        for o in outcomes:
            if off == 0:
                clean0[o.expectation.name] = o.record
            if o.agreement is not None:
                z = o.agreement.z_tiles.ravel()
                clean_z[o.expectation.name].append(z[z != 0.0])  # 0: a noise-free tile (both images 0)
            stat = [c for c in o.checks if not c.passed and c.name in STATISTICAL]
            alarms_by_exp[o.expectation.name] += bool(stat)
            for metric, b in baseline.get("expectations", {}).get(o.expectation.name, {}).items():
                if off > 0 and metric in cfg.regression_metrics and b and metric in o.record.metrics:
                    change = (float(o.record.metrics[metric]) - b) / abs(b)
                    base_change.setdefault((o.expectation.name, metric), []).append(change)
                    worse = -change if metric in HIGHER_IS_BETTER else change
                    base_exceed[off] |= worse > cfg.regression_margin
        if v.checks & STATISTICAL:
            alarms.append((off, v))
        print(f"unmutated seed offset {off:3d}: {'pass' if v.passed else 'FAIL ' + ', '.join(v.failing)} "
              f"p_min={v.p_min:.3g} (level {v.level:.2g}) {v.where} | gate {wall[-1]:.1f}s", flush=True)
    levels = {o.expectation.name: o.agreement.level for o in outcomes if o.agreement is not None}

    # (2) power, (3) effect size
    rows, overhead = [], []
    for name in names:
        if name in mutants.ISOLATED:  # in a child process, killed after HANG_TIMEOUT_S
            t0 = time.perf_counter()
            v = mutants.run_isolated(name, work, HANG_TIMEOUT_S, args.gate)
            print(f"{name:24s} " + (f"gate run did not end in {HANG_TIMEOUT_S} s (killed)" if v is None else
                                    f"{'DETECTED' if not v.passed else 'missed  '} [{', '.join(v.failing)}] "
                                    f"{v.evidence} | {v.where}") + f" | {time.perf_counter() - t0:.1f}s", flush=True)
            rows.append((mutants.BY_NAME[name], v, None))
            continue
        t0 = time.perf_counter()
        outcomes = run_gate(cfg, overrides={"pathtracer": mutants.load_mutant(name, work)})
        wall.append(time.perf_counter() - t0)
        v = mutants.verdict(outcomes)
        render.append(v.time_s)
        overhead.append(wall[-1] - v.time_s)  # mutant compile + scene set-up + checks
        tests, nonfinite = [], 0
        for o in outcomes:
            n = o.expectation.name
            if o.record.image is None or n not in levels:
                continue
            nonfinite += int((~np.all(np.isfinite(o.record.image), axis=-1)).sum())
            tests.append(_tests(mutants.label(o.expectation), o.record.image, clean0[n].image, clean0[n].variance,
                                refs[n], o.expectation.tile, masks[n]))
        z_crit = float(norm.isf(min(levels.values()) / 2))  # per-test levels differ a little between scenes
        e = effect(tests, z_crit, nonfinite)
        rows.append((mutants.BY_NAME[name], v, e))
        print(f"{name:24s} {'DETECTED' if not v.passed else 'missed  '} [{', '.join(v.failing)}] "
              f"p_min={v.p_min:.3g} {v.evidence} | {v.where} | effect {e.z_expected:.3g} sd at {e.where} "
              f"({_rel(e.rel)}), power {e.power:.3f}, 99% at {_multiple(e.multiple_99, spp)} | gate {wall[-1]:.1f}s",
              flush=True)

    detected = sum(v is not None and not v.passed for _, v, _ in rows)
    k, n = len(alarms), args.seeds
    alpha_run = 1.0 - (1.0 - cfg.alpha) ** len(levels)
    p_tail = float(binom.sf(k - 1, n, alpha_run)) if k else 1.0
    timing = (f"median {statistics.median(wall):.1f} s, max {max(wall):.1f} s (renders alone: median "
              f"{statistics.median(render):.1f} s, max {max(render):.1f} s)")
    calib = []
    for name_, zs in clean_z.items():
        if zs:
            z = np.concatenate(zs)
            calib.append(f"{mutants.label(next(e for e in exps if e.name == name_))}: {z.size} noisy tile z-scores, "
                         f"mean {z.mean():+.3f}, sd {z.std():.3f}, {np.mean(np.abs(z) > 2.5758):.2%} beyond ±2.576")
    calib_text = "; ".join(calib) + " (N(0, 1) if the noise model holds: sd 1, 1% beyond ±2.576)"
    per_exp = ", ".join(f"{mutants.label(e)} {alarms_by_exp[e.name]}" for e in exps)
    false_line = (f"false alarms of the statistical checks ({', '.join(sorted(STATISTICAL))}): {k} of {n} seeds (gate "
                  f"runs; expected {n * alpha_run:.2g}: α = {cfg.alpha:g} for each of {len(levels)} expectations, "
                  f"shared by its agreement, variance and outlier tests, {alpha_run:.3g} per run; "
                  f"P(≥ {k}) = {p_tail:.3g}); per "
                  f"expectation: {per_exp} of {n} (expected {n * cfg.alpha:.2g} each)")
    base_parts = []
    for (name_, metric), changes in base_change.items():
        ch = np.array(changes)
        worse = -ch if metric in HIGHER_IS_BETTER else ch
        base_parts.append(f"{mutants.label(next(e for e in exps if e.name == name_))} {metric}: "
                          f"{int((worse > cfg.regression_margin).sum())} of {n - 1}, change {ch.mean():+.1%} ± "
                          f"{ch.std(ddof=1) if ch.size > 1 else 0:.1%}")
    base_line = (f"baseline margins across seeds: the gate compares with its baseline only at the recorded seed "
                 f"(offset 0), where the clean runs match it exactly; at the other seeds (what any change of the "
                 f"renderer's random numbers amounts to) {sum(base_exceed)} of {n - 1} clean runs have some metric worse "
                 f"than its baseline by more than the {cfg.regression_margin:.0%} margin. Per metric, runs over the "
                 f"margin and relative change against the baseline (mean ± sd over seeds): " + "; ".join(base_parts))
    print(f"\ndetected {detected} of {len(rows)} mutants")
    print(false_line)
    print(base_line)
    print(f"gate run (render + checks): {timing}")
    print(f"calibration: {calib_text}")

    if args.markdown:
        cmd = ".venv/bin/python -m benchmarks.gate_power " + " ".join(argv if argv is not None else sys.argv[1:])
        lines = ["| bug | description | detected | failing checks | p-value or margin | where | "
                 "effect (expected \\|z\\|, CRN) | power at budget | budget for 99% power |",
                 "|---|---|---|---|---|---|---|---|---|"]
        for m, v, e in rows:
            if v is None:
                lines.append(f"| `{m.name}` | {_cell(m.description)} | **NO: the gate run never ends** (killed "
                             f"after {HANG_TIMEOUT_S} s) | — | — | — | — | — | — |")
                continue
            if e is None:  # run in a child process (mutants.ISOLATED): verdict only
                lines.append(f"| `{m.name}` | {_cell(m.description)} | {'**yes**' if not v.passed else '**NO**'} | "
                             f"{_cell(', '.join(v.failing)) or '—'} | {_cell(v.evidence) or '—'} | "
                             f"{_cell(v.where) or '—'} | — | — | — |")
                continue
            power, spp99 = f"{e.power:.3f}", _multiple(e.multiple_99, spp)
            if e.nonfinite:  # the finite check fails at any spp and seed
                power = f"1 (finite check; agreement alone {e.power:.3f})"
                spp99 = f"≤ the budget (agreement alone: {spp99})"
            lines.append(
                f"| `{m.name}` | {_cell(m.description)} | {'**yes**' if not v.passed else '**NO**'} | "
                f"{_cell(', '.join(v.failing)) or '—'} | "
                f"{_cell(v.evidence) or f'none; smallest p = {v.p_min:.3g}'} | "
                f"{_cell(v.where) or '—'} | {e.z_expected:.3g} ({_cell(e.where)}: {_rel(e.rel)}) | {power} | "
                f"{spp99} |")
        alarm_text = "; ".join(f"seed offset {s}: {', '.join(v.failing)} ({_cell(v.where)})" for s, v in alarms)
        body = [
            f"Gate: `{Path(args.gate).name}`, its `pathtracer` expectations: "
            + "; ".join(f"**{mutants.label(e)}** (seed {e.seed}, tile {e.tile}, {levels.get(e.name, math.nan):.2g} "
                        f"per test)" for e in exps)
            + f"; family-wise α = {cfg.alpha:g} per expectation, baseline "
            f"`{cfg.baseline.name if cfg.baseline else '—'}` (margin {cfg.regression_margin:.0%}). "
            f"{default_threads()} threads, {platform.machine()}, {date.today().isoformat()}.",
            "",
            f"**Detected: {detected} of {len(rows)} mutants** at the gate's seeds.",
            "",
            *lines,
            "",
            f"**F{false_line[1:]}**" + (f": {alarm_text}." if alarms else ".")
            + f" Smallest agreement p-value over the {n} clean runs: {min(clean_p):.3g}.",
            "",
            f"**B{base_line[1:]}.**",
            ""
            f"Calibration of the clean runs: {calib_text}.",
            "",
            f"Time per gate run (the {len(exps)} pathtracer expectations, render + checks, {len(wall)} runs): "
            f"{timing}; a mutant's run also imports and compiles its module (gate wall time minus render time: "
            f"median {statistics.median(overhead) if overhead else math.nan:.1f} s).",
            "",
            f"Command: `{cmd}`",
            "",
        ]
        markdown_blocks.write_blocks([Path(args.markdown)], {BLOCK: "\n".join(body)}, cmd)
        print(f"wrote {args.markdown}")
    return 0 if detected == len(rows) and p_tail > 1e-3 else 1


if __name__ == "__main__":
    sys.exit(main())

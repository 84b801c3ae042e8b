"""The gate's bias limit on the photon mappers (issue 29): false alarms of the clean renderers, power against bias.

Run (collection cached in ``--cache``, so a rerun only analyses; 101 minutes of collection on the 2-core
machine beside other jobs, 2026-12-03: 20 clean seed sets, 3 per flux mutant, 1 of no_normal_test)::

    .venv/bin/python -m benchmarks.biased_gate --sets 20 --mutant-sets 3 --other-sets 1 --markdown docs/gate-detection.md

For each of photonmap and sppm, the ``bias_limit`` of its ``cornell-box-caustics`` expectation in
``gate.toml`` (efforts, rate, seeds k, metrics) is evaluated over ``--sets`` disjoint seed sets (set j:
seeds k·j .. k·j + k − 1, what ``run_gate``'s seed offset j gives), on

- the clean renderer: false alarms (a set whose test fails);
- a photon-flux error of every size in :data:`SCALES`: power. A flux scale f multiplies every photon's flux,
  and the image is linear in it (the density estimate is a sum of fluxes, SPPM's τ too; no decision depends
  on a photon's flux), so each seed's error at any f is e(1) + (f − 1)/(f₉₈ − 1)·(e(f₉₈) − e(1)) from the
  clean render and the ``photon_flux_98`` / ``sppm_flux_98`` mutant's (f₉₈ = 1/1.02) at the same seed: exact,
  not a model;
- the renderer's other mutants of :data:`OTHER_MUTANTS`, rendered.

The errors are collected at every effort of :data:`COLLECT` (a superset of gate.toml's), so ``--efforts``
and ``--rate`` can try another design without rendering again.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
from scipy import stats

from benchmarks import markdown_blocks
from cornell_harness.evaluate import bias_extrapolation
from cornell_harness.evaluate.agreement import sidak_level
from cornell_harness.gate.config import load_config
from cornell_harness.gate.consistency import BiasLimit
from cornell_harness.gate.run import GateJob, render_bias_efforts
from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference

ROOT = Path(__file__).resolve().parent.parent
BLOCK = "biased_gate.py"
SCENE = "cornell-box-caustics"
FLUX_MUTANT = {"photonmap": "photon_flux_98", "sppm": "sppm_flux_98"}
OTHER_MUTANTS = {"photonmap": ("no_normal_test",), "sppm": ("sppm_flux_added_after_shrink",)}
F98 = 1 / 1.02
SCALES = (0.995, 0.99, 0.98, 0.97, 0.95, 1.02)
METRICS = ("mean_radiance_rel_error", "region.caustic.mean_radiance_rel_error",
           "region.glass-shadow.mean_radiance_rel_error")
#: The efforts collected per renderer: a superset of gate.toml's.
COLLECT = {"photonmap": (62500, 250000), "sppm": (4, 8, 16, 32)}


def expectation(cfg, renderer: str):
    return next(e for e in cfg.expectations if e.renderer == renderer and e.scene == SCENE and e.bias_limit)


def collect(renderer: str, variant: str, sets: int, k: int, cache: Path, bias: BiasLimit, exp) -> dict:
    """{seed: {metric: [error per collected effort]}} of ``variant`` (clean or a mutant), cached in ``cache``."""
    rows = {}
    if cache.exists():
        for line in cache.read_text().splitlines():
            r = json.loads(line)
            if (r["renderer"], r["variant"]) == (renderer, variant):
                rows[r["seed"]] = r["errors"]
    scene = resolve_scene(SCENE)
    ref = load_reference(scene)
    if variant == "clean":
        entry = resolve([renderer])[0]
    else:
        from tests import mutants
        entry = mutants.load_mutant(variant, Path("/tmp/cbox-biased-gate-mutants"))
    entry = entry.with_settings(exp.settings) if exp.settings else entry
    one = dataclasses.replace(bias, efforts=COLLECT[renderer], seeds=1, metrics=METRICS)
    for seed in range(sets * k):
        if seed in rows:
            continue
        t = time.time()
        job = GateJob(dataclasses.replace(exp, bias_limit=one), entry.spec, dict(entry.settings), None, seed, None)
        errs = render_bias_efforts(job, scene, ref, entry)
        if isinstance(errs, str):
            raise RuntimeError(errs)
        rows[seed] = {m: [float(x) for x in v[0]] for m, v in errs.items()}
        with cache.open("a") as f:
            f.write(json.dumps({"renderer": renderer, "variant": variant, "seed": seed, "errors": rows[seed],
                                "time_s": round(time.time() - t, 2)}) + "\n")
        print(f"{renderer} {variant} seed {seed}: {time.time() - t:.1f} s", file=sys.stderr, flush=True)
    return rows


def errors_at(rows: dict, seeds: list[int], metric: str, cols: list[int]) -> np.ndarray:
    return np.array([[rows[s][metric][c] for c in cols] for s in seeds])


def set_verdicts(rows: dict, bias: BiasLimit, renderer: str, sets: int, alpha: float,
                 scale_rows: tuple[dict, float] | None = None) -> list[tuple[bool, dict]]:
    """Per seed set: (failed, {metric: LimitTest}) of the gate's bias limit on ``rows`` (or on the flux scale f
    made from clean ``rows`` and the flux mutant's rows: ``scale_rows = (mutant_rows, f)``)."""
    cols = [COLLECT[renderer].index(e) for e in bias.efforts]
    level = sidak_level(alpha, len(bias.metrics))
    out = []
    for j in range(sets):
        seeds = bias.seed_list(j)
        tests = {}
        for m in bias.metrics:
            e = errors_at(rows, seeds, m, cols)
            if scale_rows is not None:
                mut, f = scale_rows
                e = e + (f - 1) / (F98 - 1) * (errors_at(mut, seeds, m, cols) - e)
            tests[m] = bias_extrapolation.limit_test(e, bias.efforts, bias.rate, level, bias.tolerance.get(m, 0.0))
        out.append((any(not t.passed for t in tests.values()), tests))
    return out


def _short(m: str) -> str:
    return "image" if m == "mean_radiance_rel_error" else m.split(".")[1]


def limits(rows: dict, bias: BiasLimit, renderer: str, metric: str, scale_rows=None) -> np.ndarray:
    """Every collected seed's limit b∞ of ``metric`` (the flux scale's, with ``scale_rows``)."""
    cols = [COLLECT[renderer].index(e) for e in bias.efforts]
    seeds = sorted(rows) if scale_rows is None else sorted(set(rows) & set(scale_rows[0]))
    e = errors_at(rows, seeds, metric, cols)
    if scale_rows is not None:
        mut, f = scale_rows
        e = e + (f - 1) / (F98 - 1) * (errors_at(mut, seeds, metric, cols) - e)
    return bias_extrapolation.extrapolate(e, bias.efforts, bias.rate)[0]


def power(b: np.ndarray, k: int, level: float, tolerance: float, draws: int = 400_000) -> float:
    """The test's rejection rate for seeds whose limits are normal with the mean and sd of ``b``: the
    noncentral t with k − 1 degrees of freedom beyond the critical value on either side, drawn (scipy's
    noncentral t returns NaN far out)."""
    crit = stats.t.isf(level / 2, k - 1)
    mu, sd = float(np.mean(b)), float(np.std(b, ddof=1))
    rng = np.random.default_rng(0)
    mean = mu + sd / np.sqrt(k) * rng.standard_normal(draws)
    se = sd / np.sqrt(k) * np.sqrt(rng.chisquare(k - 1, draws) / (k - 1))
    return float(np.mean((np.abs(mean) - tolerance) / se > crit))


def report(results: dict, cfg, sets: int, seconds: dict, command: str) -> str:
    lines = [f"Measured {date_now()} on {platform.machine()} ({seconds['total'] / 60:.0f} min of collection on the "
             f"shared 2-core machine, beside other jobs); `{command}`.", "",
             "Per variant: the seed sets it failed (counted), and per metric the per-seed limits b∞ (mean ± sd over "
             "every collected seed) and the rate at which the test fails a set of k such seeds (noncentral t with "
             "their mean and sd, at the metric's Šidák level; the false-alarm rate for the clean renderer).", ""]
    for renderer, res in results.items():
        b = res["bias"]
        level = sidak_level(cfg.alpha, len(b.metrics))
        tol = ", ".join(f"{_short(m)} ±{v:.2%}" for m, v in b.tolerance.items()) or "none"
        lines += [f"**{renderer}** (`bias_limit`: efforts {', '.join(map(str, b.efforts))}"
                  f"{' (' + '/'.join(b.setting) + f', spp {b.spp})' if b.setting else ' (iterations, one render)'}, "
                  f"rate {b.rate:g}, k = {b.seeds} seeds per set; tolerance {tol}; α = {cfg.alpha:g}, {level:.3g} per "
                  f"metric; {res['time_per_set']:.0f} s per set here, on one core of a loaded machine):", "",
                  "| variant | sets failed | " + " | ".join(f"{_short(m)}: b∞ mean ± sd, rate" for m in b.metrics)
                  + " |", "|---|---|" + "---|" * len(b.metrics)]
        for name, (verdicts, lims) in res["rows"].items():
            failed = sum(v[0] for v in verdicts)
            cells = [f"{np.mean(x) * 100:+.2f}% ± {np.std(x, ddof=1) * 100:.2f}% ({len(x)}), "
                     f"{power(x, b.seeds, level, b.tolerance.get(m, 0.0)):.3g}" for m, x in lims.items()]
            lines.append(f"| {name} | {failed}/{len(verdicts)} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines)


def date_now() -> str:
    from datetime import date
    return date.today().isoformat()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sets", type=int, default=10, help="disjoint seed sets per variant (default 10)")
    ap.add_argument("--mutant-sets", type=int, help="seed sets of each mutant (default: --sets)")
    ap.add_argument("--other-sets", type=int, help="seed sets of the other mutants (default: --mutant-sets)")
    ap.add_argument("--renderers", default="photonmap,sppm")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/cbox-biased-gate.jsonl"), help="the collected errors, one JSON line per (renderer, variant, seed)")
    ap.add_argument("--collect-only", action="store_true")
    ap.add_argument("--efforts", help="try other efforts (comma-separated, a subset of the collected ones)")
    ap.add_argument("--rate", type=float, help="try another rate")
    ap.add_argument("--metrics", help="try other metrics (comma-separated)")
    ap.add_argument("--markdown", type=Path, help="write the block into this file (docs/gate-detection.md)")
    args = ap.parse_args(argv)
    cfg = load_config(ROOT / "gate.toml")
    results, seconds = {}, {"total": 0.0}
    for renderer in args.renderers.split(","):
        exp = expectation(cfg, renderer)
        bias = exp.bias_limit
        if args.efforts:
            bias = dataclasses.replace(bias, efforts=tuple(int(e) for e in args.efforts.split(",")))
        if args.rate:
            bias = dataclasses.replace(bias, rate=args.rate)
        if args.metrics:
            bias = dataclasses.replace(bias, metrics=tuple(args.metrics.split(",")))
        variants = ("clean", FLUX_MUTANT[renderer], *OTHER_MUTANTS[renderer])
        msets = args.mutant_sets or args.sets
        osets = args.other_sets or msets
        count = {"clean": args.sets, FLUX_MUTANT[renderer]: msets}
        data = {v: collect(renderer, v, count.get(v, osets), bias.seeds, args.cache, bias, exp) for v in variants}
        if args.collect_only:
            continue
        times = [json.loads(line)["time_s"] for line in args.cache.read_text().splitlines()
                 if json.loads(line)["renderer"] == renderer and json.loads(line)["variant"] == "clean"]
        seconds["total"] += sum(json.loads(line)["time_s"] for line in args.cache.read_text().splitlines()
                                if json.loads(line)["renderer"] == renderer)
        def row(rows_, sets_, scale=None):
            return (set_verdicts(rows_, bias, renderer, sets_, cfg.alpha, scale),
                    {m: limits(rows_, bias, renderer, m, scale) for m in bias.metrics})

        flux = data[FLUX_MUTANT[renderer]]
        def sets_of(v):  # every complete set collected, at least the count asked for
            return max(count.get(v, osets), len(data[v]) // bias.seeds)

        rows = {"clean": row(data["clean"], sets_of("clean"))}
        for f in SCALES:
            rows[f"flux ×{f:g}"] = row(data["clean"], sets_of(FLUX_MUTANT[renderer]), (flux, f))
        rows[FLUX_MUTANT[renderer]] = row(flux, sets_of(FLUX_MUTANT[renderer]))
        for v in OTHER_MUTANTS[renderer]:
            rows[v] = row(data[v], sets_of(v))
        results[renderer] = {"bias": bias, "rows": rows, "time_per_set": float(np.mean(times)) * bias.seeds}
    if args.collect_only:
        return 0
    body = report(results, cfg, args.sets, seconds, markdown_blocks.command_line(argv))
    print(body)
    if args.markdown:
        markdown_blocks.write_blocks([args.markdown], {BLOCK: body}, markdown_blocks.command_line(argv))
    return 0


if __name__ == "__main__":
    sys.exit(main())

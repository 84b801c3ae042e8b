"""The sequential gate against the fixed-spp gate: false fails, false passes at the margin, and the cost of a verdict.

For each case (a renderer on a scene, with the margins ``gate.toml`` gives that pair) and each of ``--seeds``
seeds, ONE render to ``--max-spp`` with every look (max_spp/16 .. max_spp, doubling) as a checkpoint, no early
stop, gives every verdict below, so all of them see the same samples:

- **clean**: the render as it is;
- **mutants**: one region (``--region``) scaled by 1 + k·m, k = 0.5, 1 and 2 times that region's margin m (on
  its images, checkpoints and variance; the render is otherwise the clean one).

Each is checked twice: as a sequential expectation (``max_spp``; :mod:`cornell_harness.gate.sequential`, the
looks read from the checkpoints, which gives the verdict a renderer that stops early reaches,
tests/gate/test_gate_sequential.py) and as today's fixed-spp expectation at ``spp = max_spp`` with the same
margins (:func:`cornell_harness.gate.checks.evaluate`). The cost of a verdict is the spp and the CPU seconds of
the render up to the look it stops at (the checkpoint's), against the whole render's for the fixed gate.

Expected: clean runs fail at rate ≤ α (0.01 per expectation), a bias at 1× the margin passes at rate ≤ β
(0.05), a bias at 2× never passes. The counts over seeds are binomial; the table gives each with its
Clopper-Pearson 95% upper bound.

With ``--mutants``, the catalogue's path-tracer mutants (tests/mutants/, the gate's power test) replace the
scalings: each is rendered once (seed 0) on the first case's scene and checked both ways, so the table says
which verdict each gets and at what cost (the block ``gate_sequential.py#mutants``).

Run (about 25 minutes on an idle 2-core machine)::

    .venv/bin/python -m benchmarks.gate_sequential --seeds 20 --markdown docs/gate-detection.md

``--cases tests.user_renderers:ProgressiveNoise@cornell-box --seeds 400`` runs the reference plus exactly the
noise model the tests assume (seconds per seed): the rates of the statistics alone, without a renderer's misfit.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.stats import beta as beta_dist

from benchmarks import markdown_blocks
from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.gate.checks import evaluate
from cornell_harness.gate.config import load_config
from cornell_harness.gate.sequential import evaluate_sequential
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows import runner

ROOT = Path(__file__).resolve().parents[1]
BLOCK = "gate_sequential.py"  # the block of docs/gate-detection.md this writes (benchmarks/markdown_blocks.py)
MUTANTS_BLOCK = "gate_sequential.py#mutants"
#: (renderer, scene): the gate.toml expectations whose margins the cases take.
CASES = (("pathtracer", "cornell-box"), ("mitsuba", "cornell-box"), ("ao", "cornell-box-ao"))
MULTIPLES = (0.5, 1.0, 2.0)


def _margins(renderer: str, scene: str) -> str:
    """The ``margin = {...}`` line of gate.toml's expectation of (renderer, scene), else of its first on the
    scene (a renderer gate.toml does not name: ``tests.user_renderers:ProgressiveNoise``, the noise model)."""
    pairs = list(zip(load_config(ROOT / "gate.toml").expectations, _expect_blocks()))
    for exp, text in sorted(pairs, key=lambda p: p[0].renderer != renderer):
        if exp.scene == scene and exp.margins is not None:
            return next(line for line in text.splitlines() if line.startswith("margin"))
    raise SystemExit(f"gate.toml has no expectation on {scene} with margins")


def _expect_blocks() -> list[str]:
    return (ROOT / "gate.toml").read_text().split("[[expect]]")[1:]


def _configs(renderer: str, scene: str, max_spp: int, tmp: Path):
    """The sequential and the fixed-spp expectation of a case, and their config (alpha, beta, spending)."""
    body = f'scene = "{scene}"\nrenderer = "{renderer}"\nunbiased = true\n{_margins(renderer, scene)}\n'
    path = tmp / f"{renderer}-{scene}.toml"
    path.write_text(f"[[expect]]\n{body}max_spp = {max_spp}\n\n[[expect]]\nname = \"fixed\"\n{body}spp = {max_spp}\n")
    cfg = load_config(path)
    return cfg, cfg.expectations[0], cfg.expectations[1]


def _scaled(rec: runner.RunRecord, mask: np.ndarray, factor: float) -> runner.RunRecord:
    """``rec`` with the region ``mask`` of its image, checkpoints and variance scaled by ``factor``."""
    out = copy.copy(rec)
    out.info = dict(rec.info)

    def scale(image):
        image = np.array(image, copy=True)
        image[mask] *= factor
        return image

    out.image = scale(rec.image)
    out.variance = None if rec.variance is None else scale(scale(rec.variance))
    out.checkpoints = [dataclasses.replace(c, image=scale(c.image),
                                           variance=None if c.variance is None else scale(scale(c.variance)))
                       for c in rec.checkpoints]
    return out


def _upper(k: int, n: int) -> float:
    """Clopper-Pearson one-sided 95% upper bound of a rate seen k times in n."""
    return 1.0 if k == n else float(beta_dist.ppf(0.95, k + 1, n - k))


def run_case(renderer: str, scene_name: str, region: str, seeds: int, max_spp: int, tmp: Path) -> list[dict]:
    """One row per variant (clean, mutants) of the case: verdict counts, spp and CPU to a verdict."""
    cfg, seq, fixed = _configs(renderer, scene_name, max_spp, tmp)
    scene, (entry,) = resolve_scene(scene_name), resolve([renderer])
    ref, masks = load_reference(scene), region_masks(scene)
    margin = float(seq.margins.of(region).max())
    variants = [("clean", 1.0)] + [(f"{region} ×(1 + {k:g}·{margin:g})", 1.0 + k * margin) for k in MULTIPLES]
    rows = {name: {"case": f"{renderer} on {scene_name}", "variant": name, "seq": [], "fixed": [], "spp": [],
                   "cpu": [], "cpu_full": []} for name, _ in variants}
    for seed in range(seeds):
        t0 = time.perf_counter()
        rec = runner.run_one(entry, scene, max_spp, seed, ref, checkpoints=seq.looks())
        if rec.status != "ok":
            raise SystemExit(f"{renderer} on {scene_name}, seed {seed}: {rec.reason}")
        for name, factor in variants:
            r = rec if factor == 1.0 else _scaled(rec, masks[region], factor)
            s = evaluate_sequential(seq, r, ref, cfg, masks)
            f = evaluate(fixed, r, ref, cfg, None, None, masks)
            row = rows[name]
            row["seq"].append(s.verdict)
            row["fixed"].append(f.verdict)
            row["spp"].append(s.record.info["sequential"]["stop_spp"])
            row["cpu"].append(s.record.info["sequential"]["cpu_to_verdict_s"])
            row["cpu_full"].append(rec.cpu_time_s)
        print(f"  {renderer} on {scene_name}: seed {seed} in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return list(rows.values())


def run_mutants(renderer: str, scene_name: str, max_spp: int, tmp: Path) -> list[dict]:
    """One row per catalogue mutant of ``renderer`` (seed 0): the sequential and the fixed verdict and costs."""
    from tests.mutants import catalogue, patching

    cfg, seq, fixed = _configs(renderer, scene_name, max_spp, tmp)
    scene = resolve_scene(scene_name)
    ref, masks = load_reference(scene), region_masks(scene)
    rows = []
    for m in catalogue.MUTANTS:
        if m.renderer != renderer or m.name in catalogue.ISOLATED:
            continue
        t0 = time.perf_counter()
        rec = runner.run_one(patching.load_mutant(m.name, tmp), scene, max_spp, 0, ref, checkpoints=seq.looks())
        if rec.status != "ok":  # a render that fails fails both gates; why is in the table
            rows.append({"mutant": m.name, "seq": "fail", "fixed": "fail", "spp": 0, "cpu": 0.0, "cpu_full": 1.0,
                         "why": f"{rec.status}: {rec.reason}"})
            print(f"  {m.name}: the render {rows[-1]['why']}", file=sys.stderr)
            continue
        s = evaluate_sequential(seq, rec, ref, cfg, masks)
        f = evaluate(fixed, rec, ref, cfg, None, None, masks)
        rows.append({"mutant": m.name, "seq": s.verdict, "fixed": f.verdict,
                     "spp": s.record.info["sequential"]["stop_spp"],
                     "cpu": s.record.info["sequential"]["cpu_to_verdict_s"], "cpu_full": rec.cpu_time_s, "why": ""})
        print(f"  {m.name}: {s.verdict} at {rows[-1]['spp']} spp ({time.perf_counter() - t0:.1f} s)", file=sys.stderr)
    return rows


def mutants_markdown(rows: list[dict], case: str, args, cmd: str) -> str:
    lines = [f"The catalogue's `{case.split('@')[0]}` mutants on `{case.split('@')[1]}`, seed 0, max_spp "
             f"{args.max_spp}, with that expectation's margins; {platform.machine()}, {time.strftime('%Y-%m-%d')}.",
             "", "| mutant | sequential | fixed | spp to the sequential verdict | CPU, sequential / fixed |",
             "|---|---|---|---|---|"]
    for r in rows:
        cpu = r["cpu"] / r["cpu_full"] if r["cpu_full"] else float("nan")
        if r["why"]:
            lines.append(f"| {r['mutant']} | the render {r['why']} | (the same) | — | — |")
        else:
            lines.append(f"| {r['mutant']} | {r['seq']} | {r['fixed']} | {r['spp']} | {cpu:.2f} |")
    caught = [r for r in rows if r["seq"] != "pass"]
    mean = statistics.fmean(r["cpu"] / r["cpu_full"] for r in rows if not r["why"])
    lines += ["", f"Not passed by the sequential gate: {len(caught)} of {len(rows)} (fixed: "
              f"{sum(r['fixed'] != 'pass' for r in rows)}); mean CPU to its verdict {mean:.2f} of the fixed gate's.",
              "", f"Command: `{cmd}`", ""]
    return "\n".join(lines)


def _counts(verdicts: list[str]) -> str:
    return " / ".join(str(verdicts.count(v)) for v in ("pass", "inconclusive", "fail"))


def markdown(rows: list[dict], args, cmd: str) -> str:
    n = args.seeds
    lines = [f"{n} seeds per case, max_spp {args.max_spp} (looks {args.max_spp // 16} .. {args.max_spp}, "
             f"doubling), α = 0.01, β = 0.05, O'Brien-Fleming spending; the fixed gate at spp = {args.max_spp} "
             f"with the same margins. {platform.machine()}, {time.strftime('%Y-%m-%d')}.", "",
             "| case | variant | sequential pass / inconclusive / fail | fixed pass / inconclusive / fail | "
             "mean spp to a verdict | CPU to a verdict, sequential / fixed |",
             "|---|---|---|---|---|---|"]
    for r in rows:
        cpu = statistics.fmean(r["cpu"]) / statistics.fmean(r["cpu_full"])
        lines.append(f"| {r['case']} | {r['variant']} | {_counts(r['seq'])} | {_counts(r['fixed'])} | "
                     f"{statistics.fmean(r['spp']):.0f} of {args.max_spp} | {cpu:.2f} |")
    clean = [r for r in rows if r["variant"] == "clean"]
    at_margin = [r for r in rows if "×(1 + 1·" in r["variant"]]
    fails = sum(r["seq"].count("fail") for r in clean)
    passes = sum(r["seq"].count("pass") for r in at_margin)
    total = len(clean) * n
    lines += ["", f"**False fails** (clean, sequential): {fails} of {total}, rate ≤ {_upper(fails, total):.3f} "
              "(95% upper bound; α = 0.01 per expectation).",
              f"**False passes at the margin** (1× mutants, sequential): {passes} of {total}, rate ≤ "
              f"{_upper(passes, total):.3f} (95% upper bound; β = 0.05).", "", f"Command: `{cmd}`", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20, help="seeds per case (default 20)")
    parser.add_argument("--max-spp", type=int, default=512, help="the sequential budget, and the fixed gate's spp")
    parser.add_argument("--region", default="back-edge", help="the region the mutants scale (default back-edge)")
    parser.add_argument("--cases", default=",".join(f"{r}@{s}" for r, s in CASES),
                        help="renderer@scene, comma-separated (default: %(default)s)")
    parser.add_argument("--mutants", action="store_true",
                        help="the catalogue's mutants of the first case's renderer, not the scalings")
    parser.add_argument("--markdown", help="rewrite this file's gate_sequential.py block (#mutants with --mutants)")
    args = parser.parse_args(argv)
    cmd = markdown_blocks.command_line(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="cbox-gate-sequential-") as tmp:
        if args.mutants:
            case = args.cases.split(",")[0]
            text = mutants_markdown(run_mutants(*case.split("@"), args.max_spp, Path(tmp)), case, args, cmd)
        else:
            for case in args.cases.split(","):
                renderer, scene = case.split("@")
                rows += run_case(renderer, scene, args.region, args.seeds, args.max_spp, Path(tmp))
            text = markdown(rows, args, cmd)
    print(text)
    if args.markdown:
        markdown_blocks.write_blocks([Path(args.markdown)], {MUTANTS_BLOCK if args.mutants else BLOCK: text}, cmd)
        print(f"wrote {args.markdown}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

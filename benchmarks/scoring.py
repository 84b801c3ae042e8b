"""The cost of scoring one results row (issue 34: ≤ 0.15 s at 256² with every metric, FLIP included; ΔE00 at
1024² ≤ 0.2 s).

A row is what :func:`cornell_harness.workflows.runner.score` (the one scorer,
:func:`cornell_harness.evaluate.score.score_image`, with the scene's regions) computes for each (renderer, spp, seed) of a sweep: every image metric (:func:`cornell_harness.evaluate.metrics.image_metrics`,
FLIP included), the noise yardsticks and the named regions' metrics. The test image is the reference's stored
independent noise batch (a real 128-spp render of ``cornell-box``, 256²), scored against the stored reference as
a sweep scores its rows: the same reference object for every row, a new test image array each time.

Each item (the whole row, then each metric on its own) is timed once per round, the items interleaved
(A B C ... A B C ...) so that a change of machine load hits all alike; the figures are the medians over
``--rounds`` rounds of the wall time and of the process's CPU time, after one untimed warm-up round (numba
loads its kernels, the reference-side caches fill: a sweep pays that once per reference, not per row). The
targets are judged on the CPU time: on a machine that others load, wall time counts their work too
(flip-evaluator's CPU time counts both of its OpenMP threads).

``flip_mean (flip-evaluator 1.7)`` is the authors' library on the same images and exposures; the two "as
before" items are the row and the 1024² ΔE00 map computed as the harness did before (FLIP's map by that
library, ΔE00 in one pass over the image): the ratios come from one run. ΔE00 at 1024² is
:func:`cornell_harness.evaluate.ciede2000.delta_e2000_linear` on the image and reference upsampled 4× (nearest).

``--markdown FILE`` writes the table into the file's block ``scoring.py#cost`` (``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/scoring.py --markdown BENCHMARKS.md`` (about a minute on 2 cores).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import markdown_blocks
from cornell_harness.evaluate import ciede2000, flip, metrics, regions
from cornell_harness.evaluate import noise as yardsticks
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows import runner

BLOCK = "scoring.py#cost"
ROW_TARGET_S, DELTA_E_1024_TARGET_S = 0.15, 0.2
BEFORE_ROW = "whole row, as before (FLIP by flip-evaluator 1.7)"
BEFORE_DELTA_E = "ΔE00 map at 1024², as before (one pass)"


def items(scene, reference, image: np.ndarray) -> dict:
    """What is timed: name → a call. A fresh copy of the test image per call, as each row brings its own."""
    ref = reference.image
    exposure = metrics.display_exposure(ref)
    big_img, big_ref = (np.repeat(np.repeat(a, 4, axis=0), 4, axis=1) for a in (image, ref))

    def fresh():
        return image.copy()

    def row():
        return runner.score(scene, fresh(), reference, 128)

    return {
        "whole row (score + regions)": row,
        BEFORE_ROW: lambda: _as_before(row),
        "flip_mean": lambda: flip.flip_mean(fresh(), ref),
        "flip_mean (flip-evaluator 1.7)": lambda: float(np.mean(flip.library_flip_map(fresh(), ref))),
        "ΔE00 map + stats": lambda: metrics.delta_e2000_stats(metrics.delta_e2000(fresh(), ref, exposure,
                                                                                  full=True)[1]),
        "SSIM": lambda: metrics.ssim(fresh(), ref, exposure),
        "PSNR": lambda: metrics.psnr(fresh(), ref, exposure),
        "RMSE, MSE, relMSE, trimmed relMSE": lambda: (metrics.rmse(fresh(), ref), metrics.rel_mse(fresh(), ref),
                                                      metrics.rel_mse(fresh(), ref, trim=metrics.REL_MSE_TRIM)),
        "counts, mean radiance": lambda: (metrics.invalid_pixel_counts(fresh()),
                                          metrics.mean_radiance_rel_error(fresh(), ref)),
        "display exposure": lambda: metrics.display_exposure(ref),
        "noise yardsticks": lambda: yardsticks.noise_yardsticks(fresh(), reference, 128),
        "region metrics": lambda: regions.region_metrics(fresh(), reference, regions.region_masks(scene), spp=128),
        "ΔE00 map at 1024²": lambda: ciede2000.delta_e2000_linear(big_img, big_ref, exposure),
        BEFORE_DELTA_E: lambda: _as_before(lambda: ciede2000.delta_e2000_linear(big_img, big_ref, exposure)),
    }


def _as_before(call):
    """``call`` as the harness made it before issue 34's point 3: FLIP's map by flip-evaluator, every exposure
    of both images, and ΔE00 in one pass over the whole image (the two things that changed)."""
    own_map, chunk = flip.flip_map, ciede2000.CHUNK_PIXELS
    flip.flip_map, ciede2000.CHUNK_PIXELS = flip.library_flip_map, 1 << 62
    try:
        return call()
    finally:
        flip.flip_map, ciede2000.CHUNK_PIXELS = own_map, chunk


def measure(calls: dict, rounds: int) -> dict[str, tuple[float, float]]:
    """Median (wall, CPU) seconds per call over ``rounds`` interleaved rounds, after one untimed round."""
    for call in calls.values():
        call()
    times = {name: [] for name in calls}
    for _ in range(rounds):
        for name, call in calls.items():
            t0, c0 = time.perf_counter(), time.process_time()
            call()
            times[name].append((time.perf_counter() - t0, time.process_time() - c0))
    return {name: (statistics.median(t for t, _ in ts), statistics.median(c for _, c in ts))
            for name, ts in times.items()}


def _verdict(seconds: float, target: float) -> str:
    return f"≤ {target * 1e3:.0f} ms: **{'met' if seconds <= target else 'not met'}**"


def table(medians: dict[str, tuple[float, float]]) -> list[str]:
    """Wall and CPU medians; the targets are judged on the CPU time, which a loaded machine inflates less."""
    row = medians["whole row (score + regions)"][1]
    flip_cpu = medians["flip_mean"][1]
    lines = ["| what | wall (ms) | CPU (ms) | share of the row's CPU | target (CPU), or ratio |",
             "| --- | --- | --- | --- | --- |"]
    for name, (wall, cpu) in medians.items():
        alone = name.startswith("whole") or "1024" in name or "evaluator" in name
        note = (_verdict(cpu, ROW_TARGET_S) if name.startswith("whole") else
                _verdict(cpu, DELTA_E_1024_TARGET_S) if "1024" in name else
                f"{cpu / flip_cpu:.1f}× flip_mean's" if "evaluator" in name else "")
        if name == BEFORE_ROW:
            note += f"; {cpu / row:.1f}× the row's now"
        elif name == BEFORE_DELTA_E:
            note += f"; {cpu / medians['ΔE00 map at 1024²'][1]:.1f}× now"
        lines.append(f"| {name} | {wall * 1e3:.1f} | {cpu * 1e3:.1f} | {'' if alone else f'{cpu / row:.0%}'} "
                     f"| {note} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=15, help="interleaved rounds")
    ap.add_argument("--markdown", type=Path, action="append", default=[])
    args = ap.parse_args(argv)
    command = markdown_blocks.command_line([sys.argv[0]] + list(sys.argv[1:] if argv is None else argv))
    scene = resolve_scene("cornell-box")
    reference = load_reference(scene)
    regions.region_masks(scene)
    medians = measure(items(scene, reference, np.asarray(reference.noise)), args.rounds)
    load = os.getloadavg()[0]  # after the run: the last minute's
    body = "\n".join(table(medians) + [
        "", f"256² `cornell-box` (its stored 128-spp noise batch against its reference; the ΔE00 row upsampled "
            f"to 1024²), median of {args.rounds} interleaved rounds after a warm-up round, "
            f"{os.cpu_count()} cores, load average {load:.1f}, {time.strftime('%Y-%m-%d')}. Command: `{command}`."])
    print(body, flush=True)
    markdown_blocks.write_blocks(args.markdown, {BLOCK: body}, command)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Why the per-pixel z of `cbox reference verify` spreads far past Student-t on cornell-box-caustics.

Two tables for docs/references.md:

1. **The scene** (block ``pixel-z-scene``): engines rendered at ``--run ENGINE:BATCHESxSPP`` (batches of spp
   each, at the verification seeds, one batch at a time) against the stored Mitsuba reference, judged by
   :func:`cornell_harness.evaluate.reference_agreement.reference_agreement` as ``cbox reference verify``
   judges them: per-pixel z sd, robust spread, the fractions below −3 and above +3, the regions' χ² p, the
   fraction below −3 per region, and the median ratio of the engine's per-sample variance (variance of the
   mean × spp) to the reference's, in the pixels beyond |z| 3: how much of the reference's per-pixel noise the
   engine's samples saw.
2. **A model** (block ``pixel-z-model``): per pixel-channel an exponential sample plus, with probability p, a
   rare bright path carrying 95% of the per-sample variance, the same law in both images (no bias): an engine
   of 16 batches × 16 spp against a reference of 256 × 128, for expected rare draws p × 256 in the engine's
   render from 0.01 to 100; p = 1/256 at other splits of the engine's spp; and lognormal samples.

``--cache DIR`` keeps each run's batch images (``SCENE-ENGINE-BxN.npy``) and reads them on the next run.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks import markdown_blocks
from cornell_harness.evaluate.reference_agreement import (PIXEL_Z_TAIL, expected_pixel_z_sd,
                                                          reference_agreement)

SCENE = "cornell-box-caustics"
RUNS = ["mitsuba:16x16", "mitsuba:64x4", "mitsuba:16x64", "mitsuba:16x256", "pathtracer:16x16", "luxcore:16x16"]
#: Share of a pixel's per-sample variance that the model's rare path carries.
RARE_SHARE = 0.95
MODEL_SHAPE = (96, 96, 3)
LOGNORMAL_SHAPE = (32, 32, 3)  # every sample drawn: 3072 pixel-channels × 32768 reference samples
CACHED: list[str] = []  # the runs read from --cache, named under the table


def render_run(engine: str, batches: int, spp: int, cache: Path | None) -> np.ndarray:
    """(batches, H, W, 3) batch images of the scene at the verification seeds, from ``cache`` if there."""
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.workflows.reference_build import render_batch
    from cornell_harness.workflows.reference_verify import VERIFY_SEED_BASE

    path = cache / f"{SCENE}-{engine}-{batches}x{spp}.npy" if cache else None
    if path and path.exists():
        CACHED.append(f"{engine} {batches} × {spp}")
        return np.load(path)
    scene = resolve_scene(SCENE)
    images = np.stack([np.asarray(render_batch(engine, {}, scene, spp, VERIFY_SEED_BASE + b)[0], np.float32)
                       for b in range(batches)])
    if path:
        path.parent.mkdir(parents=True, exist_ok=True)
        np.save(path, images)
    return images


def scene_table(runs: list[str], cache: Path | None) -> list[str]:
    from cornell_harness.evaluate.regions import region_masks
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.store.references import load_reference

    scene = resolve_scene(SCENE)
    ref, masks = load_reference(scene), region_masks(scene)
    names = list(masks)
    lines = [f"| engine | batches × spp | pixel z sd (t: {expected_pixel_z_sd(16):.2f} at 16, "
             f"{expected_pixel_z_sd(64):.2f} at 64) | robust spread | below −3 | above +3 | regions' χ² p | "
             + " | ".join(f"below −3 in {n}" for n in names)
             + " | engine/reference per-sample variance (median beyond \\|z\\| 3) |",
             "| --- " * (8 + len(names)) + "|"]
    for run in runs:
        engine, _, split = run.partition(":")
        batches, spp = (int(x) for x in split.split("x"))
        x = render_run(engine, batches, spp, cache).astype(np.float64)
        mean, var = x.mean(0), x.var(0, ddof=1) / batches
        a = reference_agreement(ref.image, ref.variance, mean, var, masks)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = (mean - ref.image) / np.sqrt(ref.variance + var)
            ratio = var * batches * spp / (ref.variance * ref.spp)
        below = [float(np.mean(z[masks[n]] < -PIXEL_Z_TAIL)) for n in names]
        tail = np.abs(z) > PIXEL_Z_TAIL
        lines.append(f"| {engine} | {batches} × {spp} | {a.pixel_z_sd:.2f} | {a.pixel_z_spread:.2f} | "
                     f"{a.pixel_z_below:.1%} | {a.pixel_z_above:.2%} | {a.chi2_p:.2f} | "
                     + " | ".join(f"{b:.1%}" for b in below) + f" | {float(np.nanmedian(ratio[tail])):.3f} |")
        print(lines[-1], flush=True)
    return lines


def _model_batches(rng, truth, batches, spp, p, bright):
    """Batch means: an exponential of mean ``truth`` plus ``bright`` with probability ``p`` per sample."""
    base = truth[..., None] * rng.gamma(spp, 1.0 / spp, (*truth.shape, batches))
    return base + bright[..., None] * rng.binomial(spp, p, (*truth.shape, batches)) / spp


def _model_row(label: str, ref_b: np.ndarray, eng_b: np.ndarray) -> str:
    b_ref, b_eng = ref_b.shape[-1], eng_b.shape[-1]
    a = reference_agreement(ref_b.mean(-1), ref_b.var(-1, ddof=1) / b_ref, eng_b.mean(-1),
                            eng_b.var(-1, ddof=1) / b_eng, {})
    return (f"| {label} | {a.pixel_z_sd:.2f} | {a.pixel_z_spread:.2f} | {a.pixel_z_below:.1%} | "
            f"{a.pixel_z_above:.2%} | {a.max_abs_z:.2f} |")


def model_table(seed: int = 1) -> list[str]:
    rng = np.random.default_rng(seed)
    truth = 0.2 + 0.6 * rng.random(MODEL_SHAPE)
    lines = ["| per-sample law, engine batches × spp | pixel z sd | robust spread | below −3 | above +3 | "
             "whole image's max \\|z\\| |", "| --- | --- | --- | --- | --- | --- |"]
    rare = [(f"rare path drawn {h:g} times in the engine's 16 × 16", h, 16, 16)
            for h in (0.01, 0.03, 0.1, 0.3, 1, 3, 10, 30, 100)]
    rare += [(f"rare path of p = 1/256, engine {b} × {n}", b * n / 256, b, n)
             for b, n in ((64, 4), (16, 64), (16, 256))]
    for label, hits, batches, spp in rare:
        p = hits / (batches * spp)
        bright = truth * np.sqrt(RARE_SHARE / ((1 - RARE_SHARE) * p))
        lines.append(_model_row(label, _model_batches(rng, truth, 256, 128, p, bright),
                                _model_batches(rng, truth, batches, spp, p, bright)))
        print(lines[-1], flush=True)
    for sigma in (1.0, 2.0, 3.0):
        draw = [np.stack([rng.lognormal(0, sigma, (*LOGNORMAL_SHAPE, n)).mean(-1) for _ in range(b)], -1)
                for b, n in ((256, 128), (16, 16))]
        lines.append(_model_row(f"lognormal σ = {sigma:g}, engine 16 × 16", *draw))
        print(lines[-1], flush=True)
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", action="append", default=[], metavar="ENGINE:BxN",
                    help=f"an engine's batches × spp per batch (repeatable; default {' '.join(RUNS)})")
    ap.add_argument("--part", choices=("all", "scene", "model"), default="all")
    ap.add_argument("--cache", type=Path, help="keep (and reuse) each run's batch images here")
    ap.add_argument("--markdown", type=Path, action="append", default=[])
    args = ap.parse_args(argv)
    command = markdown_blocks.command_line([sys.argv[0]] + list(sys.argv[1:] if argv is None else argv))
    bodies = {}
    for part, name, make in (("scene", "pixel-z-scene", lambda: scene_table(args.run or RUNS, args.cache)),
                             ("model", "pixel-z-model", model_table)):
        if args.part in ("all", part):
            t0 = time.perf_counter()
            lines = make()
            took = f"{time.perf_counter() - t0:.0f} s"
            if CACHED:
                took += f"; read from the cache: {', '.join(CACHED)}"
            bodies[name] = "\n".join(lines + ["", f"Command: `{command}` ({took})."])
            CACHED.clear()
    if args.markdown:
        markdown_blocks.write_blocks(args.markdown, bodies, command)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Variance honesty both ways (issue 29): the variance check's false alarms and power, and AO's z spread per band.

Run (7 minutes on the shared 2-core machine)::

    .venv/bin/python -m benchmarks.variance_honesty --seeds 20 --ao-seeds 8 --markdown docs/gate-detection.md

(1) Every unbiased expectation of ``gate.toml`` whose renderer reports a
    variance (Mitsuba's radiance adapter reports none, so its expectations are
    skipped, said in the table), at its spp, seeds ``0 .. seeds-1`` (added to
    the expectation's seed), at a resolution of at most :data:`SIDE` pixels
    a side to keep it affordable: a larger scene is rendered with
    ``camera.resolution`` divided by k and compared with its stored reference
    averaged over k×k blocks (exact for the box filter every renderer and
    reference here uses; the reference's variance of a block mean is the
    block's sum over k⁴). The renderer's variance is then used as reported
    (F = 1: false alarms) and divided by 2 and 4 and multiplied by 4 (power),
    through :func:`harness.evaluate.variance_check.variance_check` at the
    gate's level (the Šidák share of ``alpha``).
(2) ``ao`` on ``cornell-box-ao`` at the gate's 64 spp and full resolution,
    seeds ``0 .. ao-seeds-1``: z = (render − reference)/√(reported + reference
    variance) per pixel, and per band of the reference's AO ([0, 0.1), ...,
    [0.9, 1]) its spread over the seeds: the root of the mean, over the band's
    pixels, of each pixel's sample variance of z across seeds (a pixel's own
    bias, which the agreement test judges, does not enter), and the root mean
    square of z. Pixels that agree with the reference exactly (d = 0: misses,
    AO exactly 1) say nothing and are left out, as the variance check does.

With ``--markdown``, the block ``variance_honesty.py`` of the file is rewritten
(``benchmarks/markdown_blocks.py``).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from benchmarks import markdown_blocks
from harness.adapters.registry import resolve
from harness.evaluate.variance_check import variance_check
from harness.gate.checks import statistical_alpha
from harness.gate.config import load_config
from harness.scenes.library import resolve_scene
from harness.store.references import load_reference

ROOT = Path(__file__).resolve().parent.parent
BLOCK = "variance_honesty.py"
SIDE = 64  # largest side rendered for (1)
FACTORS = (1.0, 0.5, 0.25, 4.0)  # reported / true variance
BANDS = np.round(np.arange(0.0, 1.0, 0.1), 1)


def block_mean(a: np.ndarray, k: int) -> np.ndarray:
    """Means over k×k blocks of an (H, W, 3) image."""
    h, w, c = a.shape
    return a.reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))


def reduced(exp) -> tuple:
    """The scene at ≤ SIDE pixels a side and its reference averaged to match: (scene, image, variance, k)."""
    base = resolve_scene(exp.scene)
    ref = load_reference(base)
    k = max(1, base.camera.width // SIDE)
    if k == 1:
        return base, ref.image.astype(np.float64), ref.variance.astype(np.float64), 1
    scene = resolve_scene(exp.scene, [f"camera.resolution=[{base.camera.width // k},{base.camera.height // k}]"])
    var = block_mean(ref.variance.astype(np.float64), k) / (k * k)
    return scene, block_mean(ref.image.astype(np.float64), k), var, k


def false_alarms(seeds: int) -> list[str]:
    cfg = load_config(ROOT / "gate.toml")
    level = statistical_alpha(cfg.alpha)
    rows, skipped = [], []
    for exp in (e for e in cfg.expectations if e.unbiased):
        entry = resolve([exp.renderer])[0]
        scene, ref, ref_var, k = reduced(exp)
        fails = defaultdict(lambda: [0, 0])  # factor -> [understated, overstated]
        ratios, ts = [], []
        for s in range(seeds):
            r = entry.renderer.render(scene, exp.spp, exp.seed + s)
            if r.variance is None:
                skipped.append(exp.name)
                break
            img = np.where(np.isfinite(r.image), r.image, 0.0).astype(np.float64)
            for f in FACTORS:
                v = variance_check(img, r.variance.astype(np.float64) * f, ref, ref_var, exp.spp, level)
                fails[f][0] += v.understated
                fails[f][1] += v.overstated
                if f == 1.0:
                    ratios.append(v.ratio)
                    ts.append(v.t_under)
        else:
            w, h = scene.camera.width, scene.camera.height
            cells = " | ".join(f"{fails[f][0] + fails[f][1]}/{seeds}" for f in FACTORS)
            rows.append(f"| {exp.name} | {w}×{h}{f' (÷{k})' if k > 1 else ''} | {cells} | "
                        f"{min(ratios):.2f}-{max(ratios):.2f} | {max(ts):.1f} |")
            print(rows[-1], flush=True)
    head = ["| expectation | rendered at | F = 1 (false alarms) | F = ½ | F = ¼ | F = 4 | Σd²/Σv at F = 1 | "
            "largest t at F = 1 |", "|---|---|---|---|---|---|---|---|"]
    return ([f"Variance check at the gate's level (α = {cfg.alpha:g}, Šidák share {level:.3g}; understatement "
             f"t-test at half of it), seeds 0-{seeds - 1}: runs failed, by reported/true variance F:", ""]
            + head + rows
            + ["", "Skipped, no reported variance: " + ", ".join(sorted(set(skipped))) + "." if skipped else ""])


def ao_bands(seeds: int, spp: int = 64) -> list[str]:
    scene = resolve_scene("cornell-box-ao")
    ref = load_reference(scene)
    r0 = ref.image[..., 0].astype(np.float64)
    renderer = resolve(["ao"])[0].renderer
    zs = []
    for s in range(seeds):
        r = renderer.render(scene, spp, s)
        d = r.image[..., 0].astype(np.float64) - r0
        v = r.variance[..., 0].astype(np.float64) + ref.variance[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            zs.append(np.where(d == 0, np.nan, d / np.sqrt(v)))
    z = np.array(zs)
    spread, rms, counts, worst = band_spreads(z, r0)
    inf = np.any(np.isinf(z), axis=0)
    lost = [int((inf & (r0 >= lo) & ((r0 < lo + 0.1) if lo < 0.9 else (r0 <= 1.0))).sum()) for lo in BANDS]
    rows = [f"| [{lo:.1f}, {lo + 0.1:.1f}{']' if lo == 0.9 else ')'} | "
            + (f"{n} | {sp:.3f} | {rm:.3f} | {w:.1f} | {x} |" if n else f"0 (every pixel exact: misses) | - | - | - | {x} |")
            for lo, n, sp, rm, w, x in zip(BANDS, counts, spread, rms, worst, lost)]
    return ([f"`ao` on cornell-box-ao, 64 spp, 256×256, seeds 0-{seeds - 1}: spread of z per band of the "
             "reference's AO (pixels with a finite z at every seed):", "",
             "| AO band | pixels | spread (within pixel, over seeds) | rms z | largest abs(z) | "
             "pixels left out: variance 0 and d ≠ 0 at some seed |",
             "|---|---|---|---|---|---|"] + rows)


def band_spreads(z: np.ndarray, ref: np.ndarray):
    """Per band of ``ref``: the within-pixel spread of z (seeds, H, W) over seeds, its rms, pixels, largest |z|."""
    ok = np.all(np.isfinite(z), axis=0)
    within = z.var(axis=0, ddof=1)
    out = [], [], [], []
    for lo in BANDS:
        m = (ref >= lo) & ((ref < lo + 0.1) if lo < 0.9 else (ref <= 1.0)) & ok
        n = int(m.sum())
        vals = (np.sqrt(within[m].mean()), np.sqrt((z[:, m] ** 2).mean()), n, np.abs(z[:, m]).max()) if n else \
            (np.nan, np.nan, 0, np.nan)
        for lst, x in zip(out, vals):
            lst.append(x)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--ao-seeds", type=int, default=8)
    ap.add_argument("--markdown", type=Path)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    lines = false_alarms(args.seeds) + [""] + ao_bands(args.ao_seeds)
    lines += ["", f"Command: `.venv/bin/python -m benchmarks.variance_honesty --seeds {args.seeds} --ao-seeds "
                  f"{args.ao_seeds} --markdown docs/gate-detection.md` ({(time.perf_counter() - t0) / 60:.0f} min)."]
    print("\n".join(lines), flush=True)
    if args.markdown:
        markdown_blocks.write_blocks([args.markdown], {BLOCK: "\n".join(lines)})
    return 0


if __name__ == "__main__":
    sys.exit(main())

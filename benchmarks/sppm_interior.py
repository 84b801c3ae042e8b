"""SPPM's bias on a closed-form mirror caustic, interior and edge, over many seeds.

The scene is :func:`cornell_harness.scenes.polygon_light.mirror_caustic_scene`: a diffuse patch lit only
through a mirror, nothing around it, its exact image the polygon formula for the light's image source
(:func:`cornell_harness.scenes.polygon_light.mirrored_light_image`). Each seed is one SPPM render at the
renderer's defaults (``--setting`` overrides one; ``--sampler``), with checkpoints; for each checkpoint the
table gives, over the seeds, the mean relative error of the **interior** (pixels whose every point lies more
than the largest initial radius inside the patch: no gather disc ever leaves it) and of the **edge** (the
patch's other pixels), as mean ± the 95% Student-t interval of the seeds' errors, and the interior's z.

A consistent density estimate is unbiased in the interior only up to the curvature of the irradiance over
its disc: the column ``disc`` is that bias at the initial radius (the exact image with every point's
irradiance averaged over a disc of the median initial radius), an upper bound, as the radius shrinks from
there.

With ``--markdown FILE`` the table goes into that file's block ``sppm_interior.py``
(``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/sppm_interior.py --seeds 64 --markdown docs/photon-mapping.md``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy import stats

import markdown_blocks
from cornell_harness.renderers.sppm import SPPM
from cornell_harness.scenes.analytic import subpixel_directions
from cornell_harness.scenes.polygon_light import LIGHT_A, LIGHT_B, LIGHT_LE, MIRROR_H, MIRROR_LIGHT_H, \
    mirror_caustic_scene, mirrored_light_image, polygon_irradiance

CHECKPOINTS = (16, 64, 256, 1024)  # the ones up to --iterations


def regions(scene, r0: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The exact image's first channel, the interior mask (every point more than 1.05·r0 inside the patch)
    and the edge mask (the patch's other pixels)."""
    exact, patch = mirrored_light_image(scene)
    _, interior = mirrored_light_image(scene, margin=1.05 * r0)
    return exact[..., 0], interior, patch & ~interior


def disc_bias(scene, r: float, mask: np.ndarray, sub: int = 4, rings: int = 8) -> float:
    """The relative bias of the ``mask`` pixels' mean when each point's irradiance is averaged over a disc of
    radius ``r`` on the floor (midpoint rule in the disc's area: ``rings`` rings of 4·(2k+1) points each),
    against the point values: what the curvature of the irradiance alone gives a density estimate."""
    cam = scene.camera
    d = subpixel_directions(cam, sub)
    o = np.asarray(cam.position)
    pts = (o + (-o[2] / d[..., 2])[..., None] * d).reshape(-1, 3)
    z = 2 * MIRROR_H - MIRROR_LIGHT_H
    poly = np.array([[-LIGHT_A, -LIGHT_B, z], [LIGHT_A, -LIGHT_B, z], [LIGHT_A, LIGHT_B, z], [-LIGHT_A, LIGHT_B, z]])
    up = np.array([0.0, 0.0, 1.0])
    offsets = []
    for k in range(rings):  # ring k holds the area between radii k/rings and (k+1)/rings, equal-area points
        rad = r * np.sqrt((k ** 2 + (k + 1) ** 2) / 2) / rings
        n = 4 * (2 * k + 1)
        a = 2 * np.pi * (np.arange(n) + 0.5 * (k % 2)) / n
        offsets += [(rad * np.cos(t), rad * np.sin(t), 0.0) for t in a]
    offsets = np.array(offsets)
    point = polygon_irradiance(pts, up, poly, LIGHT_LE)
    disc = np.mean([polygon_irradiance(pts + off, up, poly, LIGHT_LE) for off in offsets], axis=0)
    shape = (cam.height, sub, cam.width, sub)
    point, disc = (v.reshape(shape).mean(axis=(1, 3))[mask].mean() for v in (point, disc))
    return float(disc / point - 1)


def interval(x: np.ndarray) -> tuple[float, float]:
    """Mean and the half-width of its 95% Student-t interval."""
    return float(x.mean()), float(stats.t.ppf(0.975, len(x) - 1) * x.std(ddof=1) / np.sqrt(len(x)))


def measure(res: int, seeds: range, iterations: int, settings: dict) -> tuple[dict, float, float, float]:
    """Per checkpoint the seeds' (interior, edge) relative errors; the median initial radius, the disc bias
    at it, and the seconds the renders took."""
    scene = mirror_caustic_scene(res)
    checkpoints = tuple(c for c in CHECKPOINTS if c < iterations) + (iterations,)
    errors: dict[int, list[tuple[float, float]]] = {c: [] for c in checkpoints}
    renderer, t0, masks = SPPM(threads=1), time.perf_counter(), None
    for seed in seeds:
        out = renderer.render(scene, iterations, seed, checkpoints=checkpoints, settings=settings)
        if masks is None:
            r0 = out.info["initial_radius_median"]
            exact, interior, edge = masks = regions(scene, r0)
        for c in out.checkpoints:
            x = c.image.astype(np.float64)[..., 0]
            errors[c.spp].append(tuple(float(x[m].mean() / exact[m].mean() - 1) for m in (interior, edge)))
    return errors, r0, disc_bias(scene, r0, interior), time.perf_counter() - t0


def table(errors: dict, seeds: range, r0: float, disc: float, seconds: float, res: int, settings: dict) -> str:
    exact, interior, edge = regions(mirror_caustic_scene(res), r0)
    n, last = len(next(iter(errors.values()))), max(errors)
    told = ", ".join(f"{k} = {v}" for k, v in settings.items()) or "the defaults"
    pct = lambda v: markdown_blocks.minus(f"{100 * v:+.2f}%")  # noqa: E731
    lines = [f"SPPM at {told}, {res}², {n} seeds ({seeds[0]}-{seeds[-1]}), one render of {last} iterations each "
             f"({seconds:.0f} s in all, one thread); interior {int(interior.sum())} pixels, edge {int(edge.sum())}; "
             f"initial radius {r0:.4f} (median); disc bias at it {pct(disc)}.", "",
             "| iterations | interior: mean ± 95% CI | z | edge: mean ± 95% CI |", "|---|---|---|---|"]
    for c in sorted(errors):
        e = np.array(errors[c])
        (mi, hi), (me, he) = interval(e[:, 0]), interval(e[:, 1])
        z = mi / (e[:, 0].std(ddof=1) / np.sqrt(n))
        lines.append(f"| {c} | {pct(mi)} ± {100 * hi:.2f}% | {markdown_blocks.minus(f'{z:+.1f}')} | "
                     f"{pct(me)} ± {100 * he:.2f}% |")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=64)
    ap.add_argument("--first-seed", type=int, default=0)
    ap.add_argument("--res", type=int, default=32)
    ap.add_argument("--iterations", type=int, default=1024)
    ap.add_argument("--setting", action="append", default=[], metavar="NAME=VALUE",
                    help="an SPPM setting other than its default (repeatable)")
    ap.add_argument("--markdown", type=Path, action="append", default=[])
    args = ap.parse_args()
    settings = {}
    for item in args.setting:
        name, value = item.split("=", 1)
        settings[name] = value if name == "sampler" else int(value) if value.isdigit() else float(value)
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    errors, r0, disc, seconds = measure(args.res, seeds, args.iterations, settings)
    text = table(errors, seeds, r0, disc, seconds, args.res, settings)
    print(text)
    markdown_blocks.write_blocks(args.markdown, {"sppm_interior.py": text})


if __name__ == "__main__":
    main()

"""RGB rendering of the real Cornell box: ΔE00 per region between RGB and spectral rendering, with the noise floor.

The scene is ``cornell-box-measured`` (Cornell's measured spectra); the spectral side is its stored reference
(Mitsuba 3's spectral variant, ``src/cornell_harness/references/cornell-box-measured``). The RGB side is Mitsuba 3's RGB
variant (``mitsuba[spectral=rgb]``) on the scene's RGB projection, under each convention of
:data:`cornell_harness.scenes.spectra.RGB_CONVENTIONS`: ``illuminant_E`` (reflectance under the equal-energy
illuminant, ``mi.cornell_box()``'s values) and ``scene_light`` (white-balanced to the scene's own light; the
scene's default), the first a derived scene (``--set colour.rgb_convention=illuminant_E``). Both use the same
emission rule, so the light seen directly is the same colour in all three images.

Figures, per named region of the scene and the whole image, against the reference, at one exposure (the
reference's, :func:`cornell_harness.evaluate.metrics.exposure_scale`):

- *mean ΔE00*: the mean over the region's pixels of the per-pixel CIEDE2000;
- *ΔE00 of the mean*: the CIEDE2000 between the region's mean colours, the systematic colour shift with the
  pixel noise averaged out.

The noise floor is the same figure for an independent spectral render (the reference's renderer and variant,
other seeds) at the RGB renders' spp: what a render with no RGB error scores against this reference. An RGB
render at equal spp is no noisier than it (no wavelength sampling), so a difference is claimed (bold) only
where the RGB figure is more than twice the floor.

Run (a few minutes on 2 cores)::

    .venv/bin/python benchmarks/spectral.py --spp 1024 --markdown docs/spectral.md

It writes the block ``spectral.py`` of the page and the figure ``docs/images/spectral-delta-e.png``: the ΔE00
maps of both conventions and of the noise floor against the reference, per pixel (0-10) and of 8 × 8-pixel block
means (0-1), where the noise averages out and the systematic shift shows.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import figure_manifest
import markdown_blocks

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.ciede2000 import delta_e2000_linear
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.overrides import load_derived_scene
from cornell_harness.scenes.spectra import ILLUMINANT_E, SCENE_LIGHT
from cornell_harness.store.references import load_reference
from cornell_harness.renderers.mitsuba3 import Mitsuba3

SCENE = "cornell-box-measured"
FIGURE = Path("docs/images/spectral-delta-e.png")
#: A difference is claimed where the RGB figure exceeds this many times the noise floor.
CLAIM_FACTOR = 2.0
#: The figure's ΔE00 colour scales (viridis): per pixel, and of 8 × 8-pixel block means (the systematic shift).
FIGURE_RANGE = (0.0, 10.0)
BLOCK_RANGE = (0.0, 1.0)
#: Pixels per side of the figure's blocks: their means average the noise out, so the second row shows the shift.
BLOCK = 8
#: Seeds: the RGB renders and the independent spectral one (the reference's are 1e9 + batch).
SEED_RGB, SEED_FLOOR = 11, 12


def region_figures(img: np.ndarray, ref: np.ndarray, masks: dict[str, np.ndarray], exposure: float) -> dict:
    """{region: (mean per-pixel ΔE00, ΔE00 of the mean colours)} of ``img`` against ``ref``."""
    de = delta_e2000_linear(img, ref, exposure)
    out = {}
    for name, mask in masks.items():
        mean_shift = delta_e2000_linear(img[mask].mean(axis=0)[None], ref[mask].mean(axis=0)[None], exposure)
        out[name] = (float(de[mask].mean()), float(mean_shift[0]))
    return out


def render(scene, spp: int, seed: int, spectral: str) -> tuple[np.ndarray, dict]:
    res = Mitsuba3().render(scene, spp, seed, settings={"spectral": spectral})
    return np.asarray(res.image, dtype=np.float64), dict(res.info)


def block_means(img: np.ndarray, k: int = BLOCK) -> np.ndarray:
    """The mean colour of each k × k block of pixels, as an image of the same size (each block one colour)."""
    h, w, c = img.shape
    means = img[:h - h % k, :w - w % k].reshape(h // k, k, w // k, k, c).mean(axis=(1, 3))
    return np.repeat(np.repeat(means, k, axis=0), k, axis=1)


def write_figure(path: Path, rows: list[tuple[str, tuple[float, float], list[tuple[str, np.ndarray]]]]) -> None:
    """Rows of ΔE00 maps side by side, each panel titled, each row on its own viridis scale with its colour bar."""
    from PIL import Image, ImageDraw

    from cornell_harness.reports.images import apply_colormap

    h, w = rows[0][2][0][1].shape
    pad, title, bar = 8, 14, 22
    row_h = title + h + bar
    canvas = Image.new("RGB", (len(rows[0][2]) * (w + pad) + pad, len(rows) * row_h + 2 * pad), "white")
    draw = ImageDraw.Draw(canvas)
    for r, (caption, (lo, hi), maps) in enumerate(rows):
        y = pad + r * row_h
        for i, (label, de) in enumerate(maps):
            x = pad + i * (w + pad)
            draw.text((x, y), label, fill="black")
            canvas.paste(Image.fromarray(apply_colormap(de[:h, :w], lo, hi)), (x, y + title))
        ramp = apply_colormap(np.linspace(lo, hi, w)[None, :].repeat(6, axis=0), lo, hi)
        canvas.paste(Image.fromarray(ramp), (pad, y + title + h + 4))
        draw.text((pad + w + 6, y + title + h + 2), f"{caption}: dE00 {lo:g} to {hi:g}", fill="black")
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path, optimize=True)


def table(figures: dict[str, dict], floor: dict, order: list[str], k: int) -> list[str]:
    head = "| region | " + " | ".join(figures) + " | noise floor |"
    rows = [head, "|---|" + "---|" * (len(figures) + 1)]
    for region in order:
        f = floor[region][k]
        cells = [markdown_blocks.bold(f"{v[region][k]:.2f}", v[region][k] > CLAIM_FACTOR * f) for v in figures.values()]
        rows.append(f"| {region} | " + " | ".join(cells) + f" | {f:.2f} |")
    return rows


def headline(figures: dict[str, dict], floor: dict) -> str:
    """One sentence: each convention's image-wide figures against the floor, and its largest regional shift."""
    parts = []
    for label, v in figures.items():
        worst = max((r for r in v if r != "whole image"), key=lambda r: v[r][1])
        parts.append(f"{label}: mean ΔE00 {v['whole image'][0]:.2f} per pixel (floor {floor['whole image'][0]:.2f}), "
                     f"a shift of the mean colour of {v['whole image'][1]:.2f} image-wide and up to "
                     f"{v[worst][1]:.2f} ({worst})")
    return "Headline. " + "; ".join(parts) + "."


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spp", type=int, default=1024, help="samples per pixel of every render here (default 1024)")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help='write the table into this file\'s block "spectral.py" (repeatable)')
    ap.add_argument("--figure", type=Path, default=FIGURE, help=f"the ΔE00 maps' PNG (default {FIGURE})")
    args = ap.parse_args()
    t0 = time.perf_counter()
    scene = resolve_scene(SCENE)
    reference = load_reference(scene)
    ref = np.asarray(reference.image, dtype=np.float64)
    masks = {"whole image": np.ones(ref.shape[:2], bool), **region_masks(scene)}
    exposure = metrics.exposure_scale(ref)
    scenes = {ILLUMINANT_E: load_derived_scene(scene.path, [f"colour.rgb_convention={ILLUMINANT_E}"]),
              SCENE_LIGHT: scene}
    images, figures = {}, {}
    for convention, s in scenes.items():
        assert s.spectral.rgb_convention == convention
        images[convention], info = render(s, args.spp, SEED_RGB, "rgb")
        assert not info.get("spectral"), info
        figures[f"RGB, {convention}"] = region_figures(images[convention], ref, masks, exposure)
    spectral, info = render(scene, args.spp, SEED_FLOOR, "auto")
    assert info.get("spectral"), info
    floor = region_figures(spectral, ref, masks, exposure)
    wall = time.perf_counter() - t0
    prov = reference.provenance
    order = list(masks)
    lines = [f"`{SCENE}`, {scene.camera.width}×{scene.camera.height}: Mitsuba {Mitsuba3().version().split()[0]} "
             f"RGB variant at {args.spp} spp (seed {SEED_RGB}) on each RGB projection, against the spectral "
             f"reference ({prov.get('variant')}, {prov.get('spp')} spp in {prov.get('batches')} batches); noise "
             f"floor: an independent {info['variant']} render at {args.spp} spp (seed {SEED_FLOOR}). Bold: more "
             f"than {CLAIM_FACTOR:g}× the floor. Benchmark time {wall:.0f} s.", "",
             "Mean per-pixel ΔE00:", "", *table(figures, floor, order, 0), "",
             "ΔE00 of the region's mean colour (systematic shift):", "", *table(figures, floor, order, 1), "",
             headline(figures, floor), "",
             f"![ΔE00 maps against the spectral reference]({Path('images') / args.figure.name})"]
    text = "\n".join(lines)
    print(text)
    panels = [*[(f"RGB, {c}", img) for c, img in images.items()], ("noise floor: spectral render", spectral)]
    write_figure(args.figure, [
        ("per pixel", FIGURE_RANGE, [(label, delta_e2000_linear(img, ref, exposure)) for label, img in panels]),
        (f"{BLOCK}x{BLOCK}-pixel block means", BLOCK_RANGE,
         [(label, delta_e2000_linear(block_means(img), block_means(ref), exposure)) for label, img in panels])])
    figure_manifest.record([args.figure], markdown_blocks.command_line())
    markdown_blocks.write_blocks(args.markdown, {"spectral.py": text})


if __name__ == "__main__":
    main()

"""The paper's image grid: ``OUT/figures/images.{svg,pdf,png}``, and each of its images as a PNG in ``OUT/images/``.

One row per image (the reference first, then each renderer, labelled with its
display name and, in a smaller line, the spp, seed and time of the run the image is), columns {tonemapped image, ΔE₀₀ map, FLIP map}, in the manner of
the pbrt-v4 and SeeSharp papers' comparison figures. The pixels are the
report's own: the image as :func:`cornell_harness.evaluate.metrics.display_encode`
shows it at the report's exposure, and the false-colour maps of
:func:`cornell_harness.reports.images.error_maps` on their fixed scales (ΔE₀₀ 0..10 viridis,
FLIP 0..1 magma), with one shared colour bar per map type.

Crops: the bounding box of each named region of the scene
(:func:`cornell_harness.evaluate.regions.region_masks`; at most :data:`MAX_CROPS`,
leaving out regions whose box is most of the image, as a crop of them is no
zoom), padded, clamped to the image and widened to at most
:data:`MAX_ASPECT`:1; or the rectangles given (``--crop x,y,w,h``), which
replace the regions. Each is framed in the full images in the region's colour
(:func:`cornell_harness.reports.regions.region_color`, as in the report's region overlay) and
shown below every image as an inset framed in the same colour, pixels drawn
nearest-neighbour.

The figure is a standalone SVG with the images embedded as PNG data URIs,
converted to PDF and PNG like the charts (:func:`cornell_harness.reports.figures.write_svg_pdf_png`).
Entry point: :func:`write_image_figure`, called by :func:`cornell_harness.reports.html.write_report`.
"""

from __future__ import annotations

import base64
import math
import re
from dataclasses import dataclass
from html import escape
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.store.atomic import atomic_path
from cornell_harness.store.experiments import cell_name
from cornell_harness.reports import figures
from cornell_harness.reports.figures import FIGURES_DIR, no_converter_note, say_once, write_svg_pdf_png
from cornell_harness.reports.images import (DELTA_E_RANGE, FLIP_RANGE, MAP_COLORMAPS, apply_colormap, colorbar_data_uri, error_maps,
                            png_data_uri, to_uint8)
from cornell_harness.reports.regions import region_color

#: The folder beside report.html with the images as PNGs (an experiment folder's, beside its EXRs).
IMAGES_DIR = "images"
#: The figure's file stem in ``figures/``.
STEM = "images"
#: A two-column paper's text width (a ``figure*``).
WIDTH_IN = 7.0
#: At most this many crops, in the scene's order of regions.
MAX_CROPS = 6
#: A region whose (padded) box covers more than this share of the image is not cropped.
MAX_REGION_SHARE = 0.5
#: A crop's box is padded by this share of its longer side (at least 2 px) on every side.
CROP_PAD = 0.15
#: A crop is widened until its sides are at most this ratio apart, and is at least MIN_CROP px a side.
MAX_ASPECT = 3.0
MIN_CROP = 8

#: (file suffix, column header, error map key or None for the tonemapped image)
COLUMNS = (("", "image", None), (".delta_e2000", "ΔE₀₀ (CIEDE2000)", "de"), (".flip", "FLIP", "flip"))
_RANGES = {"de": DELTA_E_RANGE, "flip": FLIP_RANGE}
_BAR_TITLES = {"de": "ΔE₀₀ per pixel, clipped at 10", "flip": "FLIP per pixel (HDR-FLIP)"}

# Layout in viewBox units (1 unit = 7 in / total width; about 0.6 pt at three columns).
_CELL, _GAP, _MARGIN, _HEADER, _ROW_GAP, _INSET_GAP, _FONT, _LINE = 240.0, 10.0, 8.0, 22.0, 12.0, 4.0, 13.0, 16.0
_STYLE = ('text{font-family:Helvetica,Arial,"Liberation Sans","DejaVu Sans",sans-serif;font-size:13px;fill:#000}'
          ".tick{font-size:11px;fill:#222}")
# A PNG this report writes into images/ (see _stale).
_DERIVED = re.compile(r"[\w.-]+?(\.delta_e2000|\.flip)?(\.crop-[\w.-]+)?\.png")


@dataclass(frozen=True)
class Crop:
    """A rectangle of the image, in pixels, with the name and colour it is shown with."""

    name: str
    color: str
    x: int
    y: int
    w: int
    h: int

    def take(self, pixels: np.ndarray) -> np.ndarray:
        return pixels[self.y:self.y + self.h, self.x:self.x + self.w]

    @property
    def label(self) -> str:
        """How the legend names it: the region, or the rectangle given (named by its number)."""
        box = f"{self.x},{self.y} {self.w}×{self.h} px"
        return f"crop {box}" if self.name.isdigit() else f"{self.name} ({box})"


def file_stem(name: str) -> str:
    """A renderer's file-safe name, as its cells' (``cornell_harness.store.experiments.cell_name``)."""
    return cell_name(name, 0).removesuffix("__seed0")


def checked_crops(crops: Sequence[Sequence[int]], width: int, height: int) -> list[tuple[int, int, int, int]]:
    """``--crop`` rectangles (x, y, w, h) clamped to a width × height image; ValueError (naming the crop) for
    one with no pixel inside it."""
    out = []
    for crop in crops:
        if len(crop) != 4:
            raise ValueError(f"crop {tuple(crop)}: expected x,y,w,h in pixels")
        x, y, w, h = (int(v) for v in crop)
        x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + w, width), min(y + h, height)
        if w <= 0 or h <= 0 or x1 <= x0 or y1 <= y0:
            raise ValueError(f"crop {x},{y},{w},{h}: no pixel of the {width}×{height} image is inside it")
        out.append((x0, y0, x1 - x0, y1 - y0))
    return out


def _grow(lo: int, size: int, want: int, limit: int) -> tuple[int, int]:
    """[lo, lo+size) widened about its centre to ``want`` (at most ``limit``), shifted back inside [0, limit)."""
    want = min(max(size, want), limit)
    lo = int(round(lo + size / 2 - want / 2))
    return min(max(lo, 0), limit - want), want


def region_box(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """(x, y, w, h) of the mask's bounding box, padded, widened to at most MAX_ASPECT:1 and MIN_CROP px, clamped
    to the image; None for an empty mask."""
    ys, xs = np.nonzero(mask)
    if not len(xs):
        return None
    height, width = mask.shape
    x, y = int(xs.min()), int(ys.min())
    w, h = int(xs.max()) - x + 1, int(ys.max()) - y + 1
    pad = max(2, int(math.ceil(CROP_PAD * max(w, h))))
    x, w = _grow(x, w, w + 2 * pad, width)
    y, h = _grow(y, h, h + 2 * pad, height)
    x, w = _grow(x, w, max(MIN_CROP, int(math.ceil(h / MAX_ASPECT))), width)
    y, h = _grow(y, h, max(MIN_CROP, int(math.ceil(w / MAX_ASPECT))), height)
    return x, y, w, h


def choose_crops(scene, shape: tuple[int, int], crops: Sequence[Sequence[int]] | None = None) -> list[Crop]:
    """The crops shown: ``crops`` (x, y, w, h) if given, named "1", "2", …; else the scene's regions (see the
    module's docstring), each in its region colour."""
    height, width = shape
    if crops:
        return [Crop(str(i + 1), region_color(i), *box) for i, box in enumerate(checked_crops(crops, width, height))]
    chosen = []
    for i, (name, mask) in enumerate(region_masks(scene).items()):
        box = region_box(mask) if mask.shape == (height, width) else None
        if box is not None and box[2] * box[3] <= MAX_REGION_SHARE * width * height:
            chosen.append(Crop(name, region_color(i), *box))
    return chosen[:MAX_CROPS]


def image_rows(reference: np.ndarray, images: Mapping[str, np.ndarray], exposure: float,
               maps: Mapping[str, Mapping] | None = None) -> list[tuple[str, list]]:
    """[(name, [pixels per column: tonemapped, ΔE₀₀, FLIP; None where there is none])], the reference first,
    named "reference" (it has no error maps). Images whose shape is not the
    reference's are left out (the viewer notes them). ``maps``: error maps already computed
    (:func:`cornell_harness.reports.images.error_maps`, by renderer), reused."""
    def tonemapped(img):
        return to_uint8(metrics.display_encode(img, exposure))

    rows: list[tuple[str, list]] = [("reference", [tonemapped(reference), None, None])]
    for name, img in images.items():
        if img is None or np.shape(img) != reference.shape:
            continue
        m = (maps or {}).get(name) or error_maps(np.asarray(img, dtype=np.float32), reference, exposure)
        rows.append((name, [tonemapped(img)] + [
            None if m[key] is None else apply_colormap(m[key], *_RANGES[key], MAP_COLORMAPS[key])
            for key in ("de", "flip")]))
    return rows


def _wrap(text: str, room: float, font: float = _FONT) -> list[str]:
    """``text`` in lines of at most ``room`` units (about 0.6 em a character), broken after spaces, commas,
    brackets and '='; a word longer than a line stays whole."""
    per_line = max(8, int(room / (0.6 * font)))
    lines, line = [], ""
    for token in re.findall(r"[^\s,\[=]*[\s,\[=]?", text):
        if line and len(line) + len(token.rstrip()) > per_line:
            lines.append(line.rstrip())
            line = ""
        line += token
    return [s for s in lines + [line.rstrip()] if s]


def _inset_layout(crops: Sequence[Crop]) -> tuple[float, list[tuple[float, float]]]:
    """(height, [(x offset, width)]) of the insets below a cell: one row, a common height, widths as the crops'
    aspect ratios, centred; at most half a cell high."""
    if not crops:
        return 0.0, []
    aspects = [c.w / c.h for c in crops]
    room = _CELL - _INSET_GAP * (len(crops) - 1)
    height = min(room / sum(aspects), _CELL / 2)
    widths = [a * height for a in aspects]
    x = (_CELL - sum(widths) - _INSET_GAP * (len(crops) - 1)) / 2
    out = []
    for w in widths:
        out.append((x, w))
        x += w + _INSET_GAP
    return height, out


def encoded(rows: Sequence[tuple[str, list]], crops: Sequence[Crop], columns: Sequence[int]) -> dict:
    """PNG data URIs (:func:`cornell_harness.reports.images.png_data_uri`) of every cell and inset, by (row name, column, crop
    name or ""): each encoded once, for the SVG and the PNG files alike."""
    return {(name, c, key): png_data_uri(crop.take(pixels[c]) if crop else pixels[c])
            for name, pixels in rows for c in columns if pixels[c] is not None
            for key, crop in [("", None)] + [(k.name, k) for k in crops]}


def _image(x, y, w, h, uri: str, cls: str) -> str:
    # optimizeSpeed: nearest neighbour in browsers and in CairoSVG (PDF images without /Interpolate).
    return (f'<image class="{cls}" x="{x:.2f}" y="{y:.2f}" width="{w:.2f}" height="{h:.2f}" '
            f'preserveAspectRatio="none" image-rendering="optimizeSpeed" href="{uri}"/>')


def _frame(x, y, w, h, color: str, cls: str, stroke: float) -> str:
    return (f'<rect class="{cls}" x="{x:.2f}" y="{y:.2f}" width="{w:.2f}" height="{h:.2f}" fill="none" '
            f'stroke="{color}" stroke-width="{stroke:g}"/>')


def _colorbar(key: str, x: float, y: float) -> list[str]:
    lo, hi = _RANGES[key]
    width, values = _CELL * 0.9, np.linspace(lo, hi, 6)
    x0 = x + (_CELL - width) / 2
    parts = [f'<g class="colorbar" data-map="{key}">',
             f'<text x="{x + _CELL / 2:.2f}" y="{y + 11:.2f}" text-anchor="middle" class="tick">'
             f'{escape(_BAR_TITLES[key])}</text>',
             f'<image x="{x0:.2f}" y="{y + 15:.2f}" width="{width:.2f}" height="10" preserveAspectRatio="none" '
             f'href="{colorbar_data_uri(MAP_COLORMAPS[key])}"/>',
             _frame(x0, y + 15, width, 10, "#333", "colorbar-frame", 0.5)]
    for v in values:
        tx = x0 + width * (v - lo) / (hi - lo)
        text = f"{v:g}" + ("+" if key == "de" and v == hi else "")
        parts.append(f'<line x1="{tx:.2f}" x2="{tx:.2f}" y1="{y + 25:.2f}" y2="{y + 28:.2f}" stroke="#333"/>'
                     f'<text class="tick" x="{tx:.2f}" y="{y + 39:.2f}" text-anchor="middle">{text}</text>')
    return parts + ["</g>"]


def _crop_legend(crops: Sequence[Crop], x: float, y: float) -> list[str]:
    if not crops:
        return []
    parts = ['<g class="crop-legend">', f'<text x="{x:.2f}" y="{y + 13:.2f}">crops, framed in their colours:</text>']
    for k, crop in enumerate(crops):
        ty, text = y + 32 + 17 * k, crop.label
        if len(text) * 0.6 * 11 > _CELL - 18:  # the name alone rather than past the cell (the figure's edge)
            text = crop.name
        parts.append(f'<rect class="swatch" x="{x:.2f}" y="{ty - 10:.2f}" width="11" height="11" '
                     f'fill="{crop.color}"/><text class="tick" x="{x + 17:.2f}" y="{ty:.2f}">{escape(text)}</text>')
    return parts + ["</g>"]


def image_captions(viewer: Mapping, reference_spp, time_column: str = "time_s") -> dict[str, str]:
    """Row name -> what its image is: "64 spp, seed 0, 3.41 s wall" from the viewer's entries
    (:func:`cornell_harness.reports.viewer.image_viewer`), the reference's spp; parts unknown are left out."""
    clock = "CPU" if time_column == "cpu_time_s" else "wall"
    out = {"reference": f"{int(reference_spp)} spp"} if reference_spp is not None else {}
    for e in viewer.get("renderers", ()):
        parts = [f"{e['spp']} spp" if e.get("spp") is not None else "",
                 f"seed {e['seed']}" if e.get("seed") is not None else "",
                 f"{e['time_s']:.3g} s {clock}" if e.get("time_s") is not None else ""]
        out[e["name"]] = ", ".join(p for p in parts if p)
    return {k: v for k, v in out.items() if v}


def figure_svg(rows: Sequence[tuple[str, list]], crops: Sequence[Crop], columns: Sequence[int],
               labels: Mapping[str, str], uris: Mapping | None = None, captions: Mapping[str, str] | None = None
               ) -> str:
    """The grid as a standalone SVG document. ``rows``: :func:`image_rows`'s; ``columns``: indices into
    :data:`COLUMNS` shown; ``labels``: row name -> display text; ``uris``: :func:`encoded`'s, if at hand;
    ``captions``: row name -> its spp, seed and time (:func:`image_captions`), a smaller line under the name."""
    captions = captions or {}
    uris = encoded(rows, crops, columns) if uris is None else uris
    img_h, img_w = rows[0][1][0].shape[:2]
    cell_h = _CELL * img_h / img_w
    scale = _CELL / img_w
    inset_h, insets = _inset_layout(crops)
    row_h = cell_h + (_INSET_GAP + inset_h if crops else 0.0)
    wrapped = {name: _wrap(labels.get(name, name), row_h) for name, _ in rows}
    label_w = _LINE * max(len(lines) + (name in captions) for name, lines in wrapped.items()) + 6
    left = _MARGIN + label_w
    col_x = [left + j * (_CELL + _GAP) for j in range(len(columns))]
    width = col_x[-1] + _CELL + _MARGIN
    body = [f'<text x="{x + _CELL / 2:.2f}" y="{_MARGIN + 13:.2f}" text-anchor="middle" class="column-header">'
            f"{escape(COLUMNS[c][1])}</text>" for x, c in zip(col_x, columns)]
    y = _MARGIN + _HEADER
    for name, pixels in rows:
        lines = [(line, "") for line in wrapped[name]] + ([(captions[name], ' class="tick"')]
                                                          if name in captions else [])
        cx = _MARGIN + label_w / 2 - _LINE * (len(lines) - 1) / 2 + 4
        cy = y + row_h / 2
        body.append(f'<g class="row-label" data-row="{escape(name)}">' + "".join(
            f'<text transform="translate({cx + k * _LINE:.2f},{cy:.2f}) rotate(-90)" text-anchor="middle"{cls}>'
            f"{escape(line)}</text>" for k, (line, cls) in enumerate(lines)) + "</g>")
        if name == "reference" and len(columns) > 1:  # the legend of the crops, where the maps would be
            body += _crop_legend(crops, col_x[1], y)
        for x, c in zip(col_x, columns):
            if pixels[c] is None:
                continue
            body.append(_image(x, y, _CELL, cell_h, uris[name, c, ""], "cell"))
            for crop, (dx, w) in zip(crops, insets):
                body.append(_frame(x + crop.x * scale, y + crop.y * scale, crop.w * scale, crop.h * scale,
                                   crop.color, "crop-frame", 1.5))
                iy = y + cell_h + _INSET_GAP
                body.append(_image(x + dx, iy, w, inset_h, uris[name, c, crop.name], "inset"))
                body.append(_frame(x + dx, iy, w, inset_h, crop.color, "inset-frame", 2))
        y += row_h + _ROW_GAP
    for x, c in zip(col_x, columns):
        if COLUMNS[c][2] is not None:
            body += _colorbar(COLUMNS[c][2], x, y)
    height = y + 44 + _MARGIN
    return ('<?xml version="1.0" encoding="UTF-8"?>\n'
            f'<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH_IN}in" '
            f'height="{WIDTH_IN * height / width:.3f}in" viewBox="0 0 {width:.2f} {height:.2f}">'
            f'<style>{_STYLE}</style><rect width="100%" height="100%" fill="#fff"/>' + "\n".join(body) + "</svg>\n")


def _write_png(path: Path, uri: str) -> None:
    """The PNG of a data URI, written atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(base64.b64decode(uri.split(",", 1)[1]))


def _stale(folder: Path, keep: set[str], stems: set[str]) -> None:
    """Remove PNGs of an earlier report that this one did not write: those with this module's suffixes
    (``.delta_e2000``, ``.flip``, ``.crop-…``), and ``STEM.png`` whose stem is the reference's or a cell's
    (``STEM__seed*.exr`` beside it) or one this report writes. Other PNGs are not this module's and stay."""
    if not folder.is_dir():
        return
    for path in folder.iterdir():
        m = _DERIVED.fullmatch(path.name)
        if not m or path.name in keep or not path.is_file():
            continue
        base = path.name[:-len(".png")]
        if m.group(1) or m.group(2) or base in stems or any(
                p.name.startswith(f"{base}__seed") for p in folder.glob("*.exr")):
            path.unlink()


def _remove_figure(folder: Path, keep: set[str]) -> None:
    """Remove ``images.{svg,pdf,png}`` of an earlier report but the formats in ``keep``."""
    for fmt in {"svg", "pdf", "png"} - keep:
        (folder / f"{STEM}.{fmt}").unlink(missing_ok=True)


def write_image_figure(report_dir, *, scene, reference_image, images: Mapping[str, np.ndarray], exposure: float,
                       series_labels: Mapping[str, str] | None = None, crops: Sequence[Sequence[int]] | None = None,
                       maps: Mapping[str, Mapping] | None = None, captions: Mapping[str, str] | None = None
                       ) -> dict:
    """Write ``figures/images.{svg,pdf,png}`` and ``images/*.png`` under ``report_dir``, atomically; return what
    was written, paths relative to ``report_dir``: ``{"figure": [(format, path)], "pngs": [path]}``
    (empty lists without images to show).

    ``images``: renderer -> linear image of the reference's shape; ``exposure``: the report's display exposure;
    ``series_labels``: recorded name -> display text of the rows; ``crops``: (x, y, w, h) rectangles that
    replace the scene's regions; ``maps``: error maps already computed by renderer (the viewer's), reused;
    ``captions``: row name -> the spp, seed and time of its image (:func:`image_captions`).
    Raises ValueError for a crop outside the image; never for a missing converter.
    """
    report_dir = Path(report_dir)
    reference = np.asarray(reference_image, dtype=np.float32)
    rows = image_rows(reference, images, exposure, maps)
    if len(rows) < 2:
        _remove_figure(report_dir / FIGURES_DIR, set())
        return {"figure": [], "pngs": []}
    shown = range(len(COLUMNS))
    chosen = choose_crops(scene, reference.shape[:2], crops)

    uris = encoded(rows, chosen, shown)
    folder = report_dir / IMAGES_DIR
    pngs = []
    for (name, c, crop), uri in uris.items():
        path = f"{IMAGES_DIR}/{file_stem(name)}{COLUMNS[c][0]}{f'.crop-{file_stem(crop)}' if crop else ''}.png"
        _write_png(report_dir / path, uri)
        pngs.append(path)
    _stale(folder, {Path(p).name for p in pngs}, {file_stem(name) for name, _ in rows})

    svg = figure_svg(rows, chosen, shown, dict(series_labels or {}), uris=uris, captions=captions)
    cairosvg, why_not = figures._converter()  # looked up through the module: tests replace it there
    done, failed = write_svg_pdf_png(report_dir / FIGURES_DIR, STEM, svg, cairosvg)
    _remove_figure(report_dir / FIGURES_DIR, set(done))
    if cairosvg is None:
        say_once(no_converter_note(why_not))
    elif failed:
        say_once(f"the image figure could not be converted: {failed[0]}")
    return {"figure": [(fmt.upper(), f"{FIGURES_DIR}/{STEM}.{fmt}") for fmt in done], "pngs": pngs}

"""``cbox compare-image``'s pictures: a false-colour error map per image file, and the HTML report of them.

The error map is the viewer's ΔE00 map (:func:`cornell_harness.reports.images.error_maps`'
``de``: CIEDE2000 per pixel at the reference's display exposure, viridis on
the fixed 0..10 scale of :data:`cornell_harness.reports.images.DELTA_E_RANGE`) as a PNG
file. The report is the comparison report (:func:`cornell_harness.reports.html.write_report`)
with one entry per image file where a comparison has one per renderer: the
summary table, the viewer with its ΔE, relMSE and FLIP maps, and the regions
when a scene names them (the regions table lists images of known spp
only: its rows are per spp). For a reference given as a bare image file,
:class:`BareReference` stands in for the scene: the report shows the
file's name and size and marks the rest unknown.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
from pathlib import Path
from typing import Sequence

import numpy as np
from PIL import Image

from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.image_scores import ImageScore, Target
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY
from cornell_harness.store.atomic import atomic_path
from cornell_harness.reports.images import DELTA_E_RANGE, MAP_COLORMAPS, TABLES, apply_colormap

#: Suffix of each image's error-map file: ``<label>.delta_e.png``.
ERROR_MAP_SUFFIX = ".delta_e.png"


@dataclasses.dataclass(frozen=True)
class _Size:
    width: int
    height: int


@dataclasses.dataclass(frozen=True)
class BareReference:
    """The scene fields the report shows, for a reference that is only an image file: no depth, filter or
    regions are known."""

    name: str
    camera: _Size
    quantity: str = DEFAULT_QUANTITY
    description: str = "a reference image file, not a scene: its depth and pixel filter are unknown"
    max_depth: int | None = None
    pixel_filter: str = "unknown"
    regions: dict = dataclasses.field(default_factory=dict)

    def content_hash(self) -> str:
        return "none (an image file)"


def delta_e_png(img, ref, quantity: str = DEFAULT_QUANTITY, de: np.ndarray | None = None) -> np.ndarray:
    """The ΔE00 error map of ``img`` against ``ref`` as uint8 RGB pixels, as the report's viewer colours it;
    ``de``: that map (H, W), when the caller has computed it already."""
    if de is None:
        _, de = metrics.delta_e2000(img, ref, exposure=metrics.display_exposure(ref, quantity), full=True)
    return apply_colormap(de, *DELTA_E_RANGE, cmap=MAP_COLORMAPS["de"])


def write_error_map(folder: Path, score: ImageScore, target: Target, de: np.ndarray | None = None) -> Path:
    """``folder/<label>.delta_e.png`` of one scored image (``de``: its ΔE00 map, if computed); returns its path."""
    path = Path(folder) / f"{score.source.label}{ERROR_MAP_SUFFIX}"
    if de is None:
        _, de = metrics.delta_e2000(score.source.image, target.reference.image,
                                    exposure=metrics.display_exposure(target.reference.image,
                                                                      target.reference.quantity), full=True)
    with atomic_path(path) as tmp:
        # A palette PNG of the colour map's 256 entries: the pixels delta_e_png gives, a third of the bytes to
        # deflate (3 ms instead of 9 per 256²), at the fastest zlib level (optimize=True made the
        # map's write a tenth of the command's time).
        image = Image.fromarray(colormap_indices(de, *DELTA_E_RANGE))
        image.putpalette(TABLES[MAP_COLORMAPS["de"]].astype(np.uint8).tobytes())
        image.save(tmp, format="PNG", compress_level=1)
    return path


def colormap_indices(values, vmin: float, vmax: float) -> np.ndarray:
    """The uint8 index into a 256-entry colour table of each value: :func:`cornell_harness.reports.images.apply_colormap`'s rule
    (clipped to [vmin, vmax], NaN the top of the scale), so ``TABLES[cmap][indices]`` is its pixels."""
    t = np.clip((np.asarray(values, dtype=np.float64) - vmin) / (vmax - vmin), 0.0, 1.0)
    t[np.isnan(t)] = 1.0
    return np.round(t * 255).astype(np.uint8)


def write_compare_image_report(path: Path, target: Target, scores: Sequence[ImageScore], command: str) -> Path:
    """The HTML report of the scored images against ``target`` at ``path``; returns the path."""
    # Here, not at the top: the report's modules import pandas and SciPy's stats (seconds), which
    # `cbox compare-image` without --report does not pay (its cost is held within 3× idiff's: BENCHMARKS.md).
    import pandas as pd

    from cornell_harness.store.provenance import provenance
    from cornell_harness.reports.html import write_report

    runs = pd.DataFrame([{"renderer": s.source.label, "status": "ok", "spp": s.source.spp, "seed": None,
                          "version": None, **s.row()} for s in scores])
    # The summary table takes a run's numbers from rows of known spp; these rows give them to every image.
    summary = pd.DataFrame([{"renderer": s.source.label, **s.row()} for s in scores])
    ref = target.reference.image
    scene = target.scene if target.scene is not None else BareReference(
        target.path.name, _Size(ref.shape[1], ref.shape[0]), target.reference.quantity)
    prov = provenance({"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                       "kind": "compare-image"}, runs)
    prov["images"] = {s.source.label: str(s.source.path) for s in scores}
    prov["reference file"] = str(target.path)
    if scores and scores[0].flip_parameters is not None:
        prov["HDR-FLIP parameters"] = scores[0].flip_parameters
    return write_report(path, scene=scene, reference=target.reference, runs=runs, summary=summary,
                        images={s.source.label: s.source.image for s in scores}, provenance=prov, command=command,
                        title=f"cbox compare-image — {target.label}")

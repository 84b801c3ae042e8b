"""The score of an image made outside the harness (``cbox compare-image``): what it is scored against and
its numbers. Computed by :mod:`cornell_harness.workflows.compare_image`, drawn by :mod:`cornell_harness.reports.compare_image`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from cornell_harness.evaluate import regions as named_regions
from cornell_harness.scenes.model import Scene
from cornell_harness.store.atomic import json_safe

if TYPE_CHECKING:
    from cornell_harness.store.references import Reference


@dataclass
class Target:
    """What test images are scored against: the reference, its file, and the scene whose regions are scored."""

    reference: Reference  # its variance and noise are None when none is stored
    path: Path  # the reference image file
    scene: Scene | None = None  # with a scene: its regions are scored
    noise_note: str | None = None  # why this reference cannot give noise yardsticks, if it cannot
    clipped: float | None = None  # a display-referred reference file: the fraction of its pixels clipped

    @property
    def label(self) -> str:
        return self.scene.name if self.scene is not None else str(self.path)


@dataclass
class InputImage:
    """One test image, linear and checked against its target."""

    path: Path
    label: str  # unique among the images of one run (names output files and report entries)
    image: np.ndarray = field(repr=False)  # (H, W, 3) float32 linear
    spp: int | None  # from its header or given; None: unknown
    clipped: float | None = None  # display-referred files: the fraction of pixels clipped at 0 or full scale


@dataclass
class ImageScore:
    """One test image's numbers: image metrics, noise yardsticks (or why not), region metrics."""

    source: InputImage
    metrics: dict
    noise: dict | None
    noise_note: str | None
    regions: dict
    flip_parameters: dict | None  # the HDR-FLIP viewing conditions flip_mean was computed under
    delta_e_map: Any = None  # (H, W) ΔE00 at the reference's display exposure: the error map's and --fail-percent's
    orientation_note: str | None = None  # "image looks flipped vertically: ..." (evaluate.orientation), or None

    def record(self, target: Target) -> dict:
        """The score as strict-JSON-ready nested dicts (non-finite numbers as None)."""
        return json_safe({
            "image": str(self.source.path), "label": self.source.label, "reference": str(target.path),
            "scene": target.scene.name if target.scene is not None else None, "spp": self.source.spp,
            "metrics": self.metrics, "noise": self.noise, "noise_note": self.noise_note, "regions": self.regions,
            "flip_parameters": self.flip_parameters, "orientation_note": self.orientation_note})

    def row(self) -> dict:
        """Flat: metrics, yardsticks and ``region.<name>.<metric>`` columns (a results-table row's form)."""
        return {**self.metrics, **(self.noise or {}), **named_regions.region_columns(self.regions)}

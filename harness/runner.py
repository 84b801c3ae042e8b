"""The runner: renders a scene with each renderer and scores it against the reference.

A renderer that is unavailable here, or does not model a feature the scene
uses, is never run; its record says why (``status`` "unavailable" or
"skipped"). A renderer that raises is recorded as "failed" with the error, and
the other renderers still run.
"""

from __future__ import annotations

import json
import math
import traceback
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from harness import metrics, stats
from harness.adapter import RendererEntry, missing_features
from harness.reference import Reference
from harness.scene import Scene

STATUSES = ("ok", "skipped", "unavailable", "failed")


def settings_of(scene: Scene) -> str:
    """The scene settings that define what a run computes, as canonical JSON."""
    cam = scene.camera
    return json.dumps({"max_depth": scene.max_depth, "width": cam.width, "height": cam.height,
                       "pixel_filter": scene.pixel_filter}, sort_keys=True)


@dataclass
class RunRecord:
    """One renderer on one scene at one (spp, seed): outcome, image and metrics."""

    scene: str
    renderer: str
    status: str
    spp: int
    seed: int
    scene_hash: str = ""
    settings: str = "{}"
    reason: str | None = None
    version: str | None = None
    time_s: float | None = None
    approximations: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    image: np.ndarray | None = field(default=None, repr=False)
    variance: np.ndarray | None = field(default=None, repr=False)  # of the image, when the renderer gives it
    checkpoints: list = field(default_factory=list, repr=False)  # harness.adapter.Checkpoint

    @classmethod
    def new(cls, scene: Scene, renderer: str, spp: int, seed: int, **fields) -> "RunRecord":
        return cls(scene.name, renderer, "ok", spp, seed, scene.content_hash(), settings_of(scene), **fields)

    def row(self) -> dict:
        """Flat, JSON-serialisable record (no image): one row of the results table."""
        out = {
            "scene": self.scene,
            "scene_hash": self.scene_hash,
            "renderer": self.renderer,
            "status": self.status,
            "reason": self.reason,
            "version": self.version,
            "settings": self.settings,
            "approximations": json.dumps(list(self.approximations)),
            "spp": self.spp,
            "seed": self.seed,
            "time_s": None if self.time_s is None else round(self.time_s, 4),
        }
        out.update(self.metrics)
        if "mse" in self.metrics and self.time_s:
            out["efficiency"] = 1.0 / (self.metrics["mse"] * self.time_s) if self.metrics["mse"] > 0 else math.inf
        for k, v in self.info.items():
            out[f"info_{k}"] = v if isinstance(v, (str, int, float, bool)) or v is None else json.dumps(v)
        return out


def json_safe(row: dict) -> dict:
    """The row with non-finite floats (e.g. PSNR of identical images) as None: strict JSON."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in row.items()}


def run_one(entry: RendererEntry, scene: Scene, spp: int, seed: int, reference: Reference | None,
            checkpoints: Sequence[int] = ()) -> RunRecord:
    """Render and score one renderer; never raises for the renderer's own failures."""
    rec = RunRecord.new(scene, entry.name, spp, seed)
    if not entry.available:
        rec.status, rec.reason = "unavailable", entry.reason
        return rec
    r = entry.renderer
    rec.approximations = tuple(getattr(r, "approximations", ()))
    if missing := missing_features(r, scene):
        rec.status, rec.reason = "skipped", f"does not model {', '.join(missing)}"
        return rec
    try:
        rec.version = str(r.version())
        result = r.render(scene, spp, seed, checkpoints=list(checkpoints)) if checkpoints else \
            r.render(scene, spp, seed)
        image = np.asarray(result.image, dtype=np.float32)
        expected = (scene.camera.height, scene.camera.width, 3)
        if image.shape != expected:
            raise ValueError(f"returned an image of shape {image.shape}, expected {expected}")
    except Exception as e:  # any renderer bug must be reported, not crash the run
        rec.status = "failed"
        rec.reason = f"{type(e).__name__}: {e}"
        rec.info = {"traceback": traceback.format_exc(limit=8)}
        return rec
    rec.time_s, rec.info, rec.image = float(result.time_s), dict(result.info), image
    rec.variance, rec.checkpoints = result.variance, list(result.checkpoints)
    if reference is not None:
        rec.metrics = score(image, reference, spp)
    else:
        rec.metrics = metrics.invalid_pixel_counts(image)
    return rec


def score(image: np.ndarray, reference: Reference, spp: int) -> dict:
    """Every metric of ``image`` against the reference, plus its noise yardsticks."""
    out = metrics.image_metrics(image, reference.image)
    out.update(stats.noise_yardsticks(image, reference, spp))
    return out


def compare(scene: Scene, entries: Sequence[RendererEntry], spp: int, seed: int,
            reference: Reference | None) -> list[RunRecord]:
    """:func:`run_one` for each renderer, in order."""
    return [run_one(entry, scene, spp, seed, reference) for entry in entries]

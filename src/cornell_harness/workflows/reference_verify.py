"""Verifying a reference: render the scene with a second engine, compare region by region, record the verdict.

A stored reference comes from one engine (Mitsuba 3), which cannot show its
own mistakes. :func:`verify_reference` renders the scene again with another
engine (any registered renderer; the ``luxcore`` one is independent code) at
seeds from :data:`VERIFY_SEED_BASE`, none of the reference's, and judges the
two with :func:`cornell_harness.evaluate.reference_agreement.reference_agreement`.
The engine's variance of its mean comes from the spread of ``batches``
independent renders, as the reference's does (:func:`render_batches`, on the
executor ``--workers`` opens), or, with ``batches`` = 1, from the engine
itself (its :class:`~cornell_harness.adapters.api.RenderResult` ``variance``).

:func:`cornell_harness.store.references.record_verdict` records the verdict in the
user store (``verdicts.json`` of the reference's folder there), atomically, with
the digest of the images it judged: the reference's own files, the package's
stored ones included, are never written. A rebuilt reference has other images,
so the verdicts recorded on the old ones are no longer shown beside it.
"""

from __future__ import annotations

import datetime as _dt
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from cornell_harness.adapters.registry import RendererEntry, RendererError
from cornell_harness.adapters.settings import canonical
from cornell_harness.evaluate.reference_agreement import FAMILY_ALPHA, ReferenceAgreement, reference_agreement
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.model import Scene
from cornell_harness.store.references import Reference
from cornell_harness.workflows.cells import entry_for
from cornell_harness.workflows.executor import DaskExecutor, ExecutorError, InProcess, Task, task_key
from cornell_harness.workflows.reference_build import render_batches
from cornell_harness.workflows.runner import render_timed

#: First seed of a verification's renders: far from the reference's (``REFERENCE_SEED_BASE`` = 10⁹ up) and from
#: any user run's, and below 2³¹ for engines that take a signed 32-bit seed.
VERIFY_SEED_BASE = 2_000_000_000
#: Independent renders whose spread gives the engine's variance, by default.
DEFAULT_BATCHES = 16


class VerifyError(RendererError):
    """A verification cannot run as asked (spp not a multiple of batches, an engine without a variance); a
    user error, reported as one line."""


@dataclass
class Verification:
    """A second engine's render of a scene and its verdict against the stored reference."""

    agreement: ReferenceAgreement
    image: np.ndarray  # (H, W, 3) the engine's mean
    variance: np.ndarray  # its variance of the mean
    record: dict  # what :func:`record_verdict` stores
    margins: np.ndarray | None = None  # (regions, 3) the margins of the three-way verdict

    @property
    def verdict(self) -> str:
        """pass, fail or inconclusive against the margins."""
        return self.agreement.verdict(self.margins)


def render_with_variance(spec: str, settings: dict, scene: Scene, spp: int, seed: int,
                         entry: RendererEntry | None = None, time_limit_s: float | None = None
                         ) -> tuple[np.ndarray, np.ndarray | None, float, dict]:
    """One render through the one render path, with the variance the renderer reports (None if it reports none);
    with ``time_limit_s``, in a child process ended at it."""
    entry = (entry or entry_for(spec, settings)).with_time_limit(time_limit_s)
    result, _ = render_timed(entry, scene, spp, seed)
    return result.image, result.variance, float(result.time_s), dict(result.info)


def render_engine(scene: Scene, entry: RendererEntry, spp: int, batches: int,
                  executor: InProcess | DaskExecutor | None = None,
                  progress: Callable[[int, int, str], None] | None = None
                  ) -> tuple[np.ndarray, np.ndarray, float, dict, list[int]]:
    """The engine's image of ``spp`` samples, its variance of the mean, render seconds, info and seeds."""
    if batches < 1 or spp % batches:
        raise VerifyError(f"spp ({spp}) must be a positive multiple of batches ({batches})")
    seeds = [VERIFY_SEED_BASE + b for b in range(batches)]
    if batches >= 2:
        done = render_batches(scene, entry, spp // batches, seeds, executor, progress)
        return done.mean, done.variance, done.wall_s, done.info, seeds
    executor = executor or InProcess()
    task = Task(task_key("verify", scene.content_hash(), entry.spec, canonical(entry.settings), spp, seeds[0]),
                f"{entry.name} {spp} spp", render_with_variance,
                (entry.spec, dict(entry.settings), executor.share(scene), spp, seeds[0],
                 entry if executor.local else None, entry.time_limit_s))
    (outcome,) = list(executor.run([task]))
    if outcome.error is not None:
        raise ExecutorError(f"{entry.name} render (seed {seeds[0]}) failed: {outcome.error}")
    image, variance, time_s, info = outcome.value
    if progress:
        progress(1, 1, task.label)
    if variance is None:
        raise VerifyError(f"{entry.name} reports no variance of its image; verify with --batches 2 or more, whose "
                          "spread gives one")
    return np.asarray(image, np.float64), np.asarray(variance, np.float64), time_s, info, seeds


def verify_reference(scene: Scene, reference: Reference, entry: RendererEntry, spp: int,
                     batches: int = DEFAULT_BATCHES, executor: InProcess | DaskExecutor | None = None,
                     progress: Callable[[int, int, str], None] | None = None,
                     alpha: float = FAMILY_ALPHA, margins: Mapping[str, float] | None = None) -> Verification:
    """Render ``scene`` with ``entry`` and judge it against ``reference`` in the scene's regions and the whole
    image (:func:`~cornell_harness.evaluate.reference_agreement.reference_agreement`), three ways against
    ``margins`` (relative, by region name or ``image``; the others the defaults of their kind). Nothing is
    written."""
    image, variance, wall, info, seeds = render_engine(scene, entry, spp, batches, executor, progress)
    agreement = reference_agreement(reference.image, reference.variance, image, variance, region_masks(scene), alpha)
    margin_array = agreement.margins(margins)
    record = {
        "engine": entry.name,
        "engine_version": entry.renderer.version(),
        "settings": entry.settings,
        "spp": spp,
        "batches": batches,
        "variance": ("spread of the batches: unbiased sample variance / batches" if batches >= 2 else
                     "the engine's own variance of its mean"),
        "seeds": [seeds[0], seeds[-1]] if len(seeds) > 1 else seeds,
        "wall_time_s": round(wall, 3),
        "reference_spp": reference.spp,
        **agreement.summary(margin_array),
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
    }
    if info.get("variant"):
        record["variant"] = info["variant"]
    return Verification(agreement, image, variance, record, margin_array)


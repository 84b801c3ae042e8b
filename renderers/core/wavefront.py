"""The render loop shared by our renderers: passes, work units, threads, checkpoints.

A render of ``spp`` samples per pixel is split into passes
(:func:`harness.sampling.spp_passes`; pass sizes double, so power-of-two
checkpoints come free). A pass of ``n`` samples over ``P`` pixels is a range
of ``n·P`` path indices (pixel = index mod P), cut into work units of
:data:`UNIT_PATHS` paths. Each unit

- draws its random numbers from its own stream,
  ``SeedSequence([seed, pass, unit])``, and
- returns one radiance estimate per path, which is added (with its square,
  for the per-pixel variance) into the image in unit order.

So the image depends on the seed only, never on the number of threads or on
which thread ran which unit: it is bit-identical for 1 or 16 threads. Memory
is bounded by a few units in flight, whatever the spp. Units are large
(≥ 64k rays) because embreex releases the GIL only for batches that big.
"""

from __future__ import annotations

import os
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Sequence

import numpy as np

from harness.adapter import Checkpoint, RenderResult
from harness.sampling import spp_passes
from harness.scene import Scene

UNIT_PATHS = 1 << 17
#: Pass sizes double without a cap: the unit size already bounds memory.
_NO_CAP = 1 << 40

#: trace(pixel indices (m,), rng) -> radiance estimates (m, 3) float64
TraceFn = Callable[[np.ndarray, np.random.Generator], np.ndarray]


def default_threads() -> int:
    """Worker threads: ``$CBOX_THREADS`` or the machine's CPU count."""
    env = os.environ.get("CBOX_THREADS")
    if env:
        return max(1, int(env))
    return os.cpu_count() or 1


def _add_paths(acc: np.ndarray, start: int, values: np.ndarray) -> None:
    """acc[(start + i) mod P] += values[i], in a fixed order (deterministic)."""
    p, m = acc.shape[0], values.shape[0]
    first = start % p
    if m > p:  # small images: fold whole rounds with one reshape-sum
        padded = np.zeros((-(-(first + m) // p) * p, values.shape[1]))
        padded[first:first + m] = values
        acc += padded.reshape(-1, p, values.shape[1]).sum(axis=0)
        return
    head = min(m, p - first)
    acc[first:first + head] += values[:head]
    if head < m:
        acc[: m - head] += values[head:]


def render_wavefront(
    scene: Scene,
    spp: int,
    seed: int,
    trace: TraceFn,
    checkpoints: Sequence[int] = (),
    threads: int | None = None,
    info: dict | None = None,
) -> RenderResult:
    """Run ``trace`` over every (pixel, sample) and average into an image."""
    if spp < 1:
        raise ValueError(f"spp must be >= 1, got {spp}")
    cam = scene.camera
    p = cam.width * cam.height
    threads = threads or default_threads()
    acc = np.zeros((p, 3))
    acc2 = np.zeros((p, 3))  # sums of squares, for the per-pixel variance
    done, elapsed, shots = 0, 0.0, []

    def run_unit(job: tuple[int, int, int, int]) -> np.ndarray:
        k, u, start, stop = job
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, k, u])))
        pixel = np.arange(start, stop, dtype=np.int64) % p
        values = trace(pixel, rng)
        return values, values * values

    def _reduce(start: int, fut) -> None:
        values, squares = fut.result()
        _add_paths(acc, start, values)
        _add_paths(acc2, start, squares)

    with ThreadPoolExecutor(max_workers=threads) as pool:
        for k, n in enumerate(spp_passes(spp, _NO_CAP, checkpoints)):
            t0 = time.perf_counter()
            total = n * p
            jobs = [(k, u, s, min(s + UNIT_PATHS, total)) for u, s in enumerate(range(0, total, UNIT_PATHS))]
            # A sliding window of 2·threads units in flight bounds memory at any
            # spp; results are added oldest first, so the sum order is fixed.
            pending: deque = deque()
            for job in jobs:
                pending.append((job[2], pool.submit(run_unit, job)))
                if len(pending) >= 2 * threads:
                    _reduce(*pending.popleft())
            while pending:
                _reduce(*pending.popleft())
            elapsed += time.perf_counter() - t0
            done += n
            if done in checkpoints and done < spp:
                shots.append(Checkpoint(done, (acc / done).reshape(cam.height, cam.width, 3).astype(np.float32), elapsed))
    shape = (cam.height, cam.width, 3)
    mean = acc / spp
    image = mean.reshape(shape).astype(np.float32)
    if spp in checkpoints:
        shots.append(Checkpoint(spp, image, elapsed))
    variance = None
    if spp > 1:  # unbiased sample variance / spp: the variance of the pixel mean
        variance = (np.maximum(acc2 / spp - mean * mean, 0.0) / (spp - 1)).reshape(shape).astype(np.float32)
    return RenderResult(image, elapsed, spp, seed, shots, {"threads": threads, **(info or {})}, variance)

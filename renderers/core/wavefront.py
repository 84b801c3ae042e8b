"""The render loop shared by our renderers: passes, work units, threads, checkpoints.

A render of ``spp`` samples per pixel is split into passes
(:func:`harness.sampling.spp_passes`; pass sizes double, so power-of-two
checkpoints come free). A pass of ``n`` samples over ``P`` pixels is a range
of ``n·P`` paths (path j looks through pixel j mod P), cut into work units.

- Random numbers are a pure function of (pass key, path index, dimension)
  (:mod:`renderers.core.rng`; the pass key comes from
  ``SeedSequence([seed, pass])``), so they do not depend on how the paths
  are cut into units.
- Each unit returns one radiance estimate per path; estimates are added into
  the image path by path, in path order (:func:`accumulate`), units in order.

So the image depends on the seed only: it is bit-identical for any number
of threads, though the unit size follows the thread count to keep every
thread busy. Units of all passes flow through one pipeline (no barrier
between passes), at most ``2·threads`` in flight, so memory is bounded at
any spp. Unit sizes (2^13 to 2^15 paths) were measured on the Cornell box
(BENCHMARKS.md): smaller units keep a unit's arrays in cache, and embreex
still releases the GIL for batches of that size (2 threads: 1.7-2x).
"""

from __future__ import annotations

import os
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterator, Sequence

import numpy as np

from harness.adapters.registry import Checkpoint, RenderResult
from harness.adapters.seeds import pass_key, spp_passes
from harness.scenes.model import Scene
from renderers.core.sampling import jit

MAX_UNIT_PATHS = 1 << 15
MIN_UNIT_PATHS = 1 << 13
#: Pass sizes double without a cap: the unit size already bounds memory.
_NO_CAP = 1 << 40

#: trace(first, stop, pixels, key) -> radiance estimates (stop - first, 3) float64
#: for the paths first..stop-1 of a pass; path j looks through pixel j mod pixels.
TraceFn = Callable[[int, int, int, np.uint64], np.ndarray]


def default_threads() -> int:
    """Worker threads: ``$CBOX_THREADS`` or the machine's CPU count."""
    env = os.environ.get("CBOX_THREADS")
    if env:
        return max(1, int(env))
    return os.cpu_count() or 1


@jit
def accumulate(acc, acc2, first, values):
    """acc[(first + i) mod P] += values[i] and acc2 likewise with squares, i in order.

    Each pixel receives its paths' values one at a time in path order, so the
    floating-point sums are the same however the paths were cut into units.
    """
    p = acc.shape[0]
    for i in range(values.shape[0]):
        k = (first + i) % p
        for c in range(values.shape[1]):
            v = values[i, c]
            acc[k, c] += v
            acc2[k, c] += v * v


def unit_size(total: int, threads: int) -> int:
    """Paths per unit: enough units to keep ``threads`` busy, within [MIN, MAX]_UNIT_PATHS."""
    return int(min(MAX_UNIT_PATHS, max(MIN_UNIT_PATHS, -(-total // (2 * threads)))))


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
    shape = (cam.height, cam.width, 3)
    p = cam.width * cam.height
    threads = threads or default_threads()
    acc = np.zeros((p, 3))
    acc2 = np.zeros((p, 3))  # sums of squares, for the per-pixel variance
    passes = list(spp_passes(spp, _NO_CAP, checkpoints))

    def jobs() -> Iterator[tuple[int, int, int, bool]]:
        """(pass, first path, stop, last unit of its pass?) for every unit, in order."""
        for k, n in enumerate(passes):
            total, size = n * p, unit_size(n * p, threads)
            for first in range(0, total, size):
                yield k, first, min(first + size, total), first + size >= total

    keys = [pass_key(seed, k) for k in range(len(passes))]
    done, shots = 0, []
    t0 = time.perf_counter()
    with ThreadPoolExecutor(max_workers=threads) as pool:
        pending: deque = deque()

        def reduce_oldest() -> None:
            nonlocal done
            k, first, last, fut = pending.popleft()
            accumulate(acc, acc2, first, fut.result())
            if last:
                done += passes[k]
                if done in checkpoints and done < spp:
                    shots.append(Checkpoint(done, (acc / done).reshape(shape).astype(np.float32),
                                            time.perf_counter() - t0))

        for k, first, stop, last in jobs():
            pending.append((k, first, last, pool.submit(trace, first, stop, p, keys[k])))
            if len(pending) >= 2 * threads:
                reduce_oldest()
        while pending:
            reduce_oldest()
    elapsed = time.perf_counter() - t0
    mean = acc / spp
    image = mean.reshape(shape).astype(np.float32)
    if spp in checkpoints:
        shots.append(Checkpoint(spp, image, elapsed))
    variance = None
    if spp > 1:  # unbiased sample variance / spp: the variance of the pixel mean
        variance = (np.maximum(acc2 / spp - mean * mean, 0.0) / (spp - 1)).reshape(shape).astype(np.float32)
    return RenderResult(image, elapsed, spp, seed, shots, {"threads": threads, **(info or {})}, variance)

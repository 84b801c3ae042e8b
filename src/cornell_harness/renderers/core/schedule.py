"""How our renderers spread work over threads: passes, work units, an order-preserving pipeline.

:func:`run_units` is the generic part: any list of jobs (a pass's paths,
a batch of photons, a round of probe rays), each computed on a thread pool
by ``work_fn`` and handed to ``reduce_fn`` **in submission order**, with at
most ``2·threads`` jobs in flight, so memory stays bounded and the reduced
result cannot depend on which thread finished first.

:func:`render_image` is the image loop built on it. A render of ``spp``
samples per pixel is split into passes (:func:`cornell_harness.adapters.api.spp_passes`;
pass sizes double, so power-of-two checkpoints come free). A pass of ``n``
samples over ``P`` pixels is a range of ``n·P`` paths (path j looks through
pixel j mod P), cut into work units.

- Random numbers are a pure function of (pass key, path index, dimension)
  (:mod:`cornell_harness.renderers.core.rng`; the pass key is
  :func:`cornell_harness.adapters.api.pass_key`), so they do not depend on how the
  paths are cut into units.
- Each unit returns one estimate per path; they are added into the film
  path by path, in path order (:mod:`cornell_harness.renderers.core.film`), units in order.

So the image depends on the seed only: it is bit-identical for any number
of threads, though the unit size follows the thread count to keep every
thread busy. Units of all passes flow through one pipeline (no barrier
between passes). Unit sizes (2^13 to 2^15 paths) were measured on the
Cornell box (BENCHMARKS.md): smaller units keep a unit's arrays in cache,
and the ray queries hold no GIL (:mod:`cornell_harness.renderers.core.embree`).
"""

from __future__ import annotations

from collections import deque
from concurrent.futures import ThreadPoolExecutor
from typing import Callable, Iterable, Iterator, NamedTuple, Sequence, TypeVar

import numpy as np

from cornell_harness.adapters.api import Checkpoint, RenderResult, Stopwatch, default_threads, spp_passes
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.film import Film
from cornell_harness.renderers.core.sampler import BATCHES, Stream, pass_stream

MAX_UNIT_PATHS = 1 << 15
MIN_UNIT_PATHS = 1 << 13
#: Pass sizes double without a cap: the unit size already bounds memory.
_NO_CAP = 1 << 40

#: trace(first, stop, pixels, stream) -> radiance estimates (stop - first, 3) float64
#: for the paths first..stop-1 of a pass; path j looks through pixel j mod pixels
#: and draws its numbers from the pass's sampler stream (cornell_harness.renderers.core.sampler.Stream).
#: A render that asks for auxiliary images gets (estimates, aux) instead, aux (stop - first, 3·k).
TraceFn = Callable[[int, int, int, Stream], np.ndarray]

J = TypeVar("J")
R = TypeVar("R")


def run_units(jobs: Iterable[J], work_fn: Callable[[J], R], reduce_fn: Callable[[J, R], None],
              threads: int) -> None:
    """``reduce_fn(job, work_fn(job))`` for every job, work on ``threads`` threads, reductions in job order.

    Reductions run on the calling thread; at most ``2·threads`` jobs are in
    flight (submitted, not yet reduced), so a slow reduction throttles the
    producers instead of piling up results. An exception in a job, or in a
    reduction (a render stopped early), is raised here at its turn, and the
    jobs not yet started are cancelled.
    """
    with ThreadPoolExecutor(max_workers=threads) as pool:
        pending: deque = deque()
        try:
            for job in jobs:
                pending.append((job, pool.submit(work_fn, job)))
                if len(pending) >= 2 * threads:
                    done, fut = pending.popleft()
                    reduce_fn(done, fut.result())
            while pending:
                done, fut = pending.popleft()
                reduce_fn(done, fut.result())
        except BaseException:
            for _, fut in pending:
                fut.cancel()
            raise


class Unit(NamedTuple):
    """Paths first .. stop-1 of pass ``index``; ``last``: the pass's last unit."""

    index: int
    first: int
    stop: int
    last: bool


def unit_size(total: int, threads: int) -> int:
    """Paths per unit: enough units to keep ``threads`` busy, within [MIN, MAX]_UNIT_PATHS."""
    return int(min(MAX_UNIT_PATHS, max(MIN_UNIT_PATHS, -(-total // (2 * threads)))))


def pass_units(passes: Sequence[int], pixels: int, threads: int) -> Iterator[Unit]:
    """The work units of consecutive passes of ``passes[k]`` samples per pixel, in order."""
    for k, n in enumerate(passes):
        total, size = n * pixels, unit_size(n * pixels, threads)
        for first in range(0, total, size):
            yield Unit(k, first, min(first + size, total), first + size >= total)


class _Stopped(Exception):
    """Raised by a reduction when the render's ``stop`` rule ends it at the checkpoint just made."""


def render_image(
    scene: Scene,
    spp: int,
    seed: int,
    trace: TraceFn,
    checkpoints: Sequence[int] = (),
    threads: int | None = None,
    info: dict | None = None,
    sampler: str = "independent",
    aovs: Sequence[str] = (),
    variance: bool = True,
    stop: Callable[[Checkpoint], bool] | None = None,
) -> RenderResult:
    """Run ``trace`` over every (pixel, sample) and average into an image, with its variance and checkpoints.

    ``sampler`` names one of :data:`cornell_harness.renderers.core.sampler.SAMPLERS`; a
    low-discrepancy one gets its variance from independent batches; without ``variance``
    it is one randomisation and the result reports no variance. With
    ``aovs`` (names, :data:`cornell_harness.adapters.api.AOVS`), ``trace`` returns
    (estimates, aux) and the result and its checkpoints carry those images.
    ``stop`` (the ``stops_early`` declaration, :class:`cornell_harness.adapters.api.Declarations`) sees each
    checkpoint as it is made; when it returns True the render ends there, with that checkpoint's spp.
    """
    if spp < 1:
        raise ValueError(f"spp must be >= 1, got {spp}")
    cam = scene.camera
    pixels = cam.width * cam.height
    passes = list(spp_passes(spp, _NO_CAP, checkpoints))
    starts = np.concatenate([[0], np.cumsum(passes)[:-1]]).astype(int)
    streams = [pass_stream(sampler, seed, k, pixels, int(starts[k]), BATCHES if variance else 1)
               for k in range(len(passes))]
    batches = streams[0].batches
    film = Film(cam.width, cam.height, batches, tuple(aovs), variance)
    threads = threads or default_threads()
    done, shots = 0, []
    clock = Stopwatch()

    def work(unit: Unit) -> np.ndarray:
        return trace(unit.first, unit.stop, film.pixels, streams[unit.index])

    def reduce(unit: Unit, values) -> None:
        nonlocal done
        values, aux = values if aovs else (values, None)
        film.add(unit.first, values, streams[unit.index].first_sample, aux)
        if unit.last:
            done += passes[unit.index]
            if done in checkpoints and done < spp:
                shots.append(film.checkpoint(done, *clock.read()))
                if stop is not None and stop(shots[-1]):
                    raise _Stopped

    stopped = False
    try:
        run_units(pass_units(passes, film.pixels, threads), work, reduce, threads)
    except _Stopped:
        spp, stopped = done, True
    elapsed, cpu = clock.read()
    image = film.image(spp)
    aux = film.aovs(spp)
    if spp in checkpoints and not stopped:
        shots.append(Checkpoint(spp, image, elapsed, aux, cpu, film.variance(spp)))
    meta = {"threads": threads, "sampler": sampler, **({"batches": batches} if batches > 1 else {}), **(info or {})}
    return RenderResult(image, elapsed, spp, seed, shots, meta, film.variance(spp), aux, cpu)

"""The film: per-path estimates summed into pixels, and the images made from the sums.

Path j of a pass looks through pixel ``j mod P`` (:mod:`cornell_harness.renderers.core.camera`).
:func:`accumulate` adds each path's estimate, and its square, into its
pixel one path at a time in path order, so a pixel's floating-point sum is
the same however the paths were cut into work units or threads: that is
what makes an image bit-identical for any thread count.

From the sums after n samples per pixel: the image is the mean ``S/n``, and
the variance of that mean is the unbiased sample variance over n,
``(S₂/n - (S/n)²) / (n - 1)``, clamped at 0 against rounding: what the
harness's z-tests compare, and what the references store as their variance
image. That holds for independent samples only. A film of K > 1 batches
(a low-discrepancy sampler's independent randomisations, sample s in batch
s mod K: :mod:`cornell_harness.renderers.core.sampler`) also sums each batch, and the
variance of the mean is the spread of the B = min(K, n) batch means m_b
about their mean, ``Σ (m_b - m̄)² / (B (B - 1))`` (the usual estimate from
independent replicates of randomised QMC: L'Ecuyer & Lemieux 2002, "Recent
advances in randomized quasi-Monte Carlo methods"); unbiased when K divides
n, as at every power-of-two checkpoint ≥ K.

Auxiliary images (AOVs: :data:`cornell_harness.adapters.api.AOVS`) are summed
the same way, path by path, and averaged like the image; nobody asks for
their variance, so no squares are kept.

A box filter is the only pixel filter (each path belongs to exactly one
pixel), as in the references; a filter with wider support would splat.
"""

from __future__ import annotations

import numpy as np

from cornell_harness.adapters.api import Checkpoint
from cornell_harness.renderers.core.sampling import jit


@jit
def accumulate(acc, acc2, first, values):
    """acc[(first + i) mod P] += values[i] and acc2 likewise with squares, i in order."""
    p = acc.shape[0]
    for i in range(values.shape[0]):
        k = (first + i) % p
        for c in range(values.shape[1]):
            v = values[i, c]
            acc[k, c] += v
            acc2[k, c] += v * v


@jit
def accumulate_batches(acc_b, first, first_sample, values):
    """acc_b[s mod K, (first + i) mod P] += values[i], s = first_sample + (first + i) div P its sample index."""
    k, p = acc_b.shape[0], acc_b.shape[1]
    for i in range(values.shape[0]):
        b = (first_sample + (first + i) // p) % k
        for c in range(values.shape[1]):
            acc_b[b, (first + i) % p, c] += values[i, c]


@jit
def accumulate_sums(acc, first, values):
    """acc[(first + i) mod P] += values[i], i in order."""
    p = acc.shape[0]
    for i in range(values.shape[0]):
        k = (first + i) % p
        for c in range(values.shape[1]):
            acc[k, c] += values[i, c]


class Film:
    """Sums over the samples of a (height, width) image, three channels, float64; per batch if ``batches`` > 1;
    and of the auxiliary images named ``aovs``, three channels each. Without ``variance``, only the image's
    sums are kept and :meth:`variance` is None."""

    def __init__(self, width: int, height: int, batches: int = 1, aovs: tuple[str, ...] = (), variance: bool = True):
        self.shape = (height, width, 3)
        self.pixels = width * height
        self.acc = np.zeros((self.pixels, 3))
        self.acc2 = np.zeros((self.pixels, 3)) if variance else None  # sums of squares, for the variance
        self.acc_b = np.zeros((batches, self.pixels, 3)) if batches > 1 else None
        self.aov_names = tuple(aovs)
        self.acc_aov = np.zeros((self.pixels, 3 * len(aovs))) if aovs else None

    def add(self, first: int, values: np.ndarray, first_sample: int = 0, aux: np.ndarray | None = None) -> None:
        """Estimates (m, 3) of paths first .. first + m - 1 of a pass (in order, after the paths before them)
        whose first sample per pixel is ``first_sample``; ``aux`` (m, 3·len(aovs)): their auxiliary values."""
        if self.acc2 is None:
            accumulate_sums(self.acc, first, values)
        else:
            accumulate(self.acc, self.acc2, first, values)
        if self.acc_b is not None:
            accumulate_batches(self.acc_b, first, first_sample, values)
        if self.acc_aov is not None:
            accumulate_sums(self.acc_aov, first, aux)

    def aovs(self, n: int) -> dict:
        """The auxiliary images' means after ``n`` samples per pixel, by name, float32 (height, width, 3)."""
        return {name: (self.acc_aov[:, 3 * j:3 * j + 3] / n).reshape(self.shape).astype(np.float32)
                for j, name in enumerate(self.aov_names)}

    def image(self, n: int) -> np.ndarray:
        """The mean after ``n`` samples per pixel, float32 (height, width, 3)."""
        return (self.acc / n).reshape(self.shape).astype(np.float32)

    def variance(self, n: int) -> np.ndarray | None:
        """Per-pixel variance of :meth:`image` ``(n)``, float32; None for one sample (no estimate) or a film
        kept without it."""
        if n < 2 or self.acc2 is None:
            return None
        if self.acc_b is not None:
            return self._batch_variance(n)
        mean = self.acc / n
        return (np.maximum(self.acc2 / n - mean * mean, 0.0) / (n - 1)).reshape(self.shape).astype(np.float32)

    def _batch_variance(self, n: int) -> np.ndarray:
        k = self.acc_b.shape[0]
        b = min(k, n)
        counts = n // k + (np.arange(b) < n % k)  # samples in each batch so far
        means = self.acc_b[:b] / counts[:, None, None]
        spread = ((means - means.mean(axis=0)) ** 2).sum(axis=0) / (b * (b - 1))
        return spread.reshape(self.shape).astype(np.float32)

    def checkpoint(self, n: int, time_s: float, cpu_time_s: float | None = None) -> Checkpoint:
        return Checkpoint(n, self.image(n), time_s, self.aovs(n), cpu_time_s, self.variance(n))


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel a film adds with (batches and auxiliary images
    included) on a throwaway one-pixel film, so that a render's clock starts after them: a process's first
    render otherwise compiled them inside its time (0.3 s of a 1-spp Cornell box, cold cache: docs/timing.md)."""
    film = Film(1, 1, 2, ("albedo", "normal"))
    film.add(0, np.zeros((1, 3)), 0, np.zeros((1, 6)))

"""The toolkit's samplers as renderers see them: streams, stratification, progressive checkpoints,
thread independence, and a variance that is honest for a low-discrepancy mean.

The generators themselves (Sobol' matrices, Owen scrambling, padding) are tested in
``tests/renderers/core/test_sobol.py``; here they are reached the way a kernel reaches them, through
:class:`cornell_harness.renderers.core.sampler.Stream` (path j of a pass: pixel j mod P, sample
first_sample + j div P, batch sample mod K).
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

from cornell_harness.adapters.seeds import pass_key
from cornell_harness.scenes.analytic import furnace_radiance, furnace_scene
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.renderers.core import film as film_module
from cornell_harness.renderers.core.film import Film
from cornell_harness.renderers.core.rng import uniform
from cornell_harness.renderers.core.sampler import (BATCHES, BOUNCE_U, CAMERA_U, EMIT_DIR_U, EMIT_U, PMJ02,
                                                    PMJ02_TABLE, SOBOL, Stream, bounce_dim, independent, path_point, pixel_divider, sample_1d,
                                                    sample_2d, sequence_stream, vertex_dim)
from cornell_harness.renderers.pathtracer import PathTracer

pytest.importorskip("embreex")

KEY = pass_key(5, 0, 16)
PIXELS = 7  # not a power of two: pixel and sample index must not alias


def _stream(kind: int, first_sample: int = 0, batches: int = BATCHES, pixels: int = PIXELS) -> Stream:
    """A stream as :func:`cornell_harness.renderers.core.sampler.pass_stream` makes them, of any kind and key."""
    return Stream(kind, KEY, pixels, first_sample, batches, pixel_divider(pixels))


@numba.njit
def _draw_2d(st, paths, dim):
    out = np.empty((paths.size, 2))
    for k in range(paths.size):
        out[k, 0], out[k, 1] = sample_2d(st, path_point(st, paths[k]), dim)
    return out


@numba.njit
def _draw_1d(st, paths, dim):
    out = np.empty(paths.size)
    for k in range(paths.size):
        out[k] = sample_1d(st, path_point(st, paths[k]), dim)
    return out


def _paths(pixel: int, samples: np.ndarray, first_sample: int = 0) -> np.ndarray:
    """Path indices, within a pass starting at ``first_sample``, of ``samples`` of ``pixel``."""
    return (samples - first_sample) * PIXELS + pixel


def _is_net(points: np.ndarray, m: int) -> bool:
    """One point in every elementary interval 2^-a × 2^-(m-a), a = 0..m: a (0, m, 2)-net in base 2."""
    for a in range(m + 1):
        cells = np.floor(points[:, 0] * 2 ** a).astype(int) * 2 ** (m - a) + np.floor(points[:, 1] * 2 ** (m - a))
        if np.unique(cells).size != 2 ** m:
            return False
    return True


def test_independent_stream_is_the_counter_based_rng():
    """The ``independent`` sampler draws exactly what every renderer drew before samplers (images unchanged)."""
    st = independent(KEY, PIXELS)
    paths = np.arange(50)
    assert np.array_equal(_draw_1d(st, paths, 9), [uniform(KEY, j, 9) for j in paths])
    assert np.array_equal(_draw_2d(st, paths, 4)[:, 1], [uniform(KEY, j, 5) for j in paths])


@pytest.mark.parametrize("kind", [PMJ02, SOBOL, PMJ02_TABLE])
def test_each_batch_of_a_pixel_is_stratified_progressively(kind):
    """Exact: a batch's first 2^m camera samples of a pixel, for every m ≤ 8, and the next aligned block,
    are (0, m, 2)-nets; for pmj02 and pmj02table so is every later 2D decision (a vertex's BSDF direction)."""
    st = _stream(kind)
    dims = [CAMERA_U] + ([vertex_dim(3, 3)] if kind != SOBOL else [])
    for pixel in (0, 3):
        for batch in (0, BATCHES - 1):
            for dim in dims:
                for m in range(1, 9):
                    for block in (0, 1):
                        samples = batch + BATCHES * np.arange(block * 2 ** m, (block + 1) * 2 ** m)
                        pts = _draw_2d(st, _paths(pixel, samples), dim)
                        assert _is_net(pts, m), (kind, pixel, batch, dim, m, block)


@pytest.mark.parametrize("sampler", ["pmj02", "sobol", "pmj02table"])
def test_a_photon_stream_is_one_sequence_stratified_over_the_photons(sampler):
    """Exact: photons 0 .. 2^m - 1 of a map (one sequence, no batches: :func:`sequence_stream`) and the next
    aligned block put one number in each interval of width 2^-m in every emission dimension, for every
    m ≤ 10; for pmj02 they are also (0, m, 2)-nets in the emission point's, the emitted direction's and a
    bounce's 2D dimensions (each 2D decision its own padded sequence; Sobol' pairs past (0, 1) are not)."""
    st = sequence_stream(sampler, KEY)
    assert (st.pixels, st.batches) == (1, 1)
    for m in range(1, 11):
        for block in (0, 1):
            photons = np.arange(block * 2 ** m, (block + 1) * 2 ** m)
            for dim in range(5):
                cells = np.floor(_draw_1d(st, photons, dim) * 2 ** m)
                assert np.unique(cells).size == 2 ** m, (dim, m, block)
            for dim in [EMIT_U, EMIT_DIR_U, bounce_dim(2, BOUNCE_U)] if sampler != "sobol" else []:
                assert _is_net(_draw_2d(st, photons, dim), m), (dim, m, block)


def test_an_independent_photon_stream_is_the_counter_based_rng():
    """With ``independent`` photon j draws uniform(key, j, dim), as photons did before samplers."""
    paths = np.arange(40)
    assert np.array_equal(_draw_1d(sequence_stream("independent", KEY), paths, 7), [uniform(KEY, j, 7) for j in paths])


@pytest.mark.parametrize("kind", [PMJ02, SOBOL, PMJ02_TABLE])
def test_numbers_do_not_depend_on_how_samples_are_cut_into_passes(kind):
    """A sample's numbers are a function of (seed, pixel, sample index, dimension): the same whether it is
    drawn in a pass that starts at sample 0 or in a later one (first_sample 12)."""
    whole = _stream(kind)
    later = whole._replace(first_sample=12)
    samples = np.arange(12, 40)
    for dim in (CAMERA_U, vertex_dim(2, 1)):
        assert np.array_equal(_draw_2d(whole, _paths(2, samples), dim), _draw_2d(later, _paths(2, samples, 12), dim))
        assert np.array_equal(_draw_1d(whole, _paths(2, samples), dim), _draw_1d(later, _paths(2, samples, 12), dim))


@numba.njit
def _points(st, paths):
    seeds, indices = np.empty(paths.size, np.uint64), np.empty(paths.size, np.int64)
    for k in range(paths.size):
        seeds[k], indices[k] = path_point(st, paths[k])
    return seeds, indices


@pytest.mark.parametrize("kind", [PMJ02, SOBOL, PMJ02_TABLE])
def test_sample_index_in_its_batch_for_any_batch_count(kind):
    """Path j of a pass from sample f is sample s = f + j div P of pixel j mod P, point s div K of batch s mod K:
    the shift taken for a power-of-two K and the division for another K give that index, and one batch's seeds
    are the same for every sample of the pixel."""
    paths = np.arange(300)
    for batches in (1, 3, 8, 12):
        assert np.array_equal(_points(_stream(kind, 5, batches), paths)[1], (5 + paths // PIXELS) // batches), batches
    seeds = _points(_stream(kind, 0, 3), _paths(4, 3 * np.arange(20) + 2))[0]
    assert np.unique(seeds).size == 1


@pytest.mark.parametrize("kind", [PMJ02, PMJ02_TABLE])
def test_dividing_by_pixels_with_a_multiplication_is_exact(kind):
    """pixel_divider's multiplication gives path_point the quotient a division gives (a stream without the
    divider divides): for pixel counts up to 2^32 - 1, at paths on both sides of multiples of the count, up to
    the 2^32 where it hands over to the division, and past it."""
    rng = np.random.default_rng(11)
    for pixels in (2, 3, 7, 1000, 65536, 65537, 1920 * 1080, (1 << 31) + 11, (1 << 32) - 1):
        q = rng.integers(0, (1 << 32) // pixels, 200, dtype=np.int64)
        paths = np.concatenate([q * pixels + d for d in (-1, 0, 1, pixels - 1)]
                               + [np.arange((1 << 32) - 200, (1 << 32) + 200), rng.integers(0, 1 << 40, 200)])
        paths = paths[paths >= 0]
        fast, slow = _stream(kind, 3, pixels=pixels), _stream(kind, 3, pixels=pixels)._replace(divider=np.uint64(0))
        assert fast.divider != 0
        for a, b in zip(_points(fast, paths), _points(slow, paths)):
            assert np.array_equal(a, b), pixels
    assert pixel_divider(1) == 0 and pixel_divider(1 << 32) == 0


def test_batch_variance_is_the_spread_of_batch_means():
    """Film with K batches: variance of the mean = Σ (m_b - m̄)² / (B (B - 1)) over the B = min(K, n) batches."""
    rng = np.random.default_rng(0)
    pixels, k = 5, 4
    for n in (2, 3, 8, 24):
        values = rng.normal(size=(n * pixels, 3))
        f = Film(pixels, 1, batches=k)
        f.add(0, values[: 2 * pixels], 0)  # two passes: the split must not matter
        f.add(0, values[2 * pixels:], 2)
        per_sample = values.reshape(n, pixels, 3)
        b = min(k, n)
        means = np.stack([per_sample[j::k].mean(axis=0) for j in range(b)])
        expected = ((means - means.mean(axis=0)) ** 2).sum(axis=0) / (b * (b - 1))
        np.testing.assert_allclose(f.variance(n).reshape(pixels, 3), expected, rtol=1e-6)
        np.testing.assert_allclose(f.image(n).reshape(pixels, 3), per_sample.mean(axis=0), rtol=1e-6)


@pytest.mark.parametrize("sampler", ["pmj02", "sobol", "pmj02table"])
def test_same_image_and_variance_for_any_thread_count(sampler):
    scene = resolve_scene("cornell-box").with_resolution(24, 16)
    runs = [PathTracer(threads=t).render(scene, 16, seed=4, settings={"sampler": sampler}) for t in (1, 2, 3)]
    for r in runs[1:]:
        assert np.array_equal(r.image, runs[0].image) and np.array_equal(r.variance, runs[0].variance)
    assert runs[0].info["sampler"] == sampler and runs[0].info["batches"] == BATCHES


@pytest.mark.parametrize("sampler", ["pmj02", "sobol", "pmj02table"])
def test_checkpoints_are_the_shorter_renders(sampler):
    """Progressive: the 16- and 32-spp checkpoints of a 64-spp render are, bit for bit, 16- and 32-spp renders."""
    scene = resolve_scene("cornell-box").with_resolution(24, 16)
    pt = PathTracer(threads=2)
    full = pt.render(scene, 64, seed=2, checkpoints=(16, 32, 64), settings={"sampler": sampler})
    for shot in full.checkpoints[:2]:
        alone = pt.render(scene, shot.spp, seed=2, settings={"sampler": sampler})
        assert np.array_equal(shot.image, alone.image), shot.spp


# sobol's is slow (9 s): the suite's bound; pmj02, the default, and pmj02table run by default.
@pytest.mark.parametrize("sampler", ["pmj02", "pmj02table", pytest.param("sobol", marks=pytest.mark.slow)])
def test_z_scores_over_20_seeds_have_unit_spread(sampler, monkeypatch):
    """The returned variance is honest: white furnace (ρ 0.8, exact L = 5), 32×32 pixels, 64 spp, seeds 0-19.

    z = (image - 5) / sqrt(v̄), v̄ the pixel's returned variance averaged over the 20 renders (160 batch
    degrees of freedom, so z is not inflated by a per-render t distribution). Band: sd(z) in [0.94, 1.06]
    over 20480 z per channel; measured 1.011 (pmj02) and 1.005 (sobol). The per-sample variance of the same
    samples (the film's sums of squares), which ignores their negative correlation, gives 0.76 and 0.71:
    it must stay below 0.9, or this test could not tell an honest variance from an inflated one.
    """
    naive = []
    batch_variance = Film._batch_variance

    def record(self, n):
        mean = self.acc / n
        naive.append((np.maximum(self.acc2 / n - mean * mean, 0.0) / (n - 1)).reshape(self.shape))
        return batch_variance(self, n)

    monkeypatch.setattr(film_module.Film, "_batch_variance", record)
    scene = furnace_scene(0.8, 1.0, -1, res=32)
    truth = furnace_radiance(0.8, 1.0, -1)
    pt = PathTracer()
    runs = [pt.render(scene, 64, seed, settings={"sampler": sampler}) for seed in range(20)]
    images = np.array([r.image for r in runs], np.float64)
    z = (images - truth) / np.sqrt(np.mean([r.variance for r in runs], axis=0))
    z_naive = (images - truth) / np.sqrt(np.mean(naive, axis=0))
    assert 0.94 <= z.std() <= 1.06, z.std()
    assert z_naive.std() < 0.9, z_naive.std()

"""cornell_harness.evaluate.hdr_flip, the harness's own HDR-FLIP: the authors' library's map on several kinds of image,
and its cache of the reference's side (keyed by content: never an entry made for other pixels)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import CORNELL
from cornell_harness.evaluate import flip, hdr_flip
from cornell_harness.store.exr import read_exr

#: Per pixel, our map against flip_evaluator's: both compute in float32 in the same order; what differs is
#: an ulp here and there (libm's expf/powf against LLVM's lowering), which the powers near 0 can magnify
#: (measured on these cases: at most 4e-6; on the stored cornell-box noise batch, bit for bit).
ATOL = 5e-5


@pytest.fixture(scope="module")
def reference() -> np.ndarray:
    return read_exr(CORNELL.parent / "reference.exr")


def _noisy(ref, rel_sd, seed):
    rng = np.random.default_rng(seed)
    return np.maximum(ref * (1.0 + rel_sd * rng.standard_normal(ref.shape)), 0.0).astype(np.float32)


def _hdr_scene(h=40, w=72, seed=4) -> np.ndarray:
    """A high-dynamic-range image: a dim coloured gradient over ~6 decades, a few very bright pixels, black."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    img = np.stack([10 ** (6 * xx / w - 4), 10 ** (6 * yy / h - 4), np.full((h, w), 0.02)], axis=-1)
    img *= rng.lognormal(0.0, 0.3, img.shape)
    img[5:8, 10:13] = [4000.0, 3500.0, 3000.0]  # a light source
    img[20:, :6] = 0.0
    return img.astype(np.float32)


def _agree(img, ref, parameters=None):
    ours, theirs = flip.flip_map(img, ref, parameters), flip.library_flip_map(img, ref, parameters)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=ATOL)
    assert np.mean(ours) == pytest.approx(np.mean(theirs), rel=1e-5)
    return ours


def test_the_libraries_map_on_a_render(reference):
    crop = reference[16:112, 64:192]  # the light, the ceiling and both walls' edges: 7 exposures
    ours = _agree(_noisy(crop, 0.2, 1), crop)
    assert 0.01 < np.mean(ours) < 0.5


def test_the_libraries_map_on_a_high_dynamic_range_image():
    ref = _hdr_scene()
    p = flip.flip_parameters(ref)
    assert p["stopExposure"] - p["startExposure"] > 10  # many exposures, most of the range of the tone mapper
    ours = _agree(_noisy(ref, 0.3, 2), ref)
    _agree(ref * 1.5, ref)
    assert np.max(ours) > 0.3


def test_the_libraries_map_where_the_filters_are_wider_than_the_image():
    """16 × 12 pixels against filters 21 and 19 pixels wide: most taps are clamped borders (rows and columns
    not swapped: the image is not square), and at another pixels-per-degree the filters' widths change."""
    ref = _hdr_scene(12, 16, seed=5)
    img = _noisy(ref, 0.5, 3)
    _agree(img, ref)
    p = dict(flip.flip_parameters(ref), ppd=23.0)
    _agree(img, ref, p)


def test_colour_alone_and_an_image_against_itself(reference):
    crop = reference[100:160, 20:100]
    swapped = crop[..., ::-1].copy()  # the same luminance structure, other hues
    _agree(swapped, crop)
    assert not np.any(flip.flip_map(crop, crop))


def test_the_cached_reference_side_is_the_uncached_one(reference):
    ref = reference[16:80, 96:160].astype(np.float32)
    img = _noisy(ref, 0.2, 6)
    p = flip.flip_parameters(ref)
    scales = flip.exposure_scales(p)
    cache = hdr_flip.SideCache()
    args = (scales, flip.ACES_COEFFICIENTS, p["ppd"])
    first = hdr_flip.hdr_flip_map(img, ref, *args, cache=cache)
    assert (cache.hits, cache.misses, len(cache.entries)) == (0, len(scales), len(scales))
    again = hdr_flip.hdr_flip_map(img, ref.copy(), *args, cache=cache)  # the same pixels in another array
    assert (cache.hits, cache.misses) == (len(scales), len(scales))
    fresh = hdr_flip.hdr_flip_map(img, ref, *args, cache=None)
    np.testing.assert_array_equal(first, fresh)
    np.testing.assert_array_equal(again, fresh)


def test_another_reference_or_exposure_is_another_entry(reference):
    ref = reference[16:80, 96:160].astype(np.float32)
    other = reference[100:164, 20:84].astype(np.float32)
    cache = hdr_flip.SideCache()
    side = cache.side(ref, cache.digest(ref), np.float32(1.0), flip.ACES_COEFFICIENTS, flip.PIXELS_PER_DEGREE)
    for r, scale, ppd in ((other, 1.0, flip.PIXELS_PER_DEGREE), (ref, 2.0, flip.PIXELS_PER_DEGREE), (ref, 1.0, 30.0)):
        entry = cache.side(r, cache.digest(r), np.float32(scale), flip.ACES_COEFFICIENTS, ppd)
        assert entry.shape == side.shape and not np.array_equal(entry, side)
        np.testing.assert_array_equal(entry, hdr_flip.image_side(r, np.float32(scale), flip.ACES_COEFFICIENTS, ppd))
    assert cache.misses == len(cache.entries) == 4 and cache.hits == 0
    assert not side.flags.writeable  # an entry cannot be changed by whoever holds it


def test_a_reference_changed_in_place_is_not_served_its_old_side(reference):
    """The same array object, its pixels changed: the map is the one of the new pixels (computed without any
    cache), not the one of the old; through flip_map (the module's own cache) as well."""
    ref = reference[16:80, 96:160].astype(np.float32)
    img = _noisy(ref, 0.2, 7)
    p = flip.flip_parameters(ref)
    args = (flip.exposure_scales(p), flip.ACES_COEFFICIENTS, p["ppd"])
    cache = hdr_flip.SideCache()
    before, before_flip = hdr_flip.hdr_flip_map(img, ref, *args, cache=cache), flip.flip_map(img, ref, p)
    ref[10:30, 10:30] *= 3.0
    uncached = hdr_flip.hdr_flip_map(img, ref, *args, cache=None)
    np.testing.assert_array_equal(hdr_flip.hdr_flip_map(img, ref, *args, cache=cache), uncached)
    np.testing.assert_array_equal(flip.flip_map(img, ref, p), uncached)
    assert not np.array_equal(uncached, before) and np.array_equal(before, before_flip)
    # The exposures picked by default follow the new pixels too (cached by content as well).
    np.testing.assert_array_equal(flip.flip_map(img, ref), flip.flip_map(img, ref, flip.flip_parameters(ref)))


def test_the_cache_keeps_to_its_budget(reference):
    ref = reference[:32, :32].astype(np.float32)
    one = hdr_flip.image_side(ref, np.float32(1.0), flip.ACES_COEFFICIENTS, 67.0).nbytes
    cache = hdr_flip.SideCache(max_bytes=2 * one)
    for scale in (1.0, 2.0, 4.0):
        cache.side(ref, cache.digest(ref), np.float32(scale), flip.ACES_COEFFICIENTS, 67.0)
    assert len(cache.entries) == 2 and [k[2] for k in cache.entries] == [2.0, 4.0]  # the oldest went

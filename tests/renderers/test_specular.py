"""Our path tracer on mirrors and glass: furnaces with analytic answers, and determinism with spheres.

The specular furnaces (:func:`cornell_harness.scenes.analytic.specular_furnace_scene`,
:func:`~cornell_harness.scenes.analytic.specular_furnace_camera_in_glass`) are the
white furnace with lossless glass (a sphere, and a cube that makes total
internal reflection certain) and a mirror sphere in view. What each test
catches:

- **walls of albedo 0** (every path ends at the first wall; Russian roulette
  off, so each path's value is exact): glass shows exactly Le, a mirror of
  reflectance r exactly r·Le per channel, and a camera inside glass exactly
  n²·Le. Catches energy gained or lost at an interface (a (1-R) factor on
  top of choosing by R, a wrong weight), total internal reflection treated
  as absorption (the cube), glass treated as one-sided, emission after a
  delta bounce weighted by MIS (it must count fully), a mirror's reflectance
  ignored or put in the wrong channel, and, with the camera in glass, a
  missing or inverted radiance scaling η_ti² (which cancels over any round
  trip from air to air, so no scene seen from the air can catch it).
- **walls of albedo ρ > 0**: Le/(1-ρ) everywhere, from Monte Carlo with
  next-event estimation at the walls, so it also catches shadow rays that
  pass through glass or mirrors (light counted twice) and light sampling at
  delta vertices.
- Fresnel's R itself is not checked here (any R conserves energy in a
  furnace): :mod:`tests.test_bsdf` checks it against Fresnel's equations.

Monte Carlo tolerances are z-tests with the render's own variance, stated
as in ``tests/renderers/test_pathtracer.py``: two-sided false-alarm rate α with
Šidák's correction over simultaneous tests; all seeds fixed.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.conftest import ROOT
from cornell_harness.scenes.analytic import FURNACE_GLASS_IOR, furnace_radiance, specular_furnace_camera_in_glass, specular_furnace_coverage, specular_furnace_scene
from cornell_harness.scenes.loader import load_scene
from cornell_harness.renderers.pathtracer import PathTracer
from tests.renderers.test_pathtracer import tile_z, z_crit

pytest.importorskip("embreex")

CAUSTICS = ROOT / "src" / "cornell_harness" / "references" / "cornell-box-caustics" / "scene.toml"
#: Russian roulette off: with walls of albedo 0 every path ends at its first wall, so each path's value is exact.
NO_ROULETTE = {"rr_depth": 1000}
#: float32 image of values computed in float64 (a few products of order-1 weights): a few ulps of float32.
F32 = 1e-6


# --- walls of albedo 0: exact per pixel -------------------------------------------------

def test_black_furnace_glass_shows_the_emission():
    """Glass sphere and glass cube in a furnace of emitting black walls: every pixel exactly Le.

    A path meets the glass, is reflected or refracted (weight 1, or η_ti² in
    and 1/η_ti² out), leaves and ends at a wall: its value is Le whatever the
    random numbers. Light entering the cube meets its side faces past the
    critical angle, so total internal reflection is exercised on every such path.
    """
    scene = specular_furnace_scene(0.0, 1.0, res=24, objects=("glass-sphere", "glass-cube"))
    cover = specular_furnace_coverage(scene)
    assert all((c == 1).sum() >= 30 for c in cover.values())  # both in view
    res = PathTracer().render(scene, 16, seed=1, settings=NO_ROULETTE)
    np.testing.assert_allclose(res.image, 1.0, rtol=F32, atol=0)


def test_black_furnace_mirror_shows_its_reflectance():
    """A mirror sphere of reflectance r = (0.9, 0.5, 0.2) in black emitting walls: r·Le where it covers a pixel.

    Walls: exactly Le; pixels the mirror fully covers: exactly r·Le per channel;
    pixels on its outline: between the two, per channel.
    """
    r = np.array([0.9, 0.5, 0.2])
    scene = specular_furnace_scene(0.0, 2.0, res=24, objects=("mirror-sphere",), mirror_reflectance=tuple(r))
    cover = specular_furnace_coverage(scene)["mirror-sphere"]
    img = PathTracer().render(scene, 16, seed=2, settings=NO_ROULETTE).image.astype(np.float64)
    full, none = cover == 1, cover == 0
    assert full.sum() >= 30 and none.sum() >= 300
    np.testing.assert_allclose(img[none], 2.0, rtol=F32, atol=0)
    np.testing.assert_allclose(img[full], np.broadcast_to(2.0 * r, img[full].shape), rtol=F32, atol=0)
    edge = img[~full & ~none]
    assert np.all(edge >= 2.0 * r * (1 - F32)) and np.all(edge <= 2.0 * (1 + F32))


def test_camera_inside_glass_sees_n_squared_times_the_emission():
    """Camera inside a glass sphere (n = 1.5) in black emitting walls: every pixel exactly n²·Le = 2.25·Le.

    The radiance scaling η_ti² on refraction is what gives n² here (basic
    radiance L/n² is conserved, Veach 1997 §5.2); without it the image is
    Le, with it inverted Le/n².
    """
    scene = specular_furnace_camera_in_glass(0.0, 1.0, res=16)
    res = PathTracer().render(scene, 16, seed=3, settings=NO_ROULETTE)
    np.testing.assert_allclose(res.image, FURNACE_GLASS_IOR**2, rtol=F32, atol=0)


# --- walls of albedo ρ > 0: Monte Carlo --------------------------------------------------

def region_z(img: np.ndarray, var: np.ndarray, mask: np.ndarray, expected: float) -> np.ndarray:
    """z per channel of the mean over ``mask``'s pixels against ``expected``; pixels are independent."""
    n = int(mask.sum())
    return (img[mask].mean(axis=0) - expected) / np.sqrt(var[mask].sum(axis=0) / n**2)


SPECULAR_FURNACE_CASES = [0.5, 0.8]


@pytest.mark.parametrize("albedo", SPECULAR_FURNACE_CASES)
def test_specular_furnace(albedo):
    """Walls of albedo ρ emitting Le, with the glass sphere, glass cube and mirror sphere (r = 1): Le/(1-ρ).

    24×24 pixels at 1024 spp. Two families of z-tests with the render's own
    variance, each at α = 1e-3 over the 2 cases (Šidák):

    - each object's fully covered pixels (34 to 40 pixels), and the pixels
      covering no object (378), pooled per channel: 4 regions × 3 channels;
    - each 4×4 tile per channel: 36 × 3 tests of 16384 samples each.

    The path values are skewed (sample skewness 2.2 to 6.5, kurtosis up to
    66, measured per region at ρ = 0.5 and 0.8), and a z with the sample's
    own variance then has a heavier low tail than the normal: at 256 spp the
    0.1% quantile of tile z was -3.8 (normal: -3.1), hence 1024 spp, where it
    was -3.2 and the 99.9% one 3.1. The α above is nominal; measured on 30
    other seeds at ρ = 0.5, the largest tile |z| was 3.9 and the largest
    region |z| 3.3, against critical values 4.58 and 4.10.
    """
    scene = specular_furnace_scene(albedo, 1.0, res=24)
    res = PathTracer().render(scene, 1024, seed=17)
    img, var = res.image.astype(np.float64), res.variance.astype(np.float64)
    expected = furnace_radiance(albedo, 1.0, -1)
    cover = specular_furnace_coverage(scene)
    regions = {name: c == 1 for name, c in cover.items()}
    regions["walls"] = np.all([c == 0 for c in cover.values()], axis=0)
    z = np.array([region_z(img, var, m, expected) for m in regions.values()])
    assert np.abs(z).max() < z_crit(1e-3, z.size * len(SPECULAR_FURNACE_CASES)), dict(zip(regions, z))
    zt = tile_z(img, var, np.full_like(img, expected), np.zeros_like(img), tile=4)
    assert np.abs(zt).max() < z_crit(1e-3, zt.size * len(SPECULAR_FURNACE_CASES)), zt


def test_camera_inside_glass_furnace():
    """Camera inside a glass sphere, walls of albedo 0.5 emitting 1: n²·Le/(1-ρ) = 4.5 everywhere.

    16×16 pixels at 1024 spp; z-test per 4×4 tile and channel (48 tests of 16384
    samples; sample skewness 3.3) and of the image mean per channel (3 tests),
    with the render's variance, α = 1e-3 (Šidák over 51). Catches a missing or
    inverted η_ti² when walls reflect (the black-wall test above does when they do not).
    """
    scene = specular_furnace_camera_in_glass(0.5, 1.0, res=16)
    res = PathTracer().render(scene, 1024, seed=23)
    img, var = res.image.astype(np.float64), res.variance.astype(np.float64)
    expected = FURNACE_GLASS_IOR**2 * furnace_radiance(0.5, 1.0, -1)
    zt = tile_z(img, var, np.full_like(img, expected), np.zeros_like(img), tile=4)
    zm = region_z(img, var, np.ones(img.shape[:2], bool), expected)
    k = zt.size + zm.size
    assert np.abs(zt).max() < z_crit(1e-3, k), zt
    assert np.abs(zm).max() < z_crit(1e-3, k), zm


# --- determinism ---------------------------------------------------------------------

def test_caustics_scene_bit_identical_whatever_the_thread_count():
    scene = load_scene(CAUSTICS).with_resolution(32, 32)
    a, b = (PathTracer(threads=t).render(scene, 4, seed=9).image for t in (1, 2))
    assert np.array_equal(a, b)
    assert math.isfinite(float(a.sum())) and a.min() >= 0.0 and a.max() > 0.0

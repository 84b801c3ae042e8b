"""Ambient occlusion in the Mitsuba 3 adapter (src/cornell_harness/renderers/mitsuba_ao.py) against analytic AO; the stored AO reference.

The analytic scenes are a floor (y = 0, normal up) seen from straight above,
beside vertical walls that reach past every point within the maximum
distance R of what the camera sees, so they act as the infinite walls of
:mod:`cornell_harness.scenes.analytic_ao`. A pixel's expected value is the analytic
AO averaged over its footprint on the floor (a sub-pixel grid, midpoint rule),
not its centre's: AO changes across a pixel near a wall.

Each sample's estimate is a visibility V in {0, 1}, so a pixel of n samples
whose footprint's mean AO is p has variance p(1 − p)/n exactly: the z-tests
use that, not the render's own estimate.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import norm

from cornell_harness.adapters.registry import missing_features
from cornell_harness.evaluate import noise as stats
from cornell_harness.evaluate.regions import first_hits, lattice_directions
from cornell_harness.scenes.analytic_ao import ao_beside_walls, cosine_ao_beside_wall
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Camera, Diffuse, Mesh, Scene
from cornell_harness.scenes.quantities import AmbientOcclusion
from cornell_harness.store.references import load_reference

mi = pytest.importorskip("mitsuba")

from cornell_harness.renderers.mitsuba3 import Mitsuba3  # noqa: E402

#: Each z-test's family-wise false-alarm rate (Bonferroni): a correct renderer fails it for at most 1 seed in 1000.
ALPHA = 1e-3
FEATURES = frozenset({"triangle_mesh", "diffuse", "pinhole_camera", "box_filter"})


@pytest.fixture(scope="module")
def mitsuba() -> Mitsuba3:
    r = Mitsuba3()
    if r.variant()[0] == "scalar_rgb":
        pytest.skip("Mitsuba's AO needs the llvm_ad_rgb variant (LLVM >= 17)")
    return r


def _quad(name: str, corners) -> Mesh:
    return Mesh(name, np.asarray(corners, dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]]), "white")


def floor(x0: float, x1: float, z0: float, z1: float, up: bool = True) -> Mesh:
    """The quad y = 0 over [x0, x1] × [z0, z1], its front (winding) side up or down."""
    c = [(x0, 0, z1), (x1, 0, z1), (x1, 0, z0), (x0, 0, z0)]
    return _quad("floor", c if up else c[::-1])


def wall_x0(z0: float, z1: float, height: float) -> Mesh:
    """The wall x = 0 over z in [z0, z1], facing +x."""
    return _quad("wall-x", [(0, 0, z1), (0, 0, z0), (0, height, z0), (0, height, z1)])


def wall_z0(x0: float, x1: float, height: float) -> Mesh:
    """The wall z = 0 over x in [x0, x1], facing +z."""
    return _quad("wall-z", [(x0, 0, 0), (x1, 0, 0), (x1, height, 0), (x0, height, 0)])


def top_view(x: float, z: float, half_width: float, width: int, height: int, up=(0.0, 0.0, -1.0)) -> Camera:
    """Looking straight down from 2 above (x, 0, z): columns go with +x; sees x within ``half_width``."""
    fov = 2.0 * math.degrees(math.atan(half_width / 2.0))
    return Camera((x, 2.0, z), (x, 0.0, z), up, fov, "x", width, height)


def ao_scene(meshes, camera: Camera, max_distance: float, weighting: str = "cosine", miss: float = 0.0) -> Scene:
    return Scene(name="ao-test", path=Path("ao-test.toml"), features=FEATURES, camera=camera,
                 materials={"white": Diffuse("white", (0.8, 0.8, 0.8))}, meshes=tuple(meshes), max_depth=-1,
                 pixel_filter="box", quantity="ambient_occlusion",
                 ambient_occlusion=AmbientOcclusion(max_distance, weighting, "geometric", miss))


def floor_points(cam: Camera, sub: int) -> tuple[np.ndarray, np.ndarray]:
    """x and z (H, W, sub²) of a sub × sub grid of cell centres in each pixel, where the rays meet y = 0."""
    offs = (np.arange(sub) + 0.5) / sub
    col = np.arange(cam.width)[None, :, None, None] + offs[None, None, None, :]
    row = np.arange(cam.height)[:, None, None, None] + offs[None, None, :, None]
    col, row = np.broadcast_arrays(col, row)
    d = cam.directions(col, row).reshape(cam.height, cam.width, sub * sub, 3)
    t = -cam.position[1] / d[..., 1]
    return cam.position[0] + t * d[..., 0], cam.position[2] + t * d[..., 2]


def by_unique(f, *keys: np.ndarray) -> np.ndarray:
    """``f`` of each distinct tuple of ``keys`` (rounded to 1e-12), spread back to the keys' shape."""
    stacked = np.stack([np.round(k, 12).ravel() for k in keys], axis=1)
    uniq, inverse = np.unique(stacked, axis=0, return_inverse=True)
    return np.array([f(*u) for u in uniq])[inverse.ravel()].reshape(keys[0].shape)


def assert_within_noise(image: np.ndarray, expected: np.ndarray, spp: int, groups: np.ndarray) -> None:
    """z-test of each group's mean against the expected one, Bonferroni over the groups at family-wise :data:`ALPHA`.

    A pixel of expected AO p has variance p(1 − p)/spp (Bernoulli samples); a
    group whose pixels all expect exactly 1 or 0 must match exactly.
    """
    img = image[..., 0].astype(np.float64)
    assert np.array_equal(image[..., 0], image[..., 1]) and np.array_equal(image[..., 0], image[..., 2])  # grey
    var = expected * (1.0 - expected) / spp
    labels = np.unique(groups)
    z_crit = norm.isf(ALPHA / (2 * len(labels)))
    for g in labels:
        m = groups == g
        diff = img[m].mean() - expected[m].mean()
        sd = math.sqrt(var[m].sum()) / m.sum()
        if sd == 0.0:
            assert diff == 0.0, (g, img[m], expected[m])
        else:
            assert abs(diff / sd) < z_crit, (g, diff, sd, diff / sd, z_crit)


ONE_WALL_R = 1.0


@pytest.mark.parametrize("weighting, max_distance, facing_up", [("cosine", ONE_WALL_R, True),
                                                                ("uniform", ONE_WALL_R, True),
                                                                ("cosine", 0.4, True), ("cosine", ONE_WALL_R, False)])
def test_one_wall_agrees_with_analytic_ao(mitsuba, weighting, max_distance, facing_up):
    """A floor beside one wall: each pixel column (8 pixels) within noise of the analytic AO over its footprint.

    The camera sees x in [0.02, 1.30] (64 columns); pixels past R from the wall
    must be exactly 1 (R falls on pixel edges). The wall (x = 0, z in ±4,
    height 2) covers every point within R = 1 of the footprint (z within
    ±0.08). The variance the adapter returns, summed over each column whose
    pixels have p(1 − p) > 0.15 on average, must be within 5% of the sum of
    p(1 − p)/spp (about 5 standard deviations of a sample variance).
    A floor wound facing down (its back seen) must give the same: the
    hemisphere is on the camera's side. Family-wise false-alarm rate
    :data:`ALPHA` (Bonferroni over 64 columns), seed 11.
    """
    cam = top_view(0.66, 0.0, 0.64, 64, 8)
    scene = ao_scene([floor(-1.0, 3.0, -3.0, 3.0, facing_up), wall_x0(-4.0, 4.0, 2.0)], cam, max_distance, weighting)
    spp = 4096
    result = mitsuba.render(scene, spp, seed=11)
    x, _ = floor_points(cam, 8)
    if weighting == "cosine":
        per_point = cosine_ao_beside_wall(x, max_distance)
    else:
        per_point = by_unique(lambda d: ao_beside_walls([(d, 0.0)], max_distance, weighting), x)
    expected = per_point.mean(axis=-1)  # over each footprint
    far = x.min(axis=-1) > 1.01 * max_distance
    assert far.any() and np.all(result.image[far] == 1.0)
    assert expected.min() < 0.6  # the test sees real occlusion
    columns = np.broadcast_to(np.arange(cam.width), expected.shape)
    assert_within_noise(result.image, expected, spp, columns)
    want = (expected * (1 - expected) / spp).sum(axis=0)
    got = result.variance[..., 0].astype(np.float64).sum(axis=0)
    busy = want > 0.15 * cam.height / spp
    assert busy.any()
    np.testing.assert_allclose(got[busy], want[busy], rtol=0.05)


def test_corner_agrees_with_analytic_ao(mitsuba):
    """A floor in the corner of two walls (x = 0, z = 0): each pixel within noise of the two-wall quadrature.

    The camera sees x, z in [0.04, 1.32] (16 × 16 pixels, R = 1 on a pixel edge), cosine
    weighting; the expected value is the mean over a 3 × 3 grid in each pixel
    of :func:`ao_beside_walls`. Family-wise false-alarm rate :data:`ALPHA`
    (Bonferroni over 256 pixels), seed 12.
    """
    cam = top_view(0.68, 0.68, 0.64, 16, 16)
    r = 1.0
    scene = ao_scene([floor(-1.0, 4.0, -1.0, 4.0), wall_x0(0.0, 4.0, 2.0), wall_z0(0.0, 4.0, 2.0)], cam, r)
    spp = 16384
    result = mitsuba.render(scene, spp, seed=12)
    x, z = floor_points(cam, 3)
    # A(x, z) = A(z, x): evaluate each unordered pair once.
    lo, hi = np.minimum(x, z), np.maximum(x, z)
    per_point = by_unique(lambda a, b: ao_beside_walls([(a, math.pi), (b, 1.5 * math.pi)], r), lo, hi)
    expected = per_point.mean(axis=-1)  # over each footprint
    assert expected.min() < 0.4 and expected.max() > 0.9
    assert_within_noise(result.image, expected, spp, np.arange(expected.size).reshape(expected.shape))


@pytest.mark.parametrize("facing_up", [True, False])
@pytest.mark.parametrize("max_distance", [0.5, math.inf])
def test_open_plane_is_one_and_misses_read_miss_value(mitsuba, facing_up, max_distance):
    """A lone floor: A = 1 exactly wherever the camera sees it, front or back, any maximum distance (no
    self-occlusion); pixels that see past its edge (x > 1) read the miss value."""
    cam = top_view(0.56, 0.0, 0.6, 24, 6)  # x in [-0.04, 1.16]: the edge x = 1 inside column 20
    scene = ao_scene([floor(-1.0, 1.0, -1.0, 1.0, up=facing_up)], cam, max_distance, miss=0.25)
    result = mitsuba.render(scene, 64, seed=13)
    img = result.image
    x, _ = floor_points(cam, 4)
    on, off = x.max(axis=-1) < 1.0, x.min(axis=-1) > 1.0
    assert on.sum() == 20 * 6 and off.sum() == 3 * 6
    assert np.all(img[on] == 1.0)
    assert np.all(img[off] == np.float32(0.25))


def test_same_seed_same_ao_image_and_checkpoints(mitsuba):
    scene = resolve_scene("cornell-box-ao").with_resolution(24, 24)
    a = mitsuba.render(scene, 8, seed=5, checkpoints=[1, 2, 4, 8])
    b = mitsuba.render(scene, 8, seed=5)
    c = mitsuba.render(scene, 8, seed=6)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.variance, b.variance)
    assert not np.array_equal(a.image, c.image)
    assert [k.spp for k in a.checkpoints] == [1, 2, 4, 8]
    assert np.array_equal(a.checkpoints[-1].image, a.image)
    assert a.image.dtype == np.float32 and a.image.shape == (24, 24, 3)


def _all_miss(scene: Scene, k: int = 4) -> np.ndarray:
    """(H, W) bool: every one of a pixel's k × k camera rays (corners included) hits nothing.

    The Cornell box's opening is axis-aligned in the image, so such pixels see nothing at all.
    """
    cam = scene.camera
    obj, _ = first_hits(scene, lattice_directions(scene, k).reshape(-1, 3))
    miss = (obj < 0).reshape(cam.height * (k - 1) + 1, cam.width * (k - 1) + 1)
    windows = np.lib.stride_tricks.sliding_window_view(miss, (k, k))[:: k - 1, :: k - 1]
    return windows.all(axis=(-2, -1))


@pytest.mark.parametrize("miss", [None, 0.5])
def test_mitsuba_runs_the_stored_ao_scene(mitsuba, miss):
    """cornell-box-ao is no longer refused: grey images, the miss value where the camera sees past the box."""
    scene = resolve_scene("cornell-box-ao").with_resolution(64, 64)
    if miss is not None:
        scene = dataclasses.replace(scene, ambient_occlusion=dataclasses.replace(scene.ambient_occlusion,
                                                                                 miss_value=miss))
    assert missing_features(mitsuba, scene) == []
    img = mitsuba.render(scene, 16, seed=7).image
    assert np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 0], img[..., 2])
    border = _all_miss(scene)
    assert border[:, 0].all() and border[0, :].all() and border[-1, :].all() and border[:, -1].all()
    assert np.all(img[border] == np.float32(scene.ambient_occlusion.miss_value))
    inside = img[~border][..., 0]
    assert inside.min() >= 0.0 and inside.max() <= 1.0 and inside.mean() > 0.5


def test_stored_ao_reference_agrees_with_a_render(mitsuba):
    """The stored cornell-box-ao reference: a 16-spp render's mean AO within noise of it (two-sided, α = 0.001),
    its border at the miss value (0), the open middle of the floor near 1."""
    scene = resolve_scene("cornell-box-ao")
    ref = load_reference(scene)
    spp = 16
    img = mitsuba.render(scene, spp, seed=1).image
    z = stats.mean_radiance_z(img, ref.image, ref.variance, ref.spp, spp)
    assert abs(z) < norm.isf(ALPHA / 2), z
    assert np.all(ref.image[_all_miss(scene)] == 0.0)
    assert np.array_equal(ref.image[..., 0], ref.image[..., 2])

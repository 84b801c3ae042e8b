"""Motion vectors and reprojection (src/cornell_harness/renderers/core/motion.py), with two cameras of an arc.

The scene is the stored Cornell box, static; the second camera is the first
turned a few degrees about the box's vertical axis (a step of the orbit scene),
built from the scene model's :class:`Camera`: no animated scene is needed.
Exact motion vectors make the reprojected previous frame equal the current
one: exactly for the G-buffer's own positions (to the bilinear interpolation's
second-order error), within noise for a path-traced image. Disocclusion is
checked against Embree's answer to whether the previous camera saw each point.

The ``check_*`` functions take the motion module so that the mutants of
``tests/mutants/temporal.py`` (a copy of it, patched) can be run through them.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cornell_harness.renderers.core import motion
from cornell_harness.renderers.core.gbuffer import gbuffer
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.scenes.library import resolve_scene
from tests.renderers.sequences import orbit

pytest.importorskip("embreex")

RES = 64
#: The arc's step between the two cameras; a step twice as long for the disocclusion test, whose parallax of
#: the boxes against the back wall uncovers a strip a few pixels wide.
DEGREES = 6.0
LONG_STEP = 12.0


def two_cameras(degrees: float):
    """(scene, geometry, G-buffer of the first camera, of the second, the second scene)."""
    scene = resolve_scene("cornell-box").with_resolution(RES, RES)
    second = dataclasses.replace(scene, camera=orbit(scene.camera, degrees))
    geom = SceneGeometry(scene)
    return scene, geom, gbuffer(scene, geom), gbuffer(second, geom), second


@pytest.fixture(scope="module")
def arc():
    return two_cameras(DEGREES)


@pytest.fixture(scope="module")
def long_arc():
    return two_cameras(LONG_STEP)


def surface_footprint(g, camera) -> np.ndarray:
    """(H, W) the width of a pixel on the surface it sees (scene units): its width at its depth over the cosine
    between the view ray and the surface's normal."""
    view = g.position - np.asarray(camera.position, dtype=np.float64)
    view /= np.linalg.norm(view, axis=-1, keepdims=True)
    cos = np.abs(np.sum(view * g.normal, axis=-1))
    return g.depth * 2.0 * camera.tan_half_fov()[0] / camera.width / cos


def interior(g, reach: int = 2) -> np.ndarray:
    """(H, W) pixels whose neighbours within ``reach`` see the same face (object, normal): away from edges, where
    a reprojection's four taps all show the pixel's face."""
    out = g.object >= 0
    n = np.nan_to_num(g.normal)
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            o = np.roll(np.roll(g.object, dy, 0), dx, 1)
            m = np.roll(np.roll(n, dy, 0), dx, 1)
            out &= (o == g.object) & (np.sum(m * n, axis=-1) > 0.999)
    out[:reach], out[-reach:], out[:, :reach], out[:, -reach:] = False, False, False, False
    return out


def check_positions_reproject(module, arc) -> None:
    """Reprojecting the first frame's positions by exact motion vectors gives the second frame's: to 5% of a
    pixel's footprint on the surface inside faces (bilinear interpolation of a plane's projective map), to one
    footprint at their edges (where taps of other faces are rejected and the kept ones renormalised); and the
    history is kept for at least 90% of the pixels that see the box."""
    scene, _, g0, g1, second = arc
    mv = module.motion_vectors(g1.position, g1.object, scene.camera, second.camera)
    values, valid = module.reproject(np.nan_to_num(g0.position), mv, g0, g1)
    seen = g1.object >= 0
    assert valid[seen].mean() > 0.9, valid[seen].mean()
    error = np.linalg.norm(values - g1.position, axis=-1) / surface_footprint(g1, second.camera)
    inside = valid & interior(g1)
    assert inside.sum() > 0.4 * seen.sum()
    assert np.percentile(error[inside], 99) < 0.05 and error[inside].max() < 0.2, \
        (np.percentile(error[inside], 99), error[inside].max())
    assert error[valid].max() < 1.5, error[valid].max()


def occluded_before(arc) -> np.ndarray:
    """(H, W) True where the second camera's point was hidden from the first camera (Embree's segment test), or
    off its image: the pixels a correct reprojection has no history for."""
    scene, geom, _, g1, _ = arc
    seen = g1.object >= 0
    p = g1.position[seen]
    origin = np.asarray(scene.camera.position, dtype=np.float64)
    d = p - origin
    t = np.linalg.norm(d, axis=1)
    visible = geom.unoccluded(np.repeat(origin[None], len(p), 0).astype(np.float32),
                              (d / t[:, None]).astype(np.float32), (t * (1 - 1e-3)).astype(np.float32))
    film = scene.camera.project_to_pixels(p)
    inside = (film[:, 0] >= 0) & (film[:, 0] < RES) & (film[:, 1] >= 0) & (film[:, 1] < RES)
    out = np.zeros(seen.shape, bool)
    out[seen] = ~(visible & inside)
    return out


def check_disocclusion_rejected(module, arc) -> None:
    """Every pixel whose point the first camera did not see, nor its four neighbours' (the strip the
    arc uncovers, less its one-pixel rims, where a previous pixel centre on the same wall within a pixel is a
    fair history), is left without history: at most 2% kept, of at least 10 pixels; while the pixels two or
    more pixels away from the strip keep theirs (95%)."""
    scene, _, g0, g1, second = arc
    hidden = occluded_before(arc)
    core = hidden.copy()
    for axis in (0, 1):
        core &= np.roll(hidden, 1, axis) & np.roll(hidden, -1, axis)
    mv = module.motion_vectors(g1.position, g1.object, scene.camera, second.camera)
    _, valid = module.reproject(np.nan_to_num(g0.position), mv, g0, g1)
    assert core.sum() >= 10, core.sum()
    assert valid[core].mean() <= 0.02, f"{valid[core].mean():.0%} of the uncovered pixels kept a history"
    near = np.zeros_like(hidden)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            near |= np.roll(np.roll(hidden, dy, 0), dx, 1)
    far = (g1.object >= 0) & ~near
    assert valid[far].mean() >= 0.95, valid[far].mean()


def test_motion_vectors_of_a_still_camera_are_zero(arc):
    scene, _, g0, _, _ = arc
    mv = motion.motion_vectors(g0.position, g0.object, scene.camera, scene.camera)
    seen = g0.object >= 0
    assert np.isnan(mv[~seen]).all()
    np.testing.assert_allclose(mv[seen], 0.0, atol=1e-9)


def test_motion_vectors_point_where_the_previous_camera_saw_the_point(arc):
    """The previous camera's ray through pixel centre + motion vector passes through the current point."""
    scene, _, _, g1, second = arc
    mv = motion.motion_vectors(g1.position, g1.object, scene.camera, second.camera)
    seen = g1.object >= 0
    rows, cols = np.nonzero(seen)
    d = scene.camera.directions(cols + 0.5 + mv[rows, cols, 0], rows + 0.5 + mv[rows, cols, 1])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    v = g1.position[rows, cols] - np.asarray(scene.camera.position)
    miss = np.linalg.norm(np.cross(d, v), axis=1) / np.linalg.norm(v, axis=1)
    assert miss.max() < 1e-9
    assert 1.0 < np.abs(mv[seen][:, 0]).mean() < 20.0  # the arc moves the image by pixels, not by nothing


def test_motion_vectors_follow_a_moving_object():
    """A still camera and an object moved by an offset: its pixels' vectors point where it was (the offset
    projected), the others' are zero."""
    scene = resolve_scene("cornell-box").with_resolution(RES, RES)
    names = scene.object_names()
    k = names.index("small-box")
    shift = np.array([0.1, 0.0, 0.0])
    moved = dataclasses.replace(scene, meshes=tuple(
        dataclasses.replace(m, vertices=m.vertices + shift) if i == k else m for i, m in enumerate(scene.meshes)))
    g = gbuffer(moved)
    offsets_now = np.zeros((len(names), 3))
    offsets_now[k] = shift
    mv = motion.motion_vectors(g.position, g.object, scene.camera, scene.camera, np.zeros_like(offsets_now),
                               offsets_now)
    on = g.object == k
    assert on.sum() > 20
    np.testing.assert_allclose(mv[(g.object >= 0) & ~on], 0.0, atol=1e-9)
    before = scene.camera.project_to_pixels(g.position[on] - shift)
    rows, cols = np.nonzero(on)
    np.testing.assert_allclose(mv[on], before - np.stack([cols + 0.5, rows + 0.5], 1), atol=1e-9)
    assert np.all(mv[on][:, 0] < -1.0)  # moved right: it was to the left


def test_reprojected_positions_equal_the_current_ones(arc):
    check_positions_reproject(motion, arc)


def test_disocclusions_are_rejected(long_arc):
    check_disocclusion_rejected(motion, long_arc)


def test_reprojected_render_equals_a_fresh_render_within_noise(arc):
    """The first camera's path-traced image, reprojected by exact motion vectors, against the second camera's
    fresh render (independent seeds): z = difference / √(both variances), over the pixels with history, has
    mean square at most 1.2 and no more than 0.5% beyond 4 (the reprojected variance is the taps' bilinear mean
    of variances, at least that of their mean: z is if anything smaller than a standard normal)."""
    from cornell_harness.renderers.pathtracer import PathTracer

    scene, _, g0, g1, second = arc
    pt = PathTracer(threads=2)
    r0, r1 = pt.render(scene, 64, 11), pt.render(second, 64, 12)
    mv = motion.motion_vectors(g1.position, g1.object, scene.camera, second.camera)
    stacked = np.concatenate([r0.image, r0.variance], axis=-1).astype(np.float64)
    values, valid = motion.reproject(stacked, mv, g0, g1)
    assert valid.mean() > 0.85
    diff = values[..., :3] - r1.image
    var = values[..., 3:] + r1.variance
    z = (diff / np.sqrt(np.maximum(var, 1e-12)))[valid & interior(g1) & (var.min(axis=-1) > 0)]
    assert len(z) > 1000
    assert (z ** 2).mean() < 1.1 and abs(z.mean()) < 0.1 and (np.abs(z) > 4).mean() < 0.005, \
        ((z ** 2).mean(), z.mean(), (np.abs(z) > 4).mean())


def test_reproject_rejects_other_objects_and_turned_normals():
    """The consistency test on its own: another object, a normal turned by more than ~25°, or a point off the
    tangent plane by more than 1% of the depth each reject a tap."""
    n = np.array([0.0, 0.0, 1.0])
    p = np.array([0.0, 0.0, -1.0])
    turned = np.array([0.0, np.sin(0.5), np.cos(0.5)])
    args = [(0, n, p), (1, n, p), (0, turned, p), (0, n, p + [0.0, 0.0, 0.02]), (0, n, p + [0.5, 0.0, 0.0])]
    got = [bool(motion.consistent(o, nn, pp, 0, n, p, 1.0)) for o, nn, pp in args]
    assert got == [True, False, False, False, True]

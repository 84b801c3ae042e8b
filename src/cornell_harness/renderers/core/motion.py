"""Motion vectors and reprojection: where each pixel's surface was in the previous frame, and the history read there.

What every temporal method of ours shares (temporal accumulation,
:mod:`cornell_harness.renderers.temporal`; SVGF, :mod:`cornell_harness.renderers.svgf`), as in
temporal anti-aliasing (Karis 2014, "High Quality Temporal Supersampling"; Salvi
2016, "An Excursion in Temporal Supersampling") and SVGF's reprojection (Schied
et al. 2017, §4.1). Everything here is a pure function of arrays and cameras, so
it is tested with two :class:`cornell_harness.scenes.model.Camera` objects and no
animated scene.

**Motion vectors** (:func:`motion_vectors`): pixel (row, col) of the current
frame sees the point p of its G-buffer (:mod:`cornell_harness.renderers.core.gbuffer`), on
object o. An animation moves whole objects by translation, so that material
point was at p − offset_now[o] + offset_prev[o] in the previous frame, and the
previous camera saw it at film coordinates (x, y) (continuous pixel units,
:mod:`cornell_harness.renderers.core.camera`'s convention). The motion vector is
(x, y) − (col + ½, row + ½): from the pixel's centre to where its surface was.

**Reprojection** (:func:`reproject`): the history at the pixel centre the
motion vector points at, bilinear between the four previous pixel centres
around it; each of the four taps is kept only if it shows the same surface
(disocclusion rejection, as SVGF's "consistency" tests): the same object, a
normal within :data:`NORMAL_COS` of the current one, and a position (moved by
its object's motion) within :data:`DEPTH_TOLERANCE` of the current depth from
the current point's tangent plane, a depth test that a surface seen at a grazing
angle passes between neighbouring pixels. The weights of the kept taps are
renormalised; a pixel none of whose taps is kept (or whose point was off the
previous image or behind its camera) has no history: disoccluded.
"""

from __future__ import annotations

import numpy as np

from cornell_harness.scenes.model import Camera, Scene

#: Least cosine between a history tap's normal and the current pixel's (≈ 25°).
NORMAL_COS = 0.9
#: Largest distance of a history tap's point from the current point's tangent plane, as a fraction of its depth.
DEPTH_TOLERANCE = 0.01
#: Least total bilinear weight of the kept taps for a pixel to keep its history.
MIN_WEIGHT = 1e-3


def object_offsets(scene: Scene, frame: int) -> np.ndarray:
    """(objects, 3) float64: each object's translation at ``frame`` relative to the scene file's position, in
    :meth:`cornell_harness.scenes.model.Scene.object_names`' order (the G-buffer's object ids); zeros for a
    still scene (``scene.animation`` None) and for objects without a track."""
    names = scene.object_names()
    animation = getattr(scene, "animation", None)
    if animation is None:
        return np.zeros((len(names), 3))
    return np.array([np.asarray(animation.offset(name, frame), dtype=np.float64) for name in names]).reshape(-1, 3)


def _offset_of(offsets: np.ndarray | None, object_ids: np.ndarray) -> np.ndarray:
    """(..., 3) the offset of each pixel's object (zeros where ``offsets`` is None or the pixel saw nothing)."""
    if offsets is None:
        return np.zeros(object_ids.shape + (3,))
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
    return np.where((object_ids >= 0)[..., None], offsets[np.maximum(object_ids, 0)], 0.0)


def motion_vectors(positions: np.ndarray, object_ids: np.ndarray, camera_prev: Camera, camera_now: Camera,
                   offsets_prev: np.ndarray | None = None, offsets_now: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 2) float64 motion vectors (dx, dy) in pixels (module docstring), NaN where the pixel saw nothing
    or its point was behind the previous camera.

    ``positions`` (H, W, 3): the current frame's world positions (the G-buffer's, NaN where nothing is seen);
    ``object_ids`` (H, W): its objects (-1: none); ``offsets_prev``/``offsets_now`` (objects, 3): each object's
    translation in the two frames (:func:`object_offsets`; None: nothing moves but the camera).
    ``camera_now`` gives the image size; the two cameras must have the same.
    """
    h, w = object_ids.shape
    if (camera_now.width, camera_now.height) != (w, h) or (camera_prev.width, camera_prev.height) != (w, h):
        raise ValueError(f"cameras of {camera_prev.width}x{camera_prev.height} and {camera_now.width}x"
                         f"{camera_now.height} for a {w}x{h} G-buffer")
    before = positions - _offset_of(offsets_now, object_ids) + _offset_of(offsets_prev, object_ids)
    forward = camera_prev.frame()[2]
    z = (before - np.asarray(camera_prev.position, dtype=np.float64)) @ forward
    with np.errstate(invalid="ignore", divide="ignore"):
        film = camera_prev.project_to_pixels(before.reshape(-1, 3)).reshape(h, w, 2)
    rows, cols = np.mgrid[0:h, 0:w]
    motion = film - np.stack([cols + 0.5, rows + 0.5], axis=-1)
    seen = (object_ids >= 0) & (z > 0)
    return np.where(seen[..., None], motion, np.nan)


def reproject(history: np.ndarray, motion: np.ndarray, prev, now, offsets_prev: np.ndarray | None = None,
              offsets_now: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The previous frame's ``history`` (H, W, C) read where ``motion`` points, with disocclusion rejection.

    ``prev`` and ``now`` are the two frames' G-buffers (anything with ``depth``, ``position``, ``normal``
    and ``object`` as :class:`cornell_harness.renderers.core.gbuffer.GBuffer` has); the offsets as
    :func:`motion_vectors` takes them. Returns (values (H, W, C) float64, 0 where there is no history;
    valid (H, W) bool).
    """
    h, w = now.object.shape
    rows, cols = np.mgrid[0:h, 0:w]
    with np.errstate(invalid="ignore"):
        x = cols + motion[..., 0]  # the tap grid's coordinates: pixel (r, c)'s centre is at (c, r)
        y = rows + motion[..., 1]
    finite = np.isfinite(x) & np.isfinite(y)
    x, y = np.where(finite, x, -2.0), np.where(finite, y, -2.0)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    moved = _offset_of(offsets_now, prev.object) - _offset_of(offsets_prev, prev.object)
    prev_position = prev.position + moved  # the previous frame's points where they are now
    values = np.zeros((h, w, history.shape[-1]))
    total = np.zeros((h, w))
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        tx, ty = x0 + dx, y0 + dy
        weight = (fx if dx else 1.0 - fx) * (fy if dy else 1.0 - fy)
        inside = finite & (tx >= 0) & (tx < w) & (ty >= 0) & (ty < h)
        cx, cy = np.clip(tx, 0, w - 1), np.clip(ty, 0, h - 1)
        keep = inside & consistent(prev.object[cy, cx], prev.normal[cy, cx], prev_position[cy, cx],
                                   now.object, now.normal, now.position, now.depth)
        weight = np.where(keep, weight, 0.0)
        values += weight[..., None] * np.where(keep[..., None], history[cy, cx], 0.0)
        total += weight
    valid = total >= MIN_WEIGHT
    values = np.where(valid[..., None], values / np.where(valid, total, 1.0)[..., None], 0.0)
    return values, valid


def consistent(object_prev, normal_prev, position_prev, object_now, normal_now, position_now, depth_now):
    """Whether a history tap shows the current pixel's surface (module docstring): same object, normals within
    :data:`NORMAL_COS`, the tap's point within :data:`DEPTH_TOLERANCE` · depth of the current tangent plane."""
    with np.errstate(invalid="ignore"):
        cos = np.sum(normal_prev * normal_now, axis=-1)
        plane = np.abs(np.sum((position_prev - position_now) * normal_now, axis=-1))
        return (object_now >= 0) & (object_prev == object_now) & (cos >= NORMAL_COS) \
            & (plane <= DEPTH_TOLERANCE * depth_now)

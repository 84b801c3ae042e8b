"""The G-buffer: what one primary ray through each pixel centre sees (depth, normal, position).

A rasteriser's geometry pass writes, per pixel, the nearest surface's depth,
normal and position, and screen-space effects read only those buffers
(Saito and Takahashi 1990, "Comprehensible Rendering of 3-D Shapes", the
G-buffer; Mittring 2007 for screen-space AO on it). Ours comes from the
toolkit's ray queries instead of a rasteriser: one ray per pixel through its
centre ((u, v) = (1/2, 1/2) in :mod:`cornell_harness.renderers.core.camera`'s convention), so
the G-buffer and our ray tracers agree on what each pixel sees, spheres
included. One sample per pixel, as a rasteriser without multisampling: no box
filter.

:func:`gbuffer` returns a :class:`GBuffer` of arrays (H, W[, 3]), float64:

- ``depth``: view-space depth, the distance along the camera's forward axis
  (not along the ray), what a depth buffer linearised holds; ``inf`` where the
  ray misses;
- ``position``: the world-space point the ray hits, NaN where it misses;
- ``normal``: the geometric unit normal faced towards the camera (the side
  it sees, as the AO definition of :mod:`cornell_harness.scenes.quantities` wants),
  NaN where it misses;
- ``prim``: the primitive hit (int64, :mod:`cornell_harness.renderers.core.geometry`'s
  numbering), -1 where the ray misses;
- ``object``: the object hit (int64, the index of its name in
  :meth:`cornell_harness.scenes.model.Scene.object_names`: meshes, then spheres), -1 where
  the ray misses: what motion vectors move by (an object's animation offset) and
  what disocclusion tests compare (:mod:`cornell_harness.renderers.core.motion`).

:func:`view_space` turns position and normal into the camera's frame
(x right, y up, z forward = depth), the frame screen-space passes work in.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cornell_harness.scenes.model import Camera, Scene
from cornell_harness.renderers.core.camera import camera_basis, camera_ray
from cornell_harness.renderers.core.geometry import SceneGeometry, ray_hit
from cornell_harness.renderers.core.occlusion import face_forward
from cornell_harness.renderers.core.rays import ray_buffer, set_ray
from cornell_harness.renderers.core.sampling import jit


class GBuffer(NamedTuple):
    depth: np.ndarray  # (H, W) float64 distance along the camera's forward axis; inf: miss
    position: np.ndarray  # (H, W, 3) float64 world-space hit point; NaN: miss
    normal: np.ndarray  # (H, W, 3) float64 unit geometric normal on the camera's side; NaN: miss
    prim: np.ndarray  # (H, W) int64 primitive hit; -1: miss
    object: np.ndarray  # (H, W) int64 object hit (Scene.object_names' index); -1: miss


@jit
def _centre_rays(basis, width, height, rays):
    """Ray i of ``rays`` from the camera through the centre of pixel i (row-major)."""
    origin = (basis[0, 0], basis[0, 1], basis[0, 2])
    for i in range(width * height):
        set_ray(rays, i, origin, camera_ray(basis, width, height, i, 0.5, 0.5))


@jit
def _surfaces(prim, t_sphere, rays, geo, basis, depth, position, normal):
    """Fill the G-buffer rows from the closest hits ``prim`` (and sphere distances ``t_sphere``)."""
    for i in range(prim.size):
        p = prim[i]
        if p < 0:
            depth[i] = np.inf
            for c in range(3):
                position[i, c] = np.nan
                normal[i, c] = np.nan
            continue
        _, x, n0, cos_o, _, _ = ray_hit(geo, rays, i, p, t_sphere)
        o = (rays.o[i, 0], rays.o[i, 1], rays.o[i, 2])
        n = face_forward(n0, cos_o)  # a back face seen by the camera: its normal turned to the camera
        depth[i] = (x[0] - o[0]) * basis[3, 0] + (x[1] - o[1]) * basis[3, 1] + (x[2] - o[2]) * basis[3, 2]
        for c in range(3):
            position[i, c] = x[c]
            normal[i, c] = n[c]


def gbuffer(scene: Scene, geom: SceneGeometry | None = None) -> GBuffer:
    """The G-buffer of ``scene``'s camera (module docstring); ``geom`` reuses an Embree scene already built."""
    cam = scene.camera
    geom = geom if geom is not None else SceneGeometry(scene)
    basis = camera_basis(cam)
    n = cam.width * cam.height
    rays = ray_buffer(n)
    _centre_rays(basis, cam.width, cam.height, rays)
    prim, t_sphere = geom.closest_hits(rays)
    prim = prim.astype(np.int64)
    depth, position, normal = np.empty(n), np.empty((n, 3)), np.empty((n, 3))
    _surfaces(prim, t_sphere, rays, geom.tables(), basis, depth, position, normal)
    h, w = cam.height, cam.width
    obj = np.where(prim >= 0, geom.object[np.maximum(prim, 0)], -1).astype(np.int64)
    return GBuffer(depth.reshape(h, w), position.reshape(h, w, 3), normal.reshape(h, w, 3), prim.reshape(h, w),
                   obj.reshape(h, w))


def view_space(g: GBuffer, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Position and normal (H, W, 3) in the camera's frame: x right, y up, z forward (z = ``g.depth``).

    Pixel (row, col)'s point has x/z = sx·tan_x and y/z = sy·tan_y with sx, sy
    the pixel centre's image-plane coordinates (:mod:`cornell_harness.renderers.core.camera`).
    NaN where the ray missed.
    """
    frame = np.stack(camera.frame())  # rows: right, up, forward
    position = (g.position - np.asarray(camera.position, dtype=np.float64)) @ frame.T
    return np.ascontiguousarray(position), np.ascontiguousarray(g.normal @ frame.T)

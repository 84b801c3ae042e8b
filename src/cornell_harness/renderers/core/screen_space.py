"""Screen space: where a view-space point lands on the image, and what depth a pixel of the G-buffer shows there.

The scalar geometry of screen-space techniques (:mod:`cornell_harness.renderers.ssao`):
projection of a view-space point (x right, y up, z forward = depth; camera
at the origin; :func:`cornell_harness.renderers.core.gbuffer.view_space`) to continuous
pixel coordinates and back, the screen's edges, and the depth a pixel's
tangent plane shows along another view ray. Every function takes scalars:
a numba helper that takes arrays and branches keeps a reference-count
increment and decrement of each per call (:mod:`cornell_harness.renderers.core.rays`),
atomic and shared by the threads, which made a per-read helper 2x slower.
"""

from __future__ import annotations

import numpy as np

from cornell_harness.renderers.core.sampling import jit


@jit
def project(x, y, z, cx, cy, cu, cv):
    """Where the view-space point (x, y, z), z > 0, lands: image coordinates (u = column, v = row, continuous
    pixel units) and its view ray (dx, dy, 1) = (x/z, y/z, 1).

    ``cx`` = width/(2·tx), ``cy`` = height/(2·ty), ``cu`` = width/2, ``cv`` = height/2, computed once per pass:
    one division per point instead of four.
    """
    iz = 1.0 / z
    dx, dy = x * iz, y * iz
    return cu + dx * cx, cv - dy * cy, dx, dy


@jit
def ray_through(u, v, ax, ay, tx, ty):
    """(dx, dy) of the view ray (dx, dy, 1) through image point (u, v): the inverse of :func:`project`.

    ``ax`` = 2·tx/width and ``ay`` = 2·ty/height, computed once per pass.
    """
    return u * ax - tx, ty - v * ay


@jit
def on_screen(u, v, width, height) -> bool:
    return 0.0 <= u < width and 0.0 <= v < height


@jit
def to_edge(u, v, du, dv, width, height):
    """How far (pixels) from (u, v), on screen, the line along the unit direction (du, dv) stays on screen."""
    t = np.inf
    if du > 0.0:
        t = (width - u) / du
    elif du < 0.0:
        t = -u / du
    if dv > 0.0:
        t = min(t, (height - v) / dv)
    elif dv < 0.0:
        t = min(t, -v / dv)
    return t * (1.0 - 1e-9)  # the edge itself is off screen


@jit
def plane_depth(x, y, z, nx, ny, nz, dx, dy):
    """Depth along the view ray (dx, dy, 1) of what a pixel shows: the plane through its point (x, y, z)
    with its normal n; inf where it shows nothing (z is NaN).

    Exact on flat surfaces (a plane never occludes itself); the pixel's own
    depth where the ray meets that plane edge-on or behind the camera.
    """
    if not z < np.inf:  # NaN: the pixel's camera ray missed
        return np.inf
    den = dx * nx + dy * ny + nz
    if den < 0.0:  # the normal faces the camera, so a ray that sees the plane's front has d·n < 0
        t = (x * nx + y * ny + z * nz) / den
        if t > 0.0:
            return t
    return z

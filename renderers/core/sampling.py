"""Sampling routines shared by our renderers.

The per-vertex routines are scalar numba functions (``nogil``), called from
each renderer's shading kernel; camera rays are made once per work unit, in
numpy. Everything is float64.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from harness.scene import Camera

INV_PI = 1.0 / math.pi
jit = numba.njit(cache=True, nogil=True, fastmath=False)


@jit
def orthonormal_basis(nx: float, ny: float, nz: float):
    """Tangents (s, t) with (s, t, n) right-handed, for a unit normal n.

    Duff et al. 2017, "Building an Orthonormal Basis, Revisited", JCGT 6(1), Listing 3.
    """
    sign = 1.0 if nz >= 0.0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return (1.0 + sign * nx * nx * a, sign * b, -sign * nx), (b, sign + ny * ny * a, -ny)


@jit
def cosine_hemisphere(nx: float, ny: float, nz: float, u1: float, u2: float):
    """A direction about unit normal n with pdf cosθ/π: (dx, dy, dz, cosθ).

    Malley's method, a uniform disk point lifted to the hemisphere (pbrt-v4 §A.5.3).
    """
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    lx, ly = r * math.cos(phi), r * math.sin(phi)
    lz = math.sqrt(max(0.0, 1.0 - u1))
    s, t = orthonormal_basis(nx, ny, nz)
    return (s[0] * lx + t[0] * ly + nx * lz, s[1] * lx + t[1] * ly + ny * lz, s[2] * lx + t[2] * ly + nz * lz, lz)


@jit
def triangle_barycentrics(u1: float, u2: float):
    """Uniform point in a triangle as weights (b1, b2) of edges e1, e2 (Turk 1990; pbrt-v4 §6.5.4)."""
    su = math.sqrt(u1)
    return su * (1.0 - u2), su * u2


@jit
def power_heuristic(pdf_a: float, pdf_b: float) -> float:
    """Veach's power heuristic (β = 2), Veach 1997 thesis eq. 9.13; 0 when both pdfs are 0."""
    a2, b2 = pdf_a * pdf_a, pdf_b * pdf_b
    return a2 / (a2 + b2) if a2 + b2 > 0.0 else 0.0


def camera_rays(camera: Camera, pixel: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Primary rays through uniformly jittered points of the given pixels (box filter).

    ``pixel`` is the flat index row * width + col. Returns origins and unit
    directions, float64 (m, 3).
    """
    right, up, forward = camera.frame()
    tx, ty = camera.tan_half_fov()
    row, col = np.divmod(pixel, camera.width)
    sx = (2.0 * (col + u1) / camera.width - 1.0) * tx
    sy = (1.0 - 2.0 * (row + u2) / camera.height) * ty
    d = forward + sx[:, None] * right + sy[:, None] * up
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.tile(np.asarray(camera.position, dtype=np.float64), (d.shape[0], 1))
    return o, d

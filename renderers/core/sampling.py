"""Sampling routines shared by our renderers.

They are scalar numba functions (``nogil``), called from each renderer's
kernels. Everything is float64.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from harness.scenes.model import Camera

INV_PI = 1.0 / math.pi
jit = numba.njit(cache=True, nogil=True, error_model="numpy")


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


def camera_basis(camera: Camera) -> np.ndarray:
    """(4, 3) float64: position, and right, up, forward scaled to the image plane at distance 1.

    Pixel (row, col) spans directions forward + sx·right + sy·up with
    sx in [-tan_x, tan_x] left to right and sy in [tan_y, -tan_y] top to bottom.
    """
    right, up, forward = camera.frame()
    tx, ty = camera.tan_half_fov()
    return np.stack([np.asarray(camera.position, dtype=np.float64), right * tx, up * ty, forward])


@jit
def camera_ray(basis, width: int, height: int, pixel: int, u1: float, u2: float):
    """Unit direction through a uniformly jittered point of ``pixel`` (box filter), from basis[0]."""
    row, col = pixel // width, pixel % width
    sx = 2.0 * (col + u1) / width - 1.0
    sy = 1.0 - 2.0 * (row + u2) / height
    d0 = basis[3, 0] + sx * basis[1, 0] + sy * basis[2, 0]
    d1 = basis[3, 1] + sx * basis[1, 1] + sy * basis[2, 1]
    d2 = basis[3, 2] + sx * basis[1, 2] + sy * basis[2, 2]
    inv = 1.0 / math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return d0 * inv, d1 * inv, d2 * inv

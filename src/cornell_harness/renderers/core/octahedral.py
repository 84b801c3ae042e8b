"""Octahedral maps: spherical functions stored in a square texture, with the borders bilinear lookup needs.

The octahedral parameterisation of the unit sphere (Cigolle, Donow, Evangelakos,
Mara, McGuire and Meyer 2014, "A Survey of Efficient Representations for
Independent Unit Vectors", JCGT 3(2), §3.5 and Listing 6): a direction d is
projected onto the octahedron |x| + |y| + |z| = 1, the upper half (z ≥ 0)
flattened onto the square's inner diamond and the lower half folded out onto
its four corners, giving (u, v) ∈ [-1, 1]² (:func:`octahedral_uv`,
:func:`octahedral_direction`). The square is cut into n × n texels; texel
(row i, column j) stands for the direction of its centre
(:func:`texel_directions`: u from the column, v from the row).

Bilinear lookup (:func:`bilinear_texels`) reads a map stored with a
**one-texel border** on every side, (n + 2) × (n + 2), as DDGI stores its
probes (Majercik et al. 2019, §5; RTXGI's ``ProbeBorderUpdateCS``): a texel
just outside an edge of the square is the same direction as the interior
texel mirrored along that edge (the fold maps (u, -1) and (-u, -1) to one
direction), and the four corners are all the -z pole, so each border texel
copies the mirrored interior one and each corner the diagonally opposite
interior corner (:func:`with_borders`). Lookups then never wrap.
"""

from __future__ import annotations

import math

import numpy as np

from cornell_harness.renderers.core.sampling import jit


@jit
def octahedral_uv(x, y, z):
    """The octahedral coordinates (u, v) ∈ [-1, 1]² of the nonzero direction (x, y, z)."""
    l1 = abs(x) + abs(y) + abs(z)
    u, v = x / l1, y / l1
    if z < 0.0:
        # Fold the lower half out to the corners; the sign of 0 counts as + (RTXGI's SignNotZero).
        su = 1.0 if u >= 0.0 else -1.0
        sv = 1.0 if v >= 0.0 else -1.0
        u, v = (1.0 - abs(v)) * su, (1.0 - abs(u)) * sv
    return u, v


@jit
def octahedral_direction(u, v):
    """The unit direction at octahedral coordinates (u, v) ∈ [-1, 1]² (inverse of :func:`octahedral_uv`)."""
    x, y, z = u, v, 1.0 - abs(u) - abs(v)
    if z < 0.0:
        sx = 1.0 if x >= 0.0 else -1.0
        sy = 1.0 if y >= 0.0 else -1.0
        x, y = (1.0 - abs(v)) * sx, (1.0 - abs(u)) * sy
    k = 1.0 / math.sqrt(x * x + y * y + z * z)
    return x * k, y * k, z * k


def texel_directions(n: int) -> np.ndarray:
    """Unit directions (n, n, 3) of the centres of an n × n octahedral map's texels (row i: v, column j: u)."""
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    out = np.empty((n, n, 3))
    for i in range(n):
        for j in range(n):
            out[i, j] = octahedral_direction(c[j], c[i])
    return out


def with_borders(maps: np.ndarray) -> np.ndarray:
    """Interior maps (..., n, n, C) framed by the one-texel octahedral border: (..., n + 2, n + 2, C)."""
    n = maps.shape[-2]
    out = np.zeros(maps.shape[:-3] + (n + 2, n + 2, maps.shape[-1]), maps.dtype)
    fill_borders(out, maps)
    return out


def fill_borders(out: np.ndarray, interior: np.ndarray) -> None:
    """Write ``interior`` (..., n, n, C) into ``out`` (..., n + 2, n + 2, C), its border texels included."""
    n = interior.shape[-2]
    out[..., 1:-1, 1:-1, :] = interior
    out[..., 0, 1:-1, :] = interior[..., 0, ::-1, :]  # top edge: the first row, mirrored in u
    out[..., -1, 1:-1, :] = interior[..., n - 1, ::-1, :]
    out[..., 1:-1, 0, :] = interior[..., ::-1, 0, :]  # left edge: the first column, mirrored in v
    out[..., 1:-1, -1, :] = interior[..., ::-1, n - 1, :]
    out[..., 0, 0, :] = interior[..., n - 1, n - 1, :]  # corners: the -z pole, the opposite corner
    out[..., 0, -1, :] = interior[..., n - 1, 0, :]
    out[..., -1, 0, :] = interior[..., 0, n - 1, :]
    out[..., -1, -1, :] = interior[..., 0, 0, :]


@jit
def bilinear_texels(n, u, v):
    """Where a bilinear lookup at (u, v) reads a bordered map of n × n interior texels.

    Returns (row, column, fr, fc): the upper-left of the 2 × 2 texels (indices
    into the (n + 2) × (n + 2) map) and the weights fr, fc of the second row
    and column. Texel k of the bordered map is centred at k, so the interior
    spans [0.5, n + 0.5] and the neighbours stay inside the border.
    """
    ku = min(max((u + 1.0) * 0.5 * n + 0.5, 0.5), n + 0.5)
    kv = min(max((v + 1.0) * 0.5 * n + 0.5, 0.5), n + 0.5)
    c0 = min(int(math.floor(ku)), n)
    r0 = min(int(math.floor(kv)), n)
    return r0, c0, kv - r0, ku - c0

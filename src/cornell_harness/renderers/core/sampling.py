"""Generic sample warps shared by our renderers, and the ``jit`` they are compiled with.

Scalar numba functions (``nogil``) that turn uniform numbers into points and
directions, called from every renderer's kernels; everything is float64.
What the numbers mean for a path (which dimension feeds which decision) is
:mod:`cornell_harness.renderers.core.sampler`'s; cameras are :mod:`cornell_harness.renderers.core.camera`'s.

:data:`jit` is the one decorator of every kernel and helper of ours (:data:`jit_inline`
is the same, inlined by numba into its callers):
``cache=True`` (compiled once per machine), ``nogil`` (threads run kernels in
parallel) and ``error_model="numpy"`` (a division by zero gives inf/NaN
instead of raising, so no zero checks in inner loops; every pdf division is
guarded by its caller instead).

numba's cache checks only the source file of the function it compiled, not
the toolkit functions that were inlined into it: after an edit of
``src/cornell_harness/renderers/core/lights.py`` the path tracer's cached kernel would still run
the old code. :func:`drop_stale_kernel_caches` therefore keys every cache
under ``src/cornell_harness/renderers/`` on a hash of all our renderer sources.
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path

import numba
import numpy as np

INV_PI = 1.0 / math.pi
_RENDERERS = Path(__file__).resolve().parents[1]
_STAMP = "cbox-kernel-sources.sha256"


def drop_stale_kernel_caches(root: Path = _RENDERERS) -> bool:
    """Delete numba's cached kernels under ``root`` if any ``.py`` below it changed since they were made.

    Returns True when caches were dropped. Cheap (one hash of a few hundred
    KB of source per process), and a read-only install is left alone.
    """
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    want = digest.hexdigest()
    stamp = root / "__pycache__" / _STAMP
    try:
        if stamp.read_text() == want:
            return False
    except OSError:
        pass
    try:
        for cached in [*root.rglob("__pycache__/*.nbi"), *root.rglob("__pycache__/*.nbc")]:
            cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{_STAMP}.{os.getpid()}.tmp")
        tmp.write_text(want)
        tmp.replace(stamp)  # atomic: a concurrent process sees the old stamp or the new one
    except OSError:
        return False
    return True


drop_stale_kernel_caches()
jit = numba.njit(cache=True, nogil=True, error_model="numpy")
#: :data:`jit` for the few helpers every kernel calls per decision whose body LLVM will not inline by itself
#: (:mod:`cornell_harness.renderers.core.sampler`'s ``path_point``, ``sample_1d``, ``sample_2d``, ``vertex_1d``,
#: ``vertex_2d``: a branch per sampler, so their compiled body is large; :mod:`cornell_harness.renderers.core.direct`'s
#: ``light_sample`` and ``sample_ld``, whose calls passed the scene's tables as ~100 flattened arguments):
#: numba inlines them into each caller. Without it, the photon kernels, which drew raw numbers before they
#: drew through the sampler, ran 30-80% slower (measured 2026-12-03); the path tracer ~8% (2026-12-04).
jit_inline = numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")


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
def uniform_hemisphere(nx: float, ny: float, nz: float, u1: float, u2: float):
    """A direction about unit normal n with pdf 1/(2π): (dx, dy, dz, cos θ).

    pbrt-v4 §A.5.2 (``SampleUniformHemisphere``: cos θ uniform in [0, 1), φ = 2π u2),
    with cos θ = 1 − u1 ∈ (0, 1] so that no direction lies exactly in the tangent plane.
    """
    z = 1.0 - u1
    r = math.sqrt(max(0.0, 1.0 - z * z))
    phi = 2.0 * math.pi * u2
    lx, ly = r * math.cos(phi), r * math.sin(phi)
    s, t = orthonormal_basis(nx, ny, nz)
    return (s[0] * lx + t[0] * ly + nx * z, s[1] * lx + t[1] * ly + ny * z, s[2] * lx + t[2] * ly + nz * z, z)


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


def spherical_fibonacci(n: int) -> np.ndarray:
    """n directions (n, 3) spread evenly over the sphere: the spherical Fibonacci point set.

    Keinert, Innmann, Sänger and Stamminger 2015, "Spherical Fibonacci Mapping"
    (ACM TOG 34(6)), eq. 2: z_i = 1 − (2i + 1)/n, φ_i = 2π·frac(i/Φ) with Φ the
    golden ratio (RTXGI's ``RTXGISphericalFibonacci``): equal-area bands in z,
    so each direction stands for 4π/n of solid angle.
    """
    i = np.arange(n, dtype=np.float64)
    phi = 2.0 * math.pi * np.modf(i * (math.sqrt(5.0) * 0.5 - 0.5))[0]
    z = 1.0 - (2.0 * i + 1.0) / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    return np.stack([np.cos(phi) * r, np.sin(phi) * r, z], axis=1)


def random_rotation(u1: float, u2: float, u3: float) -> np.ndarray:
    """A rotation matrix (3, 3) uniformly distributed over SO(3), from three uniform numbers.

    Shoemake 1992, "Uniform Random Rotations" (Graphics Gems III, §III.6): the
    unit quaternion (√(1−u1) sin 2πu2, √(1−u1) cos 2πu2, √u1 sin 2πu3, √u1 cos 2πu3)
    is uniform on S³, hence its rotation uniform on SO(3).
    """
    a, b = math.sqrt(1.0 - u1), math.sqrt(u1)
    x, y = a * math.sin(2.0 * math.pi * u2), a * math.cos(2.0 * math.pi * u2)
    z, w = b * math.sin(2.0 * math.pi * u3), b * math.cos(2.0 * math.pi * u3)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])

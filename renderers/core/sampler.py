"""Named sample dimensions: which random number of a path each decision uses.

In the spirit of pbrt-v4's ``Sampler::Get1D``/``Get2D`` (§8.3), a path's
decisions consume its counter-based random numbers
(:func:`renderers.core.rng.uniform`) in a fixed order, but here every
dimension has a name instead of hand arithmetic in the kernels:

- dimensions 0 and 1 (:data:`CAMERA_U`, :data:`CAMERA_V`) jitter the camera
  ray inside its pixel;
- then each path vertex (depth 1, 2, ...: the surface the depth-th segment
  reaches) owns :data:`DIMS_PER_VERTEX` dimensions, at the offsets named
  below, whether or not the integrator uses them all.

A dimension is a pure function of (depth, offset), so a decision that is
skipped (no emitter, a path ended) never shifts the numbers of the ones
after it, and two estimators that share the layout see the same numbers
for the same decision. Changing any number here changes every image:
``tests/test_pathtracer_pinned.py`` pins them.

A renderer whose decisions differ (photons from a light, probe rays) names
its own layout the same way, over :func:`uniform` with its own key.
"""

from __future__ import annotations

from renderers.core.rng import uniform
from renderers.core.sampling import jit

#: The camera ray's jitter inside its pixel (box filter), x then y.
CAMERA_U = 0
CAMERA_V = 1
CAMERA_DIMS = 2

#: Offsets inside a vertex's block: the emitter triangle (by power), the point on it (2),
#: the BSDF direction (2), Russian roulette.
EMITTER_PICK = 0
EMITTER_U = 1
EMITTER_V = 2
BSDF_U = 3
BSDF_V = 4
ROULETTE = 5
DIMS_PER_VERTEX = 6


@jit
def vertex_dim(depth, offset):
    """Dimension of ``offset`` at path vertex ``depth`` (1: the camera ray's hit)."""
    return CAMERA_DIMS + (depth - 1) * DIMS_PER_VERTEX + offset


@jit
def camera_sample(key, path):
    """The pixel jitter (u, v) in [0, 1)² of ``path``."""
    return uniform(key, path, CAMERA_U), uniform(key, path, CAMERA_V)


@jit
def vertex_1d(key, path, depth, offset) -> float:
    """One number of vertex ``depth`` (pbrt's Get1D)."""
    return uniform(key, path, vertex_dim(depth, offset))


@jit
def vertex_2d(key, path, depth, offset):
    """Two consecutive numbers of vertex ``depth``, from ``offset`` on (pbrt's Get2D)."""
    dim = vertex_dim(depth, offset)
    return uniform(key, path, dim), uniform(key, path, dim + 1)

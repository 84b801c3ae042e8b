"""Samplers, and named sample dimensions: which number of a path each decision uses.

In the spirit of pbrt-v4's ``Sampler::Get1D``/``Get2D`` (§8.3), a path's
decisions consume numbers in a fixed order, but every dimension has a name
instead of hand arithmetic in the kernels:

- dimensions 0 and 1 (:data:`CAMERA_U`, :data:`CAMERA_V`) jitter the camera
  ray inside its pixel;
- then each path vertex (depth 1, 2, ...: the surface the depth-th segment
  reaches) owns :data:`DIMS_PER_VERTEX` dimensions, at the offsets named
  below, whether or not the integrator uses them all;
- :data:`WAVELENGTH`, the hero wavelength of a spectral path
  (:mod:`cornell_harness.renderers.hero_wavelength`), is the last dimension a number can
  have, so that no vertex reaches it and the RGB renders' numbers are those
  they had before it existed.

A dimension is a pure function of (depth, offset), so a decision that is
skipped (no emitter, a path ended) never shifts the numbers of the ones
after it. Changing any number here changes every image:
``tests/renderers/test_pathtracer_pinned.py`` and ``tests/renderers/test_photon_pinned.py`` pin them.
Photon paths have their own layout (:mod:`cornell_harness.renderers.core.photons`) and
draw from :func:`sequence_stream`: one sequence over a map's photons.

Which numbers a dimension gets is the sampler's (:data:`SAMPLERS`), carried
to kernels as a :class:`Stream`; every sample stays a pure function of
(seed, pixel, sample index, dimension), so images do not depend on threads:

- ``independent``: counter-based uniform numbers (:func:`cornell_harness.renderers.core.rng.uniform`)
  of (pass key, path index, dimension), as every renderer had before samplers.
- ``pmj02``: every 1D/2D decision its own progressive (0, 2)-sequence,
  shuffled and Owen-scrambled (:func:`cornell_harness.renderers.core.sobol.padded_2d`;
  Burley 2020's padding): each power-of-two prefix of a pixel's samples is
  stratified in every elementary interval, as pmj02 is.
- ``sobol``: one Owen-scrambled Sobol' sequence across all of a path's
  dimensions per pixel (:func:`cornell_harness.renderers.core.sobol.sobol_1d`; pbrt-v4's
  ``SobolSampler`` with per-pixel scrambling), uniform past its 64 dimensions.

**Variance of a low-discrepancy mean.** Its samples are negatively
correlated, so the per-sample variance over n overstates its error and a
z-test using it loses power. The low-discrepancy samplers therefore split a
pixel's samples into :data:`BATCHES` independent randomisations: sample s
belongs to batch ``s mod K`` and is point ``s div K`` of that batch's own
scrambling (its key). The batch means are independent and unbiased, so
their spread gives the variance of the mean (:class:`cornell_harness.renderers.core.film.Film`),
and every power-of-two checkpoint ≥ K gives each batch a power-of-two prefix.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from cornell_harness.adapters.api import Setting, pass_key
from cornell_harness.renderers.core.rng import mix64, uniform
from cornell_harness.renderers.core.sampling import jit, jit_inline
from cornell_harness.renderers.core.sobol import SOBOL_MATRICES, padded_1d, padded_2d, pixel_seed, sobol_1d

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
#: The hero wavelength's number (:mod:`cornell_harness.renderers.core.wavelengths`): dimension 2^24 - 1, the last one
#: :func:`cornell_harness.renderers.core.rng.uniform` takes, past any vertex a path reaches (vertex ~2.8 million).
WAVELENGTH = (1 << 24) - 1

INDEPENDENT, PMJ02, SOBOL = 0, 1, 2
#: Sampler names (the ``sampler`` setting) and their ids in a :class:`Stream`.
SAMPLERS = {"independent": INDEPENDENT, "pmj02": PMJ02, "sobol": SOBOL}
#: Independent randomisations of a low-discrepancy render: 7 degrees of freedom per pixel's variance.
#: More give a steadier variance, fewer keep more stratification (docs/sampling.md measures both).
BATCHES = 8
#: The ``sampler`` setting of our renderers that draw from a :class:`Stream`.
SAMPLER_SETTING = Setting("sampler", str, "pmj02",
                          "random numbers: independent, pmj02 (progressive (0,2)-sequences per decision) or sobol "
                          f"(Owen-scrambled, all dimensions); the last two report the variance of {BATCHES} "
                          "independent batches", choices=tuple(SAMPLERS))
#: How a render of ours gets the variance it reports (``variance`` setting): ``batches`` as above, or ``none``.
VARIANCE_MODES = ("batches", "none")
VARIANCE_SETTING = Setting("variance", str, "batches",
                           f"batches: a low-discrepancy sampler's samples per pixel are {BATCHES} independent "
                           "randomisations whose spread is the variance reported (the gate's z-test needs it; "
                           "independent: the per-sample variance); none: one randomisation, all its "
                           "stratification (lower error at the same spp), and no variance reported: for timing and "
                           "efficiency runs, which the gate's statistical checks then skip", choices=VARIANCE_MODES)
#: ``pass_key`` stream of a low-discrepancy render's key (one key for all passes: a sequence spans them).
SEQUENCE_STREAM = 16

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


class Stream(NamedTuple):
    """What a kernel needs to draw the numbers of path j of a pass: pixel j mod ``pixels``, sample
    ``first_sample + j div pixels`` of that pixel."""

    kind: int  # INDEPENDENT, PMJ02 or SOBOL
    key: np.uint64  # the pass's key (independent) or the render's (low-discrepancy)
    pixels: int
    first_sample: int
    batches: int  # 1 for independent


def independent(key: np.uint64, pixels: int = 1, first_sample: int = 0) -> Stream:
    """The ``independent`` stream of pass ``key``: uniform(key, path, dim), whatever the pixel."""
    return Stream(INDEPENDENT, np.uint64(key), max(pixels, 1), first_sample, 1)


def pass_stream(sampler: str, seed: int, index: int, pixels: int, first_sample: int,
                batches: int = BATCHES) -> Stream:
    """The stream of pass ``index`` (its first sample per pixel ``first_sample``) of a render seeded ``seed``.

    ``independent`` keys each pass (:func:`cornell_harness.adapters.api.pass_key`); a
    low-discrepancy sampler keys the whole render, since its sequences span the passes,
    and splits each pixel's samples into ``batches`` randomisations (1: a render
    that reports no variance, as SPPM's camera passes, keeps one sequence per pixel).
    """
    kind = SAMPLERS[sampler]
    if kind == INDEPENDENT:
        return independent(pass_key(seed, index), pixels, first_sample)
    return Stream(kind, pass_key(seed, 0, SEQUENCE_STREAM), pixels, first_sample, batches)


def sequence_stream(sampler: str, key: np.uint64, pixels: int = 1, first_sample: int = 0) -> Stream:
    """One randomisation (no batches) of ``sampler`` keyed ``key``: path j is sample ``first_sample + j div
    pixels`` of sequence ``j mod pixels``.

    A photon pass is one sequence over its photons (``pixels`` 1), so the
    photons' emission and bounce decisions are stratified across the map;
    irradiance probes have one sequence per probe (``pixels`` = probes) over
    its rays, numbered by :func:`sequence_point`. ``independent``: uniform(key, path, dimension), as :func:`independent`.
    """
    kind = SAMPLERS[sampler]
    if kind == INDEPENDENT:
        return independent(key, pixels, first_sample)
    return Stream(kind, np.uint64(key), max(pixels, 1), first_sample, 1)


@jit_inline
def path_point(st, path):
    """Where ``path``'s numbers come from, computed once per path and passed to the sample functions.

    ``independent``: (pass key, path). Low-discrepancy: (pixel seed of the
    path's batch key and pixel, index in that batch's sequence); the
    divisions and the hashing they share stay out of every decision.
    """
    if st.kind == INDEPENDENT:
        return np.uint64(st.key), np.int64(path)
    s = st.first_sample + path // st.pixels
    batch_key = mix64(st.key ^ (np.uint64(s % st.batches) * _GOLDEN))
    return pixel_seed(batch_key, path % st.pixels), np.int64(s // st.batches)


@jit_inline
def sample_1d(st, point, dim) -> float:
    """Number ``dim`` of the path at ``point`` (:func:`path_point`; pbrt's Get1D)."""
    seed, index = point
    if st.kind == INDEPENDENT:
        return uniform(seed, index, dim)
    if st.kind == SOBOL:
        return sobol_1d(seed, index, dim, SOBOL_MATRICES)
    return padded_1d(seed, index, dim)


@jit_inline
def sample_2d(st, point, dim):
    """Numbers ``dim`` and ``dim + 1`` of the path at ``point``, stratified jointly (pbrt's Get2D)."""
    seed, index = point
    if st.kind == INDEPENDENT:
        return uniform(seed, index, dim), uniform(seed, index, dim + 1)
    if st.kind == SOBOL:
        return sobol_1d(seed, index, dim, SOBOL_MATRICES), sobol_1d(seed, index, dim + 1, SOBOL_MATRICES)
    return padded_2d(seed, index, dim)


@jit
def vertex_dim(depth, offset):
    """Dimension of ``offset`` at path vertex ``depth`` (1: the camera ray's hit)."""
    return CAMERA_DIMS + (depth - 1) * DIMS_PER_VERTEX + offset


@jit
def camera_sample(st, point):
    """The pixel jitter (u, v) in [0, 1)² of the path at ``point``."""
    return sample_2d(st, point, CAMERA_U)


@jit_inline
def vertex_1d(st, point, depth, offset) -> float:
    """One number of vertex ``depth`` of the path at ``point`` (pbrt's Get1D)."""
    return sample_1d(st, point, vertex_dim(depth, offset))


@jit_inline
def vertex_2d(st, point, depth, offset):
    """Two numbers of vertex ``depth`` of the path at ``point``, from ``offset`` on, stratified jointly."""
    return sample_2d(st, point, vertex_dim(depth, offset))


@jit
def sequence_point(st, path, length):
    """:func:`path_point` of ``path`` numbered sequence by sequence: point ``path mod length`` of sequence
    ``path div length`` (``independent``: (key, path), so the numbers are those of :func:`path_point`)."""
    if st.kind == INDEPENDENT:
        return np.uint64(st.key), np.int64(path)
    return path_point(st, (path % length) * st.pixels + path // length)

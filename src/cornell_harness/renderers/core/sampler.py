"""Samplers, and the dimension map: which numbers of a path each decision of every integrator draws.

In the spirit of pbrt-v4's ``Sampler::Get1D``/``Get2D`` (§8.3), a path's
decisions consume numbers in a fixed order, but every dimension has a name
instead of hand arithmetic in the kernels. This module owns the map: every
integrator draws from the named blocks declared here (:class:`Block`,
:data:`BLOCKS`), through the dimension functions below, and :data:`LAYOUTS`
says which blocks each kind of path uses; the blocks of one layout never
overlap (``tests/renderers/core/test_dimensions.py``), and no integrator
writes a dimension of its own (``tests/test_code_shape.py``). A camera path:

- :data:`CAMERA`: dimensions 0 and 1 (:data:`CAMERA_U`, :data:`CAMERA_V`)
  jitter the camera ray inside its pixel;
- :data:`VERTICES`: then each path vertex (depth 1, 2, ...: the surface the
  depth-th segment reaches) owns six dimensions, at the offsets named below
  (:func:`vertex_dim`), whether or not the integrator uses them all;
- from 2^20 on, the blocks of the extra rays an integrator casts from a
  vertex (occlusion, gather, light-sample rays), each the integrator's own;
- :data:`HERO`, the hero wavelength of a spectral path
  (:mod:`cornell_harness.renderers.hero_wavelength`), is the last dimension
  :func:`cornell_harness.renderers.core.rng.uniform` takes, so that the RGB
  renders' numbers are those they had before it existed.

Photon paths (:mod:`cornell_harness.renderers.core.photons`) and probe rays
(:mod:`cornell_harness.renderers.ddgi`) are paths of their own streams, with
their own layouts here, drawn from :func:`sequence_stream`.

A dimension is a pure function of (block, item, offset), so a decision that
is skipped (no emitter, a path ended) never shifts the numbers of the ones
after it. Changing any number here changes every image: the pinned tests
(``tests/renderers/test_*pinned.py``, ``tests/renderers/test_hero_wavelength.py``)
pin them.

Which numbers a dimension gets is the sampler's (:data:`SAMPLERS`), carried
to kernels as a :class:`Stream`; every sample stays a pure function of
(seed, pixel, sample index, dimension), so images do not depend on threads:

- ``independent``: counter-based uniform numbers (:func:`cornell_harness.renderers.core.rng.uniform`)
  of (pass key, path index, dimension), as every renderer had before samplers.
- ``pmj02``: every 1D/2D decision its own progressive (0, 2)-sequence,
  shuffled and Owen-scrambled (:func:`cornell_harness.renderers.core.sobol.padded_2d`;
  Burley 2020's padding): each power-of-two prefix of a pixel's samples is
  stratified in every elementary interval, as pmj02 is.
- ``pmj02table``: pmj02's padding and stratification with the coordinates'
  Owen scrambling moved into a table made once
  (:mod:`cornell_harness.renderers.core.owen_table`): per decision a one-round
  hash, the index shuffle, a lookup and a digital shift, four multiplications;
  its pixel seed is one SplitMix64 hash.
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
from numba.cpython.unsafe.numbers import trailing_zeros  # LLVM's cttz

from cornell_harness.adapters.api import Setting, pass_key
from cornell_harness.renderers.core.rng import mix64, uniform
from cornell_harness.renderers.core.sampling import jit, jit_inline
from cornell_harness.renderers.core.owen_table import table_1d, table_2d
from cornell_harness.renderers.core.sobol import SOBOL_MATRICES, padded_1d, padded_2d, pixel_seed, sobol_1d


class Block(NamedTuple):
    """Dimensions ``base`` .. ``stop`` - 1 of a path: ``count`` items (a vertex, a ray, a light sample) of
    ``stride`` numbers each, item i's at ``base + stride·i`` on."""

    name: str
    base: int
    stride: int
    count: int = 1

    @property
    def stop(self) -> int:
        return self.base + self.stride * self.count


#: Most rays of one kind an extra block holds per item: the bound of the settings that count them
#: (ambient's ao_samples, photonmap's gather_rays, whitted's light_samples and ao_samples).
MAX_RAYS = 1024
#: Vertices of a whitted ray tree its blocks hold: the bound of its max_depth.
MAX_TREE_DEPTH = 64
#: Where the blocks of a camera path's extra rays start: past its first 174,762 vertices, more than any
#: path reaches (Russian roulette ends them). Every block ends below rng's 2^24 dimensions.
_EXTRA = 1 << 20

# -- camera paths (one stream per pass, path j sees pixel j mod pixels) --
CAMERA = Block("camera", 0, 2)
VERTICES = Block("vertices", CAMERA.stop, 6, (_EXTRA - CAMERA.stop) // 6)
#: ao: the occlusion ray's direction, where a path's first vertex would be (AO casts no path).
AO_DIRECTION = Block("ao direction", CAMERA.stop, 2)
#: ambient: occlusion ray s of a visible point (2D).
OCCLUSION = Block("occlusion rays", _EXTRA, 2, MAX_RAYS)
#: photonmap: gather ray g's direction (2D), then its walk, laid out as :data:`VERTICES` from its own base
#: (:func:`gather_walk_base`; 682 vertices each, more than any walk to a diffuse surface reaches).
GATHER = Block("gather rays", _EXTRA, 2, MAX_RAYS)
GATHER_WALKS = Block("gather walks", 1 << 21, 1 << 12, MAX_RAYS)
#: whitted: light sample s at tree vertex d is item MAX_RAYS·(d − 1) + s (emitter pick, then its point, 2D),
#: occlusion ray s there the same item of :data:`TREE_OCCLUSION` (2D).
TREE_LIGHTS = Block("tree light samples", _EXTRA, 3, MAX_RAYS * MAX_TREE_DEPTH)
TREE_OCCLUSION = Block("tree occlusion rays", 1 << 23, 2, MAX_RAYS * MAX_TREE_DEPTH)
#: pathtracer, spectral = hero: the path's hero wavelength (:mod:`cornell_harness.renderers.core.wavelengths`).
HERO = Block("hero wavelength", (1 << 24) - 1, 1)
# -- photon paths (one sequence per photon pass) --
#: The emitter (by power), the point on it (2D), the emitted direction (2D); then per bounce k = 1, 2, ...
#: (the surface the k-th segment reaches) its BSDF direction (2D) and roulette.
PHOTON_EMISSION = Block("photon emission", 0, 5)
PHOTON_BOUNCES = Block("photon bounces", PHOTON_EMISSION.stop, 3, ((1 << 24) - PHOTON_EMISSION.stop) // 3)
# -- probe rays (one sequence per probe over its rays) and probe updates --
#: A probe ray's direct light: the light sample's emitter and point (1D, then 2D), the BSDF sample (2D).
PROBE_RAY = Block("probe ray", 0, 5)
#: An update's random rotation of the probe rays: three numbers, 1D then 2D.
PROBE_ROTATION = Block("probe rotation", 0, 3)

#: Every block, and the blocks each kind of path draws (blocks of one layout never overlap).
BLOCKS = (CAMERA, VERTICES, AO_DIRECTION, OCCLUSION, GATHER, GATHER_WALKS, TREE_LIGHTS, TREE_OCCLUSION, HERO,
          PHOTON_EMISSION, PHOTON_BOUNCES, PROBE_RAY, PROBE_ROTATION)
LAYOUTS = {
    "pathtracer, sppm and probes camera paths": (CAMERA, VERTICES),
    "pathtracer spectral = hero": (CAMERA, VERTICES, HERO),
    "ao": (CAMERA, AO_DIRECTION),
    "ambient": (CAMERA, VERTICES, OCCLUSION),
    "photonmap camera paths": (CAMERA, VERTICES, GATHER, GATHER_WALKS),
    "whitted": (CAMERA, TREE_LIGHTS, TREE_OCCLUSION),
    "photons": (PHOTON_EMISSION, PHOTON_BOUNCES),
    "probe rays": (PROBE_RAY,),
    "probe rotation": (PROBE_ROTATION,),
}

#: The dimensions of the single-item blocks, by name.
CAMERA_U, CAMERA_V = range(CAMERA.base, CAMERA.stop)
AO_U, AO_V = range(AO_DIRECTION.base, AO_DIRECTION.stop)
WAVELENGTH = HERO.base
EMIT_PICK, EMIT_U, EMIT_V, EMIT_DIR_U, EMIT_DIR_V = range(PHOTON_EMISSION.base, PHOTON_EMISSION.stop)
PROBE_EMITTER_PICK, PROBE_EMITTER_U, PROBE_EMITTER_V, PROBE_BSDF_U, PROBE_BSDF_V = range(PROBE_RAY.base,
                                                                                         PROBE_RAY.stop)
ROTATION_U1, ROTATION_U2 = PROBE_ROTATION.base, PROBE_ROTATION.base + 1
#: Offsets inside a vertex's block (:data:`VERTICES`): the emitter triangle (by power), the point on it (2),
#: the BSDF direction (2), Russian roulette. The first three are a light sample's offsets in :data:`TREE_LIGHTS`.
EMITTER_PICK, EMITTER_U, EMITTER_V, BSDF_U, BSDF_V, ROULETTE = range(VERTICES.stride)
#: Offsets inside a photon bounce's block (:data:`PHOTON_BOUNCES`).
BOUNCE_U, BOUNCE_V, BOUNCE_ROULETTE = range(PHOTON_BOUNCES.stride)

INDEPENDENT, PMJ02, SOBOL, PMJ02_TABLE = 0, 1, 2, 3
#: Sampler names (the ``sampler`` setting) and their ids in a :class:`Stream`.
SAMPLERS = {"independent": INDEPENDENT, "pmj02": PMJ02, "sobol": SOBOL, "pmj02table": PMJ02_TABLE}
#: Independent randomisations of a low-discrepancy render: 7 degrees of freedom per pixel's variance.
#: More give a steadier variance, fewer keep more stratification (docs/sampling.md measures both).
BATCHES = 8


def sampler_setting(draws: str, default: str = "independent", batches: bool = True) -> Setting:
    """The ``sampler`` setting of a renderer of ours that draws ``draws`` (words: what, and its sequences) from
    a :class:`Stream`. ``batches``: its low-discrepancy renders report the variance of :data:`BATCHES`
    batches. The renderers whose gate expectations were measured with ``independent`` keep it as default."""
    doc = (f"random numbers of {draws}: independent, pmj02 (progressive (0,2)-sequences per decision), "
           "pmj02table (the same stratification from a table, cheaper) or sobol (Owen-scrambled, all dimensions)")
    if batches:
        doc += f"; the last three report the variance of {BATCHES} independent batches"
    return Setting("sampler", str, default, doc, choices=tuple(SAMPLERS))


#: The path tracer's ``sampler`` setting.
SAMPLER_SETTING = sampler_setting("the camera paths (one sequence per pixel)", "pmj02")
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
_ONE = np.uint64(1)
_M32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)


class Stream(NamedTuple):
    """What a kernel needs to draw the numbers of path j of a pass: pixel j mod ``pixels``, sample
    ``first_sample + j div pixels`` of that pixel."""

    kind: int  # INDEPENDENT, PMJ02, SOBOL or PMJ02_TABLE
    key: np.uint64  # the pass's key (independent) or the render's (low-discrepancy)
    pixels: int
    first_sample: int
    batches: int  # 1 for independent
    divider: np.uint64 = np.uint64(0)  # pixel_divider(pixels), or 0: path_point divides


def pixel_divider(pixels: int) -> np.uint64:
    """⌈2^64 / pixels⌉, with which :func:`path_point` divides a path index below 2^32 by ``pixels`` in two
    multiplications instead of a division (exact: Lemire, Kaser & Kurz 2019, "Faster remainder by direct
    computation", Software: Practice and Experience 49(6), theorem 1, with N = 32 and F = 64); 0 for 1 pixel
    or 2^32 and more, where it divides."""
    return np.uint64(-(-(1 << 64) // pixels)) if 1 < pixels < 1 << 32 else np.uint64(0)


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
    return Stream(kind, pass_key(seed, 0, SEQUENCE_STREAM), pixels, first_sample, batches, pixel_divider(pixels))


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
    return Stream(kind, np.uint64(key), max(pixels, 1), first_sample, 1, pixel_divider(max(pixels, 1)))


@jit_inline
def path_point(st, path):
    """Where ``path``'s numbers come from, computed once per path and passed to the sample functions.

    ``independent``: (pass key, path). Low-discrepancy: (pixel seed of the
    path's batch key and pixel, index in that batch's sequence); the
    divisions and the hashing they share stay out of every decision.
    """
    if st.kind == INDEPENDENT:
        return np.uint64(st.key), np.int64(path)
    # Unsigned (numba's signed // and % take a division each, with Python's floor fix-ups); paths and
    # samples are never negative. The quotient by pixels is two multiplications where pixel_divider
    # allows, and the batch count a power of two (BATCHES or 1) in every stream we make, a shift:
    # divisions, the second waiting on the first, were most of the state's time (BENCHMARKS.md, samplers.py).
    p, pixels, batches = np.uint64(path), np.uint64(st.pixels), np.uint64(st.batches)
    if p >> _S32 == 0 and st.divider != 0:  # p div pixels: the high word of divider × p (pixel_divider)
        m = np.uint64(st.divider)
        q = ((m >> _S32) * p + (((m & _M32) * p) >> _S32)) >> _S32
    else:
        q = p // pixels
    s = np.uint64(st.first_sample) + q
    if batches & (batches - _ONE) == 0:
        index = s >> np.uint64(trailing_zeros(batches))
    else:
        index = s // batches
    batch, pixel = s - index * batches, p - q * pixels
    if st.kind == PMJ02_TABLE:  # one hash: its decisions hash (seed, dimension) again
        return mix64(st.key ^ ((pixel * batches + batch) * _GOLDEN)), np.int64(index)
    return pixel_seed(mix64(st.key ^ (batch * _GOLDEN)), pixel), np.int64(index)


@jit_inline
def sample_1d(st, point, dim) -> float:
    """Number ``dim`` of the path at ``point`` (:func:`path_point`; pbrt's Get1D)."""
    seed, index = point
    if st.kind == INDEPENDENT:
        return uniform(seed, index, dim)
    if st.kind == SOBOL:
        return sobol_1d(seed, index, dim, SOBOL_MATRICES)
    if st.kind == PMJ02_TABLE:
        return table_1d(seed, index, dim)
    return padded_1d(seed, index, dim)


@jit_inline
def sample_2d(st, point, dim):
    """Numbers ``dim`` and ``dim + 1`` of the path at ``point``, stratified jointly (pbrt's Get2D)."""
    seed, index = point
    if st.kind == INDEPENDENT:
        return uniform(seed, index, dim), uniform(seed, index, dim + 1)
    if st.kind == SOBOL:
        return sobol_1d(seed, index, dim, SOBOL_MATRICES), sobol_1d(seed, index, dim + 1, SOBOL_MATRICES)
    if st.kind == PMJ02_TABLE:
        return table_2d(seed, index, dim)
    return padded_2d(seed, index, dim)


@jit
def vertex_dim(depth, offset):
    """Dimension of ``offset`` at path vertex ``depth`` (1: the camera ray's hit)."""
    return VERTICES.base + (depth - 1) * VERTICES.stride + offset


@jit
def shifted_vertex_dim(base, depth, offset):
    """:func:`vertex_dim` in a walk whose vertices start at ``base`` (0: the camera path's own;
    :func:`gather_walk_base`)."""
    return base + vertex_dim(depth, offset)


def gather_walk_base(g: int) -> int:
    """The base of gather ray ``g``'s walk (:data:`GATHER_WALKS`), for :func:`shifted_vertex_dim`."""
    return GATHER_WALKS.base + g * GATHER_WALKS.stride


@jit
def gather_dim(g):
    """Gather ray ``g``'s direction (2D, :data:`GATHER`)."""
    return GATHER.base + g * GATHER.stride


@jit
def occlusion_dim(s):
    """Occlusion ray ``s`` of a visible point (2D, :data:`OCCLUSION`)."""
    return OCCLUSION.base + s * OCCLUSION.stride


@jit
def tree_light_dim(depth, s, offset):
    """Light sample ``s`` at ray-tree vertex ``depth``: its emitter pick (offset :data:`EMITTER_PICK`) and
    point (:data:`EMITTER_U`, 2D) in :data:`TREE_LIGHTS`."""
    return TREE_LIGHTS.base + (MAX_RAYS * (depth - 1) + s) * TREE_LIGHTS.stride + offset


@jit
def tree_occlusion_dim(depth, s):
    """Occlusion ray ``s`` at ray-tree vertex ``depth`` (2D, :data:`TREE_OCCLUSION`)."""
    return TREE_OCCLUSION.base + (MAX_RAYS * (depth - 1) + s) * TREE_OCCLUSION.stride


@jit
def bounce_dim(depth, offset):
    """Dimension of ``offset`` at a photon's ``depth``-th surface (:data:`PHOTON_BOUNCES`)."""
    return PHOTON_BOUNCES.base + (depth - 1) * PHOTON_BOUNCES.stride + offset


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

"""Tabulated Owen-scrambled (0, 2)-sequences: pmj02's stratification for a lookup and a hash per decision.

Each decision of the ``pmj02`` sampler (:func:`cornell_harness.renderers.core.sobol.padded_2d`)
Owen-scrambles three 32-bit integers by hashing (Burley 2020, "Practical Hash-based
Owen Scrambling", JCGT 9(4), listing 2): the sample index, then Sobol' dimensions 0
and 1 at the shuffled index; twelve multiplications a 2D decision. Here the two
coordinate scramblings move out of the decision into a table made once:

- :data:`TABLE` holds :data:`SETS` Owen-scrambled copies of the (0, 2)-sequence of
  Sobol' dimensions 0 and 1 (Burley's ``nested_uniform_scramble`` of each, seeded
  per set), :data:`POINTS` points each: every aligned block of 2^m points of a set
  is a (0, m, 2)-net, as pmj02's are (Christensen, Kensler & Kilpatrick 2018,
  "Progressive Multi-Jittered Sample Sequences").
- A decision at dimension d of a pixel hashes (pixel seed, d) once
  (:func:`cornell_harness.renderers.core.sobol.hash_seed`'s SplitMix64 words), picks a set,
  shuffles the sample index i by Owen-scrambling its bits
  (``nested_uniform_scramble``, the padding of Burley's section 4, as ``pmj02``: it
  maps every aligned block of indices onto an aligned block, so every power-of-two
  prefix stays a net) and reads the point there, then applies a random digital
  shift (x ⊕ a, y ⊕ b; Owen 1995 §3: xor with a constant permutes the elementary
  intervals, so nets stay nets, and makes each coordinate exactly uniform).

The shuffle decorrelates the decisions of a path (each has its own), the digital
shift randomises each point; only the nested scrambling of the coordinates
themselves is shared by the decisions drawing one set, which is what the error
at 256 spp measures against ``pmj02`` (BENCHMARKS.md). Indices past the table
(a pixel's samples per batch ≥ :data:`POINTS`) are computed, not looked up: the
same numbers, so the sequence has no end.
"""

from __future__ import annotations

import numpy as np

from cornell_harness.renderers.core.rng import mix64
from cornell_harness.renderers.core.sampling import jit, jit_inline
from cornell_harness.renderers.core.sobol import (SOBOL_MATRICES, nested_uniform_scramble, reverse_bits32,
                                                  sobol_sample, to_unit)

#: Scrambled copies of the sequence, and points of each in the table: 8 × 1024 × 8 bytes = 64 KB, in L2.
SETS, POINTS = 8, 1024
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M32 = np.uint64(0xFFFFFFFF)
_S32 = np.uint64(32)
_SET_MASK = np.uint64(SETS - 1)
_LOW = np.int64(POINTS - 1)
_SET_SEED = 0x5EED0F5E75
_LK = tuple(np.uint64(c) for c in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6))  # Burley's listing 2


def _set_seeds(s: int) -> tuple[int, int]:
    # Two 32-bit words of one SplitMix64 hash of the set: the scramblings of its x and y.
    m = (1 << 64) - 1
    z = (_SET_SEED + s * int(_GOLDEN)) & m
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & m  # rng.mix64, in Python integers
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & m
    z ^= z >> 31
    return z >> 32, z & 0xFFFFFFFF


def _reverse(x: np.ndarray) -> np.ndarray:
    # reverse_bits32 of a uint64 array of 32-bit values.
    bits = (x[:, None] >> np.arange(32, dtype=np.uint64)) & np.uint64(1)
    return (bits << np.arange(31, -1, -1, dtype=np.uint64)).sum(axis=1, dtype=np.uint64)


def _scramble(x: np.ndarray, seed: int) -> np.ndarray:
    # nested_uniform_scramble of a uint64 array of 32-bit values (uint64 arithmetic masked to 32 bits).
    v = (_reverse(x) + np.uint64(seed)) & _M32
    for c in _LK:
        v ^= (v * c) & _M32
    return _reverse(v)


def _make_table() -> np.ndarray:
    j = np.arange(POINTS, dtype=np.uint64)
    index_bits = (j[:, None] >> np.arange(32, dtype=np.uint64)) & np.uint64(1)
    dim1 = np.bitwise_xor.reduce(np.where(index_bits == 1, SOBOL_MATRICES[1].astype(np.uint64), np.uint64(0)), axis=1)
    table = np.empty((SETS, POINTS), np.uint64)
    for s in range(SETS):
        sx, sy = _set_seeds(s)
        table[s] = (_scramble(_reverse(j), sx) << _S32) | _scramble(dim1, sy)
    return table


#: Points 0 .. POINTS - 1 of every set, packed x·2^32 + y (uint64; :func:`set_point`). Made with numpy at
#: import (no compilation); numba freezes it into the kernels as a constant.
TABLE = _make_table()
_SX, _SY = (np.array(w, np.uint32) for w in zip(*map(_set_seeds, range(SETS))))


@jit
def set_point(s, j):
    """Point ``j`` of set ``s`` (any index; :data:`TABLE` holds the first): Sobol' dimensions 0 and 1 at j,
    each Owen-scrambled by the set's seeds, packed as x·2^32 + y. Dimension 0 is the reversed index."""
    x = nested_uniform_scramble(reverse_bits32(j), _SX[s])
    y = nested_uniform_scramble(sobol_sample(j, 1, SOBOL_MATRICES), _SY[s])
    return (np.uint64(x) << _S32) | np.uint64(y)


@jit_inline
def _point(seed, index, dim):
    # The packed point of decision ``dim`` at ``index`` and its digital shift (x and y words).
    z = np.uint64(seed) ^ (np.uint64(dim) * _GOLDEN)
    h, shift = mix64(z), mix64(z + _GOLDEN)  # two SplitMix64 outputs of one counter, hashed side by side
    shuffled = np.int64(nested_uniform_scramble(index, np.uint32(h & _M32)))
    s = (h >> _S32) & _SET_MASK
    if index <= _LOW:
        return TABLE[s, shuffled & _LOW], shift
    # Past the table: the scrambled low bits, the index's own high ones (aligned blocks still map to blocks).
    return set_point(s, (np.int64(index) & ~_LOW) | (shuffled & _LOW)), shift


@jit_inline
def table_1d(seed, index, dim) -> float:
    """A 1D decision at ``dim`` of the pixel of ``seed`` (:func:`cornell_harness.renderers.core.sobol.pixel_seed`),
    sample ``index``: the x of its 2D point (a scrambled van der Corput sequence), shifted."""
    v, shift = _point(seed, index, dim)
    return to_unit(np.uint32((v ^ shift) >> _S32))


@jit_inline
def table_2d(seed, index, dim):
    """A 2D decision at ``dim`` (and ``dim + 1``): the shuffled, digitally shifted point of its set."""
    v, shift = _point(seed, index, dim)
    v ^= shift
    return to_unit(np.uint32(v >> _S32)), to_unit(np.uint32(v & _M32))

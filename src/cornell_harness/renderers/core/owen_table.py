"""Tabulated Owen-scrambled (0, 2)-sequences: pmj02's stratification for a short hash and a lookup per decision.

Each decision of the ``pmj02`` sampler (:func:`cornell_harness.renderers.core.sobol.padded_2d`)
Owen-scrambles three 32-bit integers by hashing (Burley 2020, "Practical Hash-based
Owen Scrambling", JCGT 9(4), listing 2): the sample index, then Sobol' dimensions 0
and 1 at the shuffled index; twelve multiplications a 2D decision, after two
SplitMix64 hashes. Here the coordinates' scrambling moves into a table made once,
and a decision costs four multiplications and a lookup:

- :data:`TABLE` holds :data:`SETS` Owen-scrambled copies of the (0, 2)-sequence of
  Sobol' dimensions 0 and 1 (Burley's ``nested_uniform_scramble`` of each, seeded
  per set), :data:`POINTS` points each: every aligned block of 2^m points of a set
  is a (0, m, 2)-net, as pmj02's are (Christensen, Kensler & Kilpatrick 2018,
  "Progressive Multi-Jittered Sample Sequences"). A set's row is in radical-inverse
  order (entry r holds point ``reverse(r)``), so the shuffle below indexes it
  without reversing its result.
- A decision at dimension d hashes (pixel seed, d) into 64 bits h with one
  multiply-xorshift round (:func:`decision_hash`; the pixel seed is a full SplitMix64
  hash of the pixel and batch). h picks a set, seeds the index shuffle and, through one
  multiplication, gives the digital shift.
- The shuffle (:func:`shuffle_reversed`) is a seeded permutation of the reversed
  sample index of the Laine-Karras kind (Laine & Karras 2011; Burley's section 4):
  each of its steps (add a word of h, multiply by an odd number made of the other,
  xor with an even multiple of itself) changes bit k by a function of the bits below
  it, so, reversed, it maps every aligned block of indices onto an aligned block and
  every power-of-two prefix of a decision stays a net, as pmj02's padding does.
  Burley's permutation adds the seed and takes four fixed multiplications; here the
  seeded multiplier and one fixed step, two multiplications, decorrelate decisions as
  well as those four in our measurements, where two fixed steps do measurably worse
  (BENCHMARKS.md).
- The digital shift (x ⊕ a, y ⊕ b; Owen 1995 §3: xor with a constant permutes the
  elementary intervals, so nets stay nets) randomises each point's position, so a
  coordinate is uniform as far as the hash's bits are independent
  (``tests/renderers/core/test_owen_table.py`` tests it).

The shuffle decorrelates the decisions of a path (each has its own), the digital
shift randomises each point; only the nested scrambling of the coordinates
themselves is shared by the decisions drawing one set, which is what the error
at 256 spp measures against ``pmj02`` (BENCHMARKS.md). Indices past the table
(a pixel's samples per batch ≥ :data:`POINTS`) are computed, not looked up: the
same numbers, so the sequence has no end.
"""

from __future__ import annotations

import numpy as np

from cornell_harness.renderers.core.sampling import jit, jit_inline
from cornell_harness.renderers.core.sobol import (SOBOL_MATRICES, nested_uniform_scramble, reverse_bits32,
                                                  sobol_sample, to_unit)

#: Scrambled copies of the sequence, and points of each in the table: 8 × 1024 × 8 bytes = 64 KB.
SETS, POINTS = 8, 1024
_INDEX_BITS = POINTS.bit_length() - 1
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M32 = np.uint64(0xFFFFFFFF)
_ONE = np.uint64(1)
_S29, _S32 = np.uint64(29), np.uint64(32)
_TOP = np.uint64(64 - _INDEX_BITS)  # the shuffled reversed index's top bits are the table's entry
_SET_SHIFT = np.uint64(64 - (SETS - 1).bit_length())  # h's top log2(SETS) bits pick the set
_LOW = np.int64(POINTS - 1)
_HASH_MUL, _SHIFT_MUL = np.uint64(0xD1342543DE82EF95), np.uint64(0xAF251AF3B0F025B5)  # odd, bits all over
_SET_SEED = 0x5EED0F5E75
_LK = tuple(np.uint64(c) for c in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6))  # Burley's listing 2
_MIX_MUL = _LK[1]  # even: Burley's second constant


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


def _radical_order() -> np.ndarray:
    # reverse(r) over _INDEX_BITS bits, for r = 0 .. POINTS - 1 (an involution).
    r = np.arange(POINTS)
    return ((r[:, None] >> np.arange(_INDEX_BITS)) & 1) @ (1 << np.arange(_INDEX_BITS - 1, -1, -1))


def _make_table() -> np.ndarray:
    j = np.arange(POINTS, dtype=np.uint64)
    index_bits = (j[:, None] >> np.arange(32, dtype=np.uint64)) & np.uint64(1)
    dim1 = np.bitwise_xor.reduce(np.where(index_bits == 1, SOBOL_MATRICES[1].astype(np.uint64), np.uint64(0)), axis=1)
    table = np.empty((SETS, POINTS), np.uint64)
    for s in range(SETS):
        sx, sy = _set_seeds(s)
        table[s] = (_scramble(_reverse(j), sx) << _S32) | _scramble(dim1, sy)
    return np.ascontiguousarray(table[:, _radical_order()])


#: Points 0 .. POINTS - 1 of every set, packed x·2^32 + y (uint64; :func:`set_point`), entry r of a set holding
#: point reverse(r) (over log2 POINTS bits). Made with numpy at import (no compilation); numba freezes it into
#: the kernels as a constant.
TABLE = _make_table()
_SX, _SY = (np.array(w, np.uint32) for w in zip(*map(_set_seeds, range(SETS))))


@jit
def set_point(s, j):
    """Point ``j`` of set ``s`` (any index; :data:`TABLE` holds the first): Sobol' dimensions 0 and 1 at j,
    each Owen-scrambled by the set's seeds, packed as x·2^32 + y. Dimension 0 is the reversed index."""
    x = nested_uniform_scramble(reverse_bits32(j), _SX[s])
    y = nested_uniform_scramble(sobol_sample(j, 1, SOBOL_MATRICES), _SY[s])
    return (np.uint64(x) << _S32) | np.uint64(y)


@jit
def shuffle_reversed(reversed_index, h):
    """The seeded shuffle, by the 64-bit hash ``h``, of a reversed 32-bit sample index held in the high half of
    a 64-bit word; the result likewise (its top bits read the table: no masks, products wrap at 2^64).

    Each step changes bit k by a function of the bits below it (adding, multiplying by
    an odd number, xoring with an even multiple), so for every k the low k bits of the
    high half are a bijection of the input's: reversed, the high bits of the shuffled
    index depend on the index's high bits alone, so aligned blocks of indices map onto
    aligned blocks, while its low bits depend on all of them.
    """
    x = (np.uint64(reversed_index) + (h << _S32)) * ((h >> _S32) | _ONE)
    return x ^ (x * _MIX_MUL)


@jit
def decision_hash(seed, dim):
    """64 bits for decision ``dim`` of the pixel (and batch) of ``seed``: one multiply-xorshift round.

    The pixel seed is already a full SplitMix64 hash (:func:`cornell_harness.renderers.core.sampler.path_point`),
    so the dimension gets one round of its kind, not SplitMix64's two (the time saved: BENCHMARKS.md), with
    decisions and pairs of them as uniform (``tests/renderers/core/test_owen_table.py``).
    """
    z = np.uint64(seed) ^ (np.uint64(dim) * _GOLDEN)
    z = (z ^ (z >> _S32)) * _HASH_MUL
    return z ^ (z >> _S29)


@jit_inline
def _point(seed, index, dim):
    # The packed point of decision ``dim`` at ``index`` and its digital shift (x and y words).
    h = decision_hash(seed, dim)
    shift = (h ^ (h >> _S32)) * _SHIFT_MUL
    v = shuffle_reversed(np.uint64(reverse_bits32(index)) << _S32, h)
    s = h >> _SET_SHIFT
    if index <= _LOW:
        return TABLE[s, v >> _TOP], shift
    # Past the table: the shuffled low bits, the index's own high ones (aligned blocks still map to blocks).
    return set_point(s, (np.int64(index) & ~_LOW) | (np.int64(reverse_bits32(v >> _S32)) & _LOW)), shift


@jit_inline
def table_1d(seed, index, dim) -> float:
    """A 1D decision at ``dim`` of the pixel and batch of ``seed``
    (:func:`cornell_harness.renderers.core.sampler.path_point`), sample ``index``: the x of its 2D point (a
    scrambled van der Corput sequence), shifted."""
    v, shift = _point(seed, index, dim)
    return to_unit(np.uint32((v ^ shift) >> _S32))


@jit_inline
def table_2d(seed, index, dim):
    """A 2D decision at ``dim`` (and ``dim + 1``): the shuffled, digitally shifted point of its set."""
    v, shift = _point(seed, index, dim)
    v ^= shift
    return to_unit(np.uint32(v >> _S32)), to_unit(np.uint32(v & _M32))

"""Owen-scrambled Sobol' points for our renderers' numba kernels.

This module owns the Sobol' generator matrices and the hash-based Owen
scrambling of Burley 2020, "Practical Hash-based Owen Scrambling" (JCGT 9(4)),
the model of pbrt-v4's Sobol' samplers (§8.7; ``FastOwenScrambler`` in
``src/pbrt/util/lowdiscrepancy.h``). As in :mod:`cornell_harness.renderers.core.rng`, a number
is a pure function of (key, pixel, index, dimension), so a path's numbers do
not depend on batching, order or threads; which dimension feeds which
decision is :mod:`cornell_harness.renderers.core.sampler`'s.

- :data:`SOBOL_MATRICES` come from Joe & Kuo's direction numbers ("Constructing
  Sobol sequences with better two-dimensional projections", SIAM J. Sci.
  Comput. 30(5), 2008) as SciPy ships them, by the recurrence of SciPy's
  ``_initialize_v``. :func:`sobol_sample` takes the index in natural order;
  ``scipy.stats.qmc.Sobol`` draws in Gray-code order (Antonov & Saleev 1979):
  its i-th point is our point ``i ^ (i >> 1)``, the same set for every
  power-of-two prefix.
- :func:`nested_uniform_scramble` is Burley's Owen scrambling (Owen 1995,
  "Randomly permuted (t,m,s)-nets and (t,s)-sequences") of a 32-bit integer:
  bit reversal around the Laine-Karras permutation (Laine & Karras 2011,
  "Stratified sampling for stochastic transparency"), Burley's constants.
- :func:`sobol_1d` is the global sampler, each pixel its own scrambling of one
  sequence; :func:`padded_1d`/:func:`padded_2d` are Burley's shuffled,
  scrambled padding: every decision draws Sobol' dimensions 0 (and 1) at an
  index shuffled by its own seed, so every power-of-two prefix, and every
  later aligned block, of a 2D decision is a (0, m, 2)-net in base 2, the
  stratification of pmj02 (Christensen, Kensler & Kilpatrick 2018,
  "Progressive Multi-Jittered Sample Sequences", EGSR).

Arithmetic is uint64 masked to 32 bits with explicit ``np.uint64`` constants:
numba widens uint32 operands to uint64, and turns uint64 mixed with int64 into
float64.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
from numba.cpython.unsafe.numbers import trailing_zeros  # LLVM's cttz, as numba's own math.gcd uses

from cornell_harness.renderers.core.rng import mix64, uniform
from cornell_harness.renderers.core.sampling import jit

#: Dimensions of :data:`SOBOL_MATRICES` (a path uses 2 + 6 per vertex); beyond them the caller decides.
SOBOL_DIMS = 64


def _sobol_matrices(dims: int) -> np.ndarray:
    """Generator matrices (dims, 32) uint32: column b of dimension d is V[d, b], most significant bit first."""
    scipy_dir = importlib.util.find_spec("scipy").submodule_search_locations[0]  # without importing scipy.stats (slow)
    with np.load(Path(scipy_dir) / "stats" / "_sobol_direction_numbers.npz") as table:
        poly, vinit = table["poly"][:dims].astype(np.uint64), table["vinit"][:dims].astype(np.uint64)
    degree = np.array([int(p).bit_length() - 1 for p in poly])
    m = np.zeros((dims, 32), dtype=np.uint64)
    for j in range(32):  # vectorised over dimensions: ~20 ms at import, most of it reading the table
        # Joe & Kuo: m_j = m_{j-s} ^ 2^s m_{j-s} ^ XOR_{k<s-1} a_{k+1} 2^{k+1} m_{j-k-1}; poly holds 1 a_1 .. a_{s-1} 1.
        new = m[np.arange(dims), np.maximum(j - degree, 0)]
        for k in range(degree.max()):
            take = (k < degree) & ((poly >> np.maximum(degree - 1 - k, 0).astype(np.uint64)) & np.uint64(1) == 1)
            new ^= np.where(take, m[:, max(j - k - 1, 0)] << np.uint64(k + 1), np.uint64(0))
        m[:, j] = np.where(j < degree, vinit[:, j], new) if j < vinit.shape[1] else new
    m[0] = 1  # dimension 0 (poly 1) is van der Corput's: the identity
    return (m << np.arange(31, -1, -1, dtype=np.uint64)).astype(np.uint32)


SOBOL_MATRICES = _sobol_matrices(SOBOL_DIMS)


def _byte_tables(column: np.ndarray) -> np.ndarray:
    """(4, 256) uint32: entry [k, v] is the XOR of the columns that byte k of an index with value v selects."""
    bits = (np.arange(256)[:, None] >> np.arange(8)) & 1  # (256, 8)
    out = np.zeros((4, 256), np.uint32)
    for k in range(4):
        for b in range(8):
            out[k] ^= np.where(bits[:, b] == 1, column[8 * k + b], 0).astype(np.uint32)
    return out


#: Dimension 1's matrix by index byte: a shuffled index has ~16 random bits set, and four table reads
#: replace a walk over them (padded_2d draws dimension 1 for every 2D decision). 4 KB, in L1; numba
#: freezes it into the kernels as a constant, so the padded samplers take no matrices argument.
_DIM1_BYTES = _byte_tables(SOBOL_MATRICES[1])

_M32 = np.uint64(0xFFFFFFFF)
_ONE = np.uint64(1)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_S1, _S2, _S4, _S8, _S16, _S24, _S32 = (np.uint64(s) for s in (1, 2, 4, 8, 16, 24, 32))
_BYTE = np.uint64(0xFF)
_B1, _B2, _B4, _B8, _B16 = (np.uint64(b) for b in (0x55555555, 0x33333333, 0x0F0F0F0F, 0x00FF00FF, 0x0000FFFF))
_LK1, _LK2, _LK3, _LK4 = (np.uint64(c) for c in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6))
_TO_UNIT = 1.0 / 4294967296.0  # 2^-32


@jit
def reverse_bits32(x):
    """The 32 bits of ``x`` in reverse order (bit 0 becomes bit 31)."""
    x = np.uint64(x) & _M32
    x = ((x >> _S1) & _B1) | ((x & _B1) << _S1)
    x = ((x >> _S2) & _B2) | ((x & _B2) << _S2)
    x = ((x >> _S4) & _B4) | ((x & _B4) << _S4)
    x = ((x >> _S8) & _B8) | ((x & _B8) << _S8)
    return np.uint32((x >> _S16) | ((x & _B16) << _S16))


@jit
def laine_karras_permutation(x, seed):
    """Burley 2020's ``laine_karras_permutation`` with uint32 wrap-around.

    Adding the seed, and xoring x with x times an even constant, change bit k
    by a function of the bits below it: for every k the low k bits of the
    output are a bijection, chosen by the seed, of the low k bits of the input.
    """
    x = (np.uint64(x) + np.uint64(seed)) & _M32
    x ^= (x * _LK1) & _M32
    x ^= (x * _LK2) & _M32
    x ^= (x * _LK3) & _M32
    x ^= (x * _LK4) & _M32
    return np.uint32(x)


@jit
def nested_uniform_scramble(x, seed):
    """Owen scrambling in base 2 of a 32-bit integer: Burley 2020's ``nested_uniform_scramble``.

    Reversed, the Laine-Karras property reads: for every k the top k bits of
    the output are a bijection of the top k bits of the input, each bit
    flipped by a hash of the bits above it, as in Owen's nested swaps.
    """
    return reverse_bits32(laine_karras_permutation(reverse_bits32(x), seed))


@jit
def sobol_sample(index, dim, matrices):
    """The unscrambled 32-bit Sobol' integer of ``dim`` (< len(matrices)) at ``index`` (natural order, mod 2^32)."""
    i = np.uint64(index) & _M32
    v = np.uint64(0)
    while i != 0:
        # Set bits only, lowest first: a shuffled index has random bits, and a test per bit (or a
        # mask, which LLVM turns back into a branch around the load) mispredicts half of them.
        v ^= np.uint64(matrices[dim, trailing_zeros(i)])
        i &= i - _ONE
    return np.uint32(v)


@jit
def _sobol_01(index):
    # sobol_sample of dimensions 0 and 1. Dimension 0's matrix is the identity read from the top bit
    # (van der Corput), so its integer is the index's bits reversed; dimension 1 from its byte tables.
    i = np.uint64(index) & _M32
    t = _DIM1_BYTES
    y = t[0, i & _BYTE] ^ t[1, (i >> _S8) & _BYTE] ^ t[2, (i >> _S16) & _BYTE] ^ t[3, i >> _S24]
    return reverse_bits32(index), np.uint32(y)


@jit
def to_unit(x) -> float:
    """A 32-bit integer as the float64 x·2^-32 in [0, 1): exact, so never 1.0."""
    return float(x) * _TO_UNIT


@jit
def pixel_seed(key, pixel):
    """The hash of (key, pixel) that every dimension's seed of that pixel starts from.

    The samplers' seeds are chained SplitMix64 finalisers of (key, pixel,
    dimension); a kernel computes this prefix once per path and each decision
    adds only its dimension (:func:`hash_seed`), a third of the hashing.
    """
    return mix64(mix64(np.uint64(key) + _GOLDEN) ^ (np.uint64(pixel) * _GOLDEN))


@jit
def _dim_hash(seed, dim):
    # The odd multiplier spreads small dimensions over 64 bits.
    return mix64(np.uint64(seed) ^ (np.uint64(dim) * _GOLDEN))


@jit
def hash_seed(seed, dim):
    """A well-mixed 32-bit seed for dimension ``dim`` of a pixel's :func:`pixel_seed`."""
    return np.uint32(_dim_hash(seed, dim) >> _S32)


@jit
def sobol_1d(seed, index, dim, matrices) -> float:
    """Dimension ``dim`` of the global Sobol' sequence at ``index``, Owen-scrambled per (pixel seed, dim).

    A pixel's points are one Owen scrambling of the sequence, so every
    power-of-two prefix (and later aligned block) of dimensions 0 and 1 is a
    (0, m, 2)-net. Dimensions past ``matrices`` fall back to
    :func:`cornell_harness.renderers.core.rng.uniform`, still a pure function of the three.
    """
    if dim >= matrices.shape[0]:
        return uniform(_dim_hash(seed, dim), index, 0)
    return to_unit(nested_uniform_scramble(sobol_sample(index, dim, matrices), hash_seed(seed, dim)))


@jit
def _padded_seeds(seed, dim):
    # (index shuffle, first coordinate, second coordinate): both words of one hash, and a word of its remix.
    h = _dim_hash(seed, dim)
    return np.uint32(h & _M32), np.uint32(h >> _S32), np.uint32(mix64(h + _GOLDEN) >> _S32)


@jit
def padded_1d(seed, index, dim) -> float:
    """A 1D decision at ``dim``: Sobol' dimension 0 at a shuffled index, Owen-scrambled (Burley 2020's padding).

    The shuffle is Owen scrambling of the index, so it maps every aligned block
    [j·2^m, (j+1)·2^m) of indices onto an aligned block, whose points are a
    net (the higher index bits add a constant digital shift, the low m bits
    go through the matrix's invertible top-left m×m corner): stratification
    survives while the shuffle, seeded per (pixel seed, dim), decorrelates the
    decisions. Equals the first coordinate of :func:`padded_2d` at the same arguments.
    """
    shuffle, sx, _ = _padded_seeds(seed, dim)
    # Dimension 0 is the reversed index, so scramble(reverse(i)) = reverse(LK(i)): two reversals fewer.
    return to_unit(reverse_bits32(laine_karras_permutation(nested_uniform_scramble(index, shuffle), sx)))


@jit
def padded_2d(seed, index, dim):
    """A 2D decision at ``dim``: Sobol' dimensions (0, 1) at a shuffled index, each Owen-scrambled.

    Sobol' dimensions 0 and 1 form a (0, 2)-sequence: every aligned block of
    2^m indices is a (0, m, 2)-net, which the shuffle (see :func:`padded_1d`)
    and Owen scrambling (a nested permutation of elementary intervals) keep.
    """
    shuffle, sx, sy = _padded_seeds(seed, dim)
    x, y = _sobol_01(nested_uniform_scramble(index, shuffle))
    return to_unit(nested_uniform_scramble(x, sx)), to_unit(nested_uniform_scramble(y, sy))

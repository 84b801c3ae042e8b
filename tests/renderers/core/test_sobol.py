"""Owen-scrambled Sobol' points: scipy's sequence, exact bit helpers, exact stratification, unbiased randomisation."""

from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from scipy.stats import kstest, qmc

from cornell_harness.renderers.core.sobol import (
    SOBOL_DIMS,
    SOBOL_MATRICES,
    hash_seed,
    laine_karras_permutation,
    nested_uniform_scramble,
    padded_1d,
    padded_2d,
    pixel_seed,
    reverse_bits32,
    sobol_1d,
    sobol_sample,
    to_unit,
)

M32 = 0xFFFFFFFF
PADDED_2D, SOBOL_PAIR, PADDED_1D = 0, 1, 2
KEYS = (np.uint64(0x243F6A8885A308D3), np.uint64(7))


@numba.njit(nogil=True)
def _ints(which, a, b, matrices):
    """One integer helper over arrays: reverse, Laine-Karras, Owen scramble (a, seed b), or Sobol' (index a, dim b)."""
    out = np.empty(len(a), dtype=np.uint64)
    for i in range(len(a)):
        if which == 0:
            out[i] = reverse_bits32(a[i])
        elif which == 1:
            out[i] = laine_karras_permutation(a[i], b[i])
        elif which == 2:
            out[i] = nested_uniform_scramble(a[i], b[i])
        else:
            out[i] = sobol_sample(a[i], b[i], matrices)
    return out


@numba.njit(nogil=True)
def _eval(which, keys, pixels, indices, dims, matrices):
    """Samples (n, 2): padded_2d; sobol_1d at (dim, dim + 1); padded_1d (second column 0)."""
    out = np.zeros((len(keys), 2))
    for i in range(len(keys)):
        h, j, d = pixel_seed(keys[i], pixels[i]), indices[i], dims[i]
        if which == PADDED_2D:
            out[i, 0], out[i, 1] = padded_2d(h, j, d)
        elif which == SOBOL_PAIR:
            out[i, 0], out[i, 1] = sobol_1d(h, j, d, matrices), sobol_1d(h, j, d + 1, matrices)
        else:
            out[i, 0] = padded_1d(h, j, d)
    return out


def _points(which, key, pixel, indices, dim):
    """Samples of one (key, pixel, dim) at ``indices``, or of several where an argument is an array."""
    keys, pixels, indices, dims = np.broadcast_arrays(
        np.asarray(key, dtype=np.uint64), np.asarray(pixel, dtype=np.int64),
        np.asarray(indices, dtype=np.int64), np.asarray(dim, dtype=np.int64))
    return _eval(which, keys.ravel(), pixels.ravel(), indices.ravel(), dims.ravel(), SOBOL_MATRICES)


def _to_ints(u):
    """Floats x·2^-32 back to their 32-bit integers (exact: 32 bits fit a float64's 53)."""
    return (u * 4294967296.0).astype(np.uint64)


def _reverse_ref(x):
    return int(f"{x:032b}"[::-1], 2)


def _lk_ref(x, seed):
    x = (x + seed) & M32
    for c in (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6):
        x ^= (x * c) & M32
    return x


def test_matrices_reproduce_scipy_unscrambled_sobol():
    """Exact: our natural-order point gray(i) = i ^ (i >> 1) is scipy's i-th (scipy draws in Gray-code order)."""
    n = 1024
    want = _to_ints(qmc.Sobol(SOBOL_DIMS, scramble=False, bits=32).random(n))
    i = np.arange(n, dtype=np.uint64)
    idx = np.repeat(i ^ (i >> np.uint64(1)), SOBOL_DIMS)
    dims = np.tile(np.arange(SOBOL_DIMS, dtype=np.uint64), n)
    got = _ints(3, idx, dims, SOBOL_MATRICES).reshape(n, SOBOL_DIMS)
    np.testing.assert_array_equal(got, want)
    natural = _ints(3, np.repeat(i, SOBOL_DIMS), dims, SOBOL_MATRICES).reshape(n, SOBOL_DIMS)
    assert not np.array_equal(natural, want)  # the order matters: scipy's is not natural
    assert SOBOL_MATRICES.dtype == np.uint32 and SOBOL_MATRICES.shape == (SOBOL_DIMS, 32)
    # Upper triangular with unit diagonal: column b's lowest set bit is bit 31 - b, so every matrix is invertible.
    low = SOBOL_MATRICES & (~SOBOL_MATRICES + np.uint32(1))
    diagonal = np.uint32(1) << np.arange(31, -1, -1, dtype=np.uint32)
    np.testing.assert_array_equal(low, np.broadcast_to(diagonal, low.shape))


def test_bit_helpers_match_a_python_reference():
    rng = np.random.default_rng(20201)
    x = rng.integers(0, 1 << 32, 2000, dtype=np.uint64)
    seed = rng.integers(0, 1 << 32, 2000, dtype=np.uint64)
    x[:3], seed[:3] = (0, M32, 1), (0, M32, M32)
    rev = [_reverse_ref(int(v)) for v in x]
    lk = [_lk_ref(int(v), int(s)) for v, s in zip(x, seed)]
    nus = [_reverse_ref(_lk_ref(_reverse_ref(int(v)), int(s))) for v, s in zip(x, seed)]
    np.testing.assert_array_equal(_ints(0, x, seed, SOBOL_MATRICES), rev)
    np.testing.assert_array_equal(_ints(1, x, seed, SOBOL_MATRICES), lk)
    np.testing.assert_array_equal(_ints(2, x, seed, SOBOL_MATRICES), nus)
    assert reverse_bits32(1) == 1 << 31 and reverse_bits32(M32) == M32  # plain scalar calls from Python too
    assert to_unit(0) == 0.0 and to_unit(M32) < 1.0 and to_unit(1 << 31) == 0.5
    seed, other = (np.uint64(pixel_seed(KEYS[0], p)) for p in (3, 5))  # Python ints past 2^63 would overflow int64
    assert 0 <= hash_seed(seed, 5) <= M32 and hash_seed(seed, 5) != hash_seed(other, 3)


def test_owen_scramble_is_nested():
    """For every k ≤ 16 and seed, the top k output bits are a bijection of the top k input bits.

    Owen's nested swaps, proved by the reversed Laine-Karras structure (bit k of
    its output is bit k of its input xor a function of lower bits) and checked
    here exhaustively over the 2^k prefixes, with two random fillings of the
    low bits. Hence each aligned block [j·2^m, (j+1)·2^m) maps onto one such
    block, which the padded samplers' index shuffle relies on: checked too.
    """
    rng = np.random.default_rng(4)
    for seed in (0, 1, 0x9E3779B9, int(rng.integers(1 << 32))):
        for k in range(1, 17):
            prefix = np.arange(1 << k, dtype=np.uint64) << np.uint64(32 - k)
            seeds = np.full(1 << k, seed, dtype=np.uint64)
            tops = [_ints(2, prefix | rng.integers(0, 1 << (32 - k), 1 << k, dtype=np.uint64), seeds, SOBOL_MATRICES)
                    >> np.uint64(32 - k) for _ in range(2)]
            np.testing.assert_array_equal(tops[0], tops[1])
            np.testing.assert_array_equal(np.sort(tops[0]), np.arange(1 << k))
        for start in (0, 1 << 16, 0xABCD << 16):
            x = np.arange(start, start + (1 << 16), dtype=np.uint64)
            block = _ints(2, x, np.full(1 << 16, seed, np.uint64), SOBOL_MATRICES)
            assert np.unique(block >> np.uint64(16)).size == 1
            np.testing.assert_array_equal(np.sort(block & np.uint64(0xFFFF)), np.arange(1 << 16))


def _assert_stratified(x, y=None, m_max=10):
    """Every aligned block of 2^m of the 2^m_max points is one per elementary interval of area 2^-m.

    All shapes 2^-a × 2^-(m-a) in 2D (a (0, m, 2)-net), intervals of 2^-m in 1D; exact integer cells.
    """
    x = _to_ints(x)
    y = None if y is None else _to_ints(y)
    for m in range(m_max + 1):
        for a in range(m + 1) if y is not None else (m,):
            cells = x >> np.uint64(32 - a) << np.uint64(m - a)
            if y is not None:
                cells |= y >> np.uint64(32 - (m - a))
            rows = np.sort(cells.reshape(-1, 1 << m), axis=1)
            assert (rows == np.arange(1 << m)).all(), (m, a)


def test_every_power_of_two_block_is_stratified():
    """Exact: first 2^m points, every later aligned block (within 1024 and one far out), m ≤ 10, all shapes."""
    n = 1 << 10
    for start in (0, 5 << 20):
        idx = np.arange(start, start + n)
        for key in KEYS:
            for pixel in (0, 12345):
                for dim in (0, 7, 1000):  # any decision dimension: padding uses Sobol' dimensions 0 and 1 only
                    p = _points(PADDED_2D, key, pixel, idx, dim)
                    _assert_stratified(p[:, 0], p[:, 1])
                    _assert_stratified(_points(PADDED_1D, key, pixel, idx, dim)[:, 0])
                s = _points(SOBOL_PAIR, key, pixel, idx, 0)
                _assert_stratified(s[:, 0], s[:, 1])
        # Every Sobol' dimension alone is a (0, 1)-sequence, so each sobol_1d dimension is stratified in 1D.
        s = _points(SOBOL_PAIR, KEYS[0], 3, idx[:, None], np.arange(0, SOBOL_DIMS, 2)[None, :]).reshape(n, -1, 2)
        for d in range(s.shape[1]):
            _assert_stratified(s[:, d, 0])
            _assert_stratified(s[:, d, 1])


def test_values_are_a_pure_function_of_key_pixel_index_dim():
    """Same bits in any order, in threads, and from scalar calls; dimensions past SOBOL_DIMS too."""
    keys, pixels, indices, dims = (a.ravel() for a in np.meshgrid(
        np.array(KEYS), np.array([0, 1, 99999]), np.r_[0:48, 1 << 20, (1 << 32) - 1],
        np.array([0, 1, 2, 5, SOBOL_DIMS - 2, SOBOL_DIMS, 300]), indexing="ij"))
    pixels, indices, dims = pixels.astype(np.int64), indices.astype(np.int64), dims.astype(np.int64)
    order = np.random.default_rng(0).permutation(len(keys))
    for which in (PADDED_2D, SOBOL_PAIR, PADDED_1D):
        ref = _eval(which, keys, pixels, indices, dims, SOBOL_MATRICES)
        assert ref.min() >= 0.0 and ref.max() < 1.0
        shuffled = np.empty_like(ref)
        shuffled[order] = _eval(which, keys[order], pixels[order], indices[order], dims[order], SOBOL_MATRICES)
        halves = np.array_split(order, 2)
        with ThreadPoolExecutor(2) as pool:
            parts = list(pool.map(lambda o: _eval(which, keys[o], pixels[o], indices[o], dims[o], SOBOL_MATRICES),
                                  halves))
        threaded = np.empty_like(ref)
        for o, part in zip(halves, parts):
            threaded[o] = part
        np.testing.assert_array_equal(shuffled.view(np.uint64), ref.view(np.uint64))
        np.testing.assert_array_equal(threaded.view(np.uint64), ref.view(np.uint64))
        assert np.unique(ref[:, 0]).size > 0.99 * len(ref)  # and they do depend on every argument
    for i in order[:50]:
        h, j, d = np.uint64(pixel_seed(keys[i], int(pixels[i]))), int(indices[i]), int(dims[i])
        assert padded_2d(h, j, d) == tuple(_eval(PADDED_2D, keys[i:i + 1], pixels[i:i + 1],
                                                 indices[i:i + 1], dims[i:i + 1], SOBOL_MATRICES)[0])
        assert padded_1d(h, j, d) == padded_2d(h, j, d)[0]
        assert sobol_1d(h, j, d, SOBOL_MATRICES) == sobol_1d(h, j, d, SOBOL_MATRICES.copy())


def test_randomisation_is_unbiased_and_decisions_uncorrelated():
    """Means within 6 sigma of 1/2; correlations within 6 sigma of 0 (both ~1e-9 false-alarm rates each)."""
    n = 1 << 14
    pixels = np.arange(n)
    tol = 6.0 * np.sqrt(1.0 / 12.0 / n)  # sd of the mean of n uniforms: each randomisation is uniform exactly
    for index in (0, 1, 77, 1 << 20):
        for which, dim in ((PADDED_2D, 3), (SOBOL_PAIR, 0), (SOBOL_PAIR, 40)):
            p = _points(which, KEYS[index % 2], pixels, index, dim)
            assert abs(p.mean(axis=0) - 0.5).max() < tol, (index, which, dim)
            assert kstest(p[:, 0], "uniform").pvalue > 1e-4
    m = 4096
    bound = 6.0 / np.sqrt(m)  # sd of the sample correlation of m independent pairs is about 1/sqrt(m)
    idx = np.arange(m)
    a = _points(PADDED_2D, KEYS[0], 11, idx, 2)
    b = _points(PADDED_2D, KEYS[0], 11, idx, 8)
    c = _points(PADDED_1D, KEYS[0], 11, idx, 3)[:, 0]
    nbr = _points(PADDED_2D, KEYS[0], 12, idx, 2)
    for u, v in [(a[:, 0], b[:, 0]), (a[:, 0], b[:, 1]), (a[:, 1], c), (a[:, 0], a[:, 1]), (a[:, 0], nbr[:, 0])]:
        assert abs(np.corrcoef(u, v)[0, 1]) < bound
    # Pixels are independent randomisations: their estimates (here of ∫∫xy, 16 samples) are uncorrelated.
    # (Not sample by sample for sobol_1d: two scramblings of one sequence share the index's bits, e.g. the
    # first bit, so pixels' i-th samples correlate over i within one realisation; only estimates matter.)
    for which in (PADDED_2D, SOBOL_PAIR):
        p = _points(which, KEYS[1], np.arange(m)[:, None], np.arange(16)[None, :], 0).reshape(m, 16, 2)
        est = (p[..., 0] * p[..., 1]).mean(axis=1)
        assert abs(np.corrcoef(est[:-1], est[1:])[0, 1]) < bound
    # The test has power: without the index shuffle two padded decisions share the index's bits and correlate.
    i = np.arange(m, dtype=np.uint64)
    vdc = _ints(0, i, i, SOBOL_MATRICES)
    u, v = (_ints(2, vdc, np.full(m, hash_seed(np.uint64(pixel_seed(1, 2)), d), dtype=np.uint64), SOBOL_MATRICES) for d in (3, 4))
    assert abs(np.corrcoef(u.astype(float), v.astype(float))[0, 1]) > 5 * bound


def test_integration_error_far_below_independent_sampling():
    """∫∫ xy = 1/4 with 256 points, RMSE over 64 pixels (randomisations).

    Independent sampling's RMSE is sqrt(Var(xy)/256) = sqrt((1/9 - 1/16)/256) ≈ 0.0138.
    Measured: padded_2d 1.3e-4 (ratio 107), sobol_1d 1.4e-4 (ratio 100); the RMSE of
    scrambled nets falls as n^-3/2 for smooth integrands, so 10x leaves ample room.
    """
    n, reps = 256, 64
    independent = np.sqrt((1.0 / 9.0 - 1.0 / 16.0) / n)
    for which in (PADDED_2D, SOBOL_PAIR):
        p = _points(which, KEYS[1], np.arange(reps)[:, None], np.arange(n)[None, :], 0).reshape(reps, n, 2)
        rmse = np.sqrt(np.mean(((p[..., 0] * p[..., 1]).mean(axis=1) - 0.25) ** 2))
        assert rmse < independent / 10.0, (which, rmse, independent / rmse)

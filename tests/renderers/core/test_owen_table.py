"""The tabulated (0, 2)-sequences of ``pmj02table``: the table is the computed sequence, the index shuffle keeps
aligned blocks, every power-of-two block of a decision is a net across the table's end, and the randomisation is
uniform, unbiased and decorrelated."""

import numba
import numpy as np
from scipy.stats import chi2

from cornell_harness.renderers.core.owen_table import (POINTS, SETS, TABLE, set_point, shuffle_reversed, table_1d,
                                                       table_2d)
from cornell_harness.renderers.core.sampler import BSDF_U, CAMERA_U, EMITTER_PICK, EMITTER_U, vertex_dim
from cornell_harness.renderers.core.sobol import pixel_seed
from tests.renderers.core.test_samplers import _is_net

KEY = np.uint64(0x243F6A8885A308D3)


@numba.njit
def _sets(n):
    out = np.empty((SETS, n), np.uint64)
    for s in range(SETS):
        for j in range(n):
            out[s, j] = set_point(s, j)
    return out


@numba.njit
def _draw(seeds, indices, dim, two):
    out = np.zeros((seeds.size, indices.size, 2))
    for a in range(seeds.size):
        for b in range(indices.size):
            if two:
                out[a, b, 0], out[a, b, 1] = table_2d(seeds[a], indices[b], dim)
            else:
                out[a, b, 0] = table_1d(seeds[a], indices[b], dim)
    return out


def _seeds(n: int) -> np.ndarray:
    return np.array([pixel_seed(KEY, p) for p in range(n)], np.uint64)


def test_the_table_is_the_computed_sequence():
    """numpy's table at import equals the kernel's points, entry r holding point reverse(r) (10 bits), and the
    sets are different scramblings."""
    computed = _sets(POINTS)
    radical = [int(f"{r:010b}"[::-1], 2) for r in range(POINTS)]
    assert POINTS == 1024 and np.array_equal(TABLE, computed[:, radical])
    assert len({tuple(t[:8]) for t in TABLE}) == SETS


@numba.njit
def _shuffled(x, h):
    out = np.empty(x.size, np.uint64)
    for i in range(x.size):
        out[i] = shuffle_reversed(x[i], h)
    return out


def test_the_shuffle_is_nested():
    """For every k ≤ 14 and hash, the low k bits of the shuffled reversed index (the high half of the word) are a
    bijection of its low k bits, whatever the bits above: exhaustively over the 2^k values, with two random
    fillings of the other bits. Reversed, that maps every aligned block of sample indices onto an aligned block.
    The low half stays zero."""
    rng = np.random.default_rng(7)
    for h in (0, (1 << 64) - 1, 0x9E3779B97F4A7C15, *rng.integers(0, 1 << 63, 3)):
        h = np.uint64(h)
        for k in range(1, 15):
            low = np.arange(1 << k, dtype=np.uint64)
            outs = [_shuffled((low | (rng.integers(0, 1 << (32 - k), 1 << k, dtype=np.uint64) << np.uint64(k)))
                              << np.uint64(32), h) >> np.uint64(32) & np.uint64((1 << k) - 1) for _ in range(2)]
            np.testing.assert_array_equal(outs[0], outs[1])
            np.testing.assert_array_equal(np.sort(outs[0]), low)
        assert (_shuffled(np.arange(1 << 12, dtype=np.uint64) << np.uint64(32), h) & np.uint64(0xFFFFFFFF)).max() == 0


def test_every_power_of_two_block_is_a_net_across_the_tables_end():
    """Exact: for every m ≤ 11, the first 2^m samples of a 2D decision and every aligned block up to index
    4096 (past the table's 1024, where points are computed) are (0, m, 2)-nets; a 1D decision's put one
    number in each interval of width 2^-m."""
    seeds = _seeds(3)
    for dim in (2, 9, 1000):
        pts = _draw(seeds, np.arange(4096), dim, True)
        one = _draw(seeds, np.arange(4096), dim, False)[..., 0]
        assert np.array_equal(one, pts[..., 0])  # 1D is the 2D point's x
        for m in range(1, 12):
            for start in range(0, 4096, max(2 ** m, 512)):
                for p in range(seeds.size):
                    assert _is_net(pts[p, start:start + 2 ** m], m), (dim, m, start)


def test_randomisation_is_unbiased_and_decisions_uncorrelated():
    """Over 2^14 pixels, each sample index's coordinates have mean 1/2 within 6 sigma (each is exactly
    uniform: a digital shift); within a pixel two decisions, and a decision's x and y, are uncorrelated."""
    n = 1 << 14
    tol = 6.0 * np.sqrt(1.0 / 12.0 / n)
    for index in (0, 1, 77, POINTS + 5):
        p = _draw(_seeds(n), np.array([index]), 4, True)[:, 0]
        assert abs(p.mean(axis=0) - 0.5).max() < tol, index
        assert abs(np.mean(p[:, 0] * p[:, 1]) - 0.25) < 6.0 * np.sqrt(7.0 / 144.0 / n), index
    m = 4096
    bound = 6.0 / np.sqrt(m)
    one = _seeds(1)
    a, b = _draw(one, np.arange(m), 2, True)[0], _draw(one, np.arange(m), 8, True)[0]
    for u, v in [(a[:, 0], b[:, 0]), (a[:, 0], b[:, 1]), (a[:, 1], b[:, 1]), (a[:, 0], a[:, 1])]:
        assert abs(np.corrcoef(u, v)[0, 1]) < bound


def test_integration_error_far_below_independent_sampling():
    """∫∫ xy = 1/4 with 256 points of one decision, RMSE over 64 pixels: below a tenth of independent
    sampling's sqrt((1/9 - 1/16)/256) ≈ 0.0138, as pmj02's (test_sobol.py)."""
    p = _draw(_seeds(64), np.arange(256), 6, True)
    rmse = np.sqrt(np.mean(((p[..., 0] * p[..., 1]).mean(axis=1) - 0.25) ** 2))
    assert rmse < np.sqrt((1.0 / 9.0 - 1.0 / 16.0) / 256) / 10.0, rmse


@numba.njit
def _decisions_at(seeds, index, dims):
    # Per pixel seed, the x and y of a 2D decision at each of ``dims`` and sample ``index``.
    out = np.empty((seeds.size, len(dims), 2))
    for a in range(seeds.size):
        for k in range(len(dims)):
            out[a, k, 0], out[a, k, 1] = table_2d(seeds[a], index, dims[k])
    return out


def _chi2_uniform(cells: np.ndarray, n_cells: int, alpha: float) -> tuple[float, float]:
    """Pearson's statistic of integer cells against the uniform distribution over ``n_cells``, and the level
    it must stay below (its (1 - alpha) quantile, n_cells - 1 degrees of freedom)."""
    counts = np.bincount(cells, minlength=n_cells)
    expected = cells.size / n_cells
    return float(((counts - expected) ** 2).sum() / expected), float(chi2.isf(alpha, n_cells - 1))


def test_points_are_uniform_over_pixels():
    """Pearson χ² over 2^16 pixel seeds (fixed key), each check at level 1e-6 (21 checks: a false alarm about
    once in 48,000 keys, were the hash ideal). For sample indices 0, 1, 29 (within a batch at 256 spp), 255 and
    past the table: each coordinate of a decision in 256 intervals, its (x, y) in 16 × 16 cells, and the x of
    two decisions of one path jointly in 16 × 16 (the camera jitter, a vertex's emitter point and BSDF
    direction, the next vertex's emitter pick): each point and each pair of decisions is uniform."""
    alpha = 1e-6
    seeds = _seeds(1 << 16)
    dims = np.array([CAMERA_U, vertex_dim(1, EMITTER_U), vertex_dim(1, BSDF_U), vertex_dim(2, EMITTER_PICK)])
    for index in (0, 1, 29, 255, POINTS + 77):
        p = _decisions_at(seeds, index, dims)
        fine, coarse = np.floor(p * 256).astype(np.int64), np.floor(p * 16).astype(np.int64)
        checks = {"x": fine[:, 1, 0], "y": fine[:, 1, 1], "xy": coarse[:, 2, 0] * 16 + coarse[:, 2, 1]}
        if index in (0, 29):
            checks |= {f"x{a} x{b}": coarse[:, a, 0] * 16 + coarse[:, b, 0] for a, b in ((0, 1), (1, 2), (2, 3))}
        for name, cells in checks.items():
            stat, level = _chi2_uniform(cells, 256, alpha)
            assert stat < level, (index, name, stat, level)

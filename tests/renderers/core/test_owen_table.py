"""The tabulated (0, 2)-sequences of ``pmj02table``: the table is the computed sequence, every power-of-two
block of a decision is a net across the table's end, and the randomisation is unbiased and decorrelated."""

import numba
import numpy as np

from cornell_harness.renderers.core.owen_table import POINTS, SETS, TABLE, set_point, table_1d, table_2d
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
    """numpy's table at import equals the kernel's points, and the sets are different scramblings."""
    computed = _sets(POINTS)
    assert np.array_equal(TABLE, computed)
    assert len({tuple(t[:8]) for t in TABLE}) == SETS


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

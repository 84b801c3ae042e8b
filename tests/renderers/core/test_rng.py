"""Counter-based random numbers: uniform, independent across dimensions, paths and keys."""

import numba
import numpy as np
from scipy.stats import chisquare, kstest

from cornell_harness.adapters.seeds import pass_key
from cornell_harness.renderers.core.rng import uniform


@numba.njit
def _fill(key, paths, dims):
    out = np.empty((paths, dims))
    for i in range(paths):
        for j in range(dims):
            out[i, j] = uniform(key, i, j)
    return out


def test_uniform_and_in_range():
    x = _fill(pass_key(1, 0), 1 << 16, 4)
    assert x.min() >= 0.0 and x.max() < 1.0
    # KS and chi-square at alpha = 1e-4 each: a correct generator fails once in 10^4 keys.
    assert kstest(x.ravel(), "uniform").pvalue > 1e-4
    assert chisquare(np.histogram(x.ravel(), bins=64, range=(0, 1))[0]).pvalue > 1e-4


def test_dimensions_paths_and_keys_are_uncorrelated():
    x = _fill(pass_key(1, 0), 1 << 16, 3)
    y = _fill(pass_key(1, 1), 1 << 16, 1)
    bound = 4 / np.sqrt(x.shape[0])  # |r| of independent uniforms; alpha ~ 6e-5 each
    assert abs(np.corrcoef(x[:, 0], x[:, 1])[0, 1]) < bound
    assert abs(np.corrcoef(x[:-1, 0], x[1:, 0])[0, 1]) < bound
    assert abs(np.corrcoef(x[:, 0], y[:, 0])[0, 1]) < bound


def test_pure_function_of_its_inputs():
    k = pass_key(7, 3)
    assert uniform(k, 123, 4) == uniform(k, 123, 4)
    assert uniform(k, 123, 4) != uniform(k, 124, 4)
    assert pass_key(7, 3) == k and pass_key(7, 4) != k


def test_kernel_caches_follow_every_renderer_source(tmp_path):
    """An edit of any renderer module drops numba's cached kernels (inlined toolkit code is not tracked by numba)."""
    from cornell_harness.renderers.core.sampling import drop_stale_kernel_caches

    (tmp_path / "core").mkdir()
    (tmp_path / "core" / "lights.py").write_text("x = 1\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
    (cache / "pathtracer._shade-1.py311.nbi").write_text("stale")
    assert drop_stale_kernel_caches(tmp_path)
    assert not (cache / "pathtracer._shade-1.py311.nbi").exists()
    (cache / "pathtracer._shade-1.py311.nbi").write_text("fresh")
    assert not drop_stale_kernel_caches(tmp_path)  # nothing changed: the cache is kept
    (tmp_path / "core" / "lights.py").write_text("x = 2\n")
    assert drop_stale_kernel_caches(tmp_path) and not (cache / "pathtracer._shade-1.py311.nbi").exists()

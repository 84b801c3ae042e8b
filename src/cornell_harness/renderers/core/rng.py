"""Counter-based random numbers for our renderers' numba kernels.

A uniform number is a pure function of (key, path, dimension): the 64-bit
SplitMix64 finaliser (Steele, Lea & Flood 2014, "Fast splittable
pseudorandom number generators", OOPSLA) applied twice. No state is carried
between calls, so the numbers a path sees do not depend on how paths are
batched, ordered or shared among threads. The key is per pass, never per
work unit (units are cut by thread count, and the image must not depend on
it): :func:`cornell_harness.adapters.api.pass_key`, the seed derivation every
renderer shares.
"""

from __future__ import annotations

import numpy as np

from cornell_harness.renderers.core.sampling import jit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_DIM_BITS = np.uint64(24)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2^-53


@jit
def mix64(z):
    """SplitMix64's finaliser: a bijection of uint64 with full avalanche."""
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@jit
def uniform(key, path, dim) -> float:
    """A uniform float64 in [0, 1) for ``path`` (< 2^40) and ``dim`` (< 2^24) of stream ``key``."""
    counter = (np.uint64(path) << _DIM_BITS) | np.uint64(dim)
    z = mix64(np.uint64(key) ^ mix64(counter * _GOLDEN))
    return float(z >> _S11) * _TO_UNIT

"""Seeds and sample budgets shared by every renderer.

A render of ``spp`` samples per pixel is done in passes; each pass gets its own
32-bit seed derived from the user's ``seed`` and the pass index with NumPy's
``SeedSequence`` (hash-based, so seeds k and k+1 give unrelated streams).
"""

from __future__ import annotations

from typing import Iterator, Sequence

import numpy as np


def pass_seed(seed: int, index: int) -> int:
    """32-bit seed of pass ``index`` of a render seeded with ``seed``."""
    if seed < 0 or index < 0:
        raise ValueError(f"seed and pass index must be non-negative, got {seed}, {index}")
    return int(np.random.SeedSequence([seed, index]).generate_state(1, dtype=np.uint32)[0])


def spp_passes(spp: int, max_per_pass: int, checkpoints: Sequence[int] = ()) -> Iterator[int]:
    """Sizes of consecutive passes summing to ``spp``.

    Passes double (1, 1, 2, 4, ...) up to ``max_per_pass``, then stay at that
    size, so every power-of-two spp up to ``max_per_pass`` is a pass boundary and
    a render's image does not depend on which of those checkpoints were
    asked for. Any other checkpoint in (0, spp) adds a boundary of its own.
    """
    if spp < 1:
        raise ValueError(f"spp must be >= 1, got {spp}")
    if max_per_pass < 1:
        raise ValueError(f"max_per_pass must be >= 1, got {max_per_pass}")
    stops = {int(c) for c in checkpoints if 0 < c < spp} | {spp}
    b = 1
    while b < spp:
        stops.add(b)
        b += min(b, max_per_pass)
    done = 0
    for stop in sorted(stops):
        yield stop - done
        done = stop

"""The one seed derivation (cornell_harness.adapters.seeds): frame seeds of a sequence."""

from __future__ import annotations

import pytest


def test_frame_seeds_are_distinct_31_bit_and_not_the_still_seed():
    from cornell_harness.adapters.seeds import frame_seed

    seeds = [frame_seed(s, f) for s in range(4) for f in range(64)]
    assert len(set(seeds)) == len(seeds) and all(0 <= x < 2 ** 31 for x in seeds)
    assert frame_seed(0, 0) != 0 and frame_seed(3, 5) == frame_seed(3, 5)
    with pytest.raises(ValueError, match="non-negative"):
        frame_seed(0, -1)

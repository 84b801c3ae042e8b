"""Pass schedules and pass seeds."""

import numpy as np
import pytest

from cornell_harness.adapters.seeds import pass_seed, spp_passes


@pytest.mark.parametrize("spp, cap, checkpoints", [(1, 8, ()), (10, 4, ()), (300, 128, (1, 2, 4, 100)), (64, 1, ())])
def test_passes_sum_to_spp_and_respect_cap(spp, cap, checkpoints):
    passes = list(spp_passes(spp, cap, checkpoints))
    assert sum(passes) == spp and max(passes) <= cap and min(passes) >= 1
    totals = {sum(passes[: i + 1]) for i in range(len(passes))}
    assert set(checkpoints) <= totals


def test_power_of_two_checkpoints_do_not_change_the_schedule():
    assert list(spp_passes(256, 64, (1, 2, 4, 8, 16, 32, 64, 128))) == list(spp_passes(256, 64))


def test_pass_seeds_distinct_and_stable():
    seeds = {pass_seed(s, k) for s in range(20) for k in range(20)}
    assert len(seeds) == 400
    assert pass_seed(3, 7) == pass_seed(3, 7)
    with pytest.raises(ValueError):
        pass_seed(-1, 0)


def test_one_seed_derivation_for_every_renderer():
    """Mitsuba's 32-bit pass seed is the low word of our 64-bit pass key: one derivation, two widths."""
    from cornell_harness.adapters.seeds import pass_key

    for s, k in [(0, 0), (5, 3), (123456, 77)]:
        assert pass_seed(s, k) == int(pass_key(s, k)) & 0xFFFFFFFF
        assert pass_seed(s, k) == int(np.random.SeedSequence([s, k]).generate_state(1, dtype=np.uint32)[0])

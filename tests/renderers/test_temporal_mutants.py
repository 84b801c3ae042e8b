"""The temporal renderers' mutants (tests/mutants/temporal.py), each failing the closed-form check that pins its code.

The gate holds no sequence expectation (``tests/mutants/catalogue.py``'s
LOW_POWER says so), so these are where they are caught. Each mutant's copy of
its module is loaded (:func:`tests.mutants.load_module`) and run through the
check the real module passes in its own test file; no check compiles a copy
of the toolkit's kernels (the motion module is NumPy, the probes' copy patches
only ``probes.py`` and reuses the real kernels).
"""

from __future__ import annotations

import sys

import pytest

from tests import mutants
from tests.mutants.temporal import MOTION
from tests.renderers.core.test_motion import (DEGREES, LONG_STEP, check_disocclusion_rejected,
                                              check_positions_reproject, two_cameras)
from tests.renderers.test_probe_sequences import check_step_decay
from tests.renderers.test_temporal import check_svgf_variance

pytest.importorskip("embreex")

TEMPORAL = [m.name for m in mutants.MUTANTS if m.name in mutants.catalogue.TEMPORAL_CATCHERS]


def _motion_check(name, work):
    mutants.load_module(name, work)
    module = sys.modules[mutants.module_name(name, MOTION)]
    if name == "motion_vectors_off_by_one":
        check_positions_reproject(module, two_cameras(DEGREES))
    else:
        check_disocclusion_rejected(module, two_cameras(LONG_STEP))


CHECKS = {
    # Vectors a pixel too long move the reprojected positions by a pixel's footprint.
    "motion_vectors_off_by_one": _motion_check,
    # Keeping every tap gives the strip the arc uncovers the history of the box that hid it.
    "no_disocclusion_rejection": _motion_check,
    # The hysteresis the wrong way round decays at (1 − h) + hρ = 0.6, not h + (1 − h)ρ = 0.9.
    "hysteresis_wrong_way_round": lambda name, work: check_step_decay(mutants.load_module(name, work), 0.8, 0.5),
    # The moments of the current frame alone: a variance estimate of 0 once the history is long.
    "svgf_variance_not_accumulated": lambda name, work: check_svgf_variance(mutants.load_module(name, work)),
}


def test_every_temporal_mutant_has_a_check():
    assert set(CHECKS) == set(TEMPORAL) == {m.name for m in mutants.catalogue.temporal.MUTANTS}


@pytest.mark.parametrize("name", TEMPORAL)
def test_mutant_is_caught(name, tmp_path_factory):
    with pytest.raises(AssertionError):
        CHECKS[name](name, tmp_path_factory.mktemp("temporal-mutants"))

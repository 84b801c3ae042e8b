"""The mutant catalogue: every family's mutants in one tuple, by name, and what the gate is known not to catch.

One module per renderer family holds its bugs (:mod:`tests.mutants.pathtracer`,
:mod:`~tests.mutants.photon_mapping`, :mod:`~tests.mutants.ambient_occlusion`,
:mod:`~tests.mutants.probes`, :mod:`~tests.mutants.denoising`, :mod:`~tests.mutants.whitted`,
:mod:`~tests.mutants.spectral`, :mod:`~tests.mutants.temporal`); a new algorithm
adds its module here. :data:`LOW_POWER` lists the mutants below the gate's
resolution (with why, and what catches them instead), :data:`ISOLATED` those
that once hung the gate.
"""

from __future__ import annotations

from tests.mutants import ambient_occlusion, denoising, pathtracer, photon_mapping, probes, spectral, temporal, whitted
from tests.mutants.model import Mutant

FAMILIES = (pathtracer, photon_mapping, ambient_occlusion, probes, denoising, whitted, spectral, temporal)
MUTANTS: tuple[Mutant, ...] = tuple(m for family in FAMILIES for m in family.MUTANTS)

BY_NAME = {m.name: m for m in MUTANTS}
assert len(BY_NAME) == len(MUTANTS), "mutant names must be unique"

#: Where each temporal mutant is caught (tests/renderers/test_temporal_mutants.py).
TEMPORAL_CATCHERS = {
    "hysteresis_wrong_way_round": "tests/renderers/test_temporal_mutants.py (the step change's decay λ = h + (1 − h)ρ)",
    "motion_vectors_off_by_one": "tests/renderers/test_temporal_mutants.py (reprojected positions)",
    "no_disocclusion_rejection": "tests/renderers/test_temporal_mutants.py (the strip the arc uncovers)",
    "svgf_variance_not_accumulated": "tests/renderers/test_temporal_mutants.py (the moments' variance, 2(1 − α)/(2 − α))",
}

#: Mutants the gate cannot fail: a bias too small at its CI budget (power < 99% over seeds, as measured by
#: ``benchmarks/gate_power.py``, docs/gate-detection.md), or a change that does not take the image away from
#: the reference: name -> why, and what catches them instead.
#: None of the path tracer's since gate.toml has the furnace and light-panel expectations; before them, the
#: Cornell box alone missed cosine_pdf_mismatch (0.85 sd) and had power 0.2 on mis_pdf_area_measure.
LOW_POWER: dict[str, str] = {
    "no_normal_test": "it moves images towards the reference, so no check that scores agreement can fail it "
                      "without asserting a bias. Jensen's estimate divides by the area of a disc that a corner "
                      "cuts, so with the normal test concave corners read dark; without it, the other face's "
                      "photons fill the cut part, which is right wherever the two faces' irradiance is alike "
                      "(the incoming-side test still stops thin surfaces). cornell-box without gathering, "
                      "seeds 0-2, 8x8 tiles against Mitsuba at the ceiling's right edge: -52% to -54% clean, -28% "
                      "to -36% mutated; with k = 200, 1M photons, max_radius 0.05, -22% to -24% clean and +2% to +5% "
                      "mutated; of 1024 tiles, four had a larger error than every clean seed, by at most 1.7 "
                      "points (small box's top front edge: +10% to +17% against +2% to +9%). Three corner-caustic "
                      "scenes (docs/photon-mapping.md) changed no pixel beyond 18%. The bias limit (issue 29) does "
                      "not change this: on cornell-box-caustics its limits are +0.05% (image) and +0.04% (caustic) "
                      "against -0.07% and -0.25% clean (benchmarks/biased_gate.py, 8 seeds). Caught by "
                      "tests/renderers/test_photons.py::test_normal_test_keeps_wall_photons_off_the_floor",
    # The recursive ray tracer (issue 32): a biased approximation the gate holds no expectation for.
    **{m.name: "the gate has no whitted expectation: it is a biased approximation of the reference by design "
               "(no diffuse interreflection, no caustics), with no budget to hold it to. Caught by "
               "tests/renderers/test_whitted.py::test_mutant_is_caught (the normal-incidence transmittance, the "
               "umbra, the polygon formula, the constant ambient's ρ·La)" for m in whitted.MUTANTS},
    # The temporal renderers': their bugs show over frames, and the gate renders still images.
    **{m.name: "the gate holds no sequence expectation (its lag, flicker and ghosting budgets are the sequence "
               "workflow's), and a still image is a sequence's first frame, with no history. Caught by "
               f"{TEMPORAL_CATCHERS[m.name]}" for m in temporal.MUTANTS},
}
assert set(LOW_POWER) <= set(BY_NAME)

#: Mutants of the path tracer's ``spectral = "hero"`` mode: the gate runs them on its hero expectation only
#: (:func:`tests.mutants.patching.gate_config`'s ``spectral``).
SPECTRAL = frozenset(m.name for m in spectral.MUTANTS)

#: Mutants that once made a gate run never end (a NaN throughput survived Russian roulette, so in the
#: closed furnace the path bounced forever): tests and the benchmark run them in a child process with a
#: time limit, so a regression fails instead of hanging the suite.
ISOLATED = {"nan_throughput"}
assert ISOLATED <= set(BY_NAME)

"""The temporal renderers' mutants: the probes' update over frames, motion vectors and reprojection, SVGF.

The gate holds no sequence expectation (lag, flicker and ghosting budgets are
the sequence workflow's), so each is caught by the test that pins its code
(:data:`tests.mutants.catalogue.LOW_POWER` says which).
"""

from __future__ import annotations

from tests.mutants.model import CORE, PROBES, SVGF, Edit, Mutant

MOTION = f"{CORE}/motion.py"

MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "hysteresis_wrong_way_round",
        "the probes' hysteresis taken as the new update's weight instead of the old texel's (TAA's alpha and "
        "RTXGI's hysteresis confused): lerp(old, new, h) in place of lerp(new, old, h)",
        (Edit("history_weight", "return hysteresis", "return 1.0 - hysteresis", PROBES),),
        "probes",
    ),
    Mutant(
        "motion_vectors_off_by_one",
        "motion vectors measured from the pixel's left edge minus half a pixel instead of its centre: every "
        "vector one pixel too long along x",
        (Edit("motion_vectors", "film - np.stack([cols + 0.5, rows + 0.5], axis=-1)",
              "film - np.stack([cols - 0.5, rows + 0.5], axis=-1)", MOTION),),
        "pathtracer+temporal",
    ),
    Mutant(
        "no_disocclusion_rejection",
        "every history tap inside the previous image kept, whatever surface it shows: the uncovered background "
        "takes the history of the object that hid it (ghosting)",
        (Edit("reproject", """
              keep = inside & consistent(prev.object[cy, cx], prev.normal[cy, cx], prev_position[cy, cx],
                                         now.object, now.normal, now.position, now.depth)""",
              "keep = inside", MOTION),),
        "pathtracer+temporal",
    ),
    Mutant(
        "svgf_variance_not_accumulated",
        "SVGF's luminance moments taken from the current frame only, not blended into their history: with one "
        "sample per pixel the variance estimate is 0 once the history is long enough, and the à-trous filter's "
        "luminance weight stops all filtering",
        (Edit("accumulate_moments", "moments = np.where(valid[..., None], am * current + (1.0 - am) * old_moments, "
              "current)", "moments = current", SVGF),),
        "pathtracer+svgf",
    ),
)

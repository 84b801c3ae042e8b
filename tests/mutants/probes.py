"""The irradiance probes' mutants, in their algorithm (src/cornell_harness/renderers/ddgi.py)."""

from __future__ import annotations

from tests.mutants.model import DDGI, Edit, Mutant

MUTANTS: tuple[Mutant, ...] = (
    # -- DDGI irradiance probes (probes; the algorithm is src/cornell_harness/renderers/ddgi.py) ----------------------------
    Mutant(
        "chebyshev_inverted",
        "Chebyshev visibility test written the wrong way round (r < μ): probes are darkened where they see "
        "the point and trusted where a wall hides it (light leaks)",
        (Edit("probe_irradiance", "r > mean", "r < mean", DDGI),),
        "probes",
    ),
    Mutant(
        "irradiance_not_cosine_weighted",
        "an irradiance texel's ray weight max(0, n·ω) replaced by 1 on the texel's hemisphere (as for a "
        "radiance average): a uniform hemisphere mean instead of the cosine-weighted irradiance",
        (Edit("_blend_irradiance", """
              w = max(0.0, texels[a, b, 0] * directions[r, 0] + texels[a, b, 1] * directions[r, 1]
                      + texels[a, b, 2] * directions[r, 2])""", """
              w = 1.0 if texels[a, b, 0] * directions[r, 0] + texels[a, b, 1] * directions[r, 1] \\
                  + texels[a, b, 2] * directions[r, 2] > 0.0 else 0.0""", DDGI),),
        "probes",
    ),
    Mutant(
        "probe_index_off_by_one",
        "a lookup's base probe one cell too far along x (floor(...) + 1, clamped to the grid): every point "
        "reads the probes of the next cell over",
        (Edit("probe_irradiance", "gx = min(max(int(math.floor((bx - vol.origin[0]) / vol.spacing[0])), 0), nx - 1)",
              "gx = min(max(int(math.floor((bx - vol.origin[0]) / vol.spacing[0])) + 1, 0), nx - 1)", DDGI),),
        "probes",
    ),
)

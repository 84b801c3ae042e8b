"""The irradiance probes' mutants, in their algorithm (src/cornell_harness/renderers/ddgi.py)."""

from __future__ import annotations

from tests.mutants.model import DDGI, Mutant

MUTANTS: tuple[Mutant, ...] = (
    # -- DDGI irradiance probes (probes; the algorithm is src/cornell_harness/renderers/ddgi.py) ----------------------------
    Mutant(
        "chebyshev_inverted",
        "Chebyshev visibility test written the wrong way round (r < μ): probes are darkened where they see "
        "the point and trusted where a wall hides it (light leaks)",
        (("                if r > mean:  # farther than the surfaces the probe saw this way: maybe hidden\n",
          "                if r < mean:  # farther than the surfaces the probe saw this way: maybe hidden\n", DDGI),),
        "probes",
    ),
    Mutant(
        "irradiance_not_cosine_weighted",
        "an irradiance texel's ray weight max(0, n·ω) replaced by 1 on the texel's hemisphere (as for a "
        "radiance average): a uniform hemisphere mean instead of the cosine-weighted irradiance",
        (("                    w = max(0.0, texels[a, b, 0] * directions[r, 0] + texels[a, b, 1] * directions[r, 1]\n"
          "                            + texels[a, b, 2] * directions[r, 2])\n",
          "                    w = 1.0 if texels[a, b, 0] * directions[r, 0] + texels[a, b, 1] * directions[r, 1] \\\n"
          "                        + texels[a, b, 2] * directions[r, 2] > 0.0 else 0.0\n", DDGI),),
        "probes",
    ),
    Mutant(
        "probe_index_off_by_one",
        "a lookup's base probe one cell too far along x (floor(...) + 1, clamped to the grid): every point "
        "reads the probes of the next cell over",
        (("    gx = min(max(int(math.floor((bx - vol.origin[0]) / vol.spacing[0])), 0), nx - 1)\n",
          "    gx = min(max(int(math.floor((bx - vol.origin[0]) / vol.spacing[0])) + 1, 0), nx - 1)\n", DDGI),),
        "probes",
    ),
)

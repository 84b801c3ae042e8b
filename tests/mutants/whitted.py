"""The recursive ray tracer's mutants (src/cornell_harness/renderers/whitted.py, and the toolkit's shadow-ray origin it uses).

The gate has no whitted expectation (a biased approximation with no budget against the reference), so
tests/renderers/test_whitted.py::test_mutant_is_caught catches each, and :data:`tests.mutants.catalogue.LOW_POWER`
says why the gate cannot.
"""

from __future__ import annotations

from tests.mutants.model import CORE, WHITTED, Edit, Mutant

MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "whitted_attenuation_without_fresnel",
        "shadow attenuation that lets a straight shadow ray through glass unscaled (the Fresnel transmittance "
        "forgotten): attenuate becomes ignore, glass casts no shadow",
        (Edit("_cross", "factor = 1.0 - fresnel_dielectric(cos_o, geo.eta[p])[0]", "factor = 1.0", WHITTED),),
        "whitted",
    ),
    Mutant(
        "whitted_shadow_ray_not_offset",
        "the shadow ray starts on the surface itself, not offset off it: it hits the surface it leaves "
        "(shadow acne), darkening lit floors in a speckle",
        (Edit("light_sample", "a = offset_origin(x, n, geo.offset)", "a = x", f"{CORE}/direct.py"),),
        "whitted",
    ),
    Mutant(
        "whitted_ambient_twice",
        "the constant ambient term β·ρ·La added twice at a diffuse hit (once more after a refactor)",
        (Edit("_shade", "out.L[q, c] += w[c] * la[depth, c]", """
              out.L[q, c] += w[c] * la[depth, c]  # the ambient term, β·ρ·La
              out.L[q, c] += w[c] * la[depth, c]""", WHITTED),),
        "whitted",
    ),
)

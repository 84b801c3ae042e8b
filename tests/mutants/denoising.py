"""The OIDN denoise stage's mutants (src/cornell_harness/renderers/oidn.py), made of the denoised path tracer."""

from __future__ import annotations

from tests.mutants.model import OIDN, Edit, Mutant

MUTANTS: tuple[Mutant, ...] = (
    # -- denoised path tracing (pathtracer+oidn; src/cornell_harness/renderers/oidn.py) ------------------------------------------
    Mutant(
        "oidn_ldr",
        "the beauty filtered as LDR (hdr off: pyoidn.denoise's default), so radiance above 1 is clipped",
        (Edit("_run", '_filter(device, images, quality, hdr=True, cleanAux=aux == "prefiltered")',
              '_filter(device, images, quality, hdr=False, cleanAux=aux == "prefiltered")', OIDN),),
        "pathtracer+oidn",
    ),
    Mutant(
        "oidn_aux_not_prefiltered",
        "albedo and normal flagged clean (cleanAux) but passed as rendered, never prefiltered: what "
        "pyoidn.denoise(clean_aux=True) does; the glass sphere's noisy auxiliary images are kept as detail",
        (Edit("_run", """
              _filter(device, {"albedo": albedo, "output": albedo}, quality)
              _filter(device, {"normal": normal, "output": normal}, quality)""",
              "pass  # the auxiliary images as rendered", OIDN),),
        "pathtracer+oidn",
    ),
    Mutant(
        "oidn_checkpoints_not_denoised",
        "only the final image denoised: the checkpoints below it keep the path tracer's noisy image",
        (Edit("Denoised.render", "Checkpoint(c.spp, image, c.time_s + dt, c.aovs, plus(c.cpu_time_s, dcpu))",
              "Checkpoint(c.spp, image if c.spp == spp else c.image, c.time_s + dt, c.aovs, plus(c.cpu_time_s, dcpu))",
              OIDN),),
        "pathtracer+oidn",
    ),
)

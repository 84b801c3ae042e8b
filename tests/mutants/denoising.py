"""The OIDN denoise stage's mutants (src/cornell_harness/renderers/oidn.py), made of the denoised path tracer."""

from __future__ import annotations

from tests.mutants.model import OIDN, Mutant

MUTANTS: tuple[Mutant, ...] = (
    # -- denoised path tracing (pathtracer+oidn; src/cornell_harness/renderers/oidn.py) ------------------------------------------
    Mutant(
        "oidn_ldr",
        "the beauty filtered as LDR (hdr off: pyoidn.denoise's default), so radiance above 1 is clipped",
        (('    _filter(device, images, quality, hdr=True, cleanAux=aux == "prefiltered")\n',
          '    _filter(device, images, quality, hdr=False, cleanAux=aux == "prefiltered")\n', OIDN),),
        "pathtracer+oidn",
    ),
    Mutant(
        "oidn_aux_not_prefiltered",
        "albedo and normal flagged clean (cleanAux) but passed as rendered, never prefiltered: what "
        "pyoidn.denoise(clean_aux=True) does; the glass sphere's noisy auxiliary images are kept as detail",
        (('            _filter(device, {"albedo": albedo, "output": albedo}, quality)\n'
          '            _filter(device, {"normal": normal, "output": normal}, quality)\n',
          '            pass  # the auxiliary images as rendered\n', OIDN),),
        "pathtracer+oidn",
    ),
    Mutant(
        "oidn_checkpoints_not_denoised",
        "only the final image denoised: the checkpoints below it keep the path tracer's noisy image",
        (("            shots.append(Checkpoint(c.spp, image, c.time_s + dt, c.aovs, plus(c.cpu_time_s, dcpu)))\n",
          "            shots.append(Checkpoint(c.spp, image if c.spp == spp else c.image, c.time_s + dt, c.aovs,\n"
          "                                    plus(c.cpu_time_s, dcpu)))\n",
          OIDN),),
        "pathtracer+oidn",
    ),
)

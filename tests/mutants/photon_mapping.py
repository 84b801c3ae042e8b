"""The photon mappers' mutants: photonmap (photon tracing, the photon map's estimate) and SPPM."""

from __future__ import annotations

from tests.mutants.model import CORE, SPPM, Edit, Mutant

PHOTONS, PHOTON_MAP = f"{CORE}/photons.py", f"{CORE}/photon_map.py"

MUTANTS: tuple[Mutant, ...] = (
    # -- photon mapping (photonmap, sppm) ------------------------------------------------
    Mutant(
        "photon_power_not_divided",
        "photon flux not divided by the number of photons emitted (each photon carries the light's whole "
        "power)",
        (Edit("shoot", "photons.power[:] /= max(emitted, 1)", "", PHOTONS),),
        "photonmap",
    ),
    Mutant(
        "double_cosine",
        "density estimate weighted by the cosine of each photon's incidence, which its flux already counts",
        (Edit("_estimate", "w = kernel_weight(kernel, dist[i, a], r)", "w = kernel_weight(kernel, dist[i, a], r) * cos_in",
              PHOTON_MAP),),
        "photonmap",
    ),
    Mutant(
        "caustic_photon_on_specular_surface",
        "caustic photons stored where they leave the last specular surface (the ray's origin) instead of "
        "where they land",
        (Edit("_scatter", "_store(out.photons, ns, x, power, d, n, depth, caustic)", """
              o = (rays.o[i, 0], rays.o[i, 1], rays.o[i, 2])
              _store(out.photons, ns, o if mode == STORE_CAUSTIC else x, power, d, n, depth, caustic)""", PHOTONS),),
        "photonmap",
    ),
    Mutant(
        "photon_direction_reuses_point_dims",
        "a photon's emitted direction drawn from the sample dimensions of its point on the emitter (EMIT_U for "
        "both decisions): where a photon leaves the light decides where it goes",
        (Edit("_emit", "sample_2d(stream, pt, EMIT_DIR_U)", "sample_2d(stream, pt, EMIT_U)", PHOTONS),),
        "photonmap",
    ),
    Mutant(
        "no_normal_test",
        "no normal test in the density estimate: photons on a wall count on the floor at their corner",
        (Edit("photon_faces", """
              if cos_n < NORMAL_COS_MIN:
                  return 0.0""", "", PHOTON_MAP),),
        "photonmap",
    ),
    Mutant(
        "photon_flux_98",
        "the photons emitted counted 2% high, so every photon's flux is 2% low (the flux divided by 1.02 times the "
        "photons emitted): an emitted count that also counts photons that never left the light, e.g. samples "
        "re-drawn after a zero-pdf emission, or batches traced and then dropped",
        (Edit("shoot", 'emitted = state["emitted"]', 'emitted = state["emitted"] + state["emitted"] // 50', PHOTONS),),
        "photonmap",
    ),
    Mutant(
        "sppm_flux_98",
        "SPPM's photons per iteration counted 2% high, so the gathered flux is 2% low (the flux divided by 1.02 "
        "times the photons shot), as photon_flux_98 in the photon mapper",
        (Edit("Progress.iterate", "phi /= photons", "phi /= photons + photons // 50", SPPM),),
        "sppm",
    ),
    Mutant(
        "sppm_flux_added_after_shrink",
        "SPPM's flux update adds the iteration's flux after scaling the sum to the new radius "
        "(τ' = τ·r'²/r² + Φ instead of (τ + Φ)·r'²/r²): the photons gathered in the old disc are counted in the "
        "smaller new one, a bias that falls only as log(i)/i",
        (Edit("Progress._update", "(self.tau[hit] + phi[hit]) * (r_new ** 2 / self.radius[hit] ** 2)[:, None]",
              "self.tau[hit] * (r_new ** 2 / self.radius[hit] ** 2)[:, None] + phi[hit]", SPPM),),
        "sppm",
    ),
    Mutant(
        "no_radius_shrinking",
        "SPPM's α left out of the photon-count update (N' = N + M): the radius never shrinks, and the image "
        "converges to a blurred one",
        (Edit("Progress._update", "self.n[hit] + alpha * m[hit]", "self.n[hit] + m[hit]", SPPM),),
        "sppm",
    ),
    Mutant(
        "sppm_power_not_divided",
        "SPPM's gathered flux not divided by the iteration's photon count",
        (Edit("Progress.iterate", "phi /= photons", "", SPPM),),
        "sppm",
    ),
    Mutant(
        "sppm_footprint_area_not_width",
        "SPPM's pixel footprint taken as its area, the pixel's solid angle times the squared distance (Ω·t²), "
        "instead of its width (√Ω·t): on a 256² image the radius starts about 100 times too small, so few photons "
        "are gathered and the estimate is noise",
        (Edit("footprints", "cone_width * distance", "cone_width ** 2 * distance ** 2", SPPM),),
        "sppm",
    ),
)

"""The hero-wavelength path tracer's mutants (src/cornell_harness/renderers/hero_wavelength.py: the ``spectral = "hero"`` mode of the
path tracer). The gate's hero expectation (cornell-box-measured against Mitsuba's spectral reference) fails each
(tests/gate/test_gate_power.py, slow), and tests/renderers/test_hero_wavelength.py::test_mutant_is_caught shows the
spectral furnace failing each."""

from __future__ import annotations

from tests.mutants.model import HERO, Edit, Mutant

MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "hero_wrong_cmf",
        "each wavelength's radiance weighted by the matching functions of the next wavelength of the path "
        "(nodes[(j + 1) % 4]: the rotation applied twice), so wavelengths are paired with the wrong CMF",
        (Edit("_start_paths", "spec.cmf_rgb[nodes[j], c] * inv",
              "spec.cmf_rgb[nodes[(j + 1) % N_WAVELENGTHS], c] * inv", HERO),),
    ),
    Mutant(
        "hero_pdf_ignored",
        "the wavelengths' sampling pdf ignored: each divided by the uniform density 1/(λ_max - λ_min) as if "
        "sampled uniformly, though they follow the visible-wavelength pdf",
        # The sampled range, LAMBDA_MAX - LAMBDA_MIN of core/wavelengths.py, which the kernel's module does not import.
        (Edit("_start_paths", "p = pdf[j]", "p = 1.0 / (830.5 - 359.5)  # uniform over the range", HERO),),
    ),
    Mutant(
        "hero_emission_normalised_twice",
        "the emission spectra divided by Σȳ when resampled (as emission_rgb's projection does), though the "
        "sensor weights already divide by it: every emitter 1/106.9 as bright",
        (Edit("spectral_tables",
              "le = np.array([on_grid(s) for s in rows_le]).reshape(len(rows_le), -1) if rows_le "
              "else np.zeros((1, rho.shape[1]))", """
              from cornell_harness.scenes.spectra import observer
              le = np.array([on_grid(s) / observer()[1][:, 1].sum() for s in rows_le]).reshape(len(rows_le), -1) \\
                  if rows_le else np.zeros((1, rho.shape[1]))""", HERO),),
    ),
)

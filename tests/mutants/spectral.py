"""The hero-wavelength path tracer's mutants (src/cornell_harness/renderers/hero_wavelength.py: the ``spectral = "hero"`` mode of the
path tracer). The gate's hero expectation (cornell-box-measured against Mitsuba's spectral reference) fails each
(tests/gate/test_gate_power.py, slow), and tests/renderers/test_hero_wavelength.py::test_mutant_is_caught shows the
spectral furnace failing each."""

from __future__ import annotations

from tests.mutants.model import Mutant

HERO = "cornell_harness/renderers/hero_wavelength.py"

MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "hero_wrong_cmf",
        "each wavelength's radiance weighted by the matching functions of the next wavelength of the path "
        "(nodes[(j + 1) % 4]: the rotation applied twice), so wavelengths are paired with the wrong CMF",
        (("sensor[q, j, c] = spec.cmf_rgb[nodes[j], c] * inv",
          "sensor[q, j, c] = spec.cmf_rgb[nodes[(j + 1) % N_WAVELENGTHS], c] * inv", HERO),),
    ),
    Mutant(
        "hero_pdf_ignored",
        "the wavelengths' sampling pdf ignored: each divided by the uniform density 1/(λ_max - λ_min) as if "
        "sampled uniformly, though they follow the visible-wavelength pdf",
        (("            p = pdf[j]\n",
          "            p = 1.0 / (LAMBDA_MAX - LAMBDA_MIN)  # uniform over the range\n", HERO),
         ("from cornell_harness.renderers.core.wavelengths import N_WAVELENGTHS,",
          "from cornell_harness.renderers.core.wavelengths import LAMBDA_MAX, LAMBDA_MIN, N_WAVELENGTHS,", HERO)),
    ),
    Mutant(
        "hero_emission_normalised_twice",
        "the emission spectra divided by Σȳ when resampled (as emission_rgb's projection does), though the "
        "sensor weights already divide by it: every emitter 1/106.9 as bright",
        (("le = np.array([on_grid(s) for s in rows_le])",
          "le = np.array([on_grid(s) / sensor_rgb_norm() for s in rows_le])", HERO),
         ("def spectral_tables(",
          "def sensor_rgb_norm():\n    from cornell_harness.scenes.spectra import observer\n\n    return observer()[1][:, 1].sum()\n\n\n"
          "def spectral_tables(", HERO)),
    ),
)

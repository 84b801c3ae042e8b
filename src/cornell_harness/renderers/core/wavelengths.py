"""Wavelengths of a spectral path: how they are sampled, their pdf, and the spectra a kernel reads at them.

A hero-wavelength path (Wilkie, Nawaz, Droske, Weidlich and Hanika 2014,
"Hero Wavelength Spectral Sampling", EGSR; the integrator is
:mod:`cornell_harness.renderers.hero_wavelength`) carries :data:`N_WAVELENGTHS` = 4
wavelengths, sampled from one number u as pbrt-v4 does
(``SampledWavelengths::SampleVisible``, §4.6.5):

- u_j = u + j/4 mod 1 for j = 0..3 (the hero u_0 = u and its three
  rotations: Wilkie §3's rotation of the secondary wavelengths by a quarter
  of the range each, here in primary sample space, as pbrt-v4 does, so that
  every λ_j has the same density p);
- λ_j = P⁻¹(u_j), P the cdf of pbrt-v4's visible-wavelength pdf
  (``VisibleWavelengthsPDF``: p(λ) ∝ sech²(0.0072 (λ − 538)), a fit to the
  sum of the CIE matching functions), restricted and normalised to the range
  below. Why this pdf rather than uniform: the matching functions are near 0
  over a third of 360-830 nm, and uniform samples there carry almost
  nothing; importance sampling them lowers the colour noise (pbrt-v4 reports
  it so), and p > 0 over the whole range, so the estimate stays unbiased
  wherever a spectrum is non-zero.

The scale: the harness projects a spectrum S to linear sRGB by the sums over
the observer's 1 nm table, RGB = M · Σ_i S(λ_i) x̄(λ_i) / Σ_i ȳ(λ_i)
(:func:`cornell_harness.scenes.spectra.emission_rgb`). Here every spectrum is
resampled onto that table (:func:`on_grid`, the same interpolation) and held
constant over each node's 1 nm bin [λ_i − ½, λ_i + ½): a continuous λ reads
node :func:`bin_of`. The estimator f(bin(λ)) / p(λ) then has expectation
Σ_i f(λ_i) · 1 nm exactly, the harness's sum, so a spectral emitter seen
directly converges to ``emission_rgb`` of its spectrum (not to a trapezoid
integral 1e-4 away from it). Hence the sampled range [359.5, 830.5] nm.

:func:`sensor_rgb` (the table ``cmf_rgb``) is what one wavelength's radiance
adds to a pixel's linear sRGB per unit: M · (x̄, ȳ, z̄)(λ_i) / Σ ȳ; a path's
estimate is Σ_j S(λ_j) · cmf_rgb[bin(λ_j)] / (4 · p(λ_j)), each division
guarded (p = 0 gives 0).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from cornell_harness.scenes.spectra import Spectrum, observer, xyz_to_linear_srgb
from cornell_harness.renderers.core.sampling import jit

#: Wavelengths per path (Wilkie et al. 2014 use 4: one SIMD register).
N_WAVELENGTHS = 4
#: The observer's table (cornell_harness.scenes.spectra.observer): nodes 360..830 nm at 1 nm.
LAMBDA_FIRST, LAMBDA_LAST = 360.0, 830.0
N_BINS = int(LAMBDA_LAST - LAMBDA_FIRST) + 1
#: The sampled range: each node's 1 nm bin (module docstring).
LAMBDA_MIN, LAMBDA_MAX = LAMBDA_FIRST - 0.5, LAMBDA_LAST + 0.5
#: pbrt-v4's visible-wavelength pdf, sech²(K (λ − CENTRE)) up to normalisation.
_K, _CENTRE = 0.0072, 538.0
_T_MIN, _T_MAX = math.tanh(_K * (LAMBDA_MIN - _CENTRE)), math.tanh(_K * (LAMBDA_MAX - _CENTRE))


@jit
def visible_pdf(lam) -> float:
    """p(λ) per nm: K sech²(K (λ − 538)) / (tanh(K (λ_max − 538)) − tanh(K (λ_min − 538))) in the range, else 0."""
    if not (LAMBDA_MIN <= lam <= LAMBDA_MAX):
        return 0.0
    c = math.cosh(_K * (lam - _CENTRE))
    return _K / ((_T_MAX - _T_MIN) * c * c)


@jit
def sample_visible(u) -> float:
    """λ = P⁻¹(u) for u in [0, 1): 538 + atanh(tanh(K (λ_min − 538)) + u (T_max − T_min)) / K, clamped to the range
    (pbrt-v4's ``SampleVisibleWavelengths``, there for 360-830 nm)."""
    lam = _CENTRE + math.atanh(_T_MIN + u * (_T_MAX - _T_MIN)) / _K
    return min(max(lam, LAMBDA_MIN), LAMBDA_MAX)


@jit
def bin_of(lam) -> int:
    """The table node whose 1 nm bin holds λ (0 .. N_BINS − 1)."""
    return min(max(int(math.floor(lam - LAMBDA_MIN)), 0), N_BINS - 1)


@jit
def rotated(u, j) -> float:
    """u + j/N mod 1: the j-th wavelength's number from the hero's (Wilkie et al. 2014, §3)."""
    v = u + j / N_WAVELENGTHS
    return v - 1.0 if v >= 1.0 else v


@jit
def hero_wavelengths(u):
    """The path's 4 wavelengths from one number u: (table nodes (4-tuple of int), pdfs per nm (4-tuple)); the
    hero is j = 0."""
    l0, l1, l2, l3 = sample_visible(u), sample_visible(rotated(u, 1)), sample_visible(rotated(u, 2)), \
        sample_visible(rotated(u, 3))
    return ((bin_of(l0), bin_of(l1), bin_of(l2), bin_of(l3)),
            (visible_pdf(l0), visible_pdf(l1), visible_pdf(l2), visible_pdf(l3)))


def on_grid(spectrum: Spectrum) -> np.ndarray:
    """The spectrum at the table's nodes (N_BINS,), as :func:`cornell_harness.scenes.spectra.emission_rgb` reads it."""
    grid, _ = observer()
    assert grid[0] == LAMBDA_FIRST and grid[-1] == LAMBDA_LAST and grid.size == N_BINS, "the observer's table moved"
    return np.ascontiguousarray(spectrum.at(grid), dtype=np.float64)


@functools.cache
def sensor_rgb() -> np.ndarray:
    """(N_BINS, 3): M · (x̄, ȳ, z̄)(λ_i) / Σ ȳ, the linear sRGB a unit of radiance at node i adds (per nm)."""
    _, xyz_bar = observer()
    table = np.ascontiguousarray(xyz_bar @ xyz_to_linear_srgb().T / xyz_bar[:, 1].sum())
    table.setflags(write=False)
    return table

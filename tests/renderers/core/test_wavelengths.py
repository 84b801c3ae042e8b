"""Wavelength sampling of the hero-wavelength path tracer (src/cornell_harness/renderers/core/wavelengths.py): the pdf, its inverse
cdf, the rotation of the secondary wavelengths, and the scale of the estimate (exact, not statistical)."""

from __future__ import annotations

import numpy as np
from scipy.integrate import quad

from cornell_harness.scenes.spectra import Spectrum, emission_rgb, observer
from cornell_harness.renderers.core.wavelengths import (LAMBDA_MAX, LAMBDA_MIN, N_BINS, bin_of, hero_wavelengths, on_grid,
                                        rotated, sample_visible, sensor_rgb, visible_pdf)


def test_pdf_is_normalised_and_positive_over_the_range_only():
    total, _ = quad(visible_pdf, LAMBDA_MIN, LAMBDA_MAX, points=[538.0], limit=200)
    assert abs(total - 1.0) < 1e-10
    assert visible_pdf(LAMBDA_MIN - 1e-9) == 0.0 and visible_pdf(LAMBDA_MAX + 1e-9) == 0.0
    assert min(visible_pdf(x) for x in np.linspace(LAMBDA_MIN, LAMBDA_MAX, 101)) > 0.0


def test_sampling_inverts_the_cdf_of_the_pdf():
    """P(sample_visible(u)) = u: the numbers are distributed by exactly the pdf the estimate divides by."""
    for u in (0.0, 1e-6, 0.1, 0.37, 0.5, 0.9, 1.0 - 1e-12):
        lam = sample_visible(u)
        cdf, _ = quad(visible_pdf, LAMBDA_MIN, lam, limit=200)
        assert abs(cdf - u) < 1e-9, (u, lam, cdf)
    # pbrt-v4's SampleVisibleWavelengths over its 360-830 nm: 538 - 138.888889 atanh(0.85691062 - 1.82750197 u);
    # ours is the same curve over the half-nm-wider range, so the medians nearly agree.
    assert abs(sample_visible(0.5) - (538 - 138.888889 * np.arctanh(0.85691062 - 1.82750197 * 0.5))) < 0.5


def test_secondary_wavelengths_are_the_rotations_of_the_hero():
    u = 0.8
    assert [rotated(u, j) for j in range(4)] == [0.8, 0.8 + 0.25 - 1.0, 0.8 + 0.5 - 1.0, 0.8 + 0.75 - 1.0]
    nodes, pdfs = hero_wavelengths(u)
    for j in range(4):
        lam = sample_visible(rotated(u, j))
        assert nodes[j] == bin_of(lam) and pdfs[j] == visible_pdf(lam)
    assert len(set(nodes)) == 4
    assert bin_of(LAMBDA_MIN) == 0 and bin_of(LAMBDA_MAX) == N_BINS - 1 and bin_of(400.49) == 40


def test_the_estimate_integrates_to_emission_rgb_exactly():
    """E[S(bin(λ)) cmf_rgb[bin(λ)] / p(λ)] over λ ~ p is Σ_i S_i cmf_rgb[i] (each node's 1 nm bin), which is
    emission_rgb(S): the expectation per bin is the integral of p/p over that bin, 1 nm. Checked by
    quadrature over each bin."""
    s = Spectrum((380.0, 450.0, 600.0, 780.0), (0.2, 1.5, 0.7, 2.0))
    values, cmf = on_grid(s), sensor_rgb()
    weights = [quad(lambda x: visible_pdf(x) / visible_pdf(x), LAMBDA_MIN + i, LAMBDA_MIN + i + 1)[0]
               for i in range(0, N_BINS, 47)]
    assert np.allclose(weights, 1.0, rtol=0, atol=1e-12)
    np.testing.assert_allclose(values @ cmf, emission_rgb(s), rtol=1e-10)
    grid, xyz_bar = observer()
    assert sensor_rgb().shape == (N_BINS, 3) and grid.size == N_BINS

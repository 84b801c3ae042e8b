"""harness.evaluate.ciede2000 (numpy, no colour-science import) against colour-science, which it replaces in
the metrics: the same numbers, and Sharma et al.'s published test pairs."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from harness.evaluate import ciede2000 as de

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message=".*Matplotlib.*")
    import colour


@pytest.fixture(scope="module")
def rgb():
    rng = np.random.default_rng(7)
    # HDR-ish values, exact zeros, greys (achromatic: the hue special cases) and a few negatives.
    img = rng.lognormal(-1.5, 1.5, (64, 64, 3))
    img[:4] = 0.0
    img[4:8] = img[4:8, :, :1]
    img[8, :8] *= -1
    return img


def test_as_colour_science(rgb):
    d65 = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    npm = colour.normalised_primary_matrix(colour.RGB_COLOURSPACES["sRGB"].primaries, d65)
    np.testing.assert_allclose(de.RGB_TO_XYZ, npm, rtol=0, atol=1e-15)
    lab_ours, lab_theirs = de.linear_srgb_to_lab(rgb), colour.XYZ_to_Lab(rgb @ npm.T, d65)
    np.testing.assert_allclose(lab_ours, lab_theirs, rtol=1e-12, atol=1e-12)
    other = de.linear_srgb_to_lab(rgb[::-1] * 0.9)
    np.testing.assert_allclose(de.delta_e2000(lab_ours, other),
                               colour.delta_E(lab_theirs, other, method="CIE 2000"), rtol=1e-12, atol=1e-12)
    v = np.clip(rgb, 0, 1)
    np.testing.assert_allclose(de.srgb_eotf_inverse(v), colour.models.eotf_inverse_sRGB(v), rtol=0, atol=1e-15)
    np.testing.assert_allclose(de.srgb_eotf(v), colour.models.eotf_sRGB(v), rtol=0, atol=1e-15)
    assert de.srgb_eotf(0.5) == pytest.approx(0.21404, abs=1e-5)


@pytest.mark.parametrize("lab_1, lab_2, expected", [  # Sharma et al. 2005, table 1: pairs 1, 7, 17, 25, 34
    ((50.0, 2.6772, -79.7751), (50.0, 0.0, -82.7485), 2.0425),
    ((50.0, 0.0, 0.0), (50.0, -1.0, 2.0), 2.3669),
    ((50.0, 2.5, 0.0), (56.0, -27.0, -3.0), 31.9030),
    ((60.2574, -34.0099, 36.2677), (60.4626, -34.1751, 39.4387), 1.2644),
    ((2.0776, 0.0795, -1.1350), (0.9033, -0.0636, -0.5514), 0.9082),
])
def test_sharma_pairs(lab_1, lab_2, expected):
    assert float(de.delta_e2000(np.array(lab_1), np.array(lab_2))) == pytest.approx(expected, abs=5e-5)

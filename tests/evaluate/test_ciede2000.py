"""cornell_harness.evaluate.ciede2000 (numpy, no colour-science import) against colour-science, which it replaces in the
metrics, and against the array-wise original it was sped up from (tests/evaluate/ciede2000_numpy.py): the same
numbers, edge cases included, and Sharma et al.'s published test pairs."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from cornell_harness.evaluate import ciede2000 as de
from cornell_harness.evaluate.pixels import zero_broken_pixels
from cornell_harness.store.exr import read_exr
from tests.evaluate import ciede2000_numpy as oracle

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
                               colour.delta_E(lab_ours, other, method="CIE 2000"), rtol=1e-12, atol=1e-12)
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


def _lab_pairs(n=20000, seed=11):
    """CIELAB pairs that reach every branch of eqs. (10) and (14): hues either side of 0°/360°, hue differences
    around ±180°, zero chroma on one side or both, and NaN."""
    rng = np.random.default_rng(seed)
    L, C, h = rng.uniform(0, 100, (n, 2)), rng.uniform(0, 60, (n, 2)), rng.uniform(0, 360, (n, 2))
    C[:500, 0] = 0.0
    C[500:1000] = 0.0
    h[1000:3000, 0], h[1000:3000, 1] = rng.uniform(350, 360, 2000), rng.uniform(0, 10, 2000)  # wrap at 0/360
    h[3000:5000, 1] = (h[3000:5000, 0] + rng.uniform(175, 185, 2000)) % 360  # |h1 - h2| near 180
    h[5000:5010] = [0.0, 180.0]
    lab = np.stack([L, C * np.cos(np.radians(h)), C * np.sin(np.radians(h))], axis=-1)
    lab[6000, 0, 1], lab[6001, 1] = np.nan, np.nan
    return lab[:, 0], lab[:, 1]


def test_as_the_original_on_lab_pairs():
    lab_1, lab_2 = _lab_pairs()
    ours, theirs = de.delta_e2000(lab_1, lab_2), oracle.delta_e2000(lab_1, lab_2)
    np.testing.assert_array_equal(np.isnan(ours), np.isnan(theirs))
    assert np.isnan(ours[6000]) and np.isnan(ours[6001])
    np.testing.assert_allclose(ours, theirs, rtol=1e-12, atol=1e-12)
    assert de.delta_e2000(lab_1[:3], lab_1[:3]).tolist() == [0.0, 0.0, 0.0]


def _near_neutral(rgb):
    """Pixels within 1e-6 of grey: their CIELAB a*, b* are rounding noise, whose hue angle (eq. 7) and so ΔE00
    (through eqs. 14-22) depends on the order of the XYZ matrix product's additions, which BLAS chooses."""
    return np.ptp(rgb, axis=-1) <= 1e-6 * np.max(np.abs(rgb), axis=-1)


def test_as_the_original_on_images(rgb):
    rng = np.random.default_rng(3)
    img = rgb.copy()
    img[9, 0, 1], img[9, 1, 2], img[9, 2] = np.nan, np.inf, -np.inf  # broken pixels: black, as the rule says
    ref = rng.lognormal(-1.5, 1.5, rgb.shape)
    ref[:2] = 0.0
    ref[10, 0, 0] = np.nan  # the reference's are taken as they are
    np.testing.assert_allclose(de.linear_srgb_to_lab(rgb), oracle.linear_srgb_to_lab(rgb), rtol=1e-12, atol=1e-11)
    for exposure in (1.0, 0.37, 5.0):
        ours = de.delta_e2000_linear(img, ref, exposure)
        theirs = oracle.delta_e2000(oracle.linear_srgb_to_lab(zero_broken_pixels(img) * exposure),
                                    oracle.linear_srgb_to_lab(ref * exposure))
        np.testing.assert_array_equal(np.isnan(ours), np.isnan(theirs))
        assert np.isnan(ours[10, 0]) and np.isfinite(ours[9, :3]).all()
        grey = _near_neutral(zero_broken_pixels(img)) | _near_neutral(ref)
        np.testing.assert_allclose(ours[~grey], theirs[~grey], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(ours[grey], theirs[grey], rtol=1e-6)


def test_as_the_original_on_a_render():
    """A real 16-spp-like image: a noisy copy of the stored cornell-box reference, at its display exposure."""
    from cornell_harness.evaluate.metrics import exposure_scale
    from pathlib import Path

    ref = read_exr(Path(__file__).resolve().parents[2] / "src/cornell_harness/references/cornell-box/reference.exr").astype(float)
    img = ref * np.random.default_rng(5).lognormal(0.0, 0.5, ref.shape)
    exposure = exposure_scale(ref)
    ours = de.delta_e2000_linear(img, ref, exposure)
    theirs = oracle.delta_e2000(oracle.linear_srgb_to_lab(img * exposure), oracle.linear_srgb_to_lab(ref * exposure))
    grey = _near_neutral(img) | _near_neutral(ref)
    np.testing.assert_allclose(ours[~grey], theirs[~grey], rtol=1e-10, atol=1e-12)
    assert np.mean(ours) == pytest.approx(np.mean(theirs), rel=1e-12)
    assert np.percentile(ours, 95) == pytest.approx(np.percentile(theirs, 95), rel=1e-12)


def test_in_chunks_as_in_one_pass(rgb, monkeypatch):
    """Computed chunk by chunk (a 1024² image is 16 chunks): every pixel as the whole image in one pass gives,
    chunks that do not divide the image included."""
    rng = np.random.default_rng(11)
    ref = rng.lognormal(-1.5, 1.5, rgb.shape)
    img = rgb.copy()
    img[20, 5, 0] = np.nan
    whole = de.delta_e2000_linear(img, ref, 0.8)
    assert rgb.shape[0] * rgb.shape[1] <= de.CHUNK_PIXELS  # the default: one chunk here
    monkeypatch.setattr(de, "CHUNK_PIXELS", 1000)
    chunked = de.delta_e2000_linear(img, ref, 0.8)
    np.testing.assert_array_equal(chunked, whole)
    assert np.isfinite(chunked[20, 5])

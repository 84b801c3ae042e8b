"""The spectral furnace's closed form (cornell_harness.scenes.analytic): per wavelength the white furnace's series,
projected to linear sRGB as the scene model projects an emitter.

Independent of the renderers: the closed form is checked against colour-science's own integration of the
per-wavelength radiance, against the emitter rule where the series is L alone, and against the Neumann
series summed term by term; the scene it belongs to is checked to be the spectral scene the loader would make.
"""

from __future__ import annotations

import colour
import numpy as np
import pytest

from cornell_harness.scenes.analytic import SPECTRAL_FURNACE_ALBEDO, SPECTRAL_FURNACE_EMISSION, furnace_radiance, spectral_furnace_radiance, spectral_furnace_scene
from cornell_harness.scenes.spectra import ILLUMINANT_E, SCENE_LIGHT, Spectrum, emission_rgb, reflectance_rgb

GRID = np.arange(360.0, 831.0)


def _colour_science_rgb(values: np.ndarray) -> np.ndarray:
    """colour-science's integration of a spectrum on GRID (ȳ-normalised), to linear sRGB, as a second opinion."""
    sd = colour.SpectralDistribution(dict(zip(GRID, values)))
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz = colour.sd_to_XYZ(sd, cmfs, method="Integration", k=1.0 / cmfs.values[:, 1].sum())
    return colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_encoding=False,
                             chromatic_adaptation_transform=None)


def test_unbounded_furnace_is_L_over_one_minus_rho_per_wavelength():
    rho, le = SPECTRAL_FURNACE_ALBEDO.at(GRID), SPECTRAL_FURNACE_EMISSION.at(GRID)
    want = _colour_science_rgb(le / (1.0 - rho))
    np.testing.assert_allclose(spectral_furnace_radiance(), want, rtol=1e-9)
    # The scale of the emitter rule: a furnace of albedo 0 (max_depth 1: emission only) is emission_rgb(L).
    np.testing.assert_allclose(spectral_furnace_radiance(1), emission_rgb(SPECTRAL_FURNACE_EMISSION), rtol=1e-10)


@pytest.mark.parametrize("max_depth", [1, 2, 5])
def test_bounded_depth_is_the_neumann_series_cut_after_D_segments(max_depth):
    """L·Σ_{k<D} ρ^k per wavelength, i.e. the sum of emission_rgb of each term L·ρ^k."""
    grid = GRID
    terms = [emission_rgb(Spectrum(tuple(grid), tuple(SPECTRAL_FURNACE_EMISSION.at(grid)
                                                       * SPECTRAL_FURNACE_ALBEDO.at(grid) ** k)))
             for k in range(max_depth)]
    np.testing.assert_allclose(spectral_furnace_radiance(max_depth), np.sum(terms, axis=0), rtol=1e-9)
    # and converges to the unbounded one (ρ ≤ 0.85: 0.85^250 < 1e-17).
    np.testing.assert_allclose(spectral_furnace_radiance(250), spectral_furnace_radiance(-1), rtol=1e-12)


def test_the_spectral_answer_is_not_the_rgb_answer():
    """The RGB projection's furnace, Le_c/(1-ρ_c) per channel, is off the spectral answer by far more than the
    path tracer tests resolve (the RGB error this scene exists to show): > 10% in some channel."""
    scene = spectral_furnace_scene()
    rho, le = scene.materials["grey"].reflectance, scene.meshes[0].radiance
    rgb = np.array([furnace_radiance(r, e, -1) for r, e in zip(rho, le)])
    spectral = spectral_furnace_radiance()
    assert np.all(spectral > 0) and np.all(rgb > 0)
    assert np.max(np.abs(rgb / spectral - 1.0)) > 0.10, (rgb, spectral)


@pytest.mark.parametrize("convention", [ILLUMINANT_E, SCENE_LIGHT])
def test_scene_binds_the_spectra_and_holds_their_projection(convention):
    scene = spectral_furnace_scene(max_depth=3, res=8, convention=convention)
    sp = scene.spectral
    assert sp.rgb_convention == convention and sp.emission("box") == SPECTRAL_FURNACE_EMISSION
    assert sp.reflectance("grey") == SPECTRAL_FURNACE_ALBEDO
    light = SPECTRAL_FURNACE_EMISSION if convention == SCENE_LIGHT else None
    assert scene.materials["grey"].reflectance == reflectance_rgb(SPECTRAL_FURNACE_ALBEDO, convention, light)
    assert scene.meshes[0].radiance == emission_rgb(SPECTRAL_FURNACE_EMISSION)
    assert scene.max_depth == 3 and (scene.camera.width, scene.camera.height) == (8, 8)
    assert all(0.0 < x < 1.0 for x in scene.materials["grey"].reflectance)
    assert scene.content_hash() != spectral_furnace_scene(3, 8, ILLUMINANT_E if convention == SCENE_LIGHT
                                                          else SCENE_LIGHT).content_hash()

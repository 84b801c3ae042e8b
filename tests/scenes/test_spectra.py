"""Sampled spectra, their RGB projection (the two conventions and the emitter rule), and spectral scene files.

The colour-science cross-check of issue 33: each measured Cornell reflectance
under illuminant E projects to the derived values stored in
``cornell-pcg.json`` to 1e-3. colour-science is imported here freely (the
harness imports it only when it projects a spectrum).
"""

from __future__ import annotations

import json
import subprocess
import sys

import colour
import numpy as np
import pytest

from tests.conftest import MINIMAL_SCENE, ROOT, cbox_in_process
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.model import SceneError
from cornell_harness.scenes.spectra import (CORNELL_PCG, ILLUMINANT_E, SCENE_LIGHT, Spectrum, emission_rgb, interpolate,
                                    observer, reflectance_rgb, xyz_to_linear_srgb)

DATA = json.loads(CORNELL_PCG.read_text())
DERIVED = DATA["derived_reference_values_colour_science_cie1931_2deg"]
WAVELENGTHS = tuple(float(x) for x in DATA["spectra"]["wavelengths_nm"])
MEASURED = {n: Spectrum(WAVELENGTHS, tuple(DATA["spectra"][f"{n}_reflectance"])) for n in ("white", "green", "red")}
LIGHT = Spectrum(tuple(float(x) for x in DATA["spectra"]["light_emission"]["wavelengths_nm"]),
                 tuple(float(x) for x in DATA["spectra"]["light_emission"]["values"]))


def _spectrum(sd) -> Spectrum:
    return Spectrum(tuple(float(x) for x in sd.wavelengths), tuple(float(x) for x in sd.values))


def test_the_packaged_data_is_the_shared_file():
    shared = ROOT.parent / "shared" / "data" / "cornell-pcg.json"
    if not shared.exists():
        pytest.skip(f"no shared data at {shared}")
    assert json.loads(shared.read_text()) == DATA


def test_linear_interpolation_and_zero_outside():
    s = Spectrum((400.0, 500.0, 700.0), (1.0, 3.0, 2.0))
    assert s.at([400, 450, 500, 600, 700]).tolist() == [1.0, 2.0, 3.0, 2.5, 2.0]
    assert s.at([399.9, 700.1, 360, 830]).tolist() == [0.0, 0.0, 0.0, 0.0]
    constant = Spectrum(s.wavelengths_nm, s.values, "constant")
    assert constant.at([360, 830]).tolist() == [1.0, 2.0]
    assert interpolate(np.array([1.0, 2.0]), np.array([4.0, 6.0]), [[1.5]]).tolist() == [[5.0]]


def test_measured_reflectances_under_E_equal_the_derived_values():
    """The issue's cross-check: illuminant E, CIE 1931 2°, linear sRGB without adaptation, to 1e-3."""
    for name, spectrum in MEASURED.items():
        want = DERIVED["illuminant_E_to_linear_sRGB_no_adaptation"][name]
        np.testing.assert_allclose(reflectance_rgb(spectrum, ILLUMINANT_E), want, atol=1e-3, rtol=0, err_msg=name)


def test_projection_equals_colour_sciences_own_integration():
    """Our sums on the 1 nm grid against colour-science's sd_to_XYZ (method "Integration") on the same samples."""
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    grid = cmfs.wavelengths
    for name, spectrum in MEASURED.items():
        sd = colour.SpectralDistribution(spectrum.at(grid), grid)
        xyz = colour.sd_to_XYZ(sd, cmfs, colour.SDS_ILLUMINANTS["E"], method="Integration") / 100.0
        np.testing.assert_allclose(reflectance_rgb(spectrum, ILLUMINANT_E), xyz_to_linear_srgb() @ xyz,
                                   atol=1e-9, err_msg=name)


def test_scene_light_rule_under_D65_gives_the_derived_D65_values():
    """With L = D65 the per-channel white balance is ~1 (sRGB's white is D65): the data's D65 values, to 1e-3."""
    d65 = _spectrum(colour.SDS_ILLUMINANTS["D65"])
    for name, spectrum in MEASURED.items():
        np.testing.assert_allclose(reflectance_rgb(spectrum, SCENE_LIGHT, d65), DERIVED["D65_to_linear_sRGB"][name],
                                   atol=1e-3, rtol=0, err_msg=name)


def test_scene_light_convention_white_balances_to_the_light():
    """ρ_c · RGB_c(L) = RGB_c(ρ·L): light reflected once is exact, and a perfect white is (1, 1, 1)."""
    white = Spectrum((300.0, 900.0), (1.0, 1.0))
    np.testing.assert_allclose(reflectance_rgb(white, SCENE_LIGHT, LIGHT), (1.0, 1.0, 1.0), atol=1e-12)
    under_e = reflectance_rgb(white, ILLUMINANT_E)
    np.testing.assert_allclose(under_e, xyz_to_linear_srgb() @ np.ones(3), atol=2e-3)  # E's XYZ ≈ (1, 1, 1)
    light = np.asarray(emission_rgb(LIGHT))
    grid = tuple(float(x) for x in observer()[0])
    for name, spectrum in MEASURED.items():
        # ρ·L sampled on the observer's own 1 nm grid, where the sums are taken: the same spectrum exactly.
        product = Spectrum(grid, tuple(spectrum.at(grid) * LIGHT.at(grid)))
        np.testing.assert_allclose(np.asarray(reflectance_rgb(spectrum, SCENE_LIGHT, LIGHT)) * light,
                                   emission_rgb(product), rtol=1e-9, err_msg=name)
    # The coloured walls differ between the conventions beyond the data's 1e-3 (the warm light has little blue).
    for name in ("green", "red"):
        diff = np.abs(np.subtract(reflectance_rgb(MEASURED[name], SCENE_LIGHT, LIGHT),
                                  reflectance_rgb(MEASURED[name], ILLUMINANT_E)))
        assert diff.max() > 0.03, (name, diff)


def test_scene_light_refuses_a_light_it_cannot_balance_to():
    blue_line = Spectrum((449.0, 450.0, 451.0), (0.0, 1.0, 0.0))  # outside the sRGB gamut: R < 0
    with pytest.raises(ValueError, match="not positive"):
        reflectance_rgb(MEASURED["white"], SCENE_LIGHT, blue_line)


def test_emitter_rule():
    """RGB = M · Σ L x̄ / Σ ȳ: the data's light to 1e-3 relative; a flat spectrum of value c has Y = c."""
    np.testing.assert_allclose(emission_rgb(LIGHT), DERIVED["light_emission_to_linear_sRGB"], rtol=1e-3)
    flat = Spectrum((300.0, 900.0), (2.5, 2.5))
    y = np.linalg.solve(xyz_to_linear_srgb(), emission_rgb(flat))[1]
    assert y == pytest.approx(2.5, rel=1e-12)
    xyz = np.linalg.solve(xyz_to_linear_srgb(), emission_rgb(LIGHT))
    np.testing.assert_allclose(xyz[:2] / xyz.sum(), DERIVED["light_chromaticity_xy"], atol=1e-3)


def _toml_list(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def spectral_scene(convention: str = ILLUMINANT_E, light_line: str = 'light = "light"', extra: str = "") -> str:
    """MINIMAL_SCENE with Cornell's white reflectance and light emission as spectra."""
    s = DATA["spectra"]
    text = MINIMAL_SCENE.replace("reflectance = [0.8, 0.8, 0.8]", 'reflectance = { spectrum = "white" }')
    text = text.replace("emitter = { radiance = [10, 10, 10] }", 'emitter = { radiance = { spectrum = "light" } }')
    return text + f"""
[colour]
observer = "CIE1931_2"
output = "linear_srgb_d65"
rgb_convention = "{convention}"
{light_line}

[spectra.white]
wavelengths_nm = {_toml_list(s["wavelengths_nm"])}
values = {_toml_list(s["white_reflectance"])}

[spectra.light]
wavelengths_nm = {_toml_list(s["light_emission"]["wavelengths_nm"])}
values = {_toml_list(s["light_emission"]["values"])}
{extra}"""


@pytest.mark.parametrize("convention", [ILLUMINANT_E, SCENE_LIGHT])
def test_a_spectral_scene_holds_the_projection_and_the_spectra(write_scene, convention):
    scene = load_scene(write_scene(spectral_scene(convention)))
    light = LIGHT if convention == SCENE_LIGHT else None
    assert scene.materials["white"].reflectance == reflectance_rgb(MEASURED["white"], convention, light)
    assert scene.meshes[1].radiance == emission_rgb(LIGHT)
    assert scene.spectral.rgb_convention == convention  # what a run reports
    assert scene.spectral.reflectance("white") == MEASURED["white"]
    assert scene.spectral.emission("light") == LIGHT and scene.spectral.emission("floor") is None


def test_spectral_content_enters_the_hash_only_when_present(write_scene):
    e = load_scene(write_scene(spectral_scene(ILLUMINANT_E), "e.toml"))
    scene_light = load_scene(write_scene(spectral_scene(SCENE_LIGHT), "l.toml"))
    assert e.content_hash() != scene_light.content_hash()
    # An unused spectrum does not change it; the same RGB values written as RGB do (no spectral content).
    unused = spectral_scene(ILLUMINANT_E, extra="\n[spectra.spare]\nwavelengths_nm = [400, 700]\nvalues = [1, 1]\n")
    assert load_scene(write_scene(unused, "u.toml")).content_hash() == e.content_hash()
    rgb = MINIMAL_SCENE.replace("[0.8, 0.8, 0.8]", _toml_list(e.materials["white"].reflectance)).replace(
        "[10, 10, 10]", _toml_list(e.meshes[1].radiance))
    as_rgb = load_scene(write_scene(rgb, "rgb.toml"))
    assert as_rgb.materials == e.materials and as_rgb.spectral is None
    assert as_rgb.content_hash() != e.content_hash()


def test_every_stored_scene_keeps_its_stored_hash():
    """RGB scenes hash as before: each stored reference's scene_hash still matches its scene (all RGB but the
    spectral cornell-box-measured)."""
    stored = sorted((ROOT / "src" / "cornell_harness" / "references").glob("*/provenance.json"))
    assert len(stored) >= 5
    for provenance in stored:
        scene = load_scene(provenance.parent / "scene.toml")
        assert (scene.spectral is None) == (scene.name != "cornell-box-measured"), scene.name
        assert scene.content_hash() == json.loads(provenance.read_text())["scene_hash"], provenance.parent.name


def test_an_rgb_scene_loads_without_colour_science():
    code = ("import sys; from cornell_harness.scenes.library import resolve_scene; resolve_scene('cornell-box'); "
            "print('colour' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "False"


@pytest.mark.parametrize("old, new, field, message", [
    ('wavelengths_nm = [400.0, 500.0', 'wavelengths_nm = [500.0, 400.0', "spectra.light.wavelengths_nm[1]",
     "strictly increasing"),
    ("values = [0.0, 8.0, 15.6, 18.4]", "values = [0.0, 8.0, 15.6]", "spectra.light.values", "one value per"),
    ("values = [0.0, 8.0, 15.6, 18.4]", "values = [0.0, -8.0, 15.6, 18.4]", "spectra.light.values[1]",
     "must be in [0, inf]"),
    ("values = [0.0, 8.0, 15.6, 18.4]", 'values = [0.0, "8", 15.6, 18.4]', "spectra.light.values[1]",
     "expected a number"),
    ('{ spectrum = "white" }', '{ spectrum = "whit" }', "materials.white.reflectance.spectrum", "did you mean 'white'"),
    ('{ spectrum = "white" }', '{ spectra = "white" }', "materials.white.reflectance.spectra", "unknown key"),
    ('rgb_convention = "illuminant_E"', 'rgb_convention = "illuminant_e"', "colour.rgb_convention",
     "did you mean 'illuminant_E'"),
    ('observer = "CIE1931_2"', 'observer = "CIE1964_10"', "colour.observer", "unknown value"),
    ('light = "light"', 'light = "white"', "colour.light", "no emitter's radiance"),
    ('[spectra.light]', '[spectra.light]\nextrapolation = "linear"', "spectra.light.extrapolation", "known: zero"),
])
def test_errors_name_the_file_and_field(write_scene, old, new, field, message):
    text = spectral_scene()
    assert old in text, old
    path = write_scene(text.replace(old, new, 1))
    with pytest.raises(SceneError) as e:
        load_scene(path)
    assert e.value.field == field and message in e.value.message, str(e.value)
    assert str(e.value).startswith(f"{path}: {field}: ")


def test_reflectance_above_one_and_missing_pipeline_are_refused(write_scene):
    text = spectral_scene().replace(_toml_list(DATA["spectra"]["white_reflectance"]),
                                    _toml_list([1.5] + DATA["spectra"]["white_reflectance"][1:]))
    with pytest.raises(SceneError, match=r"spectra\.white\.values\[0\]: a reflectance .* must be in \[0, 1\]"):
        load_scene(write_scene(text, "a.toml"))
    no_colour = spectral_scene().split("[colour]")[0]
    with pytest.raises(SceneError, match=r"materials\.white\.reflectance: a spectral value needs .*\[colour\]"):
        load_scene(write_scene(no_colour, "b.toml"))
    with pytest.raises(SceneError, match=r"colour\.light: missing required field"):
        load_scene(write_scene(spectral_scene(SCENE_LIGHT, light_line=""), "c.toml"))



def _with_sample(text: str, spectrum: str, index: int, value: float) -> str:
    """``text`` with sample ``index`` of Cornell's ``spectrum`` (``white_reflectance``, ``light_emission``) set."""
    values = DATA["spectra"][spectrum]
    values = values["values"] if isinstance(values, dict) else values
    assert _toml_list(values) in text
    return text.replace(_toml_list(values), _toml_list(values[:index] + [value] + values[index + 1:]), 1)


NEGATIVE_SAMPLES = [("light_emission", 2, -15.6, "spectra.light.values[2]", "an emission (colour.light) must be in "
                     "[0, inf], got -15.6"),
                    ("white_reflectance", 0, -0.1, "spectra.white.values[0]", "a reflectance "
                     "(materials.white.reflectance) must be in [0, 1], got -0.1")]


@pytest.mark.parametrize("convention", [ILLUMINANT_E, SCENE_LIGHT])
@pytest.mark.parametrize("spectrum, index, value, field, message", NEGATIVE_SAMPLES)
def test_a_negative_sample_is_refused_as_itself(write_scene, convention, spectrum, index, value, field, message):
    """A negative sample is named with its spectrum and index in either convention. Under scene_light the
    reflectances are white-balanced to the light, and a negative light sample used to surface as a light whose
    colour is not positive (field colour.light), not as the sample it is."""
    path = write_scene(_with_sample(spectral_scene(convention), spectrum, index, value))
    with pytest.raises(SceneError) as e:
        load_scene(path)
    assert str(e.value) == f"{path}: {field}: {message}"


@pytest.mark.parametrize("command", [["render", "-r", "pathtracer", "-o", "x.exr"], ["compare", "-r", "pathtracer"]])
def test_a_negative_sample_is_one_line_exit_2_from_the_cli(write_scene, capsys, tmp_path, monkeypatch, command):
    monkeypatch.chdir(tmp_path)
    path = write_scene(_with_sample(spectral_scene(SCENE_LIGHT), "light_emission", 1, -8.0))
    code, out, err = cbox_in_process(capsys, command[0], "--scene", str(path), *command[1:])
    assert code == 2 and err.splitlines() == [f"cbox: error: {path}: spectra.light.values[1]: an emission "
                                              "(colour.light) must be in [0, inf], got -8.0"], err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.toml"]  # refused before anything ran

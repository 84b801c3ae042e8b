"""The pbrt-v4 export, parsed back by a strict tokenizer and checked against pbrt-v4's own names and types.

pbrt-v4 is not installed here, so the file is read as pbrt-v4's parser reads it (``src/pbrt/parser.cpp``:
quoted strings, ``[`` ``]``, ``#`` comments, bare numbers and ``true``/``false``; a parameter is
``"TYPE NAME" value`` or ``"TYPE NAME" [ values ]``), and every directive, plugin, parameter name and type
is checked against :data:`PBRT_V4`, a table built from pbrt-v4's source (github.com/mmp/pbrt-v4, commit
5f7a606806a4ac7b939131ded9d7a30ebd02416e) and its file-format reference (https://pbrt.org/fileformat-v4).
pbrt-v4 stops with an error on a parameter a plugin does not read ("unused parameter"), so a name that is
not in the table would fail there too. Where each entry comes from:

- directives: ``parser.cpp`` ``parse()``; ``WorldBegin`` resets the transform (``scene.cpp``
  ``BasicSceneBuilder::WorldBegin``);
- ``Film "rgb"``: ``film.cpp`` ``FilmBaseParameters`` (``xresolution``, ``yresolution``, ``filename``),
  ``RGBFilm::Create`` (``savefp16``, ``maxcomponentvalue``), ``PixelSensor::Create`` (``iso``,
  ``whitebalance``, ``sensor``);
- ``PixelFilter "box"``: ``filters.cpp`` ``BoxFilter::Create`` (``xradius``, ``yradius``, default 0.5);
- ``Sampler "independent"``: ``samplers.cpp`` ``IndependentSampler::Create`` (``pixelsamples``, ``seed``);
- ``Integrator "path"``: ``cpu/integrators.cpp`` ``PathIntegrator::Create`` (``maxdepth``, ``lightsampler``,
  ``regularize``);
- ``Camera "perspective"``: ``cameras.cpp`` ``PerspectiveCamera::Create`` (``fov``, ``lensradius``,
  ``focaldistance``, ``frameaspectratio``, ``screenwindow``);
- ``Material``: ``materials.cpp`` ``DiffuseMaterial::Create`` (``reflectance``),
  ``ConductorMaterial::Create`` (``eta``, ``k``, ``reflectance``, roughness), ``DielectricMaterial::Create``
  (``eta`` a float or a spectrum, roughness);
- ``AreaLightSource "diffuse"``: ``lights.cpp`` ``DiffuseAreaLight::Create`` (``L``, ``scale``,
  ``twosided``, ``filename``, ``power``);
- ``Shape``: ``shapes.cpp`` ``Sphere::Create`` (``radius``, ``zmin``, ``zmax``, ``phimax``) and
  ``Triangle::CreateMesh`` (``P``, ``indices``, ``uv``, ``S``, ``N``, ``faceIndices``);
- value types: ``paramdict.cpp`` (``bool``, ``float``, ``integer``, ``point2``, ``point3``, ``vector3``,
  ``normal``, ``string``; a spectrum is ``rgb``, ``spectrum`` or ``blackbody``; a texture parameter
  also ``texture``); integers are 32-bit (``parser.cpp`` ``parseInt``).

The camera is checked by casting pbrt-v4's camera rays (``util/transform.cpp`` ``LookAt``,
``cameras.h`` ``ProjectiveCamera``) from the parsed file and comparing them with ours.
"""

from __future__ import annotations

import dataclasses
import math
import re
from dataclasses import dataclass, field

import numpy as np
import pytest

from cornell_harness.scenes.export import export_scene, mapping_table
from cornell_harness.scenes.export import pbrt_v4
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror
from cornell_harness.scenes.model import Camera, SceneError

SPECTRUM = {"rgb", "spectrum", "blackbody"}
SPECTRUM_TEXTURE = SPECTRUM | {"texture"}
FLOAT_TEXTURE = {"float", "texture"}

#: pbrt-v4's plugins and the parameters each reads: {directive: {plugin: {name: allowed types}}}.
PBRT_V4: dict[str, dict[str, dict[str, set[str]]]] = {
    "Film": {"rgb": {"xresolution": {"integer"}, "yresolution": {"integer"}, "filename": {"string"},
                     "savefp16": {"bool"}, "maxcomponentvalue": {"float"}, "iso": {"float"},
                     "whitebalance": {"float"}, "sensor": {"string"}, "cropwindow": {"float"},
                     "pixelbounds": {"integer"}, "diagonal": {"float"}}},
    "PixelFilter": {"box": {"xradius": {"float"}, "yradius": {"float"}}},
    "Sampler": {"independent": {"pixelsamples": {"integer"}, "seed": {"integer"}}},
    "Integrator": {"path": {"maxdepth": {"integer"}, "lightsampler": {"string"}, "regularize": {"bool"}}},
    "Camera": {"perspective": {"fov": {"float"}, "lensradius": {"float"}, "focaldistance": {"float"},
                               "frameaspectratio": {"float"}, "screenwindow": {"float"},
                               "shutteropen": {"float"}, "shutterclose": {"float"}}},
    "Material": {
        "diffuse": {"reflectance": SPECTRUM_TEXTURE, "displacement": FLOAT_TEXTURE},
        "conductor": {"eta": SPECTRUM_TEXTURE, "k": SPECTRUM_TEXTURE, "reflectance": SPECTRUM_TEXTURE,
                      "roughness": FLOAT_TEXTURE, "uroughness": FLOAT_TEXTURE, "vroughness": FLOAT_TEXTURE,
                      "remaproughness": {"bool"}, "displacement": FLOAT_TEXTURE},
        "dielectric": {"eta": {"float"} | SPECTRUM, "roughness": FLOAT_TEXTURE, "uroughness": FLOAT_TEXTURE,
                       "vroughness": FLOAT_TEXTURE, "remaproughness": {"bool"}, "displacement": FLOAT_TEXTURE},
    },
    "AreaLightSource": {"diffuse": {"L": SPECTRUM, "scale": {"float"}, "twosided": {"bool"},
                                    "filename": {"string"}, "power": {"float"}}},
    "Shape": {"trianglemesh": {"P": {"point3"}, "indices": {"integer"}, "uv": {"point2"}, "S": {"vector3"},
                               "N": {"normal"}, "faceIndices": {"integer"}},
              "sphere": {"radius": {"float"}, "zmin": {"float"}, "zmax": {"float"}, "phimax": {"float"}}},
}
#: Directives with a fixed count of numbers (parser.cpp), and those with no arguments.
TRANSFORMS = {"Scale": 3, "Translate": 3, "LookAt": 9}
BARE = {"WorldBegin", "AttributeBegin", "AttributeEnd"}
#: Directives allowed before WorldBegin only, and after it only (pbrt-v4's VERIFY_OPTIONS / VERIFY_WORLD).
OPTIONS = {"Film", "PixelFilter", "Sampler", "Integrator", "Camera"}
WORLD = {"Material", "AreaLightSource", "Shape", "AttributeBegin", "AttributeEnd"}
#: How many numbers one value of a type holds.
ARITY = {"float": 1, "integer": 1, "point2": 2, "point3": 3, "vector3": 3, "normal": 3, "rgb": 3}

TOKEN = re.compile(r'\s+|#[^\n]*|"[^"\n]*"|\[|\]|[^\s\[\]"#]+')
NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
INTEGER = re.compile(r"[+-]?\d+")


def tokens(text: str) -> list[str]:
    """pbrt-v4's tokens, comments dropped; anything the tokenizer cannot read fails."""
    out, pos = [], 0
    while pos < len(text):
        m = TOKEN.match(text, pos)
        assert m, f"untokenizable text at {pos}: {text[pos:pos + 40]!r}"
        if not (m.group().isspace() or m.group().startswith("#")):
            out.append(m.group())
        pos = m.end()
    return out


@dataclass
class Statement:
    directive: str
    plugin: str | None = None
    params: dict[str, tuple[str, list]] = field(default_factory=dict)  # name: (type, values)
    args: list[float] = field(default_factory=list)


def value(token: str, kind: str):
    if kind == "string":
        assert token.startswith('"'), f"string value not quoted: {token}"
        return token[1:-1]
    if kind == "bool":
        assert token in ("true", "false"), f"bool value {token}"
        return token == "true"
    if kind == "integer":
        assert INTEGER.fullmatch(token), f"integer value {token}"
        assert -2**31 <= int(token) < 2**31, f"integer {token} is not 32-bit"
        return int(token)
    assert NUMBER.fullmatch(token), f"{kind} value {token} is not a number"
    return float(token)


def parse(text: str) -> list[Statement]:
    """The statements of a pbrt-v4 file, every name and type checked against :data:`PBRT_V4`."""
    toks, i, out = tokens(text), 0, []
    while i < len(toks):
        d = toks[i]
        i += 1
        if d in BARE:
            out.append(Statement(d))
        elif d in TRANSFORMS:
            n = TRANSFORMS[d]
            out.append(Statement(d, args=[value(t, "float") for t in toks[i:i + n]]))
            assert len(out[-1].args) == n, d
            i += n
        elif d in PBRT_V4:
            plugin = value(toks[i], "string")
            assert plugin in PBRT_V4[d], f"{d} {plugin!r}: not a pbrt-v4 plugin here"
            st, i = Statement(d, plugin), i + 1
            while i < len(toks) and toks[i].startswith('"'):
                kind, _, name = value(toks[i], "string").partition(" ")
                allowed = PBRT_V4[d][plugin]
                assert name in allowed, f"{d} {plugin!r}: pbrt-v4 reads no parameter {name!r}"
                assert kind in allowed[name], f"{d} {plugin!r} {name!r}: type {kind}, pbrt-v4 takes {allowed[name]}"
                assert name not in st.params, f"{d} {plugin!r}: {name!r} twice"
                i += 1
                if toks[i] == "[":
                    end = toks.index("]", i)
                    vals, i = [value(t, kind) for t in toks[i + 1:end]], end + 1
                else:
                    vals, i = [value(toks[i], kind)], i + 1
                assert vals and len(vals) % ARITY.get(kind, 1) == 0, f"{d} {name!r}: {len(vals)} values of {kind}"
                st.params[name] = (kind, vals)
            out.append(st)
        else:
            raise AssertionError(f"unknown directive {d!r}")
    return out


def check_structure(statements: list[Statement]) -> None:
    names = [s.directive for s in statements]
    assert names.count("WorldBegin") == 1
    world = names.index("WorldBegin")
    assert all(n not in WORLD for n in names[:world]) and all(n not in OPTIONS for n in names[world + 1:])
    assert {"Film", "Camera", "Sampler", "Integrator", "PixelFilter"} <= set(names[:world])
    assert names[names.index("Camera") - 2:names.index("Camera")] == ["Scale", "LookAt"]
    depth = 0
    for n in names:
        depth += (n == "AttributeBegin") - (n == "AttributeEnd")
        assert depth in (0, 1)
    assert depth == 0


def blocks(statements: list[Statement]) -> list[list[Statement]]:
    """The statements of each AttributeBegin/AttributeEnd block."""
    out, cur = [], None
    for s in statements:
        if s.directive == "AttributeBegin":
            cur = []
        elif s.directive == "AttributeEnd":
            out.append(cur)
            cur = None
        elif cur is not None:
            cur.append(s)
    return out


def one(block: list[Statement], directive: str) -> Statement | None:
    found = [s for s in block if s.directive == directive]
    assert len(found) <= 1
    return found[0] if found else None


def vals(st: Statement, name: str) -> list:
    return st.params[name][1]


def check_material(st: Statement, material) -> None:
    if isinstance(material, Diffuse):
        assert st.plugin == "diffuse" and vals(st, "reflectance") == list(material.reflectance)
    elif isinstance(material, Mirror):
        assert st.plugin == "conductor" and vals(st, "reflectance") == list(material.reflectance)
        assert set(st.params) == {"reflectance"}  # no eta/k: pbrt-v4 refuses both with reflectance
    else:
        assert isinstance(material, Dielectric)
        assert st.plugin == "dielectric" and vals(st, "eta") == [material.int_ior / material.ext_ior]


@pytest.mark.parametrize("name", ["cornell-box", "cornell-box-caustics", "two-rooms", "light-panel"])
def test_the_export_parses_as_pbrt_v4_and_holds_the_scene(tmp_path, name):
    scene = resolve_scene(name)
    statements = parse(export_scene(scene, "pbrt-v4", tmp_path).read_text(encoding="utf-8"))
    check_structure(statements)
    top = {s.directive: s for s in statements if s.directive in OPTIONS}
    film = top["Film"]
    assert (vals(film, "xresolution"), vals(film, "yresolution")) == ([scene.camera.width], [scene.camera.height])
    assert vals(film, "savefp16") == [False]
    assert vals(top["PixelFilter"], "xradius") == vals(top["PixelFilter"], "yradius") == [0.5]
    assert vals(top["Integrator"], "maxdepth") == [pbrt_v4.maxdepth(scene.max_depth)]
    shapes = blocks(statements)
    assert len(shapes) == len(scene.meshes) + len(scene.spheres)
    for block, mesh in zip(shapes, scene.meshes):  # meshes first, in order: every vertex as the scene has it
        shape = one(block, "Shape")
        assert shape.plugin == "trianglemesh"
        np.testing.assert_array_equal(np.reshape(vals(shape, "P"), (-1, 3)), mesh.vertices)
        np.testing.assert_array_equal(np.reshape(vals(shape, "indices"), (-1, 3)), mesh.triangles)
        check_material(one(block, "Material"), scene.materials[mesh.material])
        light = one(block, "AreaLightSource")
        assert (light is None) == (not mesh.is_emitter)
        if light is not None:
            assert vals(light, "L") == list(mesh.radiance) and "twosided" not in light.params  # one-sided default
    for block, sphere in zip(shapes[len(scene.meshes):], scene.spheres):
        shape, move = one(block, "Shape"), one(block, "Translate")
        assert shape.plugin == "sphere" and vals(shape, "radius") == [sphere.radius]
        assert move.args == list(sphere.center) and block.index(move) < block.index(shape)
        check_material(one(block, "Material"), scene.materials[sphere.material])


def pbrt_camera_directions(statements: list[Statement], width: int, height: int, cols, rows) -> np.ndarray:
    """World directions of pbrt-v4's camera rays through raster points (cols, rows), from the parsed file.

    ``CTM = Scale · LookAt`` (cameraFromWorld); pbrt-v4's ``LookAt`` (util/transform.cpp) has columns
    right = up × dir, newUp = dir × right, dir; ``ProjectiveCamera`` maps raster to the screen window
    ([-1, 1] on the shorter axis, [-aspect, aspect] on the other; y flipped) and the perspective
    projection divides by tan(fov / 2).
    """
    by = {s.directive: s for s in statements}
    scale = np.diag(by["Scale"].args + [1.0])
    pos, look, up = np.reshape(by["LookAt"].args, (3, 3))
    d = (look - pos) / np.linalg.norm(look - pos)
    right = np.cross(up / np.linalg.norm(up), d)
    right /= np.linalg.norm(right)
    world_from_camera = np.eye(4)
    world_from_camera[:3, :3] = np.column_stack([right, np.cross(d, right), d])
    world_from_camera[:3, 3] = pos
    camera_from_world = scale @ np.linalg.inv(world_from_camera)
    frame = width / height
    (x0, x1), (y0, y1) = ((-frame, frame), (-1, 1)) if frame > 1 else ((-1, 1), (-1 / frame, 1 / frame))
    t = math.tan(math.radians(vals(by["Camera"], "fov")[0]) / 2)
    sx = x0 + np.asarray(cols) / width * (x1 - x0)
    sy = y1 - np.asarray(rows) / height * (y1 - y0)
    cam = np.stack([sx * t, sy * t, np.ones_like(sx), np.zeros_like(sx)], axis=-1)
    return (cam @ np.linalg.inv(camera_from_world).T)[..., :3]


@pytest.mark.parametrize("width, height", [(48, 32), (32, 48), (40, 40)])
@pytest.mark.parametrize("axis", ["x", "y", "smaller", "larger"])
def test_pbrt_v4_camera_rays_are_ours(tmp_path, width, height, axis):
    """fov axis and handedness: pbrt-v4's rays through the image corners and centre are our camera's."""
    cam = Camera(position=(0.3, 0.2, 3.5), look_at=(-0.1, 0.1, 0.0), up=(0.1, 1.0, 0.0), fov_deg=41.0,
                 fov_axis=axis, width=width, height=height)
    scene = dataclasses.replace(resolve_scene("cornell-box"), camera=cam)
    statements = parse(export_scene(scene, "pbrt-v4", tmp_path).read_text(encoding="utf-8"))
    cols, rows = np.array([0.0, width, 0.0, width, width / 2, 3.5]), np.array([0.0, 0.0, height, height, height / 2, 7.25])
    theirs = pbrt_camera_directions(statements, width, height, cols, rows)
    ours = cam.directions(cols, rows)
    theirs /= np.linalg.norm(theirs, axis=-1, keepdims=True)
    ours /= np.linalg.norm(ours, axis=-1, keepdims=True)
    np.testing.assert_allclose(theirs, ours, atol=1e-12)
    # without the Scale -1 1 1 the image would be mirrored: the check has the power to see it
    mirrored = [s for s in statements if s.directive != "Scale"]
    mirrored.insert(0, Statement("Scale", args=[1.0, 1.0, 1.0]))
    assert not np.allclose(pbrt_camera_directions(mirrored, width, height, cols[:1], rows[:1]), theirs[:1])


@pytest.mark.parametrize("ours, theirs", [(1, 0), (2, 1), (3, 2), (-1, pbrt_v4.UNBOUNDED_MAXDEPTH)])
def test_max_depth_counts_bounces_in_pbrt_v4(ours, theirs):
    assert pbrt_v4.maxdepth(ours) == theirs


def test_the_mirror_row_states_pbrt_v4s_conductor_fresnel():
    """pbrt-v4's conductor of reflectance R: R at normal incidence, 1 at grazing, less than R in between (R = 0.95)."""
    assert pbrt_v4.conductor_reflectance(0.95, 1.0) == pytest.approx(0.95, abs=1e-12)
    assert pbrt_v4.conductor_reflectance(0.95, 0.0) == pytest.approx(1.0, abs=1e-12)
    assert pbrt_v4.conductor_reflectance(0.95, math.cos(math.radians(75))) < 0.92
    assert "0.915 at 75°" in mapping_table("pbrt-v4")


def test_a_misnamed_parameter_fails_the_parser():
    with pytest.raises(AssertionError, match="reads no parameter 'maxdepht'"):
        parse('Integrator "path" "integer maxdepht" [ 5 ]')
    with pytest.raises(AssertionError, match="type float"):
        parse('Integrator "path" "float maxdepth" [ 5 ]')
    with pytest.raises(AssertionError, match="not 32-bit"):
        parse('Integrator "path" "integer maxdepth" [ 2147483648 ]')


def test_an_ambient_occlusion_scene_is_refused(tmp_path):
    with pytest.raises(SceneError, match="quantity"):
        export_scene(resolve_scene("cornell-box-ao"), "pbrt-v4", tmp_path)


def pbrt_spectrum(values: list[float]):
    """pbrt-v4's inline ``"spectrum"`` (paramdict.cpp, a ``PiecewiseLinearSpectrum``: linear between its samples,
    zero outside them, util/spectrum.cpp) as a function of wavelength; wavelengths strictly increasing."""
    lam, v = np.asarray(values[0::2]), np.asarray(values[1::2])
    assert np.all(np.diff(lam) > 0), "pbrt-v4 stops at wavelengths that are not increasing"
    return lambda at: np.interp(at, lam, v, left=0.0, right=0.0)


def test_a_spectral_scene_writes_its_spectra_and_undoes_pbrt_v4s_light_normalisation(tmp_path):
    """cornell-box-measured: every reflectance and the light as ``"spectrum"`` [λ v ...], read as pbrt-v4 reads
    them, equal the scene's spectra (its extrapolation included: explicit zero ends, the flat surface padded to
    360-830 nm); and the light's ``"float scale"``, recomputed here from colour-science's CIE 1931 tables, makes
    pbrt-v4's image of the light our emission RGB: pbrt-v4 divides L by Σ L ȳ (SpectrumToPhotometric, 1 nm sums
    over 360-830 nm) and its cie1931 sensor's XYZ is ∫ L x̄ (film.h, no division by ∫ ȳ)."""
    import colour

    from cornell_harness.scenes.spectra import emission_rgb

    scene = resolve_scene("cornell-box-measured")
    statements = parse(export_scene(scene, "pbrt-v4", tmp_path).read_text(encoding="utf-8"))
    check_structure(statements)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    grid, xyz_bar = np.asarray(cmfs.wavelengths), np.asarray(cmfs.values)
    assert (grid[0], grid[-1]) == pbrt_v4.LAMBDA_RANGE_NM  # pbrt-v4's Lambda_min, Lambda_max
    fine = np.linspace(360.0, 830.0, 47001)  # where pbrt-v4 samples, every 0.01 nm: the zero ends are 1e-3 nm ramps
    lights = 0
    for block, mesh in zip(blocks(statements), scene.meshes):
        material = one(block, "Material")
        kind, written = material.params["reflectance"]
        expected = scene.spectral.reflectance(mesh.material)
        assert kind == "spectrum" and expected is not None
        np.testing.assert_array_equal(pbrt_spectrum(written)(fine), expected.at(fine))
        if expected.extrapolation == "constant":
            assert (written[0], written[-2]) == pbrt_v4.LAMBDA_RANGE_NM
        else:  # zero outside: written as an explicit zero beyond each non-zero end
            assert (written[1], written[-1]) == (0.0, 0.0)
        light = one(block, "AreaLightSource")
        if light is None:
            continue
        lights += 1
        kind, written = light.params["L"]
        emission = scene.spectral.emission(mesh.name)
        assert kind == "spectrum" and written[-1] == 0.0 and written[-2] == 700.0 + pbrt_v4.ZERO_STEP_NM
        L = pbrt_spectrum(written)
        np.testing.assert_array_equal(L(grid), emission.at(grid))
        (scale,) = vals(light, "scale")
        assert scale == pytest.approx(float(emission.at(grid) @ xyz_bar[:, 1] / xyz_bar[:, 1].sum()), rel=1e-12)
        photometric = L(grid) @ xyz_bar[:, 1]  # SpectrumToPhotometric(L)
        xyz = scale / photometric * (L(grid) @ xyz_bar)  # what the film sees of the light, ∫ as a 1 nm sum
        rgb = np.asarray(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB) @ xyz
        np.testing.assert_allclose(rgb, emission_rgb(emission), rtol=1e-9)
        assert abs(xyz[1] / scale - 1.0) < 1e-12 and scale > 10  # without the scale the light would be 1 nit: 12x dim
    assert lights == 1


def test_a_zero_extrapolated_spectrum_gets_explicit_zero_ends_only_where_it_is_not_zero():
    from cornell_harness.scenes.spectra import Spectrum

    step = pbrt_v4.ZERO_STEP_NM
    written = pbrt_v4.spectrum_values(Spectrum((400.0, 500.0, 600.0), (0.0, 1.0, 2.0)))
    assert written == f"[ 400.0 0.0 500.0 1.0 600.0 2.0 {600.0 + step!r} 0.0 ]"
    written = pbrt_v4.spectrum_values(Spectrum((400.0, 500.0), (3.0, 0.0)))
    assert written == f"[ {400.0 - step!r} 0.0 400.0 3.0 500.0 0.0 ]"
    assert pbrt_v4.spectrum_values(Spectrum((400.0, 500.0), (3.0, 4.0), "constant")) == (
        "[ 360.0 3.0 400.0 3.0 500.0 4.0 830.0 4.0 ]")

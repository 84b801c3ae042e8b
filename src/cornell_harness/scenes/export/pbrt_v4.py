"""pbrt-v4: a scene written in pbrt-v4's text scene format (``scene.pbrt``), for ``pbrt scene.pbrt``.

Every directive and parameter is pbrt-v4's own (its ``src/pbrt/`` ``parser.cpp``, ``scene.cpp``,
``cameras.cpp``, ``film.cpp``, ``filters.cpp``, ``samplers.cpp``, ``cpu/integrators.cpp``,
``materials.cpp``, ``lights.cpp``, ``shapes.cpp``); ``tests/scenes/test_export_pbrt_v4.py`` parses
the file back and checks each name and type against that table. pbrt-v4 is not installed here, so
the file is checked, not rendered. How each aspect of a scene is written, and where pbrt-v4 differs
from our model (two-sided BSDFs, a mirror's Fresnel, spectral colour), is :data:`MAPPING`.

A scene with spectra (``Scene.spectral``) is written with the sampled spectra themselves: ``"spectrum
reflectance" [ λ v ... ]`` and ``"spectrum L" [ λ v ... ]`` (:func:`spectrum_values`), the light with the
``"float scale"`` (:func:`light_scale`) that undoes pbrt-v4's photometric normalisation of ``L``
(``lights.cpp``, ``DiffuseAreaLight::Create``: ``scale /= SpectrumToPhotometric(L)``), so that its ``rgb``
film's XYZ of the light, ∫ L x̄ dλ with no normalisation of its own, is our
:func:`cornell_harness.scenes.spectra.emission_rgb`'s ``Σ L x̄ / Σ ȳ``.

Numbers are written as Python's shortest round-trip text of the scene's float64 values (pbrt-v4
reads them with ``strtod``, then stores float32). The sample count can be changed with
``pbrt --spp N``, the seed with ``pbrt --seed S`` (the file names none, so the sampler takes it).
"""

from __future__ import annotations

import cmath
import math
from pathlib import Path

import numpy as np

from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror
from cornell_harness.scenes.model import Mesh, Scene, one_line
from cornell_harness.scenes.spectra import Spectrum, luminance, written_samples

NAME = "pbrt-v4"
FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                      "pinhole_camera", "box_filter"})

#: Samples per pixel the file gives (``pbrt --spp N`` overrides).
DEFAULT_SPP = 64
#: pbrt-v4's ``maxdepth`` for our unbounded ``max_depth = -1``: pbrt-v4 has no unbounded setting, and its
#: integers are 32-bit; Russian roulette ends paths long before.
UNBOUNDED_MAXDEPTH = 2**31 - 2
#: pbrt-v4 clamps a conductor's ``reflectance`` to this (materials.h, ConductorMaterial::GetBxDF).
CONDUCTOR_MAX_REFLECTANCE = 0.9999
#: pbrt-v4 samples wavelengths in [Lambda_min, Lambda_max] (util/spectrum.h), nm.
LAMBDA_RANGE_NM = (360.0, 830.0)
#: How far beyond a spectrum's last sample its explicit zero is written (``extrapolation = "zero"``), nm: pbrt-v4's
#: inline spectra are zero outside their samples already, but its spectrum files are extended with their end
#: values. The ramp this adds to a spectrum is an integral of (end value) · ZERO_STEP_NM / 2: 1e-6 of a flat one.
ZERO_STEP_NM = 1e-3


def maxdepth(max_depth: int) -> int:
    """pbrt-v4's ``maxdepth`` (bounces: 0 = emitters seen directly) for our ``max_depth`` (segments, Mitsuba's)."""
    return UNBOUNDED_MAXDEPTH if max_depth < 0 else max_depth - 1


def fov(scene: Scene) -> float:
    """pbrt-v4's ``fov`` in degrees: the angle across the image's shorter axis (cameras.cpp: the screen window
    is [-1, 1] along the shorter axis, [-aspect, aspect] along the other), whatever our ``fov_axis``."""
    tx, ty = scene.camera.tan_half_fov()
    return math.degrees(2.0 * math.atan(min(tx, ty)))


def conductor_reflectance(r: float, cos_theta: float) -> float:
    """The reflectance pbrt-v4 gives a ``conductor`` of ``reflectance`` r at incidence cos θ.

    pbrt-v4 turns r into a conductor of η = 1 + ik, k = 2√r/√(1 − r) (materials.h,
    ConductorMaterial::GetBxDF, r clamped to 0.9999): Fresnel reflectance (util/scattering.h,
    FrComplex) r at normal incidence, not elsewhere.
    """
    r = min(r, CONDUCTOR_MAX_REFLECTANCE)
    eta = complex(1.0, 2.0 * math.sqrt(r) / math.sqrt(1.0 - r))
    cos_t = cmath.sqrt(1.0 - (1.0 - cos_theta**2) / eta**2)
    r_parl = (eta * cos_theta - cos_t) / (eta * cos_theta + cos_t)
    r_perp = (cos_theta - eta * cos_t) / (cos_theta + eta * cos_t)
    return (abs(r_parl) ** 2 + abs(r_perp) ** 2) / 2.0


def _mirror_row() -> str:
    at = ", ".join(f"{conductor_reflectance(0.95, math.cos(math.radians(a))):.3f} at {a}°" for a in (45, 75, 85))
    return (f"`Material \"conductor\"` `\"rgb reflectance\"` R; pbrt-v4 makes it a conductor of η = 1 + ik, "
            f"k = 2√R/√(1 − R) (R clamped to {CONDUCTOR_MAX_REFLECTANCE}), whose reflectance is R at normal "
            f"incidence only: for R = 0.95, {at}, 1 at grazing. pbrt-v4 has no constant-reflectance mirror")


MAPPING = (
    ("units", "scene units", "the same (pbrt-v4 offsets rays by floating-point error bounds, at any scale)"),
    ("camera", "pinhole at `position` looking at `look_at`, `up`", "`LookAt` position look_at up, then "
                                                                   "`Camera \"perspective\"` (no near clip)"),
    ("fov axis", "`fov_deg` along `fov_axis` (x, y, smaller, larger)", "`\"float fov\"` is pbrt-v4's angle across "
                                                                       "the shorter image axis: converted, "
                                                                       "2·atan(tan(half-angle) along that axis)"),
    ("handedness", "right = forward × up; pixel (0, 0) top-left", "pbrt-v4's `LookAt` puts the image's right "
                                                                  "along up × forward, our left: `Scale -1 1 1` "
                                                                  "before it mirrors the camera (as pbrt-v4's "
                                                                  "own scenes do); `WorldBegin` resets the "
                                                                  "transform, so shapes are not mirrored"),
    ("geometry", "triangles, quads split (a, b, c), (a, c, d); spheres", "`Shape \"trianglemesh\"` "
                                                                         "(`point3 P`, `integer indices`, no "
                                                                         "normals: flat); `Shape \"sphere\"` "
                                                                         "(`float radius`) after `Translate`, "
                                                                         "in `AttributeBegin`/`AttributeEnd`"),
    ("emitter side", "front side only (counter-clockwise winding)", "`AreaLightSource \"diffuse\"` with "
                                                                    "`twosided` false (its default): emits on "
                                                                    "the side of the triangle's normal "
                                                                    "(p0 − p2) × (p1 − p2), the "
                                                                    "counter-clockwise one"),
    ("emitted radiance", "`radiance`, linear sRGB", "`\"rgb L\"`: pbrt-v4 multiplies it by sRGB's illuminant "
                                                     "(D65) normalised to luminance 1, which the `rgb` film's "
                                                     "default `cie1931` sensor (iso 100, exposure 1) maps back "
                                                     "to the same RGB"),
    ("spectral emitted radiance", "a spectrum L (`[spectra]`), whose colour is M · Σ L x̄ / Σ ȳ",
     "`\"spectrum L\" [ λ v ... ]` with `\"float scale\"` Y = Σ L ȳ / Σ ȳ: pbrt-v4 divides L by Σ L ȳ "
     "(`DiffuseAreaLight::Create`, `scale /= SpectrumToPhotometric(L)`, at 1 nm from 360 to 830 nm) and its "
     "`cie1931` sensor takes ∫ L x̄ without dividing by ∫ ȳ"),
    ("colour", "linear-sRGB RGB products; a spectral scene's sampled spectra",
     "RGB scenes: pbrt-v4 turns each RGB reflectance and emission into a spectrum (Jakob and Hanika's "
     "sigmoid fit; emission times D65); a product of spectra is not the product of their RGBs, so reflected "
     "colours differ from an RGB renderer's (ΔE00 below). Spectral scenes: `\"spectrum reflectance\" "
     "[ λ v ... ]`, the scene's samples; `extrapolation` \"zero\" written as a zero sample "
     f"{ZERO_STEP_NM:g} nm beyond each non-zero end, \"constant\" as the end values at 360 and 830 nm"),
    ("two-sidedness", "diffuse and mirror reflect on the front side only (black from behind); dielectric "
                      "both sides", "pbrt-v4's `diffuse` and `conductor` reflect on both sides and have no "
                                    "one-sided form: written two-sided, not refused. The image differs only "
                                    "where light paths meet a back face (in the Cornell box, the gap between "
                                    "the light's back and the ceiling); `dielectric` both sides, as ours"),
    ("mirror", "constant specular reflectance R, any angle", _mirror_row()),
    ("IOR", "`int_ior` inside, `ext_ior` outside, absolute", "`Material \"dielectric\"` `\"float eta\"` "
                                                             "int_ior / ext_ior: pbrt-v4's eta is relative "
                                                             "(inside over the normal's side); Fresnel, Snell "
                                                             "and the (η_i/η_t)² radiance scale depend on "
                                                             "the ratio only"),
    ("filter", "box: each pixel the mean over its own square", "`PixelFilter \"box\"` with `xradius` = "
                                                               "`yradius` = 0.5 pixel (its default): the "
                                                               "pixel's own square"),
    ("depth", "`max_depth` D path segments, -1 unbounded", f"`Integrator \"path\"` `\"integer maxdepth\"` "
                                                           f"D − 1 (pbrt-v4 counts bounces; 0 = emitters "
                                                           f"seen directly); -1: {UNBOUNDED_MAXDEPTH} "
                                                           f"(no unbounded setting; Russian roulette ends "
                                                           f"paths)"),
    ("samples", "spp, seed", f"`Sampler \"independent\"` `pixelsamples` {DEFAULT_SPP} (`pbrt --spp N`); "
                             f"no seed in the file: `pbrt --seed S`"),
    ("film", "float32 linear sRGB image", "`Film \"rgb\"` (sRGB), `filename` scene.exr, `savefp16` false "
                                          "(float32; pbrt-v4 writes half floats by default)"),
)


def _num(x) -> str:
    return repr(float(x))


def _nums(values) -> str:
    return "[ " + " ".join(_num(v) for v in np.ravel(values)) + " ]"


def _ints(values) -> str:
    return "[ " + " ".join(str(int(v)) for v in np.ravel(values)) + " ]"


def spectrum_values(spectrum: Spectrum) -> str:
    """A sampled spectrum as pbrt-v4's inline ``"spectrum"`` value ``[ λ v λ v ... ]``, its extrapolation written
    out (:func:`cornell_harness.scenes.spectra.written_samples`, :data:`ZERO_STEP_NM`)."""
    w, v = written_samples(spectrum, *LAMBDA_RANGE_NM, zero_step=ZERO_STEP_NM)
    return _nums([x for pair in zip(w, v) for x in pair])


def light_scale(emission: Spectrum) -> float:
    """The ``"float scale"`` of a ``"spectrum L"``: its luminance Y = Σ L ȳ / Σ ȳ. pbrt-v4 emits
    scale · L / Σ L ȳ (``SpectrumToPhotometric``, a sum at 1 nm over 360-830 nm) and its film's XYZ is the
    integral of that times x̄ȳz̄, so the light seen directly has XYZ Σ L x̄ / Σ ȳ, that of
    :func:`cornell_harness.scenes.spectra.emission_rgb`."""
    return luminance(emission)


def _colour(kind: str, rgb, spectrum: Spectrum | None) -> str:
    return f'"spectrum {kind}" {spectrum_values(spectrum)}' if spectrum is not None else f'"rgb {kind}" {_nums(rgb)}'


def emitter_line(scene: Scene, mesh: Mesh) -> str:
    """The ``AreaLightSource`` of an emitting mesh: RGB, or its emission spectrum with :func:`light_scale`."""
    spectrum = scene.spectral.emission(mesh.name) if scene.spectral is not None else None
    if spectrum is None:
        return f'AreaLightSource "diffuse" "rgb L" {_nums(mesh.radiance)}'
    return f'AreaLightSource "diffuse" "spectrum L" {spectrum_values(spectrum)} "float scale" [ {_num(light_scale(spectrum))} ]'


def material_lines(material, spectra: dict[str, Spectrum] | None = None) -> list[str]:
    """The ``Material`` directive of a scene material; ``spectra`` maps a field (``reflectance``) to its spectrum."""
    spectrum = (spectra or {}).get("reflectance")
    if isinstance(material, Diffuse):
        return [f'Material "diffuse" {_colour("reflectance", material.reflectance, spectrum)}']
    if isinstance(material, Mirror):
        return [f'Material "conductor" {_colour("reflectance", material.reflectance, spectrum)}']
    if isinstance(material, Dielectric):
        return [f'Material "dielectric" "float eta" [ {_num(material.eta)} ]']
    raise ValueError(f"material {material.name!r}: {type(material).__name__} has no pbrt-v4 translation")


def scene_text(scene: Scene, image: str = "scene.exr") -> str:
    """The whole ``scene.pbrt``: options, camera, then the world."""
    cam = scene.camera
    spectra = {m: scene.spectral.fields(m) for m in scene.materials} if scene.spectral is not None else {}
    lines = [
        f"# {one_line(scene.name)} ({scene.content_hash()}), exported by cornell-harness for pbrt-v4",
        f"# render: pbrt scene.pbrt [--spp N] [--seed S]   (writes {image})",
        f'Film "rgb" "integer xresolution" [ {cam.width} ] "integer yresolution" [ {cam.height} ]',
        f'    "string filename" [ "{image}" ] "bool savefp16" false',
        'PixelFilter "box" "float xradius" [ 0.5 ] "float yradius" [ 0.5 ]',
        f'Sampler "independent" "integer pixelsamples" [ {DEFAULT_SPP} ]',
        f'Integrator "path" "integer maxdepth" [ {maxdepth(scene.max_depth)} ]',
        "Scale -1 1 1",
        "LookAt " + "  ".join(" ".join(_num(c) for c in v) for v in (cam.position, cam.look_at, cam.up)),
        f'Camera "perspective" "float fov" [ {_num(fov(scene))} ]',
        "",
        "WorldBegin",
    ]
    for m in scene.meshes:
        lines += ["", f"# mesh {one_line(m.name)}", "AttributeBegin"]
        lines += ["    " + line for line in material_lines(scene.materials[m.material], spectra.get(m.material))]
        if m.is_emitter:
            lines.append("    " + emitter_line(scene, m))
        lines += [f'    Shape "trianglemesh" "point3 P" {_nums(m.vertices)}',
                  f'        "integer indices" {_ints(m.triangles)}', "AttributeEnd"]
    for s in scene.spheres:
        lines += ["", f"# sphere {one_line(s.name)}", "AttributeBegin", "    Translate " + " ".join(_num(c) for c in s.center)]
        lines += ["    " + line for line in material_lines(scene.materials[s.material], spectra.get(s.material))]
        lines += [f'    Shape "sphere" "float radius" [ {_num(s.radius)} ]', "AttributeEnd"]
    return "\n".join(lines) + "\n"


def write(scene: Scene, folder: Path) -> Path:
    """Write ``scene.pbrt`` into ``folder``; return its path."""
    path = Path(folder) / "scene.pbrt"
    path.write_text(scene_text(scene), encoding="utf-8")
    return path

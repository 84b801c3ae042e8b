"""Mitsuba 3: the one translation of a scene into Mitsuba's plugins, as dictionaries and as an XML file.

The Mitsuba adapter (``src/cornell_harness/renderers/mitsuba3.py``) loads these dictionaries with ``mi.load_dict``
(its meshes built in memory); :func:`write` writes the same dictionaries as a Mitsuba 3 XML
scene (``<scene version="3.0.0">``, Mitsuba's scene-file format, its documentation's "File
format" chapter) with each mesh a PLY file (:mod:`cornell_harness.scenes.export.ply`). Both first move
and scale the scene to the unit frame (:func:`cornell_harness.scenes.transforms.unit_frame`), so the
export renders bit for bit as the adapter does (``tests/scenes/test_export_mitsuba.py``).

A scene with spectra (``Scene.spectral``, :mod:`cornell_harness.scenes.spectral_scene`) is written
with the sampled spectra themselves, as ``irregular`` spectrum plugins (Mitsuba 3's
"Spectra" plugins: linear between samples, zero outside them, as our ``extrapolation =
"zero"``; a ``"constant"`` one gets end samples at :data:`SPECTRAL_RANGE_NM`), and must be
rendered with a ``*_spectral`` variant (``mitsuba -m llvm_ad_spectral``, or ``scalar_spectral``
without LLVM: :func:`render_command`, which ``cbox export`` prints); values the scene gives as RGB
stay ``rgb`` (which a spectral variant upsamples). A spectral variant's film normalises by its own
∫ȳ, 0.1% off colour-science's Σȳ (:func:`spectral_scale`): every emitter's radiance is written
multiplied by that factor, so the file renders on the scale of
:func:`cornell_harness.scenes.spectra.emission_rgb` and of the stored references, as the adapter does
with the same dictionaries. ``spectral=False`` writes the scene's RGB projection instead, for an RGB
variant.

The XML declares ``<default>``s for ``spp``, ``seed``, ``resx`` and ``resy``, so that

    mitsuba DIR/scene.xml -o out.exr -D spp=64 -D seed=3

renders it; ``mi.load_file(path, spp=64, seed=3)`` sets them from Python. ``seed`` is the
``independent`` sampler's seed, to which Mitsuba adds the seed ``mi.render`` is given (0 from
the ``mitsuba`` executable): the adapter's pass ``k`` of a render seeded ``s`` is this file
rendered with ``seed = pass_seed(s, k)`` (:mod:`cornell_harness.adapters.seeds`).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cornell_harness.scenes.export.ply import write_ply
from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror
from cornell_harness.scenes.model import Mesh, Scene, Sphere, one_line
from cornell_harness.scenes.spectra import Spectrum, observer, written_samples
from cornell_harness.scenes.transforms import unit_frame

NAME = "mitsuba"
FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                      "pinhole_camera", "box_filter"})
MAPPING = (
    ("units", "scene units", "moved and scaled so the bounding box is centred on the origin with diagonal 1 "
                             "(as the adapter renders; radiance is unchanged by a change of units)"),
    ("camera", "pinhole at `position` looking at `look_at`, `up`", "`perspective` sensor, `to_world` "
                                                                   "`<lookat origin target up>`"),
    ("fov axis", "`fov_deg` along `fov_axis` (x, y, smaller, larger)", "`fov` and `fov_axis`, the same values"),
    ("handedness", "right = forward × up; pixel (0, 0) top-left", "the same (Mitsuba's own convention)"),
    ("geometry", "triangles, quads split (a, b, c), (a, c, d); spheres", "`ply` shapes (float32 vertices, "
                                                                         "`face_normals` true: flat, as ours); "
                                                                         "`sphere` (`center`, `radius`)"),
    ("emitter side", "front side only (counter-clockwise winding)", "`area` emitter (`rgb` `radiance`): emits on "
                                                                    "the face normal's side only"),
    ("emitted radiance", "`radiance`, linear sRGB; or a spectrum L", "`radiance` as given; in a spectral export "
                                                                      "every emitter's values times "
                                                                      "1 / (MI_CIE_Y_NORMALIZATION · Σȳ) "
                                                                      "≈ 0.99900, which puts the spectral "
                                                                      "film's ∫ȳ normalisation on "
                                                                      "colour-science's Σȳ"),
    ("two-sidedness", "diffuse and mirror reflect on the front side only; dielectric both sides",
     "`diffuse` and `conductor` are one-sided (black from behind); `dielectric` both sides"),
    ("mirror", "constant specular reflectance R", "`conductor` with `material` none (Fresnel factor 1) and "
                                                  "`specular_reflectance` R"),
    ("colour", "RGB values (linear sRGB); a spectral scene's sampled spectra",
     "`rgb`; spectra as `irregular` spectrum plugins, for a `*_spectral` variant (`mitsuba -m llvm_ad_spectral`, "
     "which `cbox export` prints; an RGB variant stops at `IrregularSpectrum::eval(): not implemented`)"),
    ("IOR", "`int_ior` inside, `ext_ior` outside, absolute", "`dielectric` `int_ior`, `ext_ior`"),
    ("filter", "box: each pixel the mean over its own square", "`hdrfilm` (rgb, float32) with `rfilter` box"),
    ("depth", "`max_depth` path segments, -1 unbounded", "`path` `max_depth`, the same number (our convention "
                                                         "is Mitsuba's; Russian roulette from depth 5)"),
    ("samples", "spp, seed", "`independent` sampler, `sample_count` $spp, `seed` $seed (defaults in the file)"),
)

#: The ``<default>`` values an exported file declares besides the resolution: ``-D spp=...`` overrides.
DEFAULT_SPP = 64
DEFAULT_SEED = 0
#: Mitsuba's spectral variants sample wavelengths in this range (``MI_CIE_MIN``, ``MI_CIE_MAX``), nm.
SPECTRAL_RANGE_NM = (360.0, 830.0)
#: Mitsuba 3.9.1's ``MI_CIE_Y_NORMALIZATION`` (1 / 106.7503, its float32 ∫ȳ): its spectral film multiplies XYZ by
#: it (``tests/renderers/test_mitsuba_spectral.py`` checks it against the installed Mitsuba's).
MI_CIE_Y_NORMALIZATION = 0.009367658735689113
#: The variant a spectral export is rendered with, and the one to use without LLVM.
SPECTRAL_VARIANTS = ("llvm_ad_spectral", "scalar_spectral")


def spectral_scale() -> float:
    """The factor that puts a spectral variant's image on :func:`cornell_harness.scenes.spectra.emission_rgb`'s
    scale: Mitsuba's film multiplies by :data:`MI_CIE_Y_NORMALIZATION`, colour-science's projection divides by
    Σȳ (``CIE_TABLE_NOTE`` in ``src/cornell_harness/renderers/mitsuba3.py``). Images are linear in the emitted
    radiance, so it is folded into every emitter's (:func:`emitter_dict`)."""
    return float(1.0 / (MI_CIE_Y_NORMALIZATION * observer()[1][:, 1].sum()))


@dataclass(frozen=True)
class LookAt:
    """A ``to_world`` given as Mitsuba's ``<lookat>``: what the XML writes, and the adapter's ``look_at`` arguments."""

    origin: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]


@dataclass(frozen=True)
class Var:
    """A value written as ``$name``, read from the file's ``<default name=...>`` or ``-D name=...``; ``tag`` its type."""

    name: str
    tag: str


def spectrum_dict(spectrum: Spectrum, scale: float = 1.0) -> dict:
    """A sampled spectrum (times ``scale``) as Mitsuba's ``irregular`` plugin: the same samples, so the same linear
    interpolation and zero outside them; ``extrapolation = "constant"`` adds the end values at the ends of
    :data:`SPECTRAL_RANGE_NM` (:func:`cornell_harness.scenes.spectra.written_samples`)."""
    w, v = written_samples(spectrum, *SPECTRAL_RANGE_NM)
    if scale != 1.0:
        v = [x * scale for x in v]
    return {"type": "irregular", "wavelengths": ", ".join(map(_num, w)), "values": ", ".join(map(_num, v))}


def colour_dict(rgb, spectrum: Spectrum | None = None, scale: float = 1.0) -> dict:
    """A colour (times ``scale``): the spectrum where there is one (spectral variants), else the RGB value."""
    if spectrum is not None:
        return spectrum_dict(spectrum, scale)
    return {"type": "rgb", "value": [float(c) * scale for c in rgb] if scale != 1.0 else list(rgb)}


def bsdf_dict(material, spectra: dict[str, Spectrum] | None = None) -> dict:
    """A scene material as a Mitsuba 3 BSDF dictionary (cornell_harness.scenes.materials names the match); ``spectra``
    maps a field (``reflectance``) to its spectrum, for a spectral variant."""
    spectra = spectra or {}
    if isinstance(material, Diffuse):
        return {"type": "diffuse", "reflectance": colour_dict(material.reflectance, spectra.get("reflectance"))}
    if isinstance(material, Mirror):
        # material "none": Fresnel factor 1, so the reflectance is exactly specular_reflectance.
        return {"type": "conductor", "material": "none",
                "specular_reflectance": colour_dict(material.reflectance, spectra.get("reflectance"))}
    if isinstance(material, Dielectric):
        return {"type": "dielectric", "int_ior": material.int_ior, "ext_ior": material.ext_ior}
    raise ValueError(f"material {material.name!r}: {type(material).__name__} has no Mitsuba translation")


def emitter_dict(radiance, spectrum: Spectrum | None = None, scale: float = 1.0) -> dict:
    """A one-sided area emitter of constant ``radiance`` (linear sRGB), or of the emission ``spectrum``, times
    ``scale`` (:func:`spectral_scale` in a spectral variant)."""
    return {"type": "area", "radiance": colour_dict(radiance, spectrum, scale)}


def has_spectra(scene: Scene) -> bool:
    """Whether the scene gives any material or emitter as a spectrum (then a spectral variant renders those)."""
    return scene.spectral is not None and scene.spectral.used


def render_command(scene: Scene, main: Path) -> str:
    """The ``mitsuba`` command that renders the exported ``main`` file; a spectral export names its variant."""
    variant = (f"-m {SPECTRAL_VARIANTS[0]} " if has_spectra(scene) else "")
    tail = f"   (without LLVM: -m {SPECTRAL_VARIANTS[1]})" if variant else ""
    return f"mitsuba {variant}{main} -o out.exr -D spp={DEFAULT_SPP} -D seed={DEFAULT_SEED}{tail}"


def material_spectra(scene: Scene, spectral: bool) -> dict[str, dict[str, Spectrum]]:
    """Each material's spectral fields ({material: {field: spectrum}}), none unless ``spectral``."""
    if not spectral or scene.spectral is None:
        return {}
    return {m: scene.spectral.fields(m) for m in scene.spectral.materials}


def emission_spectrum(scene: Scene, mesh: Mesh, spectral: bool) -> Spectrum | None:
    return scene.spectral.emission(mesh.name) if spectral and scene.spectral is not None else None


def integrator_dict(scene: Scene) -> dict:
    # Our max_depth convention is Mitsuba's own: no translation needed.
    return {"type": "path", "max_depth": scene.max_depth}


def unit_point(scene: Scene, p) -> list[float]:
    """Point ``p`` of the scene in the unit frame, float64."""
    centre, k = unit_frame(scene)
    return ((np.asarray(p, dtype=np.float64) - centre) * k).tolist()


def unit_vertices(scene: Scene, mesh: Mesh) -> np.ndarray:
    """A mesh's vertices in the unit frame, as float32: what Mitsuba stores."""
    centre, k = unit_frame(scene)
    return ((mesh.vertices - centre) * k).astype(np.float32)


def camera_look_at(scene: Scene) -> LookAt:
    cam = scene.camera
    return LookAt(unit_point(scene, cam.position), unit_point(scene, cam.look_at), cam.up)


def sensor_dict(scene: Scene, spp, to_world, sampler: str = "independent") -> dict:
    """The camera, film and sampler; ``to_world`` a Mitsuba transform (adapter) or a :class:`LookAt` (XML)."""
    cam = scene.camera
    return {
        "type": "perspective",
        "fov": cam.fov_deg,
        "fov_axis": cam.fov_axis,
        "near_clip": 1e-4,
        "far_clip": 1e4,
        "to_world": to_world,
        "sampler": {"type": sampler, "sample_count": spp},
        "film": {
            "type": "hdrfilm",
            "width": cam.width,
            "height": cam.height,
            "rfilter": {"type": scene.pixel_filter},
            "pixel_format": "rgb",
            "component_format": "float32",
        },
    }


def sphere_dict(scene: Scene, sphere: Sphere) -> dict:
    """A sphere in the unit frame, without its BSDF."""
    return {"type": "sphere", "center": unit_point(scene, sphere.center), "radius": sphere.radius * unit_frame(scene)[1]}


def write(scene: Scene, folder: Path, spectral: bool | None = None) -> Path:
    """Write ``scene.xml`` and ``meshes/*.ply`` into ``folder``; return the XML's path. ``spectral`` (default:
    whether the scene has spectra) writes its spectra, for a ``*_spectral`` variant (module docstring)."""
    folder = Path(folder)
    spectral = has_spectra(scene) if spectral is None else spectral
    (folder / "meshes").mkdir()
    sensor = sensor_dict(scene, Var("spp", "integer"), camera_look_at(scene))
    sensor["sampler"]["seed"] = Var("seed", "integer")
    sensor["film"]["width"], sensor["film"]["height"] = Var("resx", "integer"), Var("resy", "integer")
    d: dict = {"type": "scene", "integrator": integrator_dict(scene), "sensor": sensor}
    # Shapes in the adapter's order, under its ids (spheres, then meshes), so the two scenes are one.
    # Ids and file names from our names made safe: Mitsuba substitutes `$name` in any attribute.
    bsdf_ids = {name: f"bsdf{i}-{_slug(name)}" for i, name in enumerate(scene.materials)}
    spectra = material_spectra(scene, spectral)
    scale = spectral_scale() if spectral else 1.0
    d |= {bsdf_ids[name]: bsdf_dict(m, spectra.get(name)) for name, m in scene.materials.items()}
    for i, s in enumerate(scene.spheres):
        d[f"sphere_{i}"] = sphere_dict(scene, s) | {"bsdf": {"type": "ref", "id": bsdf_ids[s.material]}}
    for i, m in enumerate(scene.meshes):
        ply = f"meshes/{i:02d}-{_slug(m.name)}.ply"
        write_ply(folder / ply, unit_vertices(scene, m), m.triangles)
        d[f"mesh_{i}"] = {"type": "ply", "filename": ply, "face_normals": True,
                          "bsdf": {"type": "ref", "id": bsdf_ids[m.material]}}
        if m.is_emitter:
            d[f"mesh_{i}"]["emitter"] = emitter_dict(m.radiance, emission_spectrum(scene, m, spectral), scale)
    defaults = {"spp": DEFAULT_SPP, "seed": DEFAULT_SEED, "resx": scene.camera.width, "resy": scene.camera.height}
    path = folder / "scene.xml"
    variant = (f"; spectra: render with a *_spectral variant (mitsuba -m {SPECTRAL_VARIANTS[0]}); emitters "
               f"scaled by {scale!r} for its film's normalisation" if spectral else "")
    path.write_text(to_xml(d, defaults, f"{scene.name} ({scene.content_hash()}), exported by cornell-harness{variant}"),
                    encoding="utf-8")
    return path


def _slug(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)[:60]


# --- dictionaries as XML: the subset of Mitsuba's dictionary convention the dictionaries above use ------------

#: The XML element of each plugin type used above (the dictionary says only ``type``).
PLUGIN_TAGS = {"path": "integrator", "perspective": "sensor", "independent": "sampler", "hdrfilm": "film",
               "box": "rfilter", "diffuse": "bsdf", "conductor": "bsdf", "dielectric": "bsdf", "area": "emitter",
               "ply": "shape", "sphere": "shape", "irregular": "spectrum"}


def to_xml(d: dict, defaults: dict[str, int], comment: str = "") -> str:
    """The ``mi.load_dict`` dictionary ``d`` of a scene as Mitsuba 3 XML, with ``<default>``s for ``$`` values.

    Each key becomes a child's ``id`` (top level) or ``name`` (nested). Floats are written as Python's
    shortest round-trip text, so Mitsuba reads the same doubles the dictionary holds.
    """
    root = ET.Element("scene", version="3.0.0")
    if comment:  # one line, and no "--", which ends an XML comment
        root.append(ET.Comment(f" {re.sub(r'-(?=-)', '- ', one_line(comment))} "))
    for name, value in defaults.items():
        ET.SubElement(root, "default", name=name, value=str(value))
    for key, value in d.items():
        if key != "type":
            _child(root, key, value, top=True)
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def _child(parent: ET.Element, key: str, value, top: bool = False) -> None:
    if isinstance(value, dict) and value.get("type") == "ref":
        ET.SubElement(parent, "ref", id=value["id"], name=key)
    elif isinstance(value, dict) and value.get("type") == "rgb":
        ET.SubElement(parent, "rgb", name=key, value=", ".join(_num(x) for x in value["value"]))
    elif isinstance(value, dict):
        if value["type"] not in PLUGIN_TAGS:
            raise ValueError(f"{key}: no XML element known for plugin type {value['type']!r}")
        attrs = {"type": value["type"], ("id" if top else "name"): key}
        if top and PLUGIN_TAGS[value["type"]] in ("integrator", "sensor"):
            attrs.pop("id")
        e = ET.SubElement(parent, PLUGIN_TAGS[value["type"]], attrs)
        for k, v in value.items():
            if k != "type":
                _child(e, k, v)
    elif isinstance(value, LookAt):
        t = ET.SubElement(parent, "transform", name=key)
        ET.SubElement(t, "lookat", origin=_vec(value.origin), target=_vec(value.target), up=_vec(value.up))
    elif isinstance(value, Var):
        ET.SubElement(parent, value.tag, name=key, value=f"${value.name}")
    elif isinstance(value, bool):
        ET.SubElement(parent, "boolean", name=key, value="true" if value else "false")
    elif isinstance(value, (int, np.integer)):
        ET.SubElement(parent, "integer", name=key, value=str(int(value)))
    elif isinstance(value, (float, np.floating)):
        ET.SubElement(parent, "float", name=key, value=_num(value))
    elif isinstance(value, str):
        ET.SubElement(parent, "string", name=key, value=value)
    elif isinstance(value, (list, tuple)) and len(value) == 3:
        ET.SubElement(parent, "point", name=key, **dict(zip("xyz", map(_num, value))))
    else:
        raise ValueError(f"{key}: cannot write {type(value).__name__} {value!r} as Mitsuba XML")


def _num(x) -> str:
    return repr(float(x))


def _vec(v) -> str:
    return ", ".join(_num(x) for x in v)

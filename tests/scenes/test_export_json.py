"""The neutral JSON export (``cbox export --format json``): every stored scene's file is valid against the shipped
schema and reads back, with the small loader below (what a renderer in another language does), into the same
scene: the same content hash, camera rays and AO definition."""

from __future__ import annotations

import dataclasses
import json
import math

import jsonschema
import numpy as np
import pytest

from cornell_harness.scenes.export import export_scene, quantities, refusal
from cornell_harness.scenes.export.json_scene import FORMAT, SCHEMA, VERSION, document
from cornell_harness.scenes.library import resolve_scene, scene_names
from cornell_harness.scenes.materials import MATERIAL_TYPES
from cornell_harness.scenes.model import Camera, Mesh, Scene, SceneError, Sphere
from cornell_harness.scenes.animation import Animation, Switch, Track
from cornell_harness.scenes.quantities import AmbientOcclusion
from cornell_harness.scenes.spectra import Spectrum
from cornell_harness.scenes.spectral_scene import SpectralContent
from cornell_harness.schemas.reader import schema, schema_file


def validator() -> jsonschema.Draft202012Validator:
    jsonschema.Draft202012Validator.check_schema(schema(SCHEMA))
    return jsonschema.Draft202012Validator(schema(SCHEMA))


def scene_from_json(doc: dict, path) -> Scene:
    """A Scene from the export, reading only the file: the camera from its basis' look-at and vertical fov."""
    assert (doc["format"], doc["version"]) == (FORMAT, VERSION)
    c = doc["camera"]
    camera = Camera(tuple(c["position"]), tuple(c["look_at"]), tuple(c["up"]), c["vertical_fov_deg"], "y",
                    c["width"], c["height"])
    materials = {name: MATERIAL_TYPES[m["type"]](name, **{k: tuple(v) if isinstance(v, list) else v
                                                          for k, v in m.items() if k not in ("type", "spectra")})
                 for name, m in doc["materials"].items()}
    meshes = tuple(Mesh(m["name"], np.array(m["vertices"], dtype=np.float64), np.array(m["triangles"], dtype=np.int64),
                        m["material"], None if m["emitter"] is None else tuple(m["emitter"]["radiance"]))
                   for m in doc["meshes"])
    spheres = tuple(Sphere(s["name"], tuple(s["center"]), s["radius"], s["material"]) for s in doc["spheres"])
    ao = doc["ambient_occlusion"]
    if ao is not None:
        ao = AmbientOcclusion(math.inf if ao["max_distance"] is None else ao["max_distance"], ao["weighting"],
                              ao["normal"], ao["miss_value"])
    spectral = None
    if "colour" in doc:
        col = doc["colour"]
        spectral = SpectralContent(
            col["observer"], col["output"], col["rgb_convention"], col["light"],
            {k: Spectrum(tuple(s["wavelengths_nm"]), tuple(s["values"]), s["extrapolation"])
             for k, s in doc["spectra"].items()},
            {k: m["spectra"] for k, m in doc["materials"].items() if "spectra" in m},
            {m["name"]: m["emitter"]["radiance_spectrum"] for m in doc["meshes"]
             if m["emitter"] and "radiance_spectrum" in m["emitter"]})
    return Scene(doc["name"], path, frozenset(doc["features"]), camera, materials, meshes, doc["max_depth"],
                 c["pixel_filter"], spheres=spheres, quantity=doc["quantity"], ambient_occlusion=ao,
                 spectral=spectral, animation=animation_from_json(doc.get("animation"), camera))


def animation_from_json(a: dict | None, camera: Camera) -> Animation | None:
    """The export's animation as the model's, from its keys only."""
    if a is None:
        return None
    cam = None if a["camera"] is None else Track(tuple(k["frame"] for k in a["camera"]),
                                                 tuple((*k["position"], *k["look_at"]) for k in a["camera"]))
    objects = {n: Track(tuple(k["frame"] for k in keys), tuple(tuple(k["translate"]) for k in keys))
               for n, keys in a["objects"].items()}
    return Animation(a["frames"], a["fps"], camera, cam, objects,
                     tuple(Switch(s["object"], s["frame"], s["on"]) for s in a["switches"]))


def assert_same_scene(back: Scene, scene: Scene) -> None:
    # The camera is written as a vertical fov: the same rays, not the same (fov_deg, fov_axis) pair.
    rows, cols = np.mgrid[0:scene.camera.height + 1:7, 0:scene.camera.width + 1:5]
    d0, d1 = scene.camera.directions(cols, rows), back.camera.directions(cols, rows)
    np.testing.assert_allclose(d1 / np.linalg.norm(d1, axis=-1, keepdims=True),
                               d0 / np.linalg.norm(d0, axis=-1, keepdims=True), rtol=0, atol=1e-14)
    assert dataclasses.replace(back, camera=scene.camera).content_hash() == scene.content_hash()


@pytest.mark.parametrize("name", scene_names())
def test_every_stored_scene_exports_valid_json_that_reads_back_as_the_same_scene(tmp_path, name):
    scene = resolve_scene(name)
    main = export_scene(scene, "json", tmp_path)
    doc = json.loads(main.read_text(encoding="utf-8"))
    validator().validate(doc)
    assert doc["content_hash"] == scene.content_hash()
    back = scene_from_json(doc, main)
    assert_same_scene(back, scene)
    np.testing.assert_array_equal(np.array(list(doc["camera"]["basis"].values())), np.array(scene.camera.frame()))


def test_the_ao_definition_is_carried_and_an_unbounded_distance_is_null(tmp_path):
    scene = resolve_scene("cornell-box-ao")
    doc = document(scene)
    assert doc["quantity"] == "ambient_occlusion"
    assert doc["ambient_occlusion"] == {"max_distance": 0.5, "weighting": "cosine", "normal": "geometric",
                                        "miss_value": 0.0}
    unbounded = dataclasses.replace(scene, ambient_occlusion=dataclasses.replace(scene.ambient_occlusion,
                                                                                 max_distance=math.inf,
                                                                                 weighting="uniform"))
    doc = json.loads(export_scene(unbounded, "json", tmp_path).read_text(encoding="utf-8"))
    validator().validate(doc)
    assert doc["ambient_occlusion"]["max_distance"] is None and doc["ambient_occlusion"]["weighting"] == "uniform"
    assert_same_scene(scene_from_json(doc, tmp_path), unbounded)


def test_the_spectral_scene_carries_its_spectra():
    scene = resolve_scene("cornell-box-measured")
    doc = document(scene)
    assert set(doc["spectra"]) == set(scene.spectral.spectra)
    assert doc["materials"]["white"]["spectra"] == {"reflectance": scene.spectral.materials["white"]["reflectance"]}
    (light,) = [m for m in doc["meshes"] if m["emitter"]]
    assert light["emitter"]["radiance_spectrum"] == scene.spectral.emitters[light["name"]]


@pytest.mark.parametrize("edit, where", [
    (lambda d: d["ambient_occlusion"].pop("miss_value"), "miss_value"),
    (lambda d: d["ambient_occlusion"].update(weighting="cosin"), "cosin"),
    (lambda d: d["camera"].update(fov_deg=40), "fov_deg"),
    (lambda d: d["meshes"][0]["triangles"][0].append(3), "triangles"),
    (lambda d: d["materials"]["white"].update(int_ior=1.5), "int_ior"),
])
def test_the_schema_refuses_a_wrong_file(edit, where):
    doc = document(resolve_scene("cornell-box-ao"))
    edit(doc)
    errors = list(validator().iter_errors(doc))
    assert errors and any(where in (str(e.message) + str(list(e.absolute_path))) or
                          any(where in str(c.message) for c in e.context) for e in errors)


def test_the_schema_ships_in_the_package():
    assert schema_file(SCHEMA).parent.name == "schemas" and schema_file(SCHEMA).is_file()


def test_each_format_carries_its_own_quantities():
    scene = resolve_scene("cornell-box-ao")
    assert "ambient_occlusion" in quantities("json") and refusal(scene, "json") is None
    for fmt in ("mitsuba", "luxcore", "pbrt-v4"):
        assert quantities(fmt) == ("radiance",)
        why = refusal(scene, fmt)
        assert isinstance(why, SceneError) and why.field == "quantity" and "carries radiance only" in str(why)


def test_the_format_claims_what_the_model_has_today():
    """A feature or quantity added to the model fails here until the format (and its schema) writes it."""
    from cornell_harness.scenes.export import json_scene
    from cornell_harness.scenes.model import FEATURES
    from cornell_harness.scenes.quantities import QUANTITIES

    assert json_scene.FEATURES == set(FEATURES) and set(json_scene.QUANTITIES) == set(QUANTITIES)
    props = schema(SCHEMA)["properties"]
    assert set(props["features"]["items"]["enum"]) == set(FEATURES) and set(props["quantity"]["enum"]) == set(QUANTITIES)

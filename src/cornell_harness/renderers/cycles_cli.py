"""The child process of the ``cycles`` renderer: build a scene in Blender (``bpy``) from a plan and render it
with Cycles, one EXR per batch.

    python -m cornell_harness.renderers.cycles_cli PLAN_DIR

``PLAN_DIR/plan.json`` (written by :func:`cornell_harness.renderers.cycles.write_plan`) holds the camera,
the materials, the meshes (their arrays in ``mesh-K.npz``), the bounce limit, the threads and the batches
(spp and seed of each). Batch k is rendered to ``PLAN_DIR/batch-K.exr`` (float32, scene-linear Rec.709,
top row first); ``PLAN_DIR/settings.json`` records every setting the render used, read back from Blender
after it was set (what the tests check).

Why a child: ``bpy`` is Blender itself (800 MB, its own OpenImageIO and OpenColorIO, exit handlers), and
its wheel is built against NumPy 1 while the harness runs on NumPy 2; it is never imported by the harness.
The program ends with ``os._exit``, so Blender's exit handlers never run. Errors are one line on stderr,
exit 2.

The scene is built with ``bpy`` directly, not through Blender's USD importer, which changes what the
materials mean (``docs/references.md``, "Cycles"):

- a diffuse surface is a Diffuse BSDF on its front face and black on its back (Cycles' BSDFs are
  two-sided, ours one-sided), switched by ``Geometry.Backfacing``;
- a mirror is a Glossy BSDF (no Fresnel: constant reflectance) of roughness 0 in the reflectance colour,
  front face only;
- a dielectric is a Glass BSDF of roughness 0 and IOR int/ext (Cycles inverts it on back faces), both faces;
- an emitter adds an Emission shader of strength 1 in the radiance colour (Cycles' mesh emission is
  radiance) to its front face only, and its light sampling is set to the front face
  (``emission_sampling`` FRONT);
- a sphere is a UV-sphere mesh with the analytic normals at its vertices (smooth shading), as in the
  LuxCore export: Cycles' only sphere, a point cloud's point, is culled from inside and cannot be glass.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

#: Exit status of a bad plan or a failed render (one line on stderr).
FAILED = 2


def configure(scene, plan: dict) -> None:
    """Every setting of Cycles, Blender's colour management and output that would break agreement with the
    reference, set explicitly (Blender's defaults in comments)."""
    r, c = scene.render, scene.cycles
    r.engine = "CYCLES"
    c.device = "CPU"
    c.samples = 1
    c.use_adaptive_sampling = False      # default on: stops pixels early, on a noise estimate
    c.use_denoising = False              # default on (OpenImageDenoise)
    c.use_guiding = False                # path guiding: off by default on CPU too; unbiased, but learns
    c.sample_clamp_direct = 0.0          # 0 by default
    c.sample_clamp_indirect = 0.0        # default 10: clamps indirect light (caustics, glass)
    c.blur_glossy = 0.0                  # "Filter Glossy", default 1: blurs glossy after diffuse bounces
    c.caustics_reflective = True
    c.caustics_refractive = True
    c.light_sampling_threshold = 0.0     # default 0.01: a roulette on light samples (unbiased, noisier)
    c.pixel_filter_type = "BOX"          # default Blackman-Harris of 1.5 pixels
    c.filter_width = 1.0
    c.film_exposure = 1.0
    c.use_animated_seed = False
    c.seed = 0
    # Cycles puts sample 0 of every render at the pixel's centre, unjittered, whatever the seed: a batch of n
    # spp would weight the centre 1/n (measured: 200 renders of 1 spp left the light's edge pixels at 1% of
    # their radiance). Each batch renders samples 1..n of n + 1 instead (:func:`render_spp`).
    c.use_sample_subset = True
    c.sample_offset = 1
    c.time_limit = 0.0
    bounces = plan["max_bounces"]
    c.max_bounces = bounces              # default 12, with per-kind limits below it
    c.diffuse_bounces = bounces          # default 4
    c.glossy_bounces = bounces           # default 4
    c.transmission_bounces = bounces     # default 12
    c.volume_bounces = bounces
    c.transparent_max_bounces = bounces
    c.min_light_bounces = 0
    c.min_transparent_bounces = 0
    r.film_transparent = False
    r.use_compositing = False
    r.use_sequencer = False
    r.dither_intensity = 0.0             # default 1 (noise added when quantising; EXR float is not)
    r.resolution_x, r.resolution_y = plan["resolution"]
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.use_border = False
    r.threads_mode = "FIXED"
    r.threads = plan["threads"]
    view = scene.view_settings
    view.view_transform = "Standard"     # default AgX (a tone curve)
    view.look = "None"
    view.exposure = 0.0
    view.gamma = 1.0
    view.use_curve_mapping = False
    out = r.image_settings
    out.file_format = "OPEN_EXR"
    out.color_depth = "32"
    out.color_mode = "RGB"
    out.exr_codec = "ZIP"
    out.color_management = "FOLLOW_SCENE"
    out.linear_colorspace_settings.name = "Linear Rec.709"


def settings(scene) -> dict:
    """The settings that matter, read back from Blender (what :func:`configure` set, and what it did not)."""
    c, r, view = scene.cycles, scene.render, scene.view_settings
    names = ("device", "samples", "use_adaptive_sampling", "use_denoising", "use_guiding", "sample_clamp_direct",
             "sample_clamp_indirect", "blur_glossy", "caustics_reflective", "caustics_refractive",
             "light_sampling_threshold", "pixel_filter_type", "filter_width", "film_exposure", "use_animated_seed",
             "use_sample_subset", "sample_offset", "sample_subset_length",
             "use_light_tree", "max_bounces", "diffuse_bounces", "glossy_bounces",
             "transmission_bounces", "volume_bounces", "transparent_max_bounces", "min_light_bounces")
    world = scene.world
    background = world.node_tree.nodes["Background"].inputs if world else None
    return {
        "cycles": {n: getattr(c, n) for n in names},
        "view_transform": view.view_transform, "look": view.look, "exposure": view.exposure, "gamma": view.gamma,
        "working_space": _working_space(),
        "exr": {"color_depth": r.image_settings.color_depth, "colorspace": r.image_settings.linear_colorspace_settings.name,
                "codec": r.image_settings.exr_codec},
        "dither_intensity": r.dither_intensity, "film_transparent": r.film_transparent,
        "resolution": [r.resolution_x, r.resolution_y, r.resolution_percentage], "threads": r.threads,
        "world": None if background is None else {"color": list(background["Color"].default_value),
                                                  "strength": background["Strength"].default_value},
        "camera": {"sensor_fit": scene.camera.data.sensor_fit, "angle": scene.camera.data.angle,
                   "type": scene.camera.data.type},
        "materials": {m.name: m.cycles.emission_sampling for m in _bpy().data.materials},
    }


def _bpy():
    import bpy

    return bpy


def _working_space() -> str:
    space = getattr(_bpy().data, "colorspace", None)  # Blender 5's per-file working space
    return getattr(space, "working_space", "Linear Rec.709")


def world(scene) -> None:
    """A black world: Cycles' default world is grey."""
    w = _bpy().data.worlds.new("black")
    w.use_nodes = True
    bg = w.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bg.inputs["Strength"].default_value = 0.0
    scene.world = w


def camera(scene, plan: dict) -> None:
    """A perspective camera whose horizontal field of view is the scene's along x (sensor fit horizontal)."""
    bpy = _bpy()
    data = bpy.data.cameras.new("camera")
    data.type = "PERSP"
    data.sensor_fit = "HORIZONTAL"
    data.sensor_width = data.sensor_height = 36.0
    data.angle = plan["camera"]["fov_x_rad"]
    data.clip_start = plan["camera"]["clip_start"]
    data.clip_end = plan["camera"]["clip_end"]
    data.shift_x = data.shift_y = 0.0
    obj = bpy.data.objects.new("camera", data)
    from mathutils import Matrix  # Blender's own: a matrix from rows (a plain nested list is read by columns)

    obj.matrix_world = Matrix(plan["camera"]["matrix"])
    scene.collection.objects.link(obj)
    scene.camera = obj


def material(name: str, spec: dict, radiance):
    """The Cycles material of one of our materials (module docstring), with the emitter's radiance if any."""
    bpy = _bpy()
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    output = nodes.new("ShaderNodeOutputMaterial")
    kind = spec["type"]
    if kind == "diffuse":
        front = nodes.new("ShaderNodeBsdfDiffuse")
        front.inputs["Color"].default_value = (*spec["reflectance"], 1.0)
        front.inputs["Roughness"].default_value = 0.0  # Lambert (Oren-Nayar above 0)
    elif kind == "mirror":
        front = nodes.new("ShaderNodeBsdfGlossy")
        front.distribution = "GGX"
        front.inputs["Color"].default_value = (*spec["reflectance"], 1.0)
        front.inputs["Roughness"].default_value = 0.0  # a delta reflection
    elif kind == "dielectric":
        front = nodes.new("ShaderNodeBsdfGlass")
        front.distribution = "GGX"
        front.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        front.inputs["Roughness"].default_value = 0.0
        front.inputs["IOR"].default_value = spec["int_ior"] / spec["ext_ior"]
    else:
        raise ValueError(f"material {name!r}: type {kind!r} is not one Cycles is given")
    surface = front.outputs[0]
    if radiance is not None:
        emission = nodes.new("ShaderNodeEmission")
        emission.inputs["Color"].default_value = (*radiance, 1.0)
        emission.inputs["Strength"].default_value = 1.0
        add = nodes.new("ShaderNodeAddShader")
        links.new(surface, add.inputs[0])
        links.new(emission.outputs[0], add.inputs[1])
        surface = add.outputs[0]
    mat.cycles.emission_sampling = "FRONT" if radiance is not None else "NONE"
    if kind != "dielectric":  # one-sided: black behind (Backfacing 1 picks the mix's second input)
        black = nodes.new("ShaderNodeBsdfDiffuse")
        black.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        geometry = nodes.new("ShaderNodeNewGeometry")
        mix = nodes.new("ShaderNodeMixShader")
        links.new(geometry.outputs["Backfacing"], mix.inputs["Fac"])
        links.new(surface, mix.inputs[1])
        links.new(black.outputs[0], mix.inputs[2])
        surface = mix.outputs[0]
    links.new(surface, output.inputs["Surface"])
    return mat


def mesh(scene, folder: Path, spec: dict, mat) -> None:
    """One mesh object: its triangles, flat or with the given vertex normals, and its material."""
    import numpy as np

    bpy = _bpy()
    arrays = np.load(folder / spec["file"])
    vertices = arrays["vertices"].astype(np.float32)
    triangles = arrays["triangles"].astype(np.int32)
    data = bpy.data.meshes.new(spec["name"])
    data.vertices.add(len(vertices))
    data.vertices.foreach_set("co", vertices.ravel().tolist())
    data.loops.add(3 * len(triangles))
    data.loops.foreach_set("vertex_index", triangles.ravel().tolist())
    data.polygons.add(len(triangles))
    data.polygons.foreach_set("loop_start", list(range(0, 3 * len(triangles), 3)))
    data.polygons.foreach_set("use_smooth", [spec["smooth"]] * len(triangles))
    data.update()
    if spec["smooth"]:
        data.normals_split_custom_set_from_vertices(arrays["normals"].astype(np.float32).tolist())
    data.validate()
    data.materials.append(mat)
    obj = bpy.data.objects.new(spec["name"], data)
    scene.collection.objects.link(obj)


def build(folder: Path, plan: dict):
    """The scene of ``plan`` in a new, empty Blender file; returns the bpy scene."""
    bpy = _bpy()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    configure(scene, plan)
    world(scene)
    camera(scene, plan)
    materials = {}  # one Blender material per (material, radiance): emitters get their own
    for spec in plan["meshes"]:
        radiance = spec.get("radiance")
        key = (spec["material"], None if radiance is None else tuple(radiance))
        if key not in materials:
            name = spec["material"] if radiance is None else f"{spec['material']}:{spec['name']}"
            materials[key] = material(name, plan["materials"][spec["material"]], radiance)
        mesh(scene, folder, spec, materials[key])
    return scene


def render_spp(scene, spp: int) -> None:
    """Render ``spp`` samples per pixel, all jittered: samples 1 to ``spp`` of ``spp + 1`` (sample 0, at the
    pixel's centre, left out; :func:`configure`)."""
    scene.cycles.samples = spp + 1
    scene.cycles.sample_offset = 1
    scene.cycles.sample_subset_length = spp


def run(folder: Path) -> None:
    plan = json.loads((folder / "plan.json").read_text())
    scene = build(folder, plan)
    record = []
    for k, batch in enumerate(plan["batches"]):
        render_spp(scene, batch["spp"])
        scene.cycles.seed = batch["seed"]
        scene.render.filepath = str(folder / f"batch-{k}.exr")
        t0, cpu0 = time.perf_counter(), time.process_time()
        _bpy().ops.render.render(write_still=True)
        record.append({"spp": batch["spp"], "seed": batch["seed"], "seconds": time.perf_counter() - t0,
                       "cpu_seconds": time.process_time() - cpu0})
        if not (folder / f"batch-{k}.exr").is_file():
            raise RuntimeError(f"Cycles wrote no image for batch {k}")
    info = settings(scene)
    info["version"] = _bpy().app.version_string
    info["batches"] = record
    (folder / "settings.json").write_text(json.dumps(info, indent=1, default=str))


def main(argv: list[str] | None = None) -> None:
    """Entry point; always leaves through ``os._exit`` (Blender's exit handlers are not wanted here)."""
    args = sys.argv[1:] if argv is None else argv
    status = 0
    try:
        if len(args) != 1:
            raise ValueError("usage: python -m cornell_harness.renderers.cycles_cli PLAN_DIR")
        run(Path(args[0]))
    except Exception as e:  # noqa: BLE001 -- a child: every failure is one line for the parent to quote
        print(f"cycles: {type(e).__name__}: {' '.join(str(e).split())}", file=sys.stderr)
        status = FAILED
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


if __name__ == "__main__":
    main()

"""LuxCore SDL export: a ``scene.scn`` (camera, materials, shapes, objects), a ``scene.cfg`` (film, path
depth, filter, sampler; it names the ``.scn`` in ``scene.file``) and one PLY file per mesh and sphere.

Written for LuxCoreRender 2.11 (``pyluxcore``), whose property names are those of its SDL reference
("LuxCore SDL Reference Manual v2.x", luxcorerender.org wiki). Rendered by ``cbox-luxcore``
(:mod:`cornell_harness.renderers.luxcore_cli`) and by the ``luxcore`` renderer (:mod:`cornell_harness.renderers.luxcore`).

How each part of our scene model (:mod:`cornell_harness.scenes.model`, :mod:`cornell_harness.scenes.materials`) is
written is :data:`MAPPING`. The facts it rests on were measured with real renders (tests/renderers/
test_luxcore.py checks each):

- emission ``gain 1``, ``power 0``, ``efficency 0`` (LuxCore's spelling) and both ``normalizebycolor``
  false give emitted radiance equal to the RGB value;
- LuxCore's ``matte`` and ``mirror`` reflect on both sides: each is wrapped in ``twosided`` with a black
  ``matte`` back, as our diffuse and mirror reflect on their front side only (Mitsuba 3's);
- a ``BOX`` filter of width 0.5 (a half-width, in pixels) is our box filter, each pixel the mean over its
  own square;
- ``path.pathdepth.total = D`` is our (Mitsuba's) ``max_depth = D`` for D >= 2, with Russian roulette off
  (see :func:`depths`); at D = 1 LuxCore also samples the lights at the first hit, so max_depth 1 is refused.

Russian roulette is off (``path.russianroulette.cap = 1``): LuxCore 2.11's is biased together with its MIS.
Its next-event estimation weights the BSDF's pdf by a roulette survival probability computed from the
BSDF's value f·cos (src/slg/engines/pathtracer.cpp, ``DirectLightSampling``, line 208: ``bsdfPdfW *=
RenderEngine::RussianRouletteProb(bsdfEval, rrImportanceCap)``, i.e. ``Clamp(bsdfEval.Filter(), cap, 1)``;
a matte's f·cos is at most 1/π, so this is the cap, 0.5 by default), while a BSDF-sampled ray that hits the
light is weighted by the pdf alone (``DirectHitFiniteLight``, line 299: ``PowerHeuristic(
pathInfo.lastBSDFPdfW, ...)``, stored by ``EyePathInfo::AddVertex`` before the roulette; the roulette itself
survives with the mean albedo, 0.8 in the furnace). The two MIS weights of a light path then sum to more than
1 at every vertex whose light sample is past the roulette depth: light is counted too much (the white
furnace +9.5% with roulette from depth 3; at max_depth 6, +6.4% with the cap 0.5 and +1.0% with a cap of
0.9). Line numbers are LuxCoreRender/LuxCore's master (d624e04; the file is unchanged since 2021, 984b63d).
With a cap of 1 the survival probability is 1 on both sides: no roulette, and consistent weights. Paths
then end only at the depth limit, so an unbounded scene is cut after :func:`diffuse_depth` diffuse bounces,
where the light it loses is provably below ``TRUNCATION`` of the brightest radiance.

Geometry is moved and scaled so the bounding box is centred on the origin with a diagonal of 1, as the
Mitsuba adapter does (:func:`cornell_harness.scenes.transforms.unit_frame`): LuxCore offsets new rays by a fixed
epsilon, which would let light leak through the walls of a tiny scene; a uniform change of units leaves
radiance images unchanged.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from cornell_harness.scenes.export.ply import write_ply
from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror
from cornell_harness.scenes.model import Scene, SceneError, Sphere
from cornell_harness.scenes.transforms import unit_frame

NAME = "luxcore"
FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                      "pinhole_camera", "box_filter"})
#: Longitude segments of a tessellated sphere (latitude rings are half as many); see :func:`sphere_mesh`.
SPHERE_SEGMENTS = 512
#: LuxCore's largest path depth, and its total and specular depth for our unbounded ``max_depth = -1``
#: (LuxCore's TILEPATHCPU crashes, a segmentation fault, at 100000; 10000 runs); diffuse bounces are cut
#: far sooner, at :func:`diffuse_depth`.
UNBOUNDED_DEPTH = 10_000
#: The most light, as a fraction of the scene's brightest radiance, that cutting paths at
#: :func:`diffuse_depth` diffuse bounces may lose (there is no Russian roulette to continue them).
TRUNCATION = 1e-5

MAPPING = (
    ("camera", "pinhole at `position` looking at `look_at`, `up`",
     "`scene.camera.type = perspective`, `lookat.orig`/`lookat.target`/`up`"),
    ("fov axis", "`fov_deg` along x, y, the smaller or the larger side",
     "`fieldofview` along the smaller side (converted from ours), with a `screenwindow` of ±aspect "
     "along the larger, moved one pixel down (LuxCore's film is stored bottom row first: "
     "`cbox-luxcore` flips it, and its rows are then one pixel off)"),
    ("handedness", "right = forward × up, row 0 at the top", "the same: LuxCore's `up` is image up"),
    ("emitter side", "one-sided: the front (CCW winding) emits, radiance = RGB",
     "`emission` on the (front) material, `gain 1`, `power 0`, `efficency 0`, `normalizebycolor` and "
     "`gain.normalizebycolor` false; LuxCore's triangle lights emit on the front side"),
    ("two-sidedness", "diffuse and mirror reflect on the front side only; dielectric both sides",
     "`twosided` with the `matte` or `mirror` in front and a black `matte` behind; `glass` as is"),
    ("filter", "box: each pixel the mean over its own square", "`film.filter.type = BOX`, width 0.5"),
    ("depth", "`max_depth` segments from the camera, -1 unbounded (Russian roulette); 1 is emission only",
     "`path.pathdepth.total` and `.specular` = max_depth (-1 as "
     f"{UNBOUNDED_DEPTH}), `.diffuse` and `.glossy` the smaller of it and n = ⌈ln ε / ln ρ⌉ (ρ the largest "
     f"diffuse reflectance, ε = {TRUNCATION:g}: the light of paths with n or more diffuse bounces, which is "
     "cut, is at most ε of the brightest radiance; 52 at ρ 0.8); Russian roulette off "
     "(`path.russianroulette.cap = 1`: LuxCore 2.11's roulette biases its MIS, see docs/references.md); "
     "max_depth 1 refused (LuxCore's depth 1 adds direct light)"),
    ("IOR", "`int_ior` behind the normal, `ext_ior` in front",
     "`glass` with `interiorior`, `exteriorior`, `kr = kt = 1`"),
    ("mirror", "constant specular reflectance R", "`mirror` with `kr = R`"),
    ("sphere", "analytic sphere",
     f"LuxCore has no sphere shape: a UV sphere of {SPHERE_SEGMENTS} × {SPHERE_SEGMENTS // 2} quads with "
     "the analytic normals at its vertices (chord error 1.9e-5 of the radius, far below a pixel)"),
    ("units", "scene units", "moved and scaled to a bounding-box diagonal of 1 (radiance unchanged)"),
)


def lux_depth(max_depth: int) -> int:
    """``path.pathdepth.total`` for our ``max_depth`` (the same count of segments; -1 as a depth never reached)."""
    return UNBOUNDED_DEPTH if max_depth < 0 else min(int(max_depth), UNBOUNDED_DEPTH)


def diffuse_depth(scene: Scene, truncation: float = TRUNCATION) -> int:
    """Diffuse bounces after which a path is cut: n = ⌈ln ε / ln ρ⌉, ρ the largest reflectance (any channel)
    of the scene's diffuse materials, so that ρⁿ <= ε (``UNBOUNDED_DEPTH`` for ρ >= 1; at least 2).

    Why it bounds the light lost: in basic radiance (radiance / n², which mirrors and lossless glass do not
    increase: their reflectance and transmittance are at most 1), each diffuse reflection scales the largest
    radiance by at most ρ. The light of the paths with n or more diffuse bounces is at most ρⁿ times the
    scene's largest basic radiance, n² times that inside glass (Veach 1997, §5.2, for radiance / n² being
    invariant). What it costs: without Russian roulette every path of a closed scene runs all n bounces
    (measured on the white furnace, ρ 0.8, n 52, 16², 256 spp: 3.9 s against 0.9 s with LuxCore's roulette
    from depth 3, and a 7× smaller standard error, 0.0017 against 0.0125); paths that leave an open scene
    end as before.
    """
    rho = max((max(m.reflectance) for m in scene.materials.values() if isinstance(m, Diffuse)), default=0.0)
    if rho >= 1.0:
        return UNBOUNDED_DEPTH
    if rho <= 0.0:
        return 2
    return max(2, min(UNBOUNDED_DEPTH, math.ceil(math.log(truncation) / math.log(rho))))


def depths(scene: Scene) -> dict[str, int]:
    """LuxCore's ``path.pathdepth.*`` for ``scene``: total and specular the scene's ``max_depth`` (-1 as
    ``UNBOUNDED_DEPTH``), diffuse and glossy the smaller of it and :func:`diffuse_depth`. With Russian
    roulette off, a bounded max_depth within the diffuse depth is rendered exactly."""
    total = lux_depth(scene.max_depth)
    diffuse = min(total, diffuse_depth(scene))
    return {"total": total, "diffuse": diffuse, "glossy": diffuse, "specular": total}


def refusal(scene: Scene) -> SceneError | None:
    """max_depth 1 cannot be expressed: LuxCore's path depth 1 adds the direct light at the first hit.

    src/slg/engines/pathtracer.cpp, ``RenderEyePath``: a vertex that is the path's last skips light sampling
    "if (sampleResult.lastPathVertex && !sampleResult.firstPathVertex)", so the camera ray's hit samples
    the lights even at depth 1 (measured on the white furnace: 1.78, emission 1 plus direct light 0.8, the
    light sampled without MIS, whose 1/r² at the cube's edges has unbounded variance).
    """
    if scene.max_depth == 1:
        return SceneError(scene.path, "render.max_depth",
                          "max_depth 1 (emission only) cannot be exported to luxcore: LuxCore's path depth 1 "
                          "also adds direct light; use 2 or more, or -1")
    return None


def camera_fov(scene: Scene) -> float:
    """LuxCore's ``fieldofview`` (degrees): the full angle along the image's smaller side."""
    tx, ty = scene.camera.tan_half_fov()
    return math.degrees(2.0 * math.atan(min(tx, ty)))


def screenwindow(width: int, height: int) -> tuple[float, float, float, float]:
    """LuxCore's ``screenwindow`` (x0, x1, y0, y1) for our pixel grid.

    LuxCore's default window is ±aspect along the larger side and ±1 along the smaller, the fov
    spanning the smaller. Its film is stored bottom row first, and once flipped its rows sit one
    pixel below ours (measured against Mitsuba: the best match is the image moved up a row). So the
    window is moved down by one pixel (2·y/height in window units).
    """
    aspect = width / height
    x, y = (aspect, 1.0) if aspect >= 1.0 else (1.0, 1.0 / aspect)
    dy = 2.0 * y / height
    return (-x, x, -y - dy, y - dy)


def sphere_mesh(sphere: Sphere, segments: int = SPHERE_SEGMENTS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, triangles, normals) of a UV sphere: ``segments`` longitudes, ``segments // 2`` rings.

    Triangles wind counter-clockwise seen from outside (our front side is a sphere's outside); the
    normals are the analytic ones, so shading is the sphere's and only the silhouette and hit points
    sit on chords, at most r·(1 − cos(π/segments)) inside the sphere.
    """
    rings = segments // 2
    theta = np.linspace(0.0, math.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * math.pi, segments + 1)[:-1]
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    n = np.stack(np.broadcast_arrays(st * np.cos(phi), ct, st * np.sin(phi)), axis=-1).reshape(-1, 3)
    idx = np.arange((rings + 1) * segments).reshape(rings + 1, segments)
    a, b = idx[:-1], np.roll(idx[:-1], -1, axis=1)
    c, d = idx[1:], np.roll(idx[1:], -1, axis=1)
    # Ring r+1 is further from +y; (a, b, d) and (a, d, c) face outwards (checked in the tests).
    tris = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3)[segments:],  # the top ring's (a, b) is one point
                           np.stack([a, d, c], -1).reshape(-1, 3)[:-segments]])  # the bottom ring's (d, c) too
    vertices = np.asarray(sphere.center, dtype=np.float64) + sphere.radius * n
    return vertices, tris, n


def _vec(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def _material_lines(name: str, material, radiance=None) -> list[str]:
    """SDL lines of one material; an emitter's material carries its emission.

    The emission goes on the ``twosided`` wrapper's front material: on the wrapper itself it lights
    the scene but a camera ray that hits the emitter sees none of it (measured: 0.13 instead of 18.4).
    """
    p = f"scene.materials.{name}"
    if isinstance(material, Dielectric):
        lines = [f'{p}.type = "glass"', f"{p}.kr = 1 1 1", f"{p}.kt = 1 1 1",
                 f"{p}.interiorior = {material.int_ior!r}", f"{p}.exteriorior = {material.ext_ior!r}"]
        emits = p
    elif isinstance(material, (Diffuse, Mirror)):
        emits = f"scene.materials.{name}__front"
        kind, key = ("matte", "kd") if isinstance(material, Diffuse) else ("mirror", "kr")
        lines = [f'{emits}.type = "{kind}"', f"{emits}.{key} = {_vec(material.reflectance)}",
                 f'{p}.type = "twosided"', f'{p}.frontmaterial = "{name}__front"', f'{p}.backmaterial = "__black"']
    else:
        raise ValueError(f"material {name!r}: {type(material).__name__} has no LuxCore translation")
    if radiance is not None:
        lines += [f"{emits}.emission = {_vec(radiance)}", f"{emits}.emission.gain = 1 1 1",
                  f"{emits}.emission.power = 0", f"{emits}.emission.efficency = 0",
                  f"{emits}.emission.normalizebycolor = 0", f"{emits}.emission.gain.normalizebycolor = 0"]
    return lines


def scene_text(scene: Scene, ply_names: list[str]) -> str:
    """The ``.scn`` file: camera, materials (one per emitter besides the scene's), shapes from ``ply_names``
    (meshes then spheres, in order) and objects."""
    centre, k = unit_frame(scene)
    cam = scene.camera
    x0, x1, y0, y1 = screenwindow(cam.width, cam.height)
    lines = ['scene.camera.type = "perspective"',
             f"scene.camera.lookat.orig = {_vec((np.asarray(cam.position) - centre) * k)}",
             f"scene.camera.lookat.target = {_vec((np.asarray(cam.look_at) - centre) * k)}",
             f"scene.camera.up = {_vec(cam.up)}",
             f"scene.camera.fieldofview = {camera_fov(scene)!r}",
             f"scene.camera.screenwindow = {x0!r} {x1!r} {y0!r} {y1!r}",
             "scene.camera.cliphither = 1e-05", "scene.camera.clipyon = 1e+30",
             'scene.materials.__black.type = "matte"', "scene.materials.__black.kd = 0 0 0"]
    for name, material in scene.materials.items():
        lines += _material_lines(name, material)
    objects = [(m.name, m.material, m.radiance) for m in scene.meshes]
    objects += [(s.name, s.material, None) for s in scene.spheres]
    for i, ((obj, material, radiance), ply) in enumerate(zip(objects, ply_names)):
        if radiance is not None:  # emission belongs to a material: each emitter gets its own copy
            mat = f"__emitter{i}"
            lines += _material_lines(mat, scene.materials[material], radiance)
        else:
            mat = material
        lines += [f'scene.shapes.shape{i}.type = "mesh"', f'scene.shapes.shape{i}.ply = "{ply}"',
                  f'scene.objects.object{i}.shape = "shape{i}"', f'scene.objects.object{i}.material = "{mat}"']
    return "\n".join(lines) + "\n"


def config_text(scene: Scene, scn: str = "scene.scn") -> str:
    """The ``.cfg`` file: unidirectional path tracing on the CPU, independent random samples, box filter.

    ``cbox-luxcore`` sets the halting spp, seed, threads and output on top of it."""
    cam, depth = scene.camera, depths(scene)
    return "\n".join([
        f'scene.file = "{scn}"',
        'renderengine.type = "PATHCPU"', 'sampler.type = "RANDOM"',
        f"film.width = {cam.width}", f"film.height = {cam.height}",
        'film.filter.type = "BOX"', "film.filter.width = 0.5",
        *(f"path.pathdepth.{k} = {v}" for k, v in depth.items()),
        # Russian roulette off: with it, LuxCore 2.11's MIS weights disagree (see the module docstring)
        "path.russianroulette.cap = 1", "path.clamping.variance.maxvalue = 0",
        'film.imagepipelines.0.0.type = "NOP"',
        'film.outputs.0.type = "RGB"', 'film.outputs.0.filename = "image.exr"',
        "batch.haltspp = 64", "renderengine.seed = 1",
    ]) + "\n"


def write(scene: Scene, folder: Path) -> Path:
    """Write ``scene.scn``, ``scene.cfg`` and the PLY meshes into ``folder``; return the ``.cfg``."""
    folder = Path(folder)
    centre, k = unit_frame(scene)
    names = []
    for i, m in enumerate(scene.meshes):
        names.append(f"mesh{i}.ply")
        write_ply(folder / names[-1], (m.vertices - centre) * k, m.triangles)
    for i, s in enumerate(scene.spheres):
        v, t, n = sphere_mesh(s)
        names.append(f"sphere{i}.ply")
        write_ply(folder / names[-1], (v - centre) * k, t, normals=n)
    (folder / "scene.scn").write_text(scene_text(scene, names))
    (folder / "scene.cfg").write_text(config_text(scene))
    return folder / "scene.cfg"

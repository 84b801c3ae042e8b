"""Blender Cycles adapter: a production path tracer (``bpy`` 5.0, the ``[cycles]`` extra), the harness's third
reference engine (``cbox reference verify --engine cycles``).

The scene is written as a plan (:func:`write_plan`: camera, materials, meshes, bounce limit, batches) into a
temporary folder and rendered by :mod:`cornell_harness.renderers.cycles_cli` in a child process started with
:func:`cornell_harness.processes.run` (so a signal or a time limit ends it with the command): ``bpy`` is
never imported here (see that module's docstring for why, and for how each material is built).

The render is split into independent batches (:func:`cornell_harness.renderers.batches.batch_plan`), batch k
with Cycles' seed ``pass_seed(seed, k)`` (31 bits), in one child; the variance of the mean comes from the
spread of the batch means, as LuxCore's. Each batch is exactly its spp per pixel (adaptive sampling off), so
a render is reproducible for a given seed and thread count.

Depth: our ``max_depth`` counts path segments (2 = direct light), Cycles' ``max_bounces`` bounces after the
first hit (0 = direct light), so ``max_bounces = max_depth − 2``, every kind's limit the same; unbounded
(−1) is Cycles' largest, :data:`UNBOUNDED_BOUNCES`, where Cycles' own Russian roulette ends the paths.
``max_depth`` 1 (emission only) has no Cycles equivalent and is refused.

``info`` holds the settings the render used, read back from Blender (``cycles``, ``view_transform``, ...).
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys
import tempfile
from functools import cache
from pathlib import Path
from typing import Sequence

import numpy as np

from cornell_harness import processes
from cornell_harness.adapters.api import Checkpoint, RenderResult, default_threads, pass_seed
from cornell_harness.extras import renderer_problem
from cornell_harness.renderers.batches import (BATCHES_SETTING, batch_plan, child_env, mean_and_variance,
                                               run_child_process)
from cornell_harness.scenes.export.luxcore import sphere_mesh
from cornell_harness.scenes.materials import Dielectric, Diffuse, Mirror
from cornell_harness.scenes.model import Scene, SceneError, object_bounds

FEATURES = frozenset({"triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light",
                      "pinhole_camera", "box_filter"})
#: Cycles' largest bounce limit (``max_bounces``' hard maximum): unbounded depth.
UNBOUNDED_BOUNCES = 1024
#: Seconds the child is given to start Blender and report its version.
VERSION_TIMEOUT_S = 120


def max_bounces(scene: Scene) -> int:
    """Cycles' ``max_bounces`` for the scene's ``max_depth`` (module docstring); SceneError for depth 1."""
    if scene.max_depth == 1:
        raise SceneError(scene.path, "render.max_depth",
                         "max_depth 1 (emission only) cannot be rendered by cycles: Cycles' fewest bounces (0) "
                         "add direct light; use 2 or more, or -1")
    return UNBOUNDED_BOUNCES if scene.max_depth < 0 else min(scene.max_depth - 2, UNBOUNDED_BOUNCES)


def camera_plan(scene: Scene) -> dict:
    """Blender's camera: the world matrix (columns right, up, −forward, position: Blender cameras look along
    their −Z with +Y up), the horizontal field of view and clipping distances around the scene."""
    cam = scene.camera
    right, up, forward = cam.frame()
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = right, up, -forward, cam.position
    lo, hi = object_bounds(scene.meshes, scene.spheres)
    far = float(np.linalg.norm(np.maximum(np.abs(lo - cam.position), np.abs(hi - cam.position))))
    return {"matrix": matrix.tolist(), "fov_x_rad": 2.0 * math.atan(cam.tan_half_fov()[0]),
            "clip_start": far * 1e-6, "clip_end": far * 2.0}


def material_plan(material) -> dict:
    if isinstance(material, Diffuse):
        return {"type": "diffuse", "reflectance": list(material.reflectance)}
    if isinstance(material, Mirror):
        return {"type": "mirror", "reflectance": list(material.reflectance)}
    if isinstance(material, Dielectric):
        return {"type": "dielectric", "int_ior": material.int_ior, "ext_ior": material.ext_ior}
    raise ValueError(f"cycles cannot render material {material.name!r} of type {material.type!r}")


def write_plan(scene: Scene, folder: Path, batches: Sequence[tuple[int, int]], threads: int) -> Path:
    """The child's plan (:mod:`cornell_harness.renderers.cycles_cli`) for ``batches`` of (spp, seed), in
    ``folder``: ``plan.json`` and one ``mesh-K.npz`` per mesh and sphere (spheres tessellated as in the
    LuxCore export, with their analytic normals)."""
    meshes = []
    for k, m in enumerate(scene.meshes):
        np.savez(folder / f"mesh-{k}.npz", vertices=m.vertices, triangles=m.triangles)
        meshes.append({"name": m.name, "material": m.material, "file": f"mesh-{k}.npz", "smooth": False,
                       "radiance": None if m.radiance is None else list(m.radiance)})
    for k, s in enumerate(scene.spheres, start=len(scene.meshes)):
        vertices, triangles, normals = sphere_mesh(s)
        np.savez(folder / f"mesh-{k}.npz", vertices=vertices, triangles=triangles, normals=normals)
        meshes.append({"name": s.name, "material": s.material, "file": f"mesh-{k}.npz", "smooth": True})
    plan = {"resolution": [scene.camera.width, scene.camera.height], "camera": camera_plan(scene),
            "max_bounces": max_bounces(scene), "threads": threads,
            "materials": {name: material_plan(m) for name, m in scene.materials.items()},
            "meshes": meshes, "batches": [{"spp": n, "seed": seed} for n, seed in batches]}
    path = folder / "plan.json"
    path.write_text(json.dumps(plan))
    return path


def run_child(folder: Path, time_limit_s: float | None = None) -> dict:
    """Render the plan in ``folder`` in a child; its ``settings.json`` (RuntimeError, quoting its stderr, if it
    fails)."""
    status, _, stderr = run_child_process([sys.executable, "-m", "cornell_harness.renderers.cycles_cli", str(folder)],
                                          folder, time_limit_s)
    if status != 0:
        said = [line for line in stderr.splitlines() if line.startswith("cycles: ")]  # the child's own last word
        raise RuntimeError(f"Cycles child exited with status {status}: {said[-1] if said else stderr}")
    return json.loads((folder / "settings.json").read_text())


def read_exr(path: Path) -> np.ndarray:
    """An EXR's RGB as float64 (H, W, 3), top row first."""
    import OpenImageIO as oiio

    image = oiio.ImageInput.open(str(path))
    if image is None:
        raise RuntimeError(f"{path}: cannot read the image Cycles wrote: {oiio.geterror()}")
    try:
        pixels = image.read_image(0, 0, 0, 3, "float")
    finally:
        image.close()
    return np.asarray(pixels, dtype=np.float64)


@cache
def _child_version() -> str:
    with tempfile.TemporaryDirectory(prefix="cbox-cycles-") as tmp:
        out = Path(tmp) / "version.txt"
        code = "import os, sys, bpy; open(sys.argv[1], 'w').write(bpy.app.version_string); os._exit(0)"
        status = processes.run([sys.executable, "-c", code, str(out)], VERSION_TIMEOUT_S,
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=child_env(Path(tmp)))
        if status != 0 or not out.is_file():
            raise RuntimeError(f"bpy.app.version_string failed in a child (status {status})")
        return out.read_text().strip()


class Cycles:
    """Blender Cycles (CPU), through a scene built with ``bpy`` in a child process."""

    name = "cycles"
    citations = (
        "Blender 5.0's Cycles, https://www.cycles-renderer.org",)
    features = FEATURES
    quantities = ("radiance",)
    estimator = "unbiased"
    settings = (BATCHES_SETTING,)

    def unavailable_reason(self) -> str | None:
        # Found, never imported: bpy is Blender, and runs only in the child (module docstring).
        if importlib.util.find_spec("bpy") is None:
            return renderer_problem(self.name) or "bpy is not installed"
        return None

    def version(self) -> str:
        return _child_version()

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None) -> RenderResult:
        batches = int((settings or {}).get("batches", BATCHES_SETTING.default))
        sizes = batch_plan(spp, max(2, batches) if spp >= 2 else 1, checkpoints)
        seeds = [pass_seed(seed, k) & 0x7FFFFFFF for k in range(len(sizes))]  # Cycles' seed is a signed int
        threads = default_threads()
        with tempfile.TemporaryDirectory(prefix="cbox-cycles-") as tmp:
            folder = Path(tmp)
            write_plan(scene, folder, list(zip(sizes, seeds)), threads)
            used = run_child(folder)
            means = [read_exr(folder / f"batch-{k}.exr") for k in range(len(sizes))]
        return _result(means, used, sizes, spp, seed, checkpoints, threads)


def _result(means, used, sizes, spp, seed, checkpoints, threads) -> RenderResult:
    """The image, the variance of its mean and the checkpoints, from the batch means."""
    shots, done, elapsed, cpu = [], 0, 0.0, 0.0
    for k, n in enumerate(sizes):
        done += n
        elapsed += used["batches"][k]["seconds"]
        cpu += used["batches"][k]["cpu_seconds"]
        if done in checkpoints:
            image, _ = mean_and_variance(means[:k + 1], sizes[:k + 1])
            shots.append(Checkpoint(done, image.astype(np.float32), elapsed, cpu_time_s=cpu))
    image, variance = mean_and_variance(means, sizes)
    info = {"threads": threads, "batches": len(sizes), "blender": used["version"],
            **{k: v for k, v in used.items() if k not in ("batches", "version")}}
    return RenderResult(image.astype(np.float32), elapsed, spp, seed, shots, info,
                        None if variance is None else variance.astype(np.float32), cpu_time_s=cpu)

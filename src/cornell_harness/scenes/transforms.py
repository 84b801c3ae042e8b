"""Scene transforms and measures: new scenes made from a scene by ``dataclasses.replace``.

Each transform returns a new :class:`~cornell_harness.scenes.model.Scene` (renamed so
its variant shows in its name) and leaves the input untouched; the meshes it
does not change are shared, not copied. The measures (:func:`emitter_area`,
:func:`emitter_power`, :func:`emitter_footprint`) are what the transforms are
checked by, and what a comparison restricted to part of the image needs.
:func:`unit_frame` is the change of units the Mitsuba adapter and its export share. The
stress suite (:mod:`cornell_harness.stress.variants`) builds its variants with them.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from cornell_harness.scenes.model import Camera, Mesh, Scene


def _triangle_areas(mesh: Mesh) -> np.ndarray:
    a, b, c = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def unit_frame(scene: Scene) -> tuple[np.ndarray, float]:
    """(centre, scale) that map the scene's bounding box to the origin with diagonal 1: ``(p - centre) * scale``.

    What Mitsuba 3 renders and exports (:mod:`cornell_harness.scenes.export.mitsuba`): its ray offsets are
    about 1e-4·(1 + |p|) scene units whatever the scene's size, so a scene far from unit size leaks
    light; a uniform change of units leaves radiance images unchanged.
    """
    lo, hi = scene.bounds()
    return (lo + hi) / 2.0, 1.0 / scene.extent()


def emitter_area(scene: Scene) -> float:
    """Total area of the emitter triangles."""
    return sum((float(_triangle_areas(m).sum()) for m in scene.emitters), 0.0)


def emitter_power(scene: Scene) -> np.ndarray:
    """Σ Le·A over emitters, per channel (the emitted power is π times this)."""
    power = np.zeros(3)
    for m in scene.emitters:
        power += float(_triangle_areas(m).sum()) * np.asarray(m.radiance, dtype=np.float64)
    return power


def shrink_lights(scene: Scene, area_factor: float = 1e-4) -> Scene:
    """Every emitter shrunk about its vertex centroid to ``area_factor`` of its area, radiance / area_factor.

    Lengths scale by sqrt(area_factor), so the power Le·A of every emitter is
    unchanged (up to float rounding).
    """
    k = math.sqrt(area_factor)
    meshes = []
    for m in scene.meshes:
        if m.is_emitter:
            centre = m.vertices.mean(axis=0)
            m = dataclasses.replace(m, vertices=centre + (m.vertices - centre) * k,
                                    radiance=tuple(float(x) / area_factor for x in m.radiance))
        meshes.append(m)
    return dataclasses.replace(scene, name=f"{scene.name}-small-light", meshes=tuple(meshes))


def scale_radiance(scene: Scene, peak: float = 1e6) -> tuple[Scene, float]:
    """Every emitter's radiance times ``s`` so that the largest channel of any emitter is ``peak``; (scene, s)."""
    top = max(max(m.radiance) for m in scene.emitters)
    s = peak / top
    meshes = tuple(dataclasses.replace(m, radiance=tuple(float(x) * s for x in m.radiance)) if m.is_emitter else m
                   for m in scene.meshes)
    return dataclasses.replace(scene, name=f"{scene.name}-radiance-{peak:g}", meshes=meshes), s


def scale_geometry(scene: Scene, s: float) -> Scene:
    """The scene with every vertex, sphere, region box and the camera's position and target multiplied by ``s``."""
    meshes = tuple(dataclasses.replace(m, vertices=m.vertices * s) for m in scene.meshes)
    spheres = tuple(dataclasses.replace(b, center=tuple(s * c for c in b.center), radius=b.radius * s)
                    for b in scene.spheres)
    regions = {k: dataclasses.replace(g, box=None if g.box is None else tuple(tuple(s * c for c in p) for p in g.box))
               for k, g in scene.regions.items()}
    cam = dataclasses.replace(scene.camera, position=tuple(s * c for c in scene.camera.position),
                              look_at=tuple(s * c for c in scene.camera.look_at))
    return dataclasses.replace(scene, name=f"{scene.name}-scaled-{s:g}", meshes=meshes, spheres=spheres,
                               regions=regions, camera=cam)


#: Grazing camera: this far in front of the Cornell box's back wall (z = -1), looking along it.
GRAZING_DISTANCE = 0.01
#: ... with its view direction this many degrees off the wall's plane, towards the wall.
GRAZING_ANGLE_DEG = 2.0


def grazing_camera(scene: Scene, res: int = 128) -> Scene:
    """The Cornell box seen from just in front of its back wall, looking along it (towards +x).

    The camera sits :data:`GRAZING_DISTANCE` in front of the back wall
    (z = -1), at x = -0.95, y = 0.4 (above the tall box), and looks towards the
    green wall, turned :data:`GRAZING_ANGLE_DEG` degrees towards the back
    wall: its central ray meets the wall at that angle, the left half of the
    image sees the wall at 2°-22°, and rays that are more grazing still run
    along the wall to the green wall.
    """
    a = math.radians(GRAZING_ANGLE_DEG)
    pos = (-0.95, 0.4, -1.0 + GRAZING_DISTANCE)
    look = (pos[0] + math.cos(a), pos[1], pos[2] - math.sin(a))
    cam = Camera(position=pos, look_at=look, up=(0.0, 1.0, 0.0), fov_deg=40.0, fov_axis="smaller",
                 width=int(res), height=int(res))
    return dataclasses.replace(scene, name=f"{scene.name}-grazing", camera=cam)


def emitter_footprint(scene: Scene, margin: int = 1) -> np.ndarray:
    """(H, W) bool: pixels that may see an emitter directly (bounding box of its projection, + ``margin`` px)."""
    cam = scene.camera
    mask = np.zeros((cam.height, cam.width), dtype=bool)
    for m in scene.emitters:
        cr = cam.project_to_pixels(m.vertices)
        c0, r0 = np.floor(cr.min(axis=0)).astype(int) - margin
        c1, r1 = np.floor(cr.max(axis=0)).astype(int) + margin
        mask[max(r0, 0):max(min(r1 + 1, cam.height), 0), max(c0, 0):max(min(c1 + 1, cam.width), 0)] = True
    return mask

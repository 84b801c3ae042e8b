"""A scene file's declared length unit: ``length_scale``, the factor from the file's lengths to scene units.

A file may give its lengths in the unit they were published in (Cornell's
box is in millimetres) and declare ``length_scale = 0.001``: every length of
the file (mesh vertices, sphere centres and radii, the camera's position and
target, region boxes, an ambient-occlusion ``max_distance``) is multiplied by
it at load, so the :class:`~cornell_harness.scenes.model.Scene` holds scene units
only and nothing downstream knows the file's unit. Absent, the scale is 1 and
the scene is exactly what it was before the key existed (same content hash).
Radiance is per scene unit (:mod:`cornell_harness.scenes.model`), so a scaled file
renders to the same image.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from cornell_harness.scenes.model import MAX_COORDINATE, Scene
from cornell_harness.scenes.transforms import scale_geometry

#: Smallest and largest ``length_scale``: nm to m is 1e-9, and a factor beyond these only invites underflow.
LENGTH_SCALE_RANGE = (1e-9, 1e9)


def apply_length_scale(err, doc: dict, scene: Scene, check_degenerate) -> Scene:
    """``scene`` with the file's ``length_scale`` (in :data:`LENGTH_SCALE_RANGE`, as the scene schema checks)
    applied; ``err(field, message)`` is the loader's error of the file, ``check_degenerate`` its check of
    triangle areas, run again on the scaled meshes."""
    s = float(doc.get("length_scale", 1.0))
    if s == 1.0:
        return scene
    out = dataclasses.replace(scale_geometry(scene, s), name=scene.name)
    if out.ambient_occlusion is not None:
        ao = out.ambient_occlusion
        out = dataclasses.replace(out, ambient_occlusion=dataclasses.replace(ao, max_distance=ao.max_distance * s))
    lo_, hi_ = out.bounds()
    cam = out.camera
    top = max(float(np.abs(lo_).max()), float(np.abs(hi_).max()), *map(abs, cam.position), *map(abs, cam.look_at))
    if top > MAX_COORDINATE:
        raise err("length_scale", f"scales a coordinate to {top:g}, beyond the {MAX_COORDINATE:g} limit")
    check_degenerate(err, out.meshes)
    return out

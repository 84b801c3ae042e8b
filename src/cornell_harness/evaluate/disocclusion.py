"""Disocclusion masks from the reference's motion: the pixels whose surface at frame i was not seen at frame i − 1.

A temporal method reprojects its history along the motion; where the surface a pixel sees now was hidden (or off
screen) in the previous frame, it has no valid history and shows ghosts. The masks here are the scene's truth,
computed from the two still scenes of the frames (``scene.at_frame(i − 1)``, ``scene.at_frame(i)``) by ray
casting through pixel centres (:func:`cornell_harness.evaluate.regions.first_hits`), not from any renderer's
buffers: each object's motion between the frames is the translation of its vertices' mean (a sphere's centre),
as animation tracks translate named objects, and the camera of each frame is its own.

A pixel is uncovered when its first hit p at frame i, on object o, moved back by o's translation to p', is not
what the previous frame's camera sees first along its ray to p' (another surface nearer, or p' outside that
frame's image). Pixels that see nothing are never uncovered.
"""

from __future__ import annotations

import numpy as np

from cornell_harness.evaluate.regions import first_hits
from cornell_harness.scenes.model import Scene

#: A previous-frame hit this near p' (relative to the scene's size) is p' itself.
SAME_POINT = 1e-4


def _centres(scene: Scene) -> np.ndarray:
    """Each object's reference point (n, 3), in :meth:`Scene.object_names` order: vertex means, sphere centres."""
    return np.array([m.vertices.mean(axis=0) for m in scene.meshes] + [s.center for s in scene.spheres],
                    dtype=np.float64)


def pixel_centre_hits(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """(object (H, W), point (H, W, 3)) first hit through each pixel's centre; -1 and NaN where none."""
    cam = scene.camera
    cols, rows = np.meshgrid(np.arange(cam.width) + 0.5, np.arange(cam.height) + 0.5)
    obj, points = first_hits(scene, cam.directions(cols, rows))
    return obj.reshape(cam.height, cam.width), points.reshape(cam.height, cam.width, 3)


def disocclusion_mask(previous: Scene, current: Scene) -> np.ndarray:
    """(H, W) bool of ``current``'s pixels whose surface ``previous`` did not show (module docstring). The scenes
    are two consecutive frames' still scenes: the same objects, in the same order."""
    if previous.object_names() != current.object_names():
        raise ValueError("the two frames' scenes have different objects")
    obj, points = pixel_centre_hits(current)
    seen = obj >= 0
    moved = np.zeros_like(points)
    moved[seen] = points[seen] - (_centres(current) - _centres(previous))[obj[seen]]
    cam = previous.camera
    origin = np.asarray(cam.position, dtype=np.float64)
    dirs = moved[seen] - origin
    # The same point, whatever object the previous frame names there: where two surfaces meet (a wall's edge on
    # the floor) either may be the first hit.
    _, hit_points = first_hits(previous, dirs)
    tol = SAME_POINT * current.extent()
    with np.errstate(invalid="ignore"):  # NaN points (no hit) are not the same point
        same = np.linalg.norm(hit_points - moved[seen], axis=1) <= tol
    in_view = np.zeros(len(dirs), dtype=bool)
    ahead = dirs @ cam.frame()[2] > 0
    if ahead.any():
        px = cam.project_to_pixels(moved[seen][ahead])
        in_view[ahead] = (px[:, 0] >= 0) & (px[:, 0] <= cam.width) & (px[:, 1] >= 0) & (px[:, 1] <= cam.height)
    out = np.zeros(obj.shape, dtype=bool)
    out[seen] = ~(same & in_view)
    return out


def disocclusion_masks(scenes: list[Scene]) -> np.ndarray:
    """(F, H, W) bool: frame 0's mask empty (it has no previous frame), then :func:`disocclusion_mask` of each
    frame against the one before it."""
    first = np.zeros((scenes[0].camera.height, scenes[0].camera.width), dtype=bool)
    return np.stack([first] + [disocclusion_mask(a, b) for a, b in zip(scenes, scenes[1:])])

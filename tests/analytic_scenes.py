"""Scenes with analytic answers, written as scene files, and their exact solutions.

The white furnace lives in :mod:`harness.stress` (the stress suite uses it too).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.scene import Scene, load_scene


def _fmt(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"

# Rectangle light over a floor: light of half-sizes (A, B) at height H, facing down.
LIGHT_A, LIGHT_B, LIGHT_H, LIGHT_LE, FLOOR_RHO = 0.3, 0.2, 1.0, 5.0, 0.75


def rectangle_light_scene(folder: Path, res: int = 16, max_depth: int = -1) -> Scene:
    """A white floor [-1,1]² at z=0 under a rectangular emitter; camera straight above, looking down.

    Nothing else is in the scene, so the floor's radiance is ρ/π · E(x), E
    from the polygon irradiance formula (:func:`polygon_irradiance`). The
    camera sees the light's black back side in the middle of the image.
    """
    a, b, h = LIGHT_A, LIGHT_B, LIGHT_H
    text = f"""format = 1
name = "rectangle-light"
features = ["triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"]
[camera]
type = "pinhole"
position = [0.0, 0.0, 3.0]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 1.0, 0.0]
fov_deg = 30.0
fov_axis = "smaller"
resolution = [{res}, {res}]
[render]
max_depth = {max_depth}
pixel_filter = "box"
[materials.white]
type = "diffuse"
reflectance = {_fmt([FLOOR_RHO] * 3)}
[materials.black]
type = "diffuse"
reflectance = [0.0, 0.0, 0.0]
[[meshes]]
name = "floor"
material = "white"
vertices = [[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]]
faces = [[0, 1, 2, 3]]
[[meshes]]
name = "light"
material = "black"
vertices = [[{-a}, {-b}, {h}], [{-a}, {b}, {h}], [{a}, {b}, {h}], [{a}, {-b}, {h}]]
faces = [[0, 1, 2, 3]]
emitter = {{ radiance = {_fmt([LIGHT_LE] * 3)} }}
"""
    path = folder / "rectangle-light.toml"
    path.write_text(text)
    return load_scene(path)


def polygon_irradiance(points: np.ndarray, normal: np.ndarray, polygon: np.ndarray, radiance: float) -> np.ndarray:
    """Irradiance at ``points`` (n,3) with ``normal`` from a Lambertian polygon of radiance L.

    Lambert's polygon formula (Arvo 1995, "Applications of Irradiance Tensors", eq. 4):
    E = (L/2) Σ_i Θ_i (u_i · n), Θ_i the angle subtended by edge i and u_i the
    unit normal of the plane through the point and that edge, for a polygon
    wound counter-clockwise as seen from the point.
    """
    e = np.zeros(len(points))
    for i in range(len(polygon)):
        r1 = polygon[i] - points
        r2 = polygon[(i + 1) % len(polygon)] - points
        r1 /= np.linalg.norm(r1, axis=1, keepdims=True)
        r2 /= np.linalg.norm(r2, axis=1, keepdims=True)
        theta = np.arccos(np.clip(np.einsum("ij,ij->i", r1, r2), -1, 1))
        c = np.cross(r1, r2)
        c /= np.linalg.norm(c, axis=1, keepdims=True)
        e += theta * (c @ normal)
    return 0.5 * radiance * np.abs(e)


def rectangle_light_image(scene: Scene, sub: int = 16) -> np.ndarray:
    """Exact box-filtered image of :func:`rectangle_light_scene` (sub×sub points per pixel)."""
    cam = scene.camera
    right, up, forward = cam.frame()
    tx, ty = cam.tan_half_fov()
    offs = (np.arange(sub) + 0.5) / sub
    col = (np.arange(cam.width)[:, None] + offs[None, :]).ravel()
    row = (np.arange(cam.height)[:, None] + offs[None, :]).ravel()
    rr, cc = np.meshgrid(row, col, indexing="ij")
    sx = (2 * cc / cam.width - 1) * tx
    sy = (1 - 2 * rr / cam.height) * ty
    d = forward + sx[..., None] * right + sy[..., None] * up
    o = np.asarray(cam.position)
    t = -o[2] / d[..., 2]
    pts = (o + t[..., None] * d).reshape(-1, 3)
    a, b, h = LIGHT_A, LIGHT_B, LIGHT_H
    poly = np.array([[-a, -b, h], [a, -b, h], [a, b, h], [-a, b, h]], float)
    e = polygon_irradiance(pts, np.array([0, 0, 1.0]), poly, LIGHT_LE)
    inside = (np.abs(pts[:, 0]) <= 1) & (np.abs(pts[:, 1]) <= 1)
    # The light's black back side hides the middle of the floor from the camera.
    tl = (h - o[2]) / d[..., 2]
    pl = (o + tl[..., None] * d).reshape(-1, 3)
    inside &= ~((np.abs(pl[:, 0]) <= a) & (np.abs(pl[:, 1]) <= b))
    radiance = np.where(inside, FLOOR_RHO / np.pi * e, 0.0).reshape(cam.height, sub, cam.width, sub)
    return np.repeat(radiance.mean(axis=(1, 3))[..., None], 3, axis=2)

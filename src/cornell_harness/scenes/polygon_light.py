"""Scenes lit by one rectangle light, whose images are exact by Lambert's polygon formula.

- **Rectangle light over a floor** (:func:`rectangle_light_scene`,
  :func:`rectangle_light_image`): one-bounce direct light with an exact
  box-filtered image from Lambert's polygon formula
  (:func:`polygon_irradiance`). Written as a scene file, so the loader is
  exercised too.
- **The same light seen only in a mirror** (:func:`mirrored_light_scene`,
  :func:`mirrored_light_image`): the floor's light is all a caustic, exact
  from the polygon formula for the light's mirror image; photon mappers
  must estimate it from photons.
- **A mirror caustic on a patch in a black world** (:func:`mirror_caustic_scene`):
  the same light and mirror, the floor cut to a patch the camera sees
  whole, with nothing around it; :func:`mirrored_light_image` is its
  exact image too (the polygon formula for the light's image source).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from cornell_harness.scenes.analytic import ANALYTIC_FEATURES, quads_to_triangles, subpixel_directions
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.materials import Mirror
from cornell_harness.scenes.model import Camera, Diffuse, Mesh, Scene

# ----------------------------------------------------------------------------------------
# Rectangle light over a floor
# ----------------------------------------------------------------------------------------

# Rectangle light over a floor: light of half-sizes (A, B) at height H, facing down.
LIGHT_A, LIGHT_B, LIGHT_H, LIGHT_LE, FLOOR_RHO = 0.3, 0.2, 1.0, 5.0, 0.75


def _fmt(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def rectangle_light_scene(folder: Path, res: int = 16, max_depth: int = -1) -> Scene:
    """A white floor [-1,1]² at z=0 under a rectangular emitter; camera straight above, looking down.

    Written to ``folder/rectangle-light.toml`` and loaded from there. Nothing
    else is in the scene, so the floor's radiance is ρ/π · E(x) (Lambert's
    law: a Lambertian surface reflects ρ/π of its irradiance as radiance),
    E from the polygon irradiance formula (:func:`polygon_irradiance`). The
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
    """Exact box-filtered image of :func:`rectangle_light_scene` (sub×sub points per pixel).

    Each point's radiance is ρ/π · E (Lambert's law), E from
    :func:`polygon_irradiance`; the box filter is the mean over a pixel's
    sub×sub grid.
    """
    cam = scene.camera
    d = subpixel_directions(cam, sub)
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


# ----------------------------------------------------------------------------------------
# A rectangle light seen by the floor only through a mirror
# ----------------------------------------------------------------------------------------

#: The mirrored light: the panel (half-sizes LIGHT_A, LIGHT_B, radiance LIGHT_LE) faces up at height
#: MIRROR_LIGHT_H under a mirror of reflectance 1 facing down at MIRROR_H; the floor is at z = 0.
MIRROR_LIGHT_H, MIRROR_H = 1.0, 1.5


def mirrored_light_scene(res: int = 24) -> Scene:
    """A floor lit only by a rectangle light's image in a mirror: all of its light is a caustic (L S D).

    The panel faces up at z = 1 (its black back faces the floor), a perfect
    mirror faces down at z = 1.5, and max_depth = 3 keeps the single bounce
    camera → floor → mirror → light (light that goes on to the mirror again
    is cut). The floor's exact radiance is :func:`mirrored_light_image`. A
    photon mapper estimates it from photons alone (the floor cannot sample
    a light it sees only in a mirror), which makes it the analytic case of
    photon density estimation.
    """
    a, b, h, top = LIGHT_A, LIGHT_B, MIRROR_LIGHT_H, MIRROR_H
    camera = Camera(position=(0.0, -2.4, 0.9), look_at=(0.0, 0.3, 0.0), up=(0.0, 0.0, 1.0), fov_deg=60.0,
                    fov_axis="smaller", width=int(res), height=int(res))
    quad = np.array([[0, 1, 2, 3]])
    meshes = (
        Mesh("floor", np.array([[-1.6, -1.6, 0], [1.6, -1.6, 0], [1.6, 1.6, 0], [-1.6, 1.6, 0]], float),
             quads_to_triangles(quad), "white", (0.0, 0.0, 0.0)),
        Mesh("panel", np.array([[-a, -b, h], [a, -b, h], [a, b, h], [-a, b, h]], float),
             quads_to_triangles(quad), "black", (LIGHT_LE,) * 3),
        Mesh("mirror", np.array([[-1.0, -1.0, top], [-1.0, 1.0, top], [1.0, 1.0, top], [1.0, -1.0, top]], float),
             quads_to_triangles(quad), "mirror", (0.0, 0.0, 0.0)),
    )
    materials = {"white": Diffuse("white", (FLOOR_RHO,) * 3), "black": Diffuse("black", (0.0,) * 3),
                 "mirror": Mirror("mirror", (1.0, 1.0, 1.0))}
    return Scene(name="mirrored-light", path=Path("analytic") / "mirrored-light.toml",
                 features=ANALYTIC_FEATURES | {"mirror"}, camera=camera, materials=materials, meshes=meshes,
                 max_depth=3, pixel_filter="box", description="a floor lit by a light's image in a mirror")


def mirrored_light_image(scene: Scene, sub: int = 8, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Exact box-filtered image of :func:`mirrored_light_scene`, and the mask of the pixels it holds for.

    A floor point p sees the light's mirror image, the panel reflected to
    z' = 2·1.5 − 1 = 2, facing down: E(p) from the polygon formula for that
    polygon, radiance ρ/π · E. A ray from p to a point q of the image crosses
    the panel's plane halfway ((p + q)/2), so the panel's black back hides
    none of it when |p_x| > 3a or |p_y| > 3b; the mask keeps the pixels whose
    every sub-sample lands on the floor there (and sees nothing else first),
    at least ``margin`` inside the floor's edge (the bounds of the scene's
    first mesh, the floor or a patch of it) and that boundary (a density
    estimate blurs across both).
    """
    cam = scene.camera
    d = subpixel_directions(cam, sub)
    o = np.asarray(cam.position)
    t = -o[2] / d[..., 2]
    pts = (o + t[..., None] * d).reshape(-1, 3)
    a, b = LIGHT_A, LIGHT_B
    z_image = 2 * MIRROR_H - MIRROR_LIGHT_H
    poly = np.array([[-a, -b, z_image], [a, -b, z_image], [a, b, z_image], [-a, b, z_image]], float)
    e = polygon_irradiance(pts, np.array([0, 0, 1.0]), poly, LIGHT_LE)
    floor = scene.meshes[0].vertices
    (x0, y0), (x1, y1) = floor[:, :2].min(axis=0) + margin, floor[:, :2].max(axis=0) - margin
    ok = (t.reshape(-1) > 0) & (pts[:, 0] >= x0) & (pts[:, 0] <= x1) & (pts[:, 1] >= y0) & (pts[:, 1] <= y1)
    ok &= (np.abs(pts[:, 0]) > 3 * a + margin) | (np.abs(pts[:, 1]) > 3 * b + margin)
    # The camera (below the panel) must not see the panel in front of the floor point.
    tl = (MIRROR_LIGHT_H - o[2]) / d[..., 2]
    pl = (o + tl[..., None] * d).reshape(-1, 3)
    ok &= ~((tl.reshape(-1) > 0) & (tl.reshape(-1) < t.reshape(-1)) & (np.abs(pl[:, 0]) <= a) & (np.abs(pl[:, 1]) <= b))
    radiance = np.where(ok, FLOOR_RHO / np.pi * e, 0.0).reshape(cam.height, sub, cam.width, sub).mean(axis=(1, 3))
    mask = ok.reshape(cam.height, sub, cam.width, sub).all(axis=(1, 3))
    return np.repeat(radiance[..., None], 3, axis=2), mask


#: The patch of :func:`mirror_caustic_scene`: x in [1.0, 1.6], |y| ≤ 0.3 on the floor (z = 0), beyond the
#: panel's shadow (|x| > 3·LIGHT_A), lit only through the mirror's part x in [0, 0.65], |y| ≤ 0.25.
CAUSTIC_PATCH = (1.0, -0.3, 1.6, 0.3)


def mirror_caustic_scene(res: int = 32) -> Scene:
    """A diffuse patch lit only through a mirror, in a black world: a closed-form caustic with edges.

    :func:`mirrored_light_scene` with the floor cut to :data:`CAUSTIC_PATCH`
    and the mirror to what carries light from the panel to the patch (every
    ray from the panel's mirror image to the patch crosses z = 1.5 within
    x in [0.025, 0.625], |y| ≤ 0.225). The camera, 0.9 above the patch's
    centre looking straight down (50°), sees the patch whole, about 72% of the
    image's width, with black around it: the discs of a density estimate
    near the patch's edge reach off it (the edge's bias), those inside do not
    (the interior, which a consistent estimator must get right up to the
    curvature of the irradiance over the disc). Its exact image is
    :func:`mirrored_light_image`.
    """
    base = mirrored_light_scene(res)
    floor, panel, mirror = base.meshes
    x0, y0, x1, y1 = CAUSTIC_PATCH
    patch = np.array([[x0, y0, 0.0], [x1, y0, 0.0], [x1, y1, 0.0], [x0, y1, 0.0]])
    top = mirror.vertices[0, 2]
    cover = np.array([[0.0, -0.25, top], [0.0, 0.25, top], [0.65, 0.25, top], [0.65, -0.25, top]])
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    camera = Camera(position=(cx, cy, 0.9), look_at=(cx, cy, 0.0), up=(0.0, 1.0, 0.0), fov_deg=50.0,
                    fov_axis="smaller", width=int(res), height=int(res))
    return dataclasses.replace(base, name="mirror-caustic", path=Path("analytic") / "mirror-caustic.toml",
                               camera=camera, description="a patch lit by a light's image in a mirror, nothing around",
                               meshes=(dataclasses.replace(floor, vertices=patch), panel,
                                       dataclasses.replace(mirror, vertices=cover)))

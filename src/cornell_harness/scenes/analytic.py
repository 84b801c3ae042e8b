"""Scenes whose images have analytic answers, and those answers.

- **White furnace** (:func:`furnace_scene`, :func:`furnace_radiance`): a closed
  cube, every face of albedo ρ emitting Le, the camera inside. Built directly
  from the dataclasses (no file); the stress suite (:mod:`cornell_harness.stress`)
  and the path tracer's tests use it.
- **Spectral furnace** (:func:`spectral_furnace_scene`, :func:`spectral_furnace_radiance`):
  the white furnace with a non-flat albedo spectrum ρ(λ) and an emission
  spectrum L(λ) (issue 33's validation of spectral renderers): per
  wavelength Le/(1-ρ), projected to linear sRGB as the scene model projects
  an emitter. Its RGB projection is an ordinary scene, whose RGB answer
  differs from the spectral one: the error of rendering it in RGB.
- **Specular furnace** (:func:`specular_furnace_scene`,
  :func:`specular_furnace_camera_in_glass`): the furnace with lossless glass
  (a sphere and a cube) and a mirror sphere inside. Lossless specular
  objects leave the furnace's radiance unchanged, Le/(1-ρ) everywhere seen
  from the air; a camera inside glass of index n sees n² times it.
- **Rectangle light over a floor** (:func:`rectangle_light_scene`,
  :func:`rectangle_light_image`): one-bounce direct light with an exact
  box-filtered image from Lambert's polygon formula
  (:func:`polygon_irradiance`). Written as a scene file, so the loader is
  exercised too.
- **The same light seen only in a mirror** (:func:`mirrored_light_scene`,
  :func:`mirrored_light_image`): the floor's light is all a caustic, exact
  from the polygon formula for the light's mirror image; photon mappers
  must estimate it from photons.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.materials import Dielectric, Mirror
from cornell_harness.scenes.model import Camera, Diffuse, Mesh, Scene, Sphere
from cornell_harness.scenes.spectra import (ILLUMINANT_E, OBSERVER, OUTPUT, SCENE_LIGHT, Spectrum, emission_rgb, observer,
                                    reflectance_rgb, xyz_to_linear_srgb)
from cornell_harness.scenes.spectral_scene import SpectralContent

# ----------------------------------------------------------------------------------------
# White furnace
# ----------------------------------------------------------------------------------------

#: Faces of the cube [-1, 1]^3 wound so their normals point INTO the box.
#: Vertex index = 4*(x>0) + 2*(y>0) + (z>0).
_CUBE_INWARD = ((0, 1, 5, 4), (2, 6, 7, 3), (4, 5, 7, 6), (0, 2, 3, 1), (1, 3, 7, 5), (0, 4, 6, 2))
_CUBE_VERTS = tuple((x, y, z) for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0))
_ALL_FEATURES = frozenset({"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"})


def _subpixel_directions(cam: Camera, sub: int) -> np.ndarray:
    """(H·sub, W·sub, 3) camera directions through a sub×sub grid of points centred in each pixel's cells."""
    offs = (np.arange(sub) + 0.5) / sub
    col = (np.arange(cam.width)[:, None] + offs[None, :]).ravel()
    row = (np.arange(cam.height)[:, None] + offs[None, :]).ravel()
    return cam.directions(col[None, :], row[:, None])


def _quads_to_triangles(quads) -> np.ndarray:
    return np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], dtype=np.int64)


def furnace_scene(albedo: float, radiance: float = 1.0, max_depth: int = -1, res: int = 16,
                  scale: float = 1.0) -> Scene:
    """A closed cube, every face of reflectance ``albedo`` emitting ``radiance``; pinhole camera at its centre.

    Its radiance everywhere, in every direction, is :func:`furnace_radiance`.
    """
    name = f"furnace-albedo-{albedo:g}"
    camera = Camera(position=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, -scale), up=(0.0, 1.0, 0.0), fov_deg=100.0,
                    fov_axis="smaller", width=int(res), height=int(res))
    mesh = Mesh("box", np.asarray(_CUBE_VERTS, dtype=np.float64) * scale, _quads_to_triangles(_CUBE_INWARD),
                "grey", (float(radiance),) * 3)
    return Scene(name=name, path=Path("stress") / f"{name}.toml", features=_ALL_FEATURES, camera=camera,
                 materials={"grey": Diffuse("grey", (float(albedo),) * 3)}, meshes=(mesh,),
                 max_depth=int(max_depth), pixel_filter="box",
                 description=f"white furnace: closed cube, albedo {albedo:g}, emission {radiance:g}")


def furnace_radiance(albedo: float, radiance: float, max_depth: int) -> float:
    """Radiance in the furnace: Le·Σ_{k<D} ρ^k at max_depth D; Le/(1-ρ) unbounded (inf at ρ = 1).

    Every surface sees uniform radiance L, and a Lambertian surface lit by
    uniform radiance L reflects ρ·L, so the rendering equation (Kajiya 1986)
    reduces to L = Le + ρ·L; its Neumann series, cut after D path segments,
    is the sum above (the white-furnace test, e.g. Pharr, Jakob and Humphreys,
    "Physically Based Rendering", 4th ed., 2023).
    """
    if max_depth < 0:
        return math.inf if albedo >= 1.0 else radiance / (1.0 - albedo)
    return radiance * sum(albedo**k for k in range(max_depth))


# ----------------------------------------------------------------------------------------
# Spectral furnace: the white furnace with a spectral albedo and a spectral emitter
# ----------------------------------------------------------------------------------------

#: The spectral furnace's albedo ρ(λ): a green band (0.85 at 530 nm) over a low floor, far from flat, so that
#: L/(1-ρ) per wavelength and per RGB channel disagree. Sampled over the observer's whole range, 360-830 nm.
SPECTRAL_FURNACE_ALBEDO = Spectrum((360.0, 450.0, 500.0, 530.0, 560.0, 620.0, 830.0),
                                   (0.15, 0.2, 0.6, 0.85, 0.6, 0.3, 0.1))
#: Its emission L(λ): a warm ramp, 0.6 at 360 nm to 1.4 at 830 nm.
SPECTRAL_FURNACE_EMISSION = Spectrum((360.0, 830.0), (0.6, 1.4))


def spectral_furnace_scene(max_depth: int = -1, res: int = 16, convention: str = ILLUMINANT_E) -> Scene:
    """:func:`furnace_scene` with albedo :data:`SPECTRAL_FURNACE_ALBEDO` and emission :data:`SPECTRAL_FURNACE_EMISSION`.

    A spectral scene as the loader makes one: ``Scene.spectral`` binds the
    material's reflectance and the box's emission to the spectra, and the
    material and mesh hold their RGB projection (the reflectance by
    ``convention``, the emission by :func:`cornell_harness.scenes.spectra.emission_rgb`),
    which RGB renderers read. The spectral answer is
    :func:`spectral_furnace_radiance`; an RGB renderer converges instead to
    :func:`furnace_radiance` of the projected values, channel by channel.
    """
    rho, le = SPECTRAL_FURNACE_ALBEDO, SPECTRAL_FURNACE_EMISSION
    base = furnace_scene(0.0, 0.0, max_depth, res)
    light = le if convention == SCENE_LIGHT else None
    spectral = SpectralContent(OBSERVER, OUTPUT, convention, "light" if light else None,
                               {"albedo": rho, "light": le}, {"grey": {"reflectance": "albedo"}}, {"box": "light"})
    name = "spectral-furnace"
    return dataclasses.replace(
        base, name=name, path=Path("stress") / f"{name}.toml",
        materials={"grey": Diffuse("grey", reflectance_rgb(rho, convention, light))},
        meshes=(dataclasses.replace(base.meshes[0], radiance=emission_rgb(le)),), spectral=spectral,
        description=f"spectral furnace: closed cube, a green-band albedo spectrum under a warm emission spectrum "
                    f"(RGB projection: {convention})")


def spectral_furnace_radiance(max_depth: int = -1) -> np.ndarray:
    """The spectral furnace's radiance in linear sRGB, (3,): M · Σ_λ S(λ) x̄(λ) / Σ_λ ȳ(λ).

    Per wavelength the furnace is the white one (:func:`furnace_radiance`):
    S(λ) = L(λ)/(1-ρ(λ)), or L(λ)·Σ_{k<D} ρ(λ)^k at max_depth D, since light of
    one wavelength stays at that wavelength. The spectrum S is projected
    exactly as :func:`cornell_harness.scenes.spectra.emission_rgb` projects an
    emitter (the sums over the observer's 1 nm table, the same matrix M), so
    a spectral renderer on that scale converges to this.
    """
    grid, xyz_bar = observer()
    rho, le = SPECTRAL_FURNACE_ALBEDO.at(grid), SPECTRAL_FURNACE_EMISSION.at(grid)
    if max_depth < 0:
        s = le / (1.0 - rho)
    else:
        s = le * sum(rho**k for k in range(max_depth))
    return xyz_to_linear_srgb() @ (s @ xyz_bar / xyz_bar[:, 1].sum())


# ----------------------------------------------------------------------------------------
# Specular furnace: glass and mirrors in the white furnace
# ----------------------------------------------------------------------------------------

#: Index of refraction of the specular furnace's glass (in air, 1.0).
FURNACE_GLASS_IOR = 1.5
#: The specular furnace's objects, all in view of the camera at the cube's centre (looking at -z,
#: 100° field of view), none containing it: name -> (kind, centre, size). A sphere's size is its
#: radius, the cube's its half-side.
SPECULAR_FURNACE_OBJECTS = {
    "glass-sphere": ("sphere", (-0.36, 0.22, -0.72), 0.24),
    "mirror-sphere": ("sphere", (0.36, 0.22, -0.72), 0.24),
    "glass-cube": ("cube", (0.0, -0.34, -0.72), 0.18),
}
_SPECULAR_FEATURES = _ALL_FEATURES | {"sphere", "mirror", "dielectric"}


def specular_furnace_scene(albedo: float, radiance: float = 1.0, res: int = 16,
                           objects: tuple[str, ...] = tuple(SPECULAR_FURNACE_OBJECTS),
                           mirror_reflectance: tuple[float, float, float] = (1.0, 1.0, 1.0),
                           max_depth: int = -1) -> Scene:
    """:func:`furnace_scene` with ``objects`` of :data:`SPECULAR_FURNACE_OBJECTS` inside.

    The glass (IOR :data:`FURNACE_GLASS_IOR` in air) is a sphere and an
    axis-aligned cube (a triangle mesh, normals outward); the mirror is a
    sphere of reflectance ``mirror_reflectance``.

    Lossless specular objects (glass; a mirror of reflectance 1) change no
    radiance in the furnace: a Fresnel interface reflects R and transmits
    1 - R of the power (basic radiance L/n² is conserved across it, Veach
    1997 §5.2), so in equilibrium the radiance seen from the air is still
    :func:`furnace_radiance`, Le/(1-ρ), in every pixel, whether its ray meets
    a wall, the mirror, or the glass. Light entering the cube keeps a
    direction component >= cos θt >= cos θc along the normal of the face it
    came in by, so its other components are <= sin θc: it meets the four
    other faces past the critical angle (total internal reflection, on every
    such path) and leaves by the face it entered or the opposite one, never
    trapped; nor is a ray inside a sphere (entered at θt, it meets the
    surface again at θt).

    With walls of albedo 0 the walls show exactly Le, and so does the glass;
    a mirror of reflectance r shows r·Le per channel (it reflects a wall).
    """
    base = furnace_scene(albedo, radiance, max_depth, res)
    materials = dict(base.materials)
    materials["glass"] = Dielectric("glass", FURNACE_GLASS_IOR, 1.0)
    materials["mirror"] = Mirror("mirror", tuple(float(x) for x in mirror_reflectance))
    meshes, spheres = list(base.meshes), []
    for name in objects:
        kind, centre, size = SPECULAR_FURNACE_OBJECTS[name]
        material = "mirror" if name.startswith("mirror") else "glass"
        if kind == "sphere":
            spheres.append(Sphere(name, centre, size, material))
        else:
            outward = tuple((a, d, c, b) for a, b, c, d in _CUBE_INWARD)
            verts = np.asarray(centre) + size * np.asarray(_CUBE_VERTS, dtype=np.float64)
            meshes.append(Mesh(name, verts, _quads_to_triangles(outward), material))
    used = {materials[o.material].feature for o in meshes + spheres} | ({"sphere"} if spheres else set())
    name = f"specular-furnace-albedo-{albedo:g}"
    return dataclasses.replace(
        base, name=name, path=Path("stress") / f"{name}.toml", features=_ALL_FEATURES | used,
        materials={k: v for k, v in materials.items() if k == "grey" or v.feature in used},
        meshes=tuple(meshes), spheres=tuple(spheres),
        description=f"white furnace (albedo {albedo:g}, emission {radiance:g}) with {', '.join(objects)}")


def specular_furnace_coverage(scene: Scene, sub: int = 16) -> dict[str, np.ndarray]:
    """Fraction of each pixel (height, width) whose camera ray first meets each specular furnace object.

    Keyed by object name (those of :data:`SPECULAR_FURNACE_OBJECTS` in
    ``scene``); measured on a sub×sub grid of points per pixel (the box
    filter's footprint), with exact float64 ray-sphere and ray-box maths. A
    fraction of 1 (0) means every grid point's ray meets (misses) the object.
    """
    cam = scene.camera
    d = _subpixel_directions(cam, sub)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = np.asarray(cam.position, dtype=np.float64)
    names = [s.name for s in scene.spheres] + [m.name for m in scene.meshes if m.name in SPECULAR_FURNACE_OBJECTS]
    t = np.full((len(names),) + d.shape[:2], np.inf)
    for k, name in enumerate(names):
        kind, centre, size = SPECULAR_FURNACE_OBJECTS[name]
        f = o - np.asarray(centre)
        if kind == "sphere":
            t[k] = Sphere(name, centre, size, "").hit_distances(o, d)
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                lo, hi = (-size - f) / d, (size - f) / d
            enter = np.minimum(lo, hi).max(axis=-1)
            leave = np.maximum(lo, hi).min(axis=-1)
            t[k] = np.where((enter <= leave) & (leave > 0), np.maximum(enter, 0.0), np.inf)
    first = np.where(np.isfinite(t).any(axis=0), t.argmin(axis=0), -1)
    shape = (cam.height, sub, cam.width, sub)
    return {name: (first == k).reshape(shape).mean(axis=(1, 3)) for k, name in enumerate(names)}


def specular_furnace_camera_in_glass(albedo: float, radiance: float = 1.0, res: int = 16) -> Scene:
    """:func:`furnace_scene` with the camera inside a glass sphere (IOR :data:`FURNACE_GLASS_IOR` in air).

    In equilibrium basic radiance L/n² is the same everywhere (Veach 1997
    §5.2), so inside glass of index n the radiance is n²·:func:`furnace_radiance`
    in every direction (2.25·Le/(1-ρ) for n = 1.5). The sphere (radius 0.5)
    is centred 0.15 from the camera: rays from the camera meet it at
    sin θ <= 0.3, far inside the critical angle (sin θc = 1/n), so none is
    trapped by total internal reflection.
    """
    base = furnace_scene(albedo, radiance, -1, res)
    name = f"furnace-camera-in-glass-albedo-{albedo:g}"
    return dataclasses.replace(
        base, name=name, path=Path("stress") / f"{name}.toml", features=_SPECULAR_FEATURES - {"mirror"},
        materials={**base.materials, "glass": Dielectric("glass", FURNACE_GLASS_IOR, 1.0)},
        spheres=(Sphere("glass-shell", (0.15, 0.0, 0.0), 0.5, "glass"),),
        description=f"white furnace (albedo {albedo:g}, emission {radiance:g}), camera inside a glass sphere")


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
    d = _subpixel_directions(cam, sub)
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
             _quads_to_triangles(quad), "white", (0.0, 0.0, 0.0)),
        Mesh("panel", np.array([[-a, -b, h], [a, -b, h], [a, b, h], [-a, b, h]], float),
             _quads_to_triangles(quad), "black", (LIGHT_LE,) * 3),
        Mesh("mirror", np.array([[-1.0, -1.0, top], [-1.0, 1.0, top], [1.0, 1.0, top], [1.0, -1.0, top]], float),
             _quads_to_triangles(quad), "mirror", (0.0, 0.0, 0.0)),
    )
    materials = {"white": Diffuse("white", (FLOOR_RHO,) * 3), "black": Diffuse("black", (0.0,) * 3),
                 "mirror": Mirror("mirror", (1.0, 1.0, 1.0))}
    return Scene(name="mirrored-light", path=Path("analytic") / "mirrored-light.toml",
                 features=_ALL_FEATURES | {"mirror"}, camera=camera, materials=materials, meshes=meshes,
                 max_depth=3, pixel_filter="box", description="a floor lit by a light's image in a mirror")


def mirrored_light_image(scene: Scene, sub: int = 8, margin: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Exact box-filtered image of :func:`mirrored_light_scene`, and the mask of the pixels it holds for.

    A floor point p sees the light's mirror image, the panel reflected to
    z' = 2·1.5 − 1 = 2, facing down: E(p) from the polygon formula for that
    polygon, radiance ρ/π · E. A ray from p to a point q of the image crosses
    the panel's plane halfway ((p + q)/2), so the panel's black back hides
    none of it when |p_x| > 3a or |p_y| > 3b; the mask keeps the pixels whose
    every sub-sample lands on the floor there (and sees nothing else first),
    at least ``margin`` inside the floor's edge and that boundary (a density
    estimate blurs across both).
    """
    cam = scene.camera
    d = _subpixel_directions(cam, sub)
    o = np.asarray(cam.position)
    t = -o[2] / d[..., 2]
    pts = (o + t[..., None] * d).reshape(-1, 3)
    a, b = LIGHT_A, LIGHT_B
    z_image = 2 * MIRROR_H - MIRROR_LIGHT_H
    poly = np.array([[-a, -b, z_image], [a, -b, z_image], [a, b, z_image], [-a, b, z_image]], float)
    e = polygon_irradiance(pts, np.array([0, 0, 1.0]), poly, LIGHT_LE)
    edge = 1.6 - margin
    ok = (t.reshape(-1) > 0) & (np.abs(pts[:, 0]) <= edge) & (np.abs(pts[:, 1]) <= edge)
    ok &= (np.abs(pts[:, 0]) > 3 * a + margin) | (np.abs(pts[:, 1]) > 3 * b + margin)
    # The camera (below the panel) must not see the panel in front of the floor point.
    tl = (MIRROR_LIGHT_H - o[2]) / d[..., 2]
    pl = (o + tl[..., None] * d).reshape(-1, 3)
    ok &= ~((tl.reshape(-1) > 0) & (tl.reshape(-1) < t.reshape(-1)) & (np.abs(pl[:, 0]) <= a) & (np.abs(pl[:, 1]) <= b))
    radiance = np.where(ok, FLOOR_RHO / np.pi * e, 0.0).reshape(cam.height, sub, cam.width, sub).mean(axis=(1, 3))
    mask = ok.reshape(cam.height, sub, cam.width, sub).all(axis=(1, 3))
    return np.repeat(radiance[..., None], 3, axis=2), mask

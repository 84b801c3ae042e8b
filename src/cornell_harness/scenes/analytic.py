"""Scenes whose images have analytic answers, and those answers.

- **White furnace** (:func:`furnace_scene`, :func:`furnace_radiance`): a closed
  cube, every face of albedo ρ emitting Le, the camera inside. Built directly
  from the dataclasses (no file); the stress suite (:mod:`cornell_harness.stress`)
  and the path tracer's tests use it.
- **Spectral furnace** (:func:`spectral_furnace_scene`, :func:`spectral_furnace_radiance`):
  the white furnace with a non-flat albedo spectrum ρ(λ) and an emission
  spectrum L(λ) (the closed form spectral renderers are checked against): per
  wavelength Le/(1-ρ), projected to linear sRGB as the scene model projects
  an emitter. Its RGB projection is an ordinary scene, whose RGB answer
  differs from the spectral one: the error of rendering it in RGB.
- **Specular furnace** (:func:`specular_furnace_scene`,
  :func:`specular_furnace_camera_in_glass`): the furnace with lossless glass
  (a sphere and a cube) and a mirror sphere inside. Lossless specular
  objects leave the furnace's radiance unchanged, Le/(1-ρ) everywhere seen
  from the air; a camera inside glass of index n sees n² times it.
- Scenes lit by one rectangle light, exact by Lambert's polygon formula, are
  :mod:`cornell_harness.scenes.polygon_light`'s.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

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
ANALYTIC_FEATURES = frozenset({"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"})


def subpixel_directions(cam: Camera, sub: int) -> np.ndarray:
    """(H·sub, W·sub, 3) camera directions through a sub×sub grid of points centred in each pixel's cells."""
    offs = (np.arange(sub) + 0.5) / sub
    col = (np.arange(cam.width)[:, None] + offs[None, :]).ravel()
    row = (np.arange(cam.height)[:, None] + offs[None, :]).ravel()
    return cam.directions(col[None, :], row[:, None])


def quads_to_triangles(quads) -> np.ndarray:
    """Each quad (a, b, c, d) as the triangles (a, b, c) and (a, c, d)."""
    return np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))], dtype=np.int64)


def furnace_scene(albedo: float, radiance: float = 1.0, max_depth: int = -1, res: int = 16,
                  scale: float = 1.0) -> Scene:
    """A closed cube, every face of reflectance ``albedo`` emitting ``radiance``; pinhole camera at its centre.

    Its radiance everywhere, in every direction, is :func:`furnace_radiance`.
    """
    name = f"furnace-albedo-{albedo:g}"
    camera = Camera(position=(0.0, 0.0, 0.0), look_at=(0.0, 0.0, -scale), up=(0.0, 1.0, 0.0), fov_deg=100.0,
                    fov_axis="smaller", width=int(res), height=int(res))
    mesh = Mesh("box", np.asarray(_CUBE_VERTS, dtype=np.float64) * scale, quads_to_triangles(_CUBE_INWARD),
                "grey", (float(radiance),) * 3)
    return Scene(name=name, path=Path("stress") / f"{name}.toml", features=ANALYTIC_FEATURES, camera=camera,
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
_SPECULAR_FEATURES = ANALYTIC_FEATURES | {"sphere", "mirror", "dielectric"}


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
            meshes.append(Mesh(name, verts, quads_to_triangles(outward), material))
    used = {materials[o.material].feature for o in meshes + spheres} | ({"sphere"} if spheres else set())
    name = f"specular-furnace-albedo-{albedo:g}"
    return dataclasses.replace(
        base, name=name, path=Path("stress") / f"{name}.toml", features=ANALYTIC_FEATURES | used,
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
    d = subpixel_directions(cam, sub)
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

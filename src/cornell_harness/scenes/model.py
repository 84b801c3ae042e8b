"""The scene model: what a scene file says, validated, and nothing more.

A scene file is TOML. It is parsed once into the frozen dataclasses below;
every renderer adapter reads these, never the file.

Units and colour space (named here once for the whole harness)
---------------------------------------------------------------
- **Lengths** are in *scene units*; the harness never assumes metres. A file
  may give them in another unit and declare the factor, ``length_scale``
  (:mod:`cornell_harness.scenes.units`); the Scene holds scene units.
- **Angles** in the file are in degrees (``fov_deg``).
- **Colour space** is linear sRGB: ITU-R BT.709 primaries, D65 white point,
  no transfer function. Every RGB triple in a scene, and every image a
  renderer returns, is in this space.
- **Radiance** (``emitter.radiance`` and image pixels) is per linear-sRGB
  channel, in W·sr⁻¹·m⁻² relative to the scene unit; images are the
  box-filtered mean of the radiance arriving through each pixel.
- **Ambient occlusion** (images of a scene whose ``quantity`` is
  ``ambient_occlusion``) is a dimensionless fraction in [0, 1], the same in
  all three channels; its definition is :mod:`cornell_harness.scenes.quantities`'.
- **Spectra**: a material's reflectance or an emitter's radiance may be a
  sampled spectrum (wavelengths in nm); the scene then declares its colour
  pipeline, and the RGB values above are the spectra's projection
  (:mod:`cornell_harness.scenes.spectra`, :mod:`cornell_harness.scenes.spectral_scene`).
- **Reflectance** of a diffuse material is its albedo per channel, in [0, 1];
  of a mirror, its specular reflectance per channel. Materials and their
  fields are :mod:`cornell_harness.scenes.materials`'.
- **Indices of refraction** are absolute (vacuum 1); a dielectric's front
  side faces its ``ext_ior`` medium.

Conventions
-----------
- ``max_depth`` counts path *segments* from the camera, as Mitsuba 3 does:
  1 = emitters seen directly, 2 = direct lighting, 3 = one indirect bounce,
  and -1 = unbounded (renderers terminate paths with Russian roulette).
  Each adapter translates this to its renderer's own convention.
- A triangle's front side is the one its counter-clockwise winding faces:
  ``n = (v1 - v0) × (v2 - v0)``. Area emitters emit from the front side only;
  diffuse surfaces reflect on the front side only (Mitsuba 3's ``diffuse``).
- Quads ``[a, b, c, d]`` are split into triangles ``(a, b, c)`` and ``(a, c, d)``.
- A sphere's front side is its outside: its normal at ``x`` is
  ``(x - center) / radius`` (Mitsuba 3's ``sphere`` without ``flip_normals``).
  Spheres do not emit.
- Pixel ``(row, col)`` = ``(0, 0)`` is the top-left of the image.

Limits
------
The loader refuses, with a :class:`SceneError` naming the file and field:

- **unknown keys**, at every level (``render.max_depht``): a misspelt
  optional key would otherwise be ignored silently; the message suggests the
  closest known key;
- coordinates (vertices, ``camera.position``/``look_at``/``up``) with
  ``|x| >`` :data:`MAX_COORDINATE` = 1e30 and emitter radiance above
  :data:`MAX_RADIANCE` = 1e30: squared lengths, areas and powers
  (``Le · A · π``) of such values overflow float64 (1e308 squared is inf);
  at the bounds they stay below ~1e92;
- ``render.max_depth`` above :data:`MAX_DEPTH` = 2³¹ - 1 (Mitsuba 3 takes
  it as a 32-bit integer);
- degenerate triangles: area at most 1e-12 of the scene's squared size,
  computed on coordinates rescaled to the scene's size (so a tiny scene's
  areas do not underflow to zero, and out-of-range values are reported as
  such, not as degenerate);
- a ``camera.resolution`` whose image buffers, estimated by
  :func:`image_memory_bytes`, exceed :data:`MAX_IMAGE_BYTES` = 16 GiB
  (about 9459 × 9459 pixels), before any renderer is called;
- scene files over :data:`MAX_SCENE_FILE_BYTES` (64 MiB; large meshes belong
  in OBJ files, up to :data:`MAX_OBJ_FILE_BYTES` = 1 GiB), files that are not
  UTF-8 text, and TOML nested deeper than the parser's recursion limit.

Features
--------
A scene declares, in ``features``, the set of :data:`FEATURES` it uses; the
loader checks the declaration against the content. Each renderer declares the
features it models, and the runner skips a renderer that lacks one.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

# Diffuse is re-exported: scenes built in code (analytic.py, tests) import it from the model.
from cornell_harness.scenes.materials import Diffuse, Material, hash_payload  # noqa: F401
# one_line is re-exported: every one-line user error (scene files, exports, the CLI) escapes its text with it.
from cornell_harness.schemas.reader import one_line  # noqa: F401
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY, AmbientOcclusion
from cornell_harness.scenes.spectral_scene import SpectralContent

if TYPE_CHECKING:
    from cornell_harness.scenes.animation import Animation

#: Every feature a scene may use, with what it means.
FEATURES: dict[str, str] = {
    "triangle_mesh": "geometry given as triangle or quad meshes",
    "sphere": "analytic spheres (center, radius)",
    "diffuse": "Lambertian reflection with a linear-sRGB reflectance",
    "mirror": "smooth conductor: perfect specular reflection with a linear-sRGB reflectance",
    "dielectric": "smooth glass: exact Fresnel reflection and refraction, total internal reflection",
    "area_light": "one-sided diffuse area emitters on meshes",
    "pinhole_camera": "a pinhole perspective camera",
    "box_filter": "each pixel is the unweighted mean over its own square",
}

PIXEL_FILTERS = ("box",)
FOV_AXES = ("x", "y", "smaller", "larger")
#: Below this area (relative to the scene's squared size) a triangle is degenerate.
DEGENERATE_REL_AREA = 1e-12

#: Largest |coordinate| in scene units (vertices, camera position, look_at, up). The harness
#: squares lengths and multiplies them (extent², edge cross products for areas, Le·A·π for
#: power): at 1e30 these stay below ~1e92, far inside float64 (max ~1.8e308), whereas a 1e308
#: coordinate overflows to inf the moment it is squared.
MAX_COORDINATE = 1e30
#: Largest emitted radiance per channel: with areas up to ~1e61 (from MAX_COORDINATE), the
#: power Le·A·π stays finite; 1e308 is inf in float32 renderers and overflows any product.
MAX_RADIANCE = 1e30
#: Largest bounded render.max_depth: Mitsuba 3 takes max_depth as a 32-bit signed integer.
MAX_DEPTH = 2**31 - 1
#: Image-sized float64 RGB buffers a run holds at once, for :func:`image_memory_bytes`: the
#: film's sums and sums of squares, the mean and variance images, checkpoints, the
#: reference and its variance, and the metrics' intermediates (colour conversions, ΔE).
IMAGE_BUFFERS = 8
#: Largest estimated image memory (:func:`image_memory_bytes`) a scene's resolution may ask
#: for: 16 GiB, about 9459 × 9459 pixels. The stress suite's largest render, 2048², is
#: estimated at 768 MiB (measured peaks: 570-710 MB).
MAX_IMAGE_BYTES = 16 * 2**30
#: Largest scene (TOML) file read; meshes of that size belong in OBJ files.
MAX_SCENE_FILE_BYTES = 64 * 2**20
#: Largest OBJ file read.
MAX_OBJ_FILE_BYTES = 2**30


def image_memory_bytes(width: int, height: int) -> int:
    """Estimated memory of a run's image buffers: width × height × 3 channels × 8 bytes × :data:`IMAGE_BUFFERS`.

    Exact integer arithmetic, so an absurd resolution (2^70) gives an absurd
    estimate, not an overflow.
    """
    return int(width) * int(height) * 3 * 8 * IMAGE_BUFFERS


class SceneError(ValueError):
    """Bad scene input. ``str()`` is the one-line message the CLI prints."""

    def __init__(self, file: Path | str, field: str, message: str):
        self.file, self.field, self.message = str(file), field, message
        super().__init__(f"{file}: {field}: {message}")


@dataclass(frozen=True)
class Camera:
    """A pinhole camera. ``fov_deg`` is the full angle along ``fov_axis``."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_deg: float
    fov_axis: str
    width: int
    height: int

    def frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Orthonormal (right, up, forward) in world space, float64.

        ``right`` = forward × up points to increasing pixel column and ``up``
        to decreasing row, as in Mitsuba 3's perspective sensor.
        """
        forward = np.subtract(self.look_at, self.position, dtype=np.float64)
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, np.asarray(self.up, dtype=np.float64))
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        return right, up, forward

    def tan_half_fov(self) -> tuple[float, float]:
        """tan of half the field of view along x (columns) and y (rows)."""
        t = math.tan(math.radians(self.fov_deg) / 2.0)
        aspect = self.width / self.height
        axis = self.fov_axis
        if axis == "smaller":
            axis = "x" if self.width <= self.height else "y"
        elif axis == "larger":
            axis = "x" if self.width >= self.height else "y"
        return (t, t / aspect) if axis == "x" else (t * aspect, t)

    def directions(self, col: np.ndarray, row: np.ndarray) -> np.ndarray:
        """World directions (not normalised, float64, shape ``col.shape + (3,)``) through image points (col, row).

        Continuous pixel units, (0, 0) the top-left corner: the inverse of
        :meth:`project_to_pixels`, and the direction our renderers' camera
        rays take (``src/cornell_harness/renderers/core/camera.py``).
        """
        right, up, forward = self.frame()
        tx, ty = self.tan_half_fov()
        sx = (2.0 * np.asarray(col, dtype=np.float64) / self.width - 1.0) * tx
        sy = (1.0 - 2.0 * np.asarray(row, dtype=np.float64) / self.height) * ty
        return forward + sx[..., None] * right + sy[..., None] * up

    def project_to_pixels(self, points: np.ndarray) -> np.ndarray:
        """(col, row) image coordinates (continuous, pixel units) of world ``points`` (n, 3) in front of the camera."""
        right, up, forward = self.frame()
        tx, ty = self.tan_half_fov()
        d = np.asarray(points, dtype=np.float64) - np.asarray(self.position, dtype=np.float64)
        z = d @ forward
        sx = (d @ right) / z / tx
        sy = (d @ up) / z / ty
        return np.stack([(sx + 1.0) / 2.0 * self.width, (1.0 - sy) / 2.0 * self.height], axis=1)


@dataclass(frozen=True)
class Mesh:
    """Triangles with one material, optionally a one-sided area emitter."""

    name: str
    vertices: np.ndarray  # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int64 indices into vertices
    material: str
    radiance: tuple[float, float, float] | None = None  # emitted, if an emitter

    @property
    def is_emitter(self) -> bool:
        return self.radiance is not None


@dataclass(frozen=True)
class Sphere:
    """An analytic sphere with one material; it does not emit."""

    name: str
    center: tuple[float, float, float]
    radius: float
    material: str

    def hit_distances(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Ray parameter t of the first hit of rays ``origin + t·dirs`` (dirs shape (..., 3)), inf if none.

        For camera rays in NumPy (region masks, analytic images); our
        renderers have their own, in numba.
        """
        oc = np.asarray(origin, dtype=np.float64) - np.asarray(self.center, dtype=np.float64)
        a = np.einsum("...i,...i->...", dirs, dirs)
        b = dirs @ oc
        disc = b * b - a * (oc @ oc - float(self.radius) ** 2)
        root = np.sqrt(np.maximum(disc, 0.0))
        near, far = (-b - root) / a, (-b + root) / a
        t = np.where(near > 0.0, near, far)  # from inside the sphere the far root is the hit
        return np.where((disc >= 0.0) & (t > 0.0), t, np.inf)


@dataclass(frozen=True)
class Region:
    """A named part of the image, for per-region metrics.

    A pixel belongs to the region when every camera ray through its
    footprint first hits one of ``objects`` (mesh or sphere names) and, if
    ``box`` is given, hits it inside that world-space box (lo, hi); pixels
    that straddle a boundary are left out. Masks are
    :mod:`cornell_harness.evaluate.regions`'. Regions do not change the image, so
    they are not part of the scene's content hash.
    """

    name: str
    objects: tuple[str, ...] = ()  # empty: any object
    box: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    description: str = ""


def object_bounds(meshes: tuple[Mesh, ...], spheres: tuple[Sphere, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned bounding box (lo, hi) of meshes and spheres, float64."""
    v = np.concatenate([m.vertices for m in meshes])
    lo, hi = v.min(axis=0), v.max(axis=0)
    for s in spheres:
        lo = np.minimum(lo, np.subtract(s.center, s.radius))
        hi = np.maximum(hi, np.add(s.center, s.radius))
    return lo, hi


def extent(lo: np.ndarray, hi: np.ndarray) -> float:
    """The scene's size: the length of its bounding box's diagonal."""
    return float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))


@dataclass(frozen=True)
class Scene:
    """A validated scene. Build it with :func:`cornell_harness.scenes.loader.load_scene`."""

    name: str
    path: Path
    features: frozenset[str]
    camera: Camera
    materials: dict[str, Material]
    meshes: tuple[Mesh, ...]
    max_depth: int
    pixel_filter: str
    description: str = ""
    spheres: tuple[Sphere, ...] = ()
    regions: dict[str, Region] = dataclasses.field(default_factory=dict)
    quantity: str = DEFAULT_QUANTITY  # what the image means (cornell_harness.scenes.quantities)
    ambient_occlusion: AmbientOcclusion | None = None  # the AO definition, for quantity ambient_occlusion
    # KEY=VALUE a derived scene's file was overridden with (cornell_harness.scenes.overrides): where its reference is
    # kept and how to rebuild it, not content (the hash reads the values they set).
    overrides: tuple[str, ...] = ()
    # Spectra of materials and emitters, and the colour pipeline that projected them to the RGB values above
    # (cornell_harness.scenes.spectral_scene); None for an RGB scene.
    spectral: SpectralContent | None = None
    # What moves, for an animated scene (cornell_harness.scenes.animation); None for a still scene.
    animation: Animation | None = None
    # The frame of an animated scene this still scene is (at_frame); None for a scene that is no frame of one.
    frame: int | None = None
    # The frame whose reference this frame shares (Animation.reference_frame): not content, since equal states
    # make equal scenes but for ``frame``.
    reference_frame: int | None = None

    @property
    def frame_count(self) -> int:
        """The number of frames: the animation's, 1 for a still scene."""
        return 1 if self.animation is None else self.animation.frames

    def at_frame(self, i: int) -> "Scene":
        """The still scene of frame ``i`` (:meth:`cornell_harness.scenes.animation.Animation.scene_at`); a still
        scene's only frame, 0, is the scene itself. IndexError outside ``[0, frame_count)``."""
        if self.animation is None:
            if i != 0:
                raise IndexError(f"frame {i!r}: a still scene has only frame 0")
            return self
        return self.animation.scene_at(self, i)

    @property
    def emitters(self) -> tuple[Mesh, ...]:
        return tuple(m for m in self.meshes if m.is_emitter)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box of all geometry (lo, hi), float64."""
        return object_bounds(self.meshes, self.spheres)

    def object_names(self) -> tuple[str, ...]:
        """Meshes then spheres, in file order: the objects regions name."""
        return tuple(m.name for m in self.meshes) + tuple(s.name for s in self.spheres)

    def extent(self) -> float:
        """Length of the bounding-box diagonal: the scene's size."""
        return extent(*self.bounds())

    def content_hash(self) -> str:
        """SHA-256 of the parsed content (not the file's bytes).

        Comments, formatting, OBJ-vs-inline choices and regions do not change
        it; any change to geometry, materials, camera, transport settings or
        quantity does. Keys that older scenes lack (spheres, a quantity other
        than radiance, the AO definition, spectral content, an animation, a frame) enter only when present,
        so the stored references of those scenes stay valid.
        """
        payload = {
            "camera": dataclasses.asdict(self.camera),
            "materials": {k: hash_payload(v) for k, v in sorted(self.materials.items())},
            "meshes": [
                {
                    "name": m.name,
                    "material": m.material,
                    "radiance": m.radiance,
                    "vertices": np.round(m.vertices, 12).tolist(),
                    "triangles": m.triangles.tolist(),
                }
                for m in self.meshes
            ],
            "max_depth": self.max_depth,
            "pixel_filter": self.pixel_filter,
            "features": sorted(self.features),
        }
        if self.spheres:
            payload["spheres"] = [dataclasses.asdict(s) for s in self.spheres]
        if self.quantity != DEFAULT_QUANTITY:
            payload["quantity"] = self.quantity
        if self.ambient_occlusion is not None:
            payload["ambient_occlusion"] = self.ambient_occlusion.hash_payload()
        if self.spectral is not None:
            payload["spectral"] = self.spectral.hash_payload()
        if self.animation is not None:
            payload["animation"] = self.animation.hash_payload()
        if self.frame is not None:  # every frame its own hash; frames at one state share a reference by frame
            payload["frame"] = self.frame
        blob = json.dumps(payload, sort_keys=True, separators=(",", ":")).encode()
        return "sha256:" + hashlib.sha256(blob).hexdigest()

    def with_resolution(self, width: int, height: int) -> "Scene":
        """The same scene rendered at another resolution (for quick runs)."""
        cam = dataclasses.replace(self.camera, width=int(width), height=int(height))
        anim = self.animation and self.animation.with_camera(
            dataclasses.replace(self.animation.camera, width=int(width), height=int(height)))
        return dataclasses.replace(self, camera=cam, animation=anim)

    def with_max_depth(self, max_depth: int) -> "Scene":
        return dataclasses.replace(self, max_depth=int(max_depth))


def triangle_arrays(scene: Scene) -> dict[str, np.ndarray]:
    """Flatten all meshes into shared arrays, the form ray tracers want.

    Returns float64 ``vertices`` (V,3), int64 ``triangles`` (T,3), and per
    triangle: ``mesh`` index and ``radiance`` (T,3, zero for non-emitters).
    Materials are looked up through the mesh index.
    """
    verts, tris, mesh_id, le = [], [], [], []
    offset = 0
    for k, m in enumerate(scene.meshes):
        verts.append(m.vertices)
        tris.append(m.triangles + offset)
        offset += len(m.vertices)
        n = len(m.triangles)
        mesh_id.append(np.full(n, k))
        le.append(np.tile(m.radiance or (0.0, 0.0, 0.0), (n, 1)))
    return {
        "vertices": np.concatenate(verts),
        "triangles": np.concatenate(tris),
        "mesh": np.concatenate(mesh_id),
        "radiance": np.concatenate(le).astype(np.float64),
    }

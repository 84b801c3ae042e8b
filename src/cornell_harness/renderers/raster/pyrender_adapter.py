"""pyrender adapter: rasterised direct lighting, the real-time baseline.

It shows what a real-time rasteriser gets without global illumination: every
pixel is the emitted radiance plus light that reached the surface straight
from the emitters, with shadows; no light bounces. Compared with the Mitsuba
reference the difference is (almost all) indirect light.

Package
-------
``pyrender2`` (a maintained fork of pyrender 0.1.45 that works with NumPy 2
and PyOpenGL >= 3.1.9; the import name is still ``pyrender``). The original
``pyrender`` 0.1.45 pins PyOpenGL 3.1.0 (whose OSMesa binding lacks
``OSMesaCreateContextAttribs``) and calls ``np.infty`` (gone in NumPy 2); with
NumPy 2 this adapter reports it unavailable. ``pyrender-maintained`` 1.0.1
ships the same code as ``pyrender2`` and is accepted too.

Headless OpenGL
---------------
pyrender renders offscreen through EGL or OSMesa, chosen by
``PYOPENGL_PLATFORM``, which PyOpenGL reads once, when it is first imported:
a process cannot switch later. If the user set it, it is used (``egl`` or
``osmesa``; anything else makes the adapter unavailable). Otherwise the
adapter picks, before importing pyrender: it looks for the libraries with
``ctypes.util.find_library`` (``EGL`` plus ``OpenGL``/``GL`` for EGL,
``OSMesa`` for OSMesa); when only one platform has its libraries it is
chosen; when both do, EGL is tried first in a short subprocess (it creates a
context, ~1-2 s, once per process) and OSMesa is used if that fails. The
choice is then put in ``PYOPENGL_PLATFORM`` for this process
(:mod:`cornell_harness.renderers.raster.platform`). On Debian:
``libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri`` (EGL, Mesa's llvmpipe works
without a GPU) or ``libosmesa6``.

How the scene is drawn
----------------------
pyrender supplies the GL context, scene graph, mesh buffers, camera
projection and one shadow-map pass per spot light. Its own shaders are
replaced (through its ``ShaderProgramCache(shader_dir=...)``) by the small
shaders in ``src/cornell_harness/renderers/raster/shaders/`` (:mod:`cornell_harness.renderers.raster.glsl`), and
its 8-bit colour buffer by a float one (:mod:`cornell_harness.renderers.raster.framebuffer`),
because pyrender's stock shader is not a Lambertian model in our units:

- it is glTF metallic-roughness: with metallic=0, roughness=1 the diffuse
  term is ``(1 - F) * 0.96 * rho / pi`` (F = Schlick Fresnel with F0 = 0.04)
  plus a GGX specular lobe, so a white plane under a point light at normal
  incidence gives 0.93x the Lambertian radiance, and the factor varies with
  the view and light angles (measured: 0.928-0.935);
- ``n.l`` is clamped to at least 0.001, so surfaces facing away still get
  light;
- the output is clamped to [0, 1], raised to 1/2.2 and read back as 8 bits;
- spot lights fall off as a squared smoothstep of the cone, not as cos(theta);
- shadows: with ``RenderFlags.SHADOWS_ALL`` (or ``SHADOWS_POINT``) Mesa
  rejects the program ("active samplers with a different type refer to the
  same texture image unit": unset sampler2D and samplerCube uniforms all
  default to unit 0), and point-light shadows are not implemented at all;
  ``SHADOWS_SPOT`` alone works on Mesa (EGL and OSMesa).

Our fragment shader computes, in float32,
``L_o = L_e + rho/pi * sum_j I_j(theta_j) * cos(theta_r) / d_j^2 * V_j``
on the front side of each triangle (CCW winding). Each triangle also gets a
back-side copy (reversed winding, black), so back sides look black but
occlude, as Mitsuba's one-sided ``diffuse``, and cast shadows whichever side
faces a light. The colour buffers are pyrender's pair (4x MSAA, resolved
by a blit) made RGBA32F and read back as float: the image is linear-sRGB
radiance, with no clamping or quantisation. Meshes are drawn in a fixed
order (pyrender takes it from a set; llvmpipe's MSAA silhouettes depend on
it), so renders are repeatable. A white Lambertian plane under a light of
intensity I gives ``rho/pi * I cos(theta) / d^2`` (tested).

Approximations (also in :attr:`Pyrender.approximations`)
--------------------------------------------------------
- **Area lights become point lights.** A one-sided area emitter of radiance L
  and area A with normal n has radiant intensity ``I(theta) = L*A*cos(theta)``
  (theta from n, zero behind). Each emitter triangle is cut into k*k equal
  sub-triangles (k from the triangle's share of
  :data:`~cornell_harness.renderers.raster.lights.DEFAULT_LIGHTS` lights, at least 1); one
  light sits at each sub-triangle's centroid with
  ``I_j(theta) = L * (A_tri/k^2) * max(cos(theta), 0)``. They are pyrender
  ``SpotLight`` nodes (for their shadow maps) whose intensity is evaluated
  by our shader with that cosine law; the cone angle only sets the shadow
  map's field of view. The Cornell box light (two triangles) becomes 32
  lights. Exact as d grows; penumbrae are the sum of 32 hard shadows.
- **Direct lighting only.** ``max_depth`` is ignored except that 1 (emitters
  only) is honoured: any other value, including the scene's -1 (unbounded),
  is rendered as 2 (emission + direct light), so no indirect light.
- **Box filter by supersampling.** The image is rendered at s x s times the
  resolution with 4x MSAA and each s x s block is averaged:
  ``s = round(sqrt(spp))``, clamped to [1, :data:`MAX_SUPERSAMPLING`], to
  the GL renderbuffer/viewport limit and to :data:`MAX_FRAMEBUFFER_PIXELS`
  (256x256: s <= 8; 512x512: s <= 4) (shading: s*s samples per pixel;
  coverage: 4*s*s). ``RenderResult.spp`` is the spp asked for;
  ``info["supersampling"]`` is s. A rasteriser is deterministic: the seed is
  ignored and no checkpoints are returned.
- **Shadows** are shadow maps: pyrender's spot-light pass (2048x2048 per
  light) with our depth shader storing the distance to the light as d/(d+K),
  K = scene size; the test is 2x2 bilinear PCF with a slope-scaled distance
  bias (:data:`~cornell_harness.renderers.raster.glsl.SHADOW_BIAS`). Each light's map
  covers a cone of about 80 degrees half-angle around the emitter normal
  (:data:`SHADOW_CONE_DEG` plus pyrender's margin); points outside it are
  treated as unoccluded. Occluders nearer to a light than 1% of the scene size (pyrender's near plane) cast no
  shadow. On the Cornell box at 128x128 against Mitsuba at max_depth 2
  (direct light, 16384 spp): mean within 0.1%, median pixel 0.06%, 99% of
  pixels within 2.4% (the rest: penumbra and edge pixels).
"""

from __future__ import annotations

import math
import shutil
import tempfile
from typing import Sequence

import numpy as np

from cornell_harness.adapters.api import RenderResult, Stopwatch
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.raster.framebuffer import BACK_SIDE_ATTR, MSAA_SAMPLES, float_renderer
from cornell_harness.renderers.raster.glsl import write_direct_lighting_shaders
from cornell_harness.renderers.raster.lights import DEFAULT_LIGHTS, light_samples
from cornell_harness.renderers.raster.platform import availability, open_platform, pyrender_distribution

#: Largest supersampling factor per axis (s x s samples per pixel).
MAX_SUPERSAMPLING = 8
#: Largest supersampled framebuffer, in pixels (about 420 MB of RGBA32F with 4x MSAA).
MAX_FRAMEBUFFER_PIXELS = 2048 * 2048
#: Half-angle of each light's shadow cone; pyrender widens its map by pi/32.
SHADOW_CONE_DEG = 75.0
#: Side of pyrender's shadow maps (pyrender.constants.SHADOW_TEX_SZ).
SHADOW_MAP_SIZE = 2048
#: Texture units pyrender keeps back from shadow maps (material textures).
_RESERVED_TEXTURE_UNITS = 6

# --------------------------------------------------------------------------
# Scene conversion
# --------------------------------------------------------------------------


def _look_pose(position, right, up, forward) -> np.ndarray:
    """pyrender pose (camera and lights look along their local -z)."""
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2] = right, up, -np.asarray(forward)
    pose[:3, 3] = position
    return pose


def _light_pose(position: np.ndarray, normal: np.ndarray) -> np.ndarray:
    helper = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    right = np.cross(normal, helper)
    right /= np.linalg.norm(right)
    up = np.cross(right, normal)
    return _look_pose(position, right, up, normal)


def _build_scene(scene: Scene):
    """A pyrender scene with the meshes and camera (no lights); and the emissive materials."""
    import pyrender

    ps = pyrender.Scene(bg_color=np.zeros(4), ambient_light=np.zeros(3))
    emissive = []
    for m in scene.meshes:
        front, le = _add_mesh(ps, scene, m)
        if m.is_emitter:
            emissive.append((front, le))
    ps.add(_camera(scene), pose=_look_pose(np.asarray(scene.camera.position, dtype=np.float64),
                                           *scene.camera.frame()))
    return ps, emissive


def _add_mesh(ps, scene: Scene, m):
    """Add mesh ``m`` to ``ps`` as its front side and a back-side copy; (front material, L_e)."""
    import pyrender

    pos = m.vertices[m.triangles]  # (T, 3, 3)
    n = np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    rho = np.asarray(scene.materials[m.material].reflectance, dtype=np.float32)
    le = np.asarray(m.radiance if m.is_emitter else (0.0, 0.0, 0.0), dtype=np.float32)
    front = pyrender.MetallicRoughnessMaterial(
        baseColorFactor=np.append(rho, np.float32(1.0)), metallicFactor=0.0, roughnessFactor=1.0,
        emissiveFactor=le, doubleSided=False, alphaMode="OPAQUE")
    # The back side (reversed winding) is black but opaque, as Mitsuba's one-sided diffuse;
    # it also makes every triangle cast a shadow whichever side faces the light.
    back = pyrender.MetallicRoughnessMaterial(
        baseColorFactor=np.array([0, 0, 0, 1], dtype=np.float32), metallicFactor=0.0, roughnessFactor=1.0,
        emissiveFactor=np.zeros(3, dtype=np.float32), doubleSided=False, alphaMode="OPAQUE")
    prims = [
        pyrender.Primitive(positions=pos.reshape(-1, 3).astype(np.float32),
                           normals=np.repeat(n, 3, axis=0).astype(np.float32), material=front, mode=4),
        pyrender.Primitive(positions=pos[:, ::-1].reshape(-1, 3).astype(np.float32),
                           normals=np.repeat(-n, 3, axis=0).astype(np.float32), material=back, mode=4),
    ]
    setattr(prims[1], BACK_SIDE_ATTR, True)
    ps.add(pyrender.Mesh(primitives=prims, name=m.name))
    return front, le


def _camera(scene: Scene):
    """pyrender's camera for ``scene``, with near and far planes hugging its bounding box."""
    import pyrender

    cam = scene.camera
    tx, ty = cam.tan_half_fov()
    position = np.asarray(cam.position, dtype=np.float64)
    lo, hi = scene.bounds()
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    far = float(np.max(np.linalg.norm(corners - position, axis=1))) * 1.01 + 1e-6 * scene.extent()
    # Near plane as far out as the geometry allows (depth precision): half the distance
    # to the bounding box, when the camera is outside it.
    outside = float(np.linalg.norm(np.maximum(0.0, np.maximum(lo - position, position - hi))))
    near = max(1e-3 * scene.extent(), 0.5 * outside)
    return pyrender.PerspectiveCamera(yfov=2.0 * math.atan(ty), aspectRatio=tx / ty, znear=near, zfar=far)


# --------------------------------------------------------------------------
# Drawing
# --------------------------------------------------------------------------


def _shadow_texel_angle() -> float:
    """The largest angle one texel of a light's shadow map subtends."""
    cone = math.radians(SHADOW_CONE_DEG)
    shadow_fov = min(2.0 * cone + math.pi / 16.0, math.pi)  # pyrender's SpotLight shadow camera
    return 2.0 * math.tan(shadow_fov / 2.0) / SHADOW_MAP_SIZE


def _accumulate(renderer, ps, emissive, batches, flags, shape) -> np.ndarray:
    """The sum of one render per batch of lights, (height, width, 3) float64."""
    import pyrender

    acc = np.zeros((*shape, 3), dtype=np.float64)
    for b, batch in enumerate(batches):
        for material, le in emissive:  # emission is added in the first pass only
            material.emissiveFactor = le if b == 0 else np.zeros(3, dtype=np.float32)
        nodes = [
            ps.add(pyrender.SpotLight(color=radiance.astype(np.float32), intensity=area,
                                      innerConeAngle=0.0, outerConeAngle=math.radians(SHADOW_CONE_DEG)),
                   pose=_light_pose(p, n))
            for p, n, radiance, area in batch
        ]
        color, _ = renderer.render(ps, flags)
        acc += color
        for node in nodes:
            ps.remove_node(node)
    return acc


def _release(renderer, plat, shader_dir: str) -> None:
    """Free the renderer, the GL context and the shader folder, whatever went wrong."""
    if renderer is not None:
        try:
            renderer.delete()
        except Exception:
            pass
    try:
        plat.delete_context()
    except Exception:
        pass
    shutil.rmtree(shader_dir, ignore_errors=True)


# --------------------------------------------------------------------------
# The adapter
# --------------------------------------------------------------------------


class Pyrender:
    """pyrender rasteriser: emission plus shadowed direct light, no indirect light."""

    name = "pyrender"
    citations = (
        "pyrender2, a maintained fork of pyrender 0.1.45 (OpenGL rasterisation)",
        'Williams 1978, "Casting Curved Shadows on Curved Surfaces" (SIGGRAPH): shadow maps')
    deterministic = True  # no sampling: the seed changes nothing
    estimator = "biased"  # direct light only, shadow maps: it does not converge to the reference
    features = frozenset({"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"})
    approximations: tuple[str, ...] = (
        f"area lights replaced by ~{DEFAULT_LIGHTS} one-sided point lights (pyrender SpotLights, cosine "
        "falloff in our shader): an area light of radiance L, area A, normal n has I(theta) = L*A*cos(theta); "
        "each emitter triangle is cut into k*k equal sub-triangles with a light of I = L*(A_tri/k^2)*cos(theta) "
        "at each centroid (Cornell box: 32 lights)",
        "direct lighting only: no indirect light; max_depth is ignored except 1 (emitters only), "
        "so the scene's -1 (unbounded) is rendered as 2 (emission + direct light)",
        "box filter by supersampling: rendered at s x s the resolution with 4x MSAA, s = round(sqrt(spp)) "
        "in 1..8 (less above 256x256 pixels), then each s x s block averaged; deterministic: seed ignored, "
        "no checkpoints",
        "shadows from 2048x2048 shadow maps, one per light (2x2 PCF, slope-scaled bias); points more than "
        f"~{SHADOW_CONE_DEG + 5.6:.0f} deg off a light's emitter normal are treated as unoccluded",
        "shading by this adapter's float Lambertian shaders, not pyrender's glTF PBR shader "
        "(0.93x Lambert plus a specular lobe, clamped 8-bit gamma output)",
    )

    def __init__(self, lights: int = DEFAULT_LIGHTS, shadows: bool = True,
                 max_supersampling: int = MAX_SUPERSAMPLING):
        self.lights = int(lights)
        self.shadows = bool(shadows)
        self.max_supersampling = int(max_supersampling)

    def unavailable_reason(self) -> str | None:
        try:
            return availability()[1]
        except Exception as e:  # never raise
            return f"availability check failed: {type(e).__name__}: {e}"

    def version(self) -> str:
        platform, _, facts = availability()
        return (f"{pyrender_distribution()} ({platform}: {facts.get('gl_renderer', '?')}, "
                f"OpenGL {facts.get('gl_version', '?')})")

    def supersampling(self, spp: int, width: int, height: int, max_size: int) -> int:
        """Supersampling factor per axis for ``spp`` (see the module docstring)."""
        s = int(round(math.sqrt(max(1, int(spp)))))
        s = min(s, self.max_supersampling, max_size // max(width, height),
                math.isqrt(MAX_FRAMEBUFFER_PIXELS // (width * height)))
        return max(1, s)

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = ()) -> RenderResult:
        platform, reason, facts = availability()
        if reason is not None:
            raise RuntimeError(f"pyrender is unavailable: {reason}")
        cam = scene.camera
        lights = [] if scene.max_depth == 1 else light_samples(scene, self.lights)
        plat = open_platform(platform)
        shader_dir = tempfile.mkdtemp(prefix="cbox-pyrender-")
        renderer, setup = None, Stopwatch()
        try:
            s = self._supersampling_here(cam, spp)
            write_direct_lighting_shaders(shader_dir, scene.extent(), _shadow_texel_angle())
            renderer = float_renderer(cam.width * s, cam.height * s, shader_dir)
            ps, emissive = _build_scene(scene)
            flags, batches = self._light_passes(lights)
            setup_s, clock = setup.wall(), Stopwatch()  # context, shaders and scene: set-up, not render
            acc = _accumulate(renderer, ps, emissive, batches, flags, (cam.height * s, cam.width * s))
            image = acc.reshape(cam.height, s, cam.width, s, 3).mean(axis=(1, 3)).astype(np.float32)
            elapsed, cpu = clock.read()
        finally:
            _release(renderer, plat, shader_dir)

        info = {
            "package": pyrender_distribution(),
            "platform": platform,
            "gl_renderer": facts.get("gl_renderer"),
            "supersampling": s,
            "msaa_samples": MSAA_SAMPLES,
            "lights": len(lights),
            "light_passes": len(batches),
            "shadows": self.shadows,
            "direct_only": True,
            "setup_s": round(setup_s, 4),
        }
        return RenderResult(image=image, time_s=elapsed, spp=int(spp), seed=int(seed), checkpoints=[], info=info,
                            cpu_time_s=cpu)

    def _supersampling_here(self, cam, spp: int) -> int:
        """:meth:`supersampling` within the current GL context's framebuffer limits."""
        from OpenGL import GL

        max_size = min(int(GL.glGetIntegerv(GL.GL_MAX_RENDERBUFFER_SIZE)),
                       int(np.min(GL.glGetIntegerv(GL.GL_MAX_VIEWPORT_DIMS))))
        if max(cam.width, cam.height) > max_size:
            raise ValueError(f"{cam.width}x{cam.height} exceeds this OpenGL's largest framebuffer ({max_size})")
        return self.supersampling(spp, cam.width, cam.height, max_size)

    def _light_passes(self, lights: list) -> tuple[object, list[list]]:
        """(render flags, lights in batches): each shadow map takes a texture unit, so with
        shadows a pass holds only as many lights as there are units to spare."""
        import pyrender
        from OpenGL import GL

        flags = pyrender.RenderFlags.OFFSCREEN
        if self.shadows:
            flags |= pyrender.RenderFlags.SHADOWS_SPOT
            units = int(GL.glGetIntegerv(GL.GL_MAX_TEXTURE_IMAGE_UNITS))
            per_pass = max(1, units - _RESERVED_TEXTURE_UNITS)
        else:
            per_pass = pyrender.constants.MAX_N_LIGHTS
        return flags, [lights[i:i + per_pass] for i in range(0, len(lights), per_pass)] or [[]]

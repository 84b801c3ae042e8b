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
choice is then put in ``PYOPENGL_PLATFORM`` for this process. On Debian:
``libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri`` (EGL, Mesa's llvmpipe works
without a GPU) or ``libosmesa6``.

How the scene is drawn
----------------------
pyrender supplies the GL context, scene graph, mesh buffers, camera
projection and one shadow-map pass per spot light. Its own shaders are
replaced (through its ``ShaderProgramCache(shader_dir=...)``) by the small
shaders in this module, and its 8-bit colour buffer by a float one, because
pyrender's stock shader is not a Lambertian model in our units:

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

This adapter's fragment shader computes, in float32,
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
  sub-triangles (k from the triangle's share of :data:`DEFAULT_LIGHTS`
  lights, at least 1); one light sits at each sub-triangle's centroid with
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
  bias (:data:`SHADOW_BIAS`). Each light's map covers a cone of about 80
  degrees half-angle around the emitter normal (:data:`SHADOW_CONE_DEG` plus
  pyrender's margin); points outside it are treated as unoccluded. Occluders
  nearer to a light than 1% of the scene size (pyrender's near plane) cast no
  shadow. On the Cornell box at 128x128 against Mitsuba at max_depth 2
  (direct light, 16384 spp): mean within 0.1%, median pixel 0.06%, 99% of
  pixels within 2.4% (the rest: penumbra and edge pixels).
"""

from __future__ import annotations

import ctypes.util
import importlib.metadata
import importlib.util
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Sequence

import numpy as np

from harness.adapter import RenderResult
from harness.scene import Scene

#: Point lights that all area emitters together are split into (about).
DEFAULT_LIGHTS = 32
#: Largest supersampling factor per axis (s x s samples per pixel).
MAX_SUPERSAMPLING = 8
#: Largest supersampled framebuffer, in pixels (about 420 MB of RGBA32F with 4x MSAA).
MAX_FRAMEBUFFER_PIXELS = 2048 * 2048
#: MSAA samples per (sub)pixel of the colour buffer (OpenGL 3 guarantees 4).
MSAA_SAMPLES = 4
#: Half-angle of each light's shadow cone; pyrender widens its map by pi/32.
SHADOW_CONE_DEG = 75.0
#: Side of pyrender's shadow maps (pyrender.constants.SHADOW_TEX_SZ).
SHADOW_MAP_SIZE = 2048
#: Shadow-test bias on the distance to the light, in shadow-map texels at the shaded
#: point: SLOPE_BIAS * tan(angle of incidence) + CONST_BIAS. Tuned against Mitsuba's
#: direct lighting (max_depth 2) on the Cornell box: no acne, penumbrae within ~1%.
SHADOW_BIAS = {"SLOPE_BIAS": 2.0, "CONST_BIAS": 1.0}
#: Texture units pyrender keeps back from shadow maps (material textures).
_RESERVED_TEXTURE_UNITS = 6

_HEADLESS = ("egl", "osmesa")
_INSTALL_HINT = "pip install 'pyrender2>=0.2.2' 'PyOpenGL>=3.1.9'"
_APT_HINT = "apt-get install libegl1 libgl1 libegl-mesa0 libgl1-mesa-dri (EGL) or libosmesa6 (OSMesa)"

# --------------------------------------------------------------------------
# Choosing the headless platform and checking that a context can be made
# --------------------------------------------------------------------------

#: Run in a subprocess to see whether a platform can create a GL context.
_PROBE = r"""
import os, sys
os.environ["PYOPENGL_PLATFORM"] = sys.argv[1]
import pyrender  # noqa: F401
if sys.argv[1] == "egl":
    from pyrender.platforms import egl
    p = egl.EGLPlatform(8, 8, device=egl.get_device_by_index(int(os.environ.get("EGL_DEVICE_ID", "0"))))
else:
    from pyrender.platforms.osmesa import OSMesaPlatform
    p = OSMesaPlatform(8, 8)
p.init_context()
p.make_current()
from OpenGL.GL import glGetString, GL_RENDERER
print(glGetString(GL_RENDERER).decode())
p.delete_context()
"""


def _libraries_present(platform: str) -> bool:
    if platform == "egl":
        return bool(ctypes.util.find_library("EGL")) and bool(
            ctypes.util.find_library("OpenGL") or ctypes.util.find_library("GL")
        )
    return bool(ctypes.util.find_library("OSMesa"))


def _probe(platform: str) -> str | None:
    """None if ``platform`` can create a context (in a subprocess), else why not."""
    try:
        p = subprocess.run([sys.executable, "-c", _PROBE, platform], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.SubprocessError) as e:
        return f"{type(e).__name__}: {e}"
    if p.returncode == 0:
        return None
    lines = [ln.strip() for ln in (p.stderr or p.stdout).splitlines() if ln.strip()]
    return lines[-1] if lines else f"exit status {p.returncode}"


def _opengl_platform_in_use() -> str | None:
    """The platform PyOpenGL was already bound to in this process, if any."""
    mod = sys.modules.get("OpenGL.platform")
    plat = getattr(mod, "PLATFORM", None)
    if plat is None:
        return None
    name = type(plat).__name__.lower()
    for p in _HEADLESS:
        if p in name:
            return p
    return name


def choose_platform() -> tuple[str | None, str]:
    """(``egl`` / ``osmesa`` or None, a sentence saying why or why not)."""
    env = os.environ.get("PYOPENGL_PLATFORM")
    if env:
        if env not in _HEADLESS:
            return None, f"PYOPENGL_PLATFORM={env!r}: pyrender renders headless only with 'egl' or 'osmesa'"
        return env, f"PYOPENGL_PLATFORM={env} (set by the user)"
    if "OpenGL.platform" in sys.modules:
        used = _opengl_platform_in_use()
        if used in _HEADLESS:
            return used, f"PyOpenGL was already imported with {used}"
        return None, (f"PyOpenGL was already imported in this process with platform {used!r}; "
                      "set PYOPENGL_PLATFORM=egl or osmesa before it is imported")
    present = [p for p in _HEADLESS if _libraries_present(p)]
    if not present:
        return None, f"no EGL or OSMesa library found; {_APT_HINT}"
    if len(present) == 1:
        return present[0], f"only {present[0]} libraries found"
    failures = []
    for p in present:
        why = _probe(p)
        if why is None:
            return p, f"{p} context works (probed in a subprocess)"
        failures.append(f"{p}: {why}")
    return None, "no headless OpenGL context could be created (" + "; ".join(failures) + ")"


def _open_platform(platform: str, width: int = 8, height: int = 8):
    """A current pyrender platform (GL context) for ``platform``."""
    if platform == "egl":
        from pyrender.platforms import egl

        device = egl.get_device_by_index(int(os.environ.get("EGL_DEVICE_ID", "0")))
        plat = egl.EGLPlatform(width, height, device=device)
    else:
        from pyrender.platforms.osmesa import OSMesaPlatform

        plat = OSMesaPlatform(width, height)
    plat.init_context()
    plat.make_current()
    return plat


def _gl_string(name: int) -> str:
    from OpenGL import GL

    s = GL.glGetString(name)
    return s.decode(errors="replace") if isinstance(s, bytes) else str(s)


_AVAILABILITY: tuple[str | None, str | None, dict] | None = None


def availability() -> tuple[str | None, str | None, dict]:
    """(platform, reason it is unavailable or None, GL facts). Computed once per process."""
    global _AVAILABILITY
    if _AVAILABILITY is None:
        try:
            platform, reason, facts = _check_availability()
        except Exception as e:  # never raise from an availability probe
            platform, reason, facts = None, f"availability check failed: {type(e).__name__}: {e}", {}
        if reason is not None:
            reason = " ".join(reason.split())  # one line (GL errors print over several)
        _AVAILABILITY = (platform, reason, facts)
    return _AVAILABILITY


def _check_availability() -> tuple[str | None, str | None, dict]:
    if importlib.util.find_spec("pyrender") is None:
        return None, f"pyrender is not installed; {_INSTALL_HINT}", {}
    platform, why = choose_platform()
    if platform is None:
        return None, why, {}
    os.environ.setdefault("PYOPENGL_PLATFORM", platform)
    try:
        import pyrender
    except Exception as e:
        return None, f"cannot import pyrender with PYOPENGL_PLATFORM={platform}: {type(e).__name__}: {e}", {}
    version = getattr(pyrender, "__version__", "0")
    if _version_tuple(version) < (0, 2) and not hasattr(np, "infty"):
        return None, (f"pyrender {version} uses np.infty, which NumPy {np.__version__} removed; "
                      f"{_INSTALL_HINT} (uninstall pyrender first)"), {}
    try:
        plat = _open_platform(platform)
    except Exception as e:
        msg = str(e) or "initialisation failed"
        return None, f"cannot create an OpenGL context with {platform}: {type(e).__name__}: {msg}", {}
    try:
        from OpenGL import GL

        facts = {
            "platform": platform,
            "platform_choice": why,
            "gl_renderer": _gl_string(GL.GL_RENDERER),
            "gl_version": _gl_string(GL.GL_VERSION),
        }
        major = GL.glGetIntegerv(GL.GL_MAJOR_VERSION)
        minor = GL.glGetIntegerv(GL.GL_MINOR_VERSION)
        if (int(major), int(minor)) < (3, 3):
            return None, f"OpenGL {facts['gl_version']} found; pyrender needs 3.3 or newer", facts
    except Exception as e:
        return None, f"OpenGL context unusable with {platform}: {type(e).__name__}: {e}", {}
    finally:
        try:
            plat.delete_context()
        except Exception:
            pass
    return platform, None, facts


def _version_tuple(v: str) -> tuple[int, ...]:
    out = []
    for part in v.split("."):
        digits = "".join(ch for ch in part if ch.isdigit())
        if not digits:
            break
        out.append(int(digits))
    return tuple(out)


def _distribution() -> str:
    """The installed distribution that provides the ``pyrender`` module, with its version."""
    try:
        names = importlib.metadata.packages_distributions().get("pyrender", [])
    except Exception:
        names = []
    for name in names or ["pyrender2", "pyrender-maintained", "pyrender"]:
        try:
            return f"{name} {importlib.metadata.version(name)}"
        except importlib.metadata.PackageNotFoundError:
            continue
    return "pyrender (unknown distribution)"


# --------------------------------------------------------------------------
# Area lights as point lights
# --------------------------------------------------------------------------


def light_samples(scene: Scene, n_lights: int = DEFAULT_LIGHTS) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """The point lights standing in for the scene's area emitters.

    Returns ``(position, normal, radiance, area)`` per light: a light of
    radiant intensity ``radiance * area * max(cos(theta), 0)`` (theta from
    ``normal``). Each emitter triangle is cut into k*k congruent sub-triangles
    (k = round(sqrt(n_lights * share of the total emitter area)), at least 1)
    and gets one light at each sub-triangle's centroid.
    """
    tris = []
    for m in scene.emitters:
        for t in m.triangles:
            a, b, c = m.vertices[t]
            cross = np.cross(b - a, c - a)
            area = 0.5 * float(np.linalg.norm(cross))
            if area > 0.0:
                tris.append((a, b, c, cross / (2.0 * area), area, np.asarray(m.radiance, dtype=np.float64)))
    total = sum(t[4] for t in tris)
    out = []
    for a, b, c, normal, area, radiance in tris:
        k = max(1, int(round(math.sqrt(n_lights * area / total))))
        e1, e2 = (b - a) / k, (c - a) / k
        centres = []
        for i in range(k):
            for j in range(k - i):
                centres.append(a + (i + 1 / 3) * e1 + (j + 1 / 3) * e2)  # upward sub-triangle
                if i + j <= k - 2:
                    centres.append(a + (i + 2 / 3) * e1 + (j + 2 / 3) * e2)  # downward sub-triangle
        for p in centres:
            out.append((p, normal, radiance, area / (k * k)))
    return out


# --------------------------------------------------------------------------
# Shaders (written to a temporary folder for pyrender's ShaderProgramCache)
# --------------------------------------------------------------------------

# pyrender turns "#ifdef NAME" into "#if 1"/"#if 0" and replaces each define's
# name by its value (NORMAL_LOC, INST_M_LOC, MAX_SPOT_LIGHTS, ...).

_MESH_VERT = """#version 330 core
layout(location = 0) in vec3 position;
#ifdef NORMAL_LOC
layout(location = NORMAL_LOC) in vec3 normal;
#endif
layout(location = INST_M_LOC) in mat4 inst_m;
uniform mat4 M;
uniform mat4 V;
uniform mat4 P;
// centroid: with MSAA, a partly covered pixel must not shade a point off the triangle.
centroid out vec3 frag_position;
centroid out vec3 frag_normal;
void main()
{
    mat4 W = M * inst_m;
    vec4 wp = W * vec4(position, 1.0);
    gl_Position = P * V * wp;
    frag_position = wp.xyz;
#ifdef NORMAL_LOC
    frag_normal = normalize(mat3(transpose(inverse(W))) * normal);
#else
    frag_normal = vec3(0.0);
#endif
}
"""

_MESH_FRAG = """#version 330 core
// Lambertian direct lighting from one-sided cosine point lights, in float.
const float PI = 3.141592653589793;
const float DIST_SCALE = @DIST_SCALE@;    // K: the shadow map stores d/(d+K)
const float TEXEL_ANGLE = @TEXEL_ANGLE@;  // largest angle one shadow-map texel subtends
const float SLOPE_BIAS = @SLOPE_BIAS@;        // in texels per unit tan(theta_r)
const float CONST_BIAS = @CONST_BIAS@;        // in texels

struct SpotLight {
    vec3 color;        // radiance L of the emitter
    float intensity;   // area of the emitter piece: I(theta) = color*intensity*cos(theta)
    vec3 position;
    vec3 direction;    // emitter normal
#ifdef SPOT_LIGHT_SHADOWS
    sampler2D shadow_map;
    mat4 light_matrix;
#endif
};
struct Material {
    vec3 emissive_factor;
    vec4 base_color_factor;
};

uniform Material material;
uniform SpotLight spot_lights[MAX_SPOT_LIGHTS];
uniform int n_spot_lights;

centroid in vec3 frag_position;
centroid in vec3 frag_normal;
out vec4 frag_color;

#ifdef SPOT_LIGHT_SHADOWS
float stored_distance(int i, ivec2 texel, ivec2 size)
{
    texel = clamp(texel, ivec2(0), size - 1);
    float s = texelFetch(spot_lights[i].shadow_map, texel, 0).r;
    return s >= 1.0 ? 3.0e38 : DIST_SCALE * s / (1.0 - s);
}

float visibility(int i, vec3 p, float dist, float cos_r, float cos_l)
{
    // Size of a shadow-map texel on a surface facing the light at this point
    // (texels subtend less than TEXEL_ANGLE away from the map's centre).
    float texel = dist * TEXEL_ANGLE * cos_l;
    float tan_r = min(sqrt(max(0.0, 1.0 - cos_r * cos_r)) / cos_r, 8.0);
    vec4 c = spot_lights[i].light_matrix * vec4(p, 1.0);
    if (c.w <= 0.0) return 1.0;
    vec2 uv = c.xy / c.w * 0.5 + 0.5;
    if (uv.x < 0.0 || uv.y < 0.0 || uv.x > 1.0 || uv.y > 1.0) return 1.0;  // outside the map
    // Slope-scaled bias: neighbouring texels see the surface up to ~texel*tan_r nearer.
    float d = dist - texel * (SLOPE_BIAS * tan_r + CONST_BIAS);
    ivec2 size = textureSize(spot_lights[i].shadow_map, 0);
    vec2 f = uv * vec2(size) - 0.5;
    ivec2 t = ivec2(floor(f));
    vec2 w = f - floor(f);
    float v00 = d <= stored_distance(i, t, size) ? 1.0 : 0.0;
    float v10 = d <= stored_distance(i, t + ivec2(1, 0), size) ? 1.0 : 0.0;
    float v01 = d <= stored_distance(i, t + ivec2(0, 1), size) ? 1.0 : 0.0;
    float v11 = d <= stored_distance(i, t + ivec2(1, 1), size) ? 1.0 : 0.0;
    return mix(mix(v00, v10, w.x), mix(v01, v11, w.x), w.y);
}
#endif

void main()
{
    vec3 n = normalize(frag_normal);
    vec3 lo = vec3(0.0);
    for (int i = 0; i < n_spot_lights; i++) {
        vec3 to_light = spot_lights[i].position - frag_position;
        float dist = length(to_light);
        vec3 l = to_light / dist;
        float cos_r = dot(n, l);
        float cos_l = -dot(spot_lights[i].direction, l);
        if (cos_r <= 0.0 || cos_l <= 0.0) continue;
        float v = 1.0;
#ifdef SPOT_LIGHT_SHADOWS
        v = visibility(i, frag_position, dist, cos_r, cos_l);
#endif
        lo += spot_lights[i].color * (spot_lights[i].intensity * cos_l * cos_r * v / (dist * dist));
    }
    frag_color = vec4(material.base_color_factor.rgb / PI * lo + material.emissive_factor, 1.0);
}
"""

_DEPTH_VERT = """#version 330 core
layout(location = 0) in vec3 position;
layout(location = INST_M_LOC) in mat4 inst_m;
uniform mat4 P;
uniform mat4 V;
uniform mat4 M;
out vec3 eye_position;
void main()
{
    vec4 e = V * M * inst_m * vec4(position, 1.0);
    eye_position = e.xyz;
    gl_Position = P * e;
}
"""

_DEPTH_FRAG = """#version 330 core
// Shadow map: distance to the light (the eye), stored as d/(d+K) in [0, 1).
const float DIST_SCALE = @DIST_SCALE@;
in vec3 eye_position;
out vec4 frag_color;
void main()
{
    float d = length(eye_position);
    gl_FragDepth = d / (d + DIST_SCALE);
    frag_color = vec4(1.0);
}
"""


def _write_shaders(folder: str, dist_scale: float, texel_angle: float) -> None:
    subs = {"@DIST_SCALE@": f"{dist_scale:.9e}", "@TEXEL_ANGLE@": f"{texel_angle:.9e}"}
    subs.update({f"@{k}@": f"{v:.9e}" for k, v in SHADOW_BIAS.items()})
    for name, text in (("mesh.vert", _MESH_VERT), ("mesh.frag", _MESH_FRAG),
                       ("mesh_depth.vert", _DEPTH_VERT), ("mesh_depth.frag", _DEPTH_FRAG)):
        for k, v in subs.items():
            text = text.replace(k, v)
        with open(os.path.join(folder, name), "w", encoding="utf-8") as f:
            f.write(text)


def _float_renderer(width: int, height: int, shader_dir: str):
    """A pyrender Renderer with our shaders and an RGBA32F colour buffer."""
    import pyrender
    from OpenGL import GL
    from pyrender.shader_program import ShaderProgramCache

    class FloatRenderer(pyrender.Renderer):
        def __init__(self):
            super().__init__(width, height)
            self._program_cache = ShaderProgramCache(shader_dir=shader_dir)

        def _sorted_mesh_nodes(self, scene):
            # pyrender draws in a set's order, which changes from run to run; with
            # MSAA, llvmpipe's silhouette pixels depend on the draw order. Fix it.
            return sorted(scene.mesh_nodes, key=lambda node: node.mesh.name)

        def _configure_main_framebuffer(self):
            # pyrender's pair of framebuffers (MSAA, then a resolve target), in RGBA32F.
            dims = (self.viewport_width, self.viewport_height)
            if self._main_fb is not None and self._main_fb_dims != dims:
                self._delete_main_framebuffer()
            if self._main_fb is not None:
                return
            w, h = dims
            samples = min(MSAA_SAMPLES, int(GL.glGetIntegerv(GL.GL_MAX_SAMPLES)))
            self._main_cb, self._main_db, self._main_cb_ms, self._main_db_ms = GL.glGenRenderbuffers(4)
            for rb, fmt, n in ((self._main_cb, GL.GL_RGBA32F, 0), (self._main_db, GL.GL_DEPTH_COMPONENT24, 0),
                               (self._main_cb_ms, GL.GL_RGBA32F, samples),
                               (self._main_db_ms, GL.GL_DEPTH_COMPONENT24, samples)):
                GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
                GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, n, fmt, w, h)
            self._main_fb, self._main_fb_ms = GL.glGenFramebuffers(2)
            for fb, cb, db in ((self._main_fb, self._main_cb, self._main_db),
                               (self._main_fb_ms, self._main_cb_ms, self._main_db_ms)):
                GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, fb)
                GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, cb)
                GL.glFramebufferRenderbuffer(GL.GL_DRAW_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_RENDERBUFFER, db)
                status = GL.glCheckFramebufferStatus(GL.GL_DRAW_FRAMEBUFFER)
                if status != GL.GL_FRAMEBUFFER_COMPLETE:
                    raise RuntimeError(f"the RGBA32F framebuffer is incomplete (status 0x{int(status):x})")
            self._main_fb_dims = dims

        def _bind_and_draw_primitive(self, primitive, pose, program, flags):
            # Back-side copies lose depth ties to front sides (at a closed mesh's
            # silhouette both meet at the same depth; the draw order is a set's order).
            back = getattr(primitive, "cbox_back_side", False)
            if back:
                GL.glEnable(GL.GL_POLYGON_OFFSET_FILL)
                GL.glPolygonOffset(1.0, 4.0)
            try:
                super()._bind_and_draw_primitive(primitive, pose, program, flags)
            finally:
                if back:
                    GL.glDisable(GL.GL_POLYGON_OFFSET_FILL)

        def _read_main_framebuffer(self, scene, flags):
            w, h = self._main_fb_dims
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb_ms)
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, self._main_fb)
            GL.glBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL.GL_COLOR_BUFFER_BIT, GL.GL_NEAREST)  # MSAA resolve
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, self._main_fb)
            GL.glReadBuffer(GL.GL_COLOR_ATTACHMENT0)
            GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 4)
            buf = GL.glReadPixels(0, 0, w, h, GL.GL_RGBA, GL.GL_FLOAT)
            if isinstance(buf, (bytes, bytearray)):
                img = np.frombuffer(buf, dtype=np.float32)
            else:
                img = np.asarray(buf, dtype=np.float32).ravel()
            # GL's row 0 is the bottom; the harness's is the top.
            return img.reshape(h, w, 4)[::-1, :, :3].copy(), None

    return FloatRenderer()


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
        prims[1].cbox_back_side = True
        ps.add(pyrender.Mesh(primitives=prims, name=m.name))
        if m.is_emitter:
            emissive.append((front, le))

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
    camera = pyrender.PerspectiveCamera(yfov=2.0 * math.atan(ty), aspectRatio=tx / ty, znear=near, zfar=far)
    ps.add(camera, pose=_look_pose(position, *cam.frame()))
    return ps, emissive


# --------------------------------------------------------------------------
# The adapter
# --------------------------------------------------------------------------


class Pyrender:
    """pyrender rasteriser: emission plus shadowed direct light, no indirect light."""

    name = "pyrender"
    deterministic = True  # no sampling: the seed changes nothing
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
        return f"{_distribution()} ({platform}: {facts.get('gl_renderer', '?')}, OpenGL {facts.get('gl_version', '?')})"

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
        import pyrender
        from OpenGL import GL

        cam = scene.camera
        lights = [] if scene.max_depth == 1 else light_samples(scene, self.lights)
        plat = _open_platform(platform)
        shader_dir = tempfile.mkdtemp(prefix="cbox-pyrender-")
        renderer = None
        try:
            max_size = min(int(GL.glGetIntegerv(GL.GL_MAX_RENDERBUFFER_SIZE)),
                           int(np.min(GL.glGetIntegerv(GL.GL_MAX_VIEWPORT_DIMS))))
            if max(cam.width, cam.height) > max_size:
                raise ValueError(f"{cam.width}x{cam.height} exceeds this OpenGL's largest framebuffer ({max_size})")
            s = self.supersampling(spp, cam.width, cam.height, max_size)
            width, height = cam.width * s, cam.height * s
            cone = math.radians(SHADOW_CONE_DEG)
            shadow_fov = min(2.0 * cone + math.pi / 16.0, math.pi)  # pyrender's SpotLight shadow camera
            texel_angle = 2.0 * math.tan(shadow_fov / 2.0) / SHADOW_MAP_SIZE
            _write_shaders(shader_dir, scene.extent(), texel_angle)
            renderer = _float_renderer(width, height, shader_dir)

            ps, emissive = _build_scene(scene)
            flags = pyrender.RenderFlags.OFFSCREEN
            if self.shadows:
                flags |= pyrender.RenderFlags.SHADOWS_SPOT
                units = int(GL.glGetIntegerv(GL.GL_MAX_TEXTURE_IMAGE_UNITS))
                per_pass = max(1, units - _RESERVED_TEXTURE_UNITS)
            else:
                per_pass = pyrender.constants.MAX_N_LIGHTS
            batches = [lights[i:i + per_pass] for i in range(0, len(lights), per_pass)] or [[]]

            acc = np.zeros((height, width, 3), dtype=np.float64)
            t0 = time.perf_counter()
            for b, batch in enumerate(batches):
                for material, le in emissive:  # emission is added in the first pass only
                    material.emissiveFactor = le if b == 0 else np.zeros(3, dtype=np.float32)
                nodes = [
                    ps.add(pyrender.SpotLight(color=radiance.astype(np.float32), intensity=area,
                                              innerConeAngle=0.0, outerConeAngle=cone),
                           pose=_light_pose(p, n))
                    for p, n, radiance, area in batch
                ]
                color, _ = renderer.render(ps, flags)
                acc += color
                for node in nodes:
                    ps.remove_node(node)
            image = acc.reshape(cam.height, s, cam.width, s, 3).mean(axis=(1, 3)).astype(np.float32)
            elapsed = time.perf_counter() - t0
        finally:
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

        info = {
            "package": _distribution(),
            "platform": platform,
            "gl_renderer": facts.get("gl_renderer"),
            "supersampling": s,
            "msaa_samples": MSAA_SAMPLES,
            "lights": len(lights),
            "light_passes": len(batches),
            "shadows": self.shadows,
            "direct_only": True,
        }
        return RenderResult(image=image, time_s=elapsed, spp=int(spp), seed=int(seed), checkpoints=[], info=info)

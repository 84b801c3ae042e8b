"""The pyrender adapter: availability never raises, calibration in radiance units, Cornell box layout."""

from __future__ import annotations

import ctypes.util
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from tests.conftest import CORNELL, ROOT
from cornell_harness.adapters.api import RenderResult
from cornell_harness.scenes.loader import load_scene
from cornell_harness.renderers.raster.lights import light_samples
from cornell_harness.renderers.raster.pyrender_adapter import Pyrender


def _run_python(code: str, env_updates: dict[str, str | None]) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    for k, v in env_updates.items():
        if v is None:
            env.pop(k, None)
        else:
            env[k] = v
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT, env=env)


_REASON = """
from cornell_harness.renderers.raster.pyrender_adapter import Pyrender
r = Pyrender().unavailable_reason()
assert r is None or (isinstance(r, str) and r and "\\n" not in r), repr(r)
print("REASON:", r)
"""


def test_unavailable_reason_never_raises_with_bogus_platform():
    p = _run_python(_REASON, {"PYOPENGL_PLATFORM": "bogus"})
    assert p.returncode == 0, p.stderr
    assert "REASON: PYOPENGL_PLATFORM='bogus'" in p.stdout


def test_unavailable_reason_when_pyrender_missing():
    p = _run_python("import sys; sys.modules['pyrender'] = None\n" + _REASON, {})
    assert p.returncode == 0, p.stderr
    assert "REASON: pyrender is not installed" in p.stdout


@pytest.fixture(scope="module")
def renderer() -> Pyrender:
    r = Pyrender()
    reason = r.unavailable_reason()
    if reason is not None:
        pytest.skip(reason)
    return r


@pytest.mark.skipif(not ctypes.util.find_library("OSMesa"), reason="no OSMesa library (apt-get install libosmesa6)")
def test_osmesa_is_used_when_only_its_library_is_found(renderer):
    code = f"""
import cornell_harness.renderers.raster.platform as gl_platform
from cornell_harness.renderers.raster.pyrender_adapter import Pyrender
gl_platform._libraries_present = lambda platform: platform == "osmesa"
from cornell_harness.scenes.loader import load_scene
r = Pyrender()
assert r.unavailable_reason() is None, r.unavailable_reason()
assert gl_platform.availability()[0] == "osmesa"
img = r.render(load_scene({str(CORNELL)!r}).with_resolution(16, 16), spp=1, seed=0).image
assert img.shape == (16, 16, 3) and (img >= 0).all() and img.max() > 1.0
print("OK")
"""
    p = _run_python(code, {"PYOPENGL_PLATFORM": None})
    assert p.returncode == 0 and "OK" in p.stdout, p.stderr


def test_supersampling_from_spp():
    r = Pyrender()
    assert [r.supersampling(spp, 64, 64, 16384) for spp in (0, 1, 2, 4, 9, 16, 64, 10_000)] == [1, 1, 1, 2, 3, 4, 8, 8]
    assert r.supersampling(64, 256, 256, 1024) == 4  # capped by the GL framebuffer size
    assert r.supersampling(64, 512, 512, 16384) == 4  # capped by memory (MAX_FRAMEBUFFER_PIXELS)
    assert r.supersampling(64, 4000, 3000, 16384) == 1


def test_light_samples_preserve_power():
    scene = load_scene(CORNELL)
    lights = light_samples(scene, 32)
    (light,) = scene.emitters
    assert len(lights) == 32
    assert math.isclose(sum(a for *_, a in lights), 0.46 * 0.38, rel_tol=1e-9)
    for p, n, radiance, _ in lights:
        assert np.allclose(n, [0, -1, 0]) and np.allclose(radiance, light.radiance)
        assert abs(p[1] - 0.99) < 1e-12 and -0.23 < p[0] < 0.23 and -0.18 < p[2] < 0.2
    centroid = np.average([p for p, *_ in lights], axis=0, weights=[a for *_, a in lights])
    assert np.allclose(centroid, [0.0, 0.99, 0.01])


# A large white floor (z = 0, facing up) under a small square emitter facing down at
# height H; the camera looks down at the floor obliquely, past the emitter.
RHO, L, SIDE, H = 0.8, 100.0, 0.1, 2.0
FLOOR_SCENE = f"""\
format = 1
name = "floor-under-small-light"
features = ["triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"]

[camera]
type = "pinhole"
position = [0, -3, 3]
look_at = [0, 0, 0]
up = [0, 0, 1]
fov_deg = 30
fov_axis = "x"
resolution = [48, 32]

[render]
max_depth = -1
pixel_filter = "box"

[materials.white]
type = "diffuse"
reflectance = [{RHO}, {RHO}, {RHO}]

[[meshes]]
name = "floor"
material = "white"
vertices = [[-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]]
faces = [[0, 1, 2, 3]]

[[meshes]]
name = "light"
material = "white"
vertices = [[-{SIDE / 2}, -{SIDE / 2}, {H}], [-{SIDE / 2}, {SIDE / 2}, {H}], [{SIDE / 2}, {SIDE / 2}, {H}], [{SIDE / 2}, -{SIDE / 2}, {H}]]
faces = [[0, 1, 2, 3]]
emitter = {{ radiance = [{L}, {L / 2}, {L / 4}] }}
"""


def _floor_points(scene) -> np.ndarray:
    """World point on z = 0 seen through each pixel centre, (H, W, 3)."""
    cam = scene.camera
    right, up, forward = cam.frame()
    tx, ty = cam.tan_half_fov()
    x = ((np.arange(cam.width) + 0.5) / cam.width * 2 - 1) * tx
    y = (1 - (np.arange(cam.height) + 0.5) / cam.height * 2) * ty
    d = forward + x[None, :, None] * right + y[:, None, None] * up
    o = np.asarray(cam.position)
    t = -o[2] / d[..., 2]
    return o + t[..., None] * d


def test_floor_radiance_matches_point_light_irradiance(renderer, tmp_path):
    path = tmp_path / "scene.toml"
    path.write_text(FLOOR_SCENE)
    scene = load_scene(path)
    result = renderer.render(scene, spp=16, seed=0)
    assert isinstance(result, RenderResult)
    img = result.image
    assert img.shape == (32, 48, 3) and img.dtype == np.float32

    # E = L A cos(theta_l) cos(theta_r) / d^2 with cos(theta_l) = cos(theta_r) = H / d.
    p = _floor_points(scene)
    d2 = p[..., 0] ** 2 + p[..., 1] ** 2 + H**2
    e = L * SIDE**2 * H**2 / d2**2
    expected = RHO / math.pi * e[..., None] * np.array([1.0, 0.5, 0.25])

    # The pixel under the light (image centre: the camera looks at the origin).
    centre = img[15:17, 23:25].mean(axis=(0, 1))
    assert np.allclose(centre, RHO / math.pi * L * SIDE**2 / H**2 * np.array([1, 0.5, 0.25]), rtol=0.02)
    # Every pixel: the cos^2/d^4 falloff over the floor (box filter vs pixel centre: < 1%).
    assert np.allclose(img, expected, rtol=0.02, atol=0)


def test_only_emitters_when_max_depth_is_1(renderer):
    scene = load_scene(CORNELL).with_resolution(32, 32).with_max_depth(1)
    img = renderer.render(scene, spp=1, seed=0).image
    (light,) = scene.emitters
    lit = img.max(axis=-1) > 0
    assert lit[:8].any() and not lit[8:].any()  # only the light, at the top
    assert np.allclose(img[lit].max(axis=0), light.radiance, rtol=1e-5)


def test_cornell_box(renderer):
    scene = load_scene(CORNELL).with_resolution(64, 64)
    result = renderer.render(scene, spp=4, seed=7)
    img = result.image
    assert img.shape == (64, 64, 3) and img.dtype == np.float32
    assert np.isfinite(img).all() and (img >= 0).all()
    assert result.spp == 4 and result.seed == 7 and result.checkpoints == []
    assert result.info["supersampling"] == 2 and result.info["lights"] == 32

    middle = img[24:40]
    left, right = middle[:, :21].mean(axis=(0, 1)), middle[:, -21:].mean(axis=(0, 1))
    assert np.argmax(left) == 0, left  # red dominant: the red wall is on the left
    assert np.argmax(right) == 1, right  # green dominant: the green wall is on the right
    # The walls themselves (outer columns): strongly coloured.
    red, green = middle[:, :5].mean(axis=(0, 1)), middle[:, -5:].mean(axis=(0, 1))
    assert red[0] > 5 * max(red[1], red[2]) and green[1] > 2 * max(green[0], green[2]), (red, green)

    # The light is seen directly at the top, with its own radiance; the ceiling is unlit.
    (light,) = scene.emitters
    top = img[:12]
    assert np.allclose(top.reshape(-1, 3).max(axis=0), light.radiance, rtol=1e-5)
    assert img[1, 2:10].max() < 1e-3
    # Deterministic: the seed changes nothing.
    assert np.allclose(renderer.render(scene, spp=4, seed=8).image, img, rtol=1e-5, atol=1e-7)

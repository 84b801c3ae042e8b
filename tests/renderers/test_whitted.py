"""Whitted-style recursive ray tracing (src/cornell_harness/renderers/whitted.py) against closed forms, the path tracer and its rules.

Statistics. Direct light with ``ambient = none`` is an unbiased estimate of
the analytic rectangle-light image and, at max_depth 3, of the path tracer's
image where the camera sees a mirror; those are z-tests with the renders' own
variances (pixels independent), each family at a false-alarm rate of
:data:`ALPHA` (Šidák). Everything else is exact: with the same seed the
samples of two renders are the same sample by sample, so a difference of
settings shows as an exact difference (to float32 rounding, :data:`F32`), and
the shadow rules are deterministic. All seeds are fixed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests import mutants
from tests.conftest import run_cbox
from tests.renderers.test_ambient import rectangle_light_la
from tests.renderers.test_pathtracer import z_crit
from cornell_harness.evaluate.agreement import agreement_test
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.polygon_light import FLOOR_RHO, rectangle_light_image, rectangle_light_scene
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.model import Scene
from cornell_harness.store.references import load_reference
from cornell_harness.renderers.pathtracer import PathTracer
from cornell_harness.renderers.whitted import Whitted

pytest.importorskip("embreex")

ALPHA = 1e-3
F32 = 1e-5
#: The umbra scene's glass: IOR 1.5 in air, so R0 = 0.04 and a straight crossing of a sphere keeps (1 − R0)².
ETA = 1.5
R0 = ((ETA - 1.0) / (ETA + 1.0)) ** 2
SPHERE_C, SPHERE_R, LIGHT_HALF, LIGHT_Z = (0.0, 0.0, 0.8), 0.3, 0.1, 2.0


def render(scene: Scene, spp: int, seed: int, renderer=None, threads: int = 2, checkpoints=(), **overrides):
    """``renderer`` (default :class:`Whitted`) with its complete settings: defaults but for ``overrides``."""
    r = renderer or Whitted(threads=threads)
    settings = {s.name: s.default for s in r.settings} | overrides
    return r.render(scene, spp, seed, checkpoints, settings=settings)


def umbra_scene(folder: Path, res: int = 24) -> Scene:
    """A floor (ρ 0.75) under a small square light (half-size 0.1, height 2, facing down) with a glass
    sphere (r 0.3) floating between them; the camera looks at the floor under the sphere from the side, low."""
    a, h = LIGHT_HALF, LIGHT_Z
    text = f"""format = 1
name = "glass-umbra"
features = ["triangle_mesh", "sphere", "diffuse", "dielectric", "area_light", "pinhole_camera", "box_filter"]
[camera]
type = "pinhole"
position = [0.0, -2.5, 0.5]
look_at = [0.0, 0.0, 0.1]
up = [0.0, 0.0, 1.0]
fov_deg = 30.0
fov_axis = "smaller"
resolution = [{res}, {res}]
[render]
max_depth = -1
pixel_filter = "box"
[materials.white]
type = "diffuse"
reflectance = [{FLOOR_RHO}, {FLOOR_RHO}, {FLOOR_RHO}]
[materials.black]
type = "diffuse"
reflectance = [0.0, 0.0, 0.0]
[materials.glass]
type = "dielectric"
int_ior = {ETA}
ext_ior = 1.0
[[meshes]]
name = "floor"
material = "white"
vertices = [[-2.0, -2.0, 0.0], [2.0, -2.0, 0.0], [2.0, 2.0, 0.0], [-2.0, 2.0, 0.0]]
faces = [[0, 1, 2, 3]]
[[meshes]]
name = "light"
material = "black"
vertices = [[{-a}, {-a}, {h}], [{-a}, {a}, {h}], [{a}, {a}, {h}], [{a}, {-a}, {h}]]
faces = [[0, 1, 2, 3]]
emitter = {{ radiance = [20.0, 20.0, 20.0] }}
[[spheres]]
name = "glass"
material = "glass"
center = [{SPHERE_C[0]}, {SPHERE_C[1]}, {SPHERE_C[2]}]
radius = {SPHERE_R}
"""
    path = folder / "glass-umbra.toml"
    path.write_text(text)
    return load_scene(path)


def _segments_hit_sphere(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Whether segment p → q (rows) passes strictly inside the sphere."""
    c = np.asarray(SPHERE_C)
    d = q - p
    t = np.clip(np.einsum("ij,ij->i", c - p, d) / np.einsum("ij,ij->i", d, d), 0.0, 1.0)
    return np.linalg.norm(p + t[:, None] * d - c, axis=1) < SPHERE_R


def umbra_pixels(scene: Scene, k: int = 4) -> np.ndarray:
    """Pixels whose every point (a k×k lattice over the closed pixel) sees the floor, not through the sphere,
    at a point from which all four light corners are hidden by the sphere. The sphere's shadow cone from each
    corner is convex and so is the light, so such a point sees no point of the light; the umbra and a pixel's
    footprint on the floor are convex, so the lattice's corners decide."""
    cam = scene.camera
    offs = np.linspace(0.0, 1.0, k)
    col = (np.arange(cam.width)[:, None] + offs[None, :]).ravel()
    row = (np.arange(cam.height)[:, None] + offs[None, :]).ravel()
    d = cam.directions(col[None, :], row[:, None]).reshape(-1, 3)
    o = np.asarray(cam.position, np.float64)
    t = -o[2] / d[:, 2]
    x = o + t[:, None] * d
    ok = (t > 0) & ~_segments_hit_sphere(np.broadcast_to(o, x.shape), x)
    a = LIGHT_HALF
    for cx, cy in ((-a, -a), (-a, a), (a, a), (a, -a)):
        ok &= _segments_hit_sphere(x, np.broadcast_to(np.array([cx, cy, LIGHT_Z]), x.shape))
    return ok.reshape(cam.height, k, cam.width, k).all(axis=(1, 3))


# -- closed forms --------------------------------------------------------------------------------------

def check_rectangle_light(renderer, tmp_path: Path, sampler: str = "independent"):
    """``ambient = none`` on the analytic rectangle-light scene, 16 light samples, 16², 32 spp: 4×4 tiles and
    the whole image z-tested against Lambert's polygon formula, α = 1e-3 over the 51 tests. Returns the render
    and the exact image."""
    scene = rectangle_light_scene(tmp_path, res=16)
    ours = render(scene, 32, 5, renderer, ambient="none", light_samples=16, sampler=sampler)
    exact = rectangle_light_image(scene, sub=64)
    agr = agreement_test(ours.image, ours.variance, exact, np.zeros_like(exact), tile=4, alpha=ALPHA)
    assert agr.passed, agr.message()
    return ours, exact


def test_direct_light_matches_the_polygon_irradiance(tmp_path):
    check_rectangle_light(None, tmp_path)


def test_the_sampler_setting_draws_the_numbers(tmp_path):
    """``sampler = pmj02`` draws other numbers than ``independent`` (same seed, another image), and is as
    unbiased: z-tested against the polygon formula as above, with the variance of its 8 batches. Its
    stratified camera jitter and light samples also land closer to the exact image."""
    indep, exact = check_rectangle_light(None, tmp_path)
    pmj, _ = check_rectangle_light(None, tmp_path, "pmj02")
    assert pmj.info["sampler"] == "pmj02" and pmj.info["batches"] == 8 and indep.info["sampler"] == "independent"
    assert not np.array_equal(pmj.image, indep.image)
    mse = {name: float(np.mean((r.image - exact) ** 2)) for name, r in (("independent", indep), ("pmj02", pmj))}
    assert mse["pmj02"] < 0.5 * mse["independent"], mse


def check_constant_ambient(renderer, tmp_path: Path) -> None:
    """The rectangle-light floor: ``ambient = constant`` minus ``none`` (same seed, so the same direct light
    sample by sample) is exactly ρ·La (Cohen et al.'s constant by hand, :func:`rectangle_light_la`) where a
    pixel sees only floor, between 0 and that where it also sees the light's black back, to float32 rounding."""
    scene = rectangle_light_scene(tmp_path, res=16)
    none = render(scene, 8, 5, renderer, ambient="none")
    const = render(scene, 8, 5, renderer, ambient="constant")
    la = rectangle_light_la()
    assert const.info["ambient_radiance"] == pytest.approx([la] * 3, rel=1e-12)
    diff = const.image.astype(np.float64) - none.image
    full = FLOOR_RHO * la
    assert np.all(diff >= -F32 * full) and np.all(diff <= full * (1 + F32)), (diff.min(), diff.max(), full)
    exact = np.abs(diff - full) <= F32 * (full + none.image)
    assert exact.mean() >= 0.6, exact.mean()


def test_constant_ambient_is_rho_la(tmp_path):
    check_constant_ambient(None, tmp_path)


def test_mirror_equals_the_path_tracer_without_diffuse_bounces():
    """cornell-box-caustics at 64²: where the camera sees the mirror sphere, whitted (max_depth 3, ambient none,
    glass blocking shadow rays as the path tracer's next-event estimation does) and the path tracer at scene
    max_depth 3 estimate the same thing: emission seen in the mirror, and the direct light at the diffuse point
    it reflects (camera, mirror, diffuse point, light: 3 segments; the path tracer's BSDF-sampled rays reach
    no further diffuse bounce). Glass seen in the mirror: both follow it to depth 3. Mean over the region per
    channel, z with both variances, α = 1e-3 over 3."""
    scene = resolve_scene("cornell-box-caustics").with_resolution(64, 64)
    mask = region_masks(scene)["mirror"]
    assert mask.sum() > 100
    ours = render(scene, 64, 7, max_depth=3, ambient="none", transparent_shadows="boolean", light_samples=2)
    pt = PathTracer(threads=2).render(scene.with_max_depth(3), 256, 8)
    n = mask.sum()
    z = (ours.image[mask].mean(axis=0) - pt.image[mask].mean(axis=0)) / np.sqrt(
        (ours.variance[mask].sum(axis=0) + pt.variance[mask].sum(axis=0)) / n**2)
    assert np.abs(z).max() < z_crit(ALPHA, 3), z
    assert ours.image[mask].mean() > 0.05  # the test compares light, not two black regions


# -- transparent shadows --------------------------------------------------------------------------------

def check_transmittance(module, tmp_path: Path) -> None:
    """The shadow rules on single segments (``module``: cornell_harness.renderers.whitted or a mutant's copy): straight up
    through the sphere's centre, attenuate keeps (1 − R0)² (normal incidence at both interfaces), ignore 1,
    boolean blocks; beside the sphere all keep 1; through the (opaque) floor all give 0."""
    geom = module.SceneGeometry(umbra_scene(tmp_path))
    seg = module.shadow_buffer(3)
    seg.o[:] = [[0.0, 0.0, 1e-3], [1.0, 1.0, 1e-3], [0.5, 0.5, -1.0]]
    seg.d[:] = [[0.0, 0.0, 1.0]] * 3
    seg.t[:] = [1.99, 1.0, 1.5]
    seg.path[:] = 0
    seg.c[:] = 1.0
    att = module.shadow_transmittance(geom, seg, True)
    ign = module.shadow_transmittance(geom, seg, False)
    assert att[0] == pytest.approx((1.0 - R0) ** 2, rel=1e-12), (att, (1.0 - R0) ** 2)
    assert att[1:].tolist() == [1.0, 0.0] and ign.tolist() == [1.0, 1.0, 0.0]
    assert geom.unoccluded(seg.o, seg.d, seg.t).tolist() == [False, True, False]


def test_transmittance_is_fresnel_at_normal_incidence(tmp_path):
    from cornell_harness.renderers import whitted

    check_transmittance(whitted, tmp_path)


def check_umbra(renderer, tmp_path: Path) -> None:
    """The floor under a floating glass sphere, ``ambient = none``, 24², 16 spp, 4 light samples, one seed
    for all: in the umbra (:func:`umbra_pixels`) ``boolean`` gives exactly 0; ``ignore`` gives the unshadowed
    direct light (ρ/π · Le·A/h² ≈ 0.048); ``attenuate`` gives it times the transmittance product, never more
    than its normal-incidence value (1 − R0)² = 0.9216 (R grows with the angle), at least that within 1% in the
    pixel nearest the sphere's axis (measured 0.9213), and down to ~0.5 where rays cross near the sphere's rim."""
    scene = umbra_scene(tmp_path)
    umbra = umbra_pixels(scene)
    assert umbra.sum() >= 4, umbra.sum()
    img = {mode: render(scene, 16, 3, renderer, ambient="none", light_samples=4, transparent_shadows=mode).image
           for mode in ("boolean", "attenuate", "ignore")}
    assert np.all(img["boolean"][umbra] == 0.0)
    assert np.all(img["ignore"][umbra] > 0.04)  # ρ/π · Le·A/h² ≈ 0.048
    ratio = img["attenuate"][umbra].astype(np.float64) / img["ignore"][umbra]
    expected = (1.0 - R0) ** 2
    assert np.all(ratio <= expected * (1 + F32)) and np.all(ratio > 0.3), (ratio.min(), ratio.max())
    assert ratio.max() >= 0.99 * expected, ratio.max()


def test_umbra_boolean_zero_attenuate_fresnel(tmp_path):
    check_umbra(None, tmp_path)


@pytest.mark.parametrize("mode", ["boolean", "attenuate", "ignore"])
def test_the_caustic_gets_no_focused_light(mode):
    """cornell-box-caustics at its stored resolution, 4 spp, default ambient (constant): in the caustic region
    (the floor where the glass sphere focuses the light) whitted's mean radiance is under 0.4 of the stored
    reference's there, whatever the shadow rule (measured 0.13 boolean, 0.24 attenuate, 0.25 ignore, of
    which the ambient term is 0.13; the reference's caustic is ~8× the floor's radiance), while on the rest of the floor beside it, the shadow region, all modes are lit."""
    scene = resolve_scene("cornell-box-caustics")
    masks = region_masks(scene)
    ref = load_reference(scene).image.astype(np.float64)
    img = render(scene, 4, 1, transparent_shadows=mode).image.astype(np.float64)
    caustic = masks["caustic"]
    share = img[caustic].mean() / ref[caustic].mean()
    assert share < 0.4, share
    assert img[masks["glass-shadow"]].mean() > 0.0


# -- determinism, settings, registration -----------------------------------------------------------------

def test_bit_identical_for_any_thread_count_and_seed_dependent():
    """Same seed: the same image and variance bit for bit on 1 and 2 threads (16 spp at 64² cuts the last pass
    into several work units), with every kind of ray (attenuated shadows, AO); another seed: another image."""
    scene = resolve_scene("cornell-box-caustics").with_resolution(64, 64)
    a, b = (render(scene, 16, 3, threads=t, ambient="ao", light_samples=2) for t in (1, 2))
    assert a.image.tobytes() == b.image.tobytes() and a.variance.tobytes() == b.variance.tobytes()
    c = render(scene, 16, 4, ambient="ao", light_samples=2)
    assert not np.array_equal(a.image, c.image)


def test_checkpoints_are_the_smaller_renders():
    scene = resolve_scene("cornell-box-caustics").with_resolution(32, 32)
    full = render(scene, 8, 2, checkpoints=(2, 8))
    small = render(scene, 2, 2)
    assert [c.spp for c in full.checkpoints] == [2, 8]
    assert full.checkpoints[0].image.tobytes() == small.image.tobytes()


def test_max_depth_1_is_emission_only():
    """max_depth 1: only the camera segment, so only emission (the light's pixels): no direct light, no
    ambient, no reflection; max_depth 2 lights the walls but shows nothing in the mirror or the glass."""
    scene = resolve_scene("cornell-box-caustics").with_resolution(32, 32)
    one = render(scene, 2, 1, max_depth=1)
    lit = one.image.max(axis=2) > 0
    assert 0 < lit.sum() < 0.03 * lit.size and one.image.max() <= np.float32(18.387)
    masks = region_masks(scene)
    two = render(scene, 2, 1, max_depth=2, ambient="none").image
    assert two[masks["walls"]].mean() > 0 and not two[masks["mirror"]].any()


def test_renderers_lists_whitted_and_its_settings():
    proc = run_cbox("renderers", "--settings")
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    i = next(k for k, line in enumerate(lines) if line.split()[:1] == ["whitted"])
    block = "\n".join(lines[i:i + 12])
    for name in ("max_depth", "light_samples", "ambient", "transparent_shadows", "ao_samples", "sampler"):
        assert name in block, block


# -- the mutants (tests/mutants/whitted.py) ----------------------------------------------------------------

WHITTED_MUTANTS = [m.name for m in mutants.MUTANTS if m.renderer == "whitted"]


def _fails(check, *args) -> bool:
    try:
        check(*args)
    except AssertionError:
        return True
    return False


#: A copy of the whole toolkit compiles for it (it patches src/cornell_harness/renderers/core/direct.py): ~27 s, so slow.
SLOW = {"whitted_shadow_ray_not_offset"}


@pytest.mark.parametrize("name", [pytest.param(n, marks=[pytest.mark.slow] if n in SLOW else [], id=n)
                                  for n in WHITTED_MUTANTS])
def test_mutant_is_caught(name, tmp_path_factory):
    """Each whitted mutant fails the test that pins its code (the gate has no whitted expectation:
    tests/mutants/catalogue.py's LOW_POWER says so): Fresnel ignored in the attenuation fails the normal-incidence
    transmittance and the umbra's (1 − R0)²; a shadow ray from the surface itself (no offset) darkens the floor
    with acne, away from the polygon formula; the ambient added twice is 2ρ·La."""
    work = tmp_path_factory.mktemp("whitted-mutants")
    module = mutants.load_module(name, work)
    renderer = module.Whitted(threads=2)
    tmp = tmp_path_factory.mktemp("scene")
    checks = {"whitted_attenuation_without_fresnel": [(check_transmittance, module, tmp), (check_umbra, renderer, tmp)],
              "whitted_shadow_ray_not_offset": [(check_rectangle_light, renderer, tmp)],
              "whitted_ambient_twice": [(check_constant_ambient, renderer, tmp)]}
    assert set(checks) == set(WHITTED_MUTANTS)
    for check, *args in checks[name]:
        assert _fails(check, *args), (name, check.__name__)

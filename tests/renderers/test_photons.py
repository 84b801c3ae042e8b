"""Photon tracing, photon maps, and our two photon mappers (photonmap, sppm) against analytic answers.

Photon mapping is biased (a density estimate blurs over its radius) and
consistent, so these tests do not z-test against a reference: they check
exact invariants (flux conservation, determinism), convergence towards an
analytic answer at the expected rate, and bias budgets in the furnace with
the measured values written next to them. Seeds are fixed: every figure
here is reproducible bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.adapters.seeds import pass_key
from cornell_harness.evaluate.convergence import loglog_slope
import dataclasses

from cornell_harness.scenes.analytic import furnace_radiance, furnace_scene
from cornell_harness.scenes.polygon_light import LIGHT_A, LIGHT_B, LIGHT_H, LIGHT_LE, MIRROR_LIGHT_H, mirrored_light_image, mirrored_light_scene, polygon_irradiance, rectangle_light_scene
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Camera

pytest.importorskip("embreex")

from cornell_harness.renderers.core.geometry import SceneGeometry  # noqa: E402
from cornell_harness.renderers.core.photon_map import KERNELS, PhotonMap, kernel_weight  # noqa: E402
from cornell_harness.renderers.core.camera import camera_basis, camera_rays  # noqa: E402
from cornell_harness.renderers.core.photons import (STORE_ALL, STORE_CAUSTIC, STORE_INDIRECT, Photons, shoot,  # noqa: E402
                                    trace_photons)
from cornell_harness.renderers.core.rays import ray_buffer  # noqa: E402
from cornell_harness.renderers.core.roulette import Q_MAX  # noqa: E402
from cornell_harness.renderers.core.sampler import SAMPLERS, sequence_stream  # noqa: E402
from cornell_harness.renderers.core.visible_points import camera_visible_points, walk_to_diffuse  # noqa: E402
from cornell_harness.renderers.photonmap import PhotonMapper  # noqa: E402
from cornell_harness.renderers.sppm import SPPM  # noqa: E402


# -- kernels and photons ----------------------------------------------------------------

@pytest.mark.parametrize("kernel", KERNELS)
def test_kernels_integrate_to_one_over_their_disc(kernel):
    """∫ K dA = 1 (midpoint rule in the radius), so a density estimate is unbiased for uniform density."""
    r, n = 0.3, 20000
    s = (np.arange(n) + 0.5) / n * r
    total = sum(kernel_weight(KERNELS.index(kernel), d, r) * 2 * math.pi * d for d in s) * (r / n)
    assert total == pytest.approx(1.0, abs=1e-6)
    assert kernel_weight(KERNELS.index(kernel), 1.01 * r, r) == 0.0


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_direct_photons_carry_the_emitted_flux(sampler):
    """In a closed box every photon lands on a wall at once: the flux of those first landings sums to
    π·Le·A (exactly, up to float32), whatever was emitted. (The box is grey, ρ = 0.5: on black walls
    nothing would be stored, test_no_photon_is_stored_on_a_black_surface.)"""
    scene = furnace_scene(0.5, 1.0, res=4)
    geom = SceneGeometry(scene)
    ph, emitted = shoot(geom, scene, pass_key(0, 0, 1), 5000, STORE_ALL, threads=2, sampler=sampler)
    first = ph.depth == 1
    assert emitted == 5000 and first.sum() == 5000 and len(ph) > 5000 and not ph.caustic.any()
    area = 6 * 2.0 * 2.0
    assert ph.power[first].astype(np.float64).sum(axis=0) == pytest.approx([math.pi * area] * 3, rel=1e-5)



def test_a_batchs_photons_come_out_bounce_by_bounce_past_the_first_buffer():
    """trace_photons' kernel writes each bounce's photons after the last one's into a buffer of twice the
    photons emitted, grown when a bounce could overflow it. In a bright furnace (ρ = 0.9: ~10 stored per
    emitted) it grows, and the photons still come out in bounce order, the first landings (one per photon
    emitted, the box being closed) with the whole emitted flux."""
    scene = furnace_scene(0.9, 1.0, res=4)
    m = 2000
    ph = trace_photons(SceneGeometry(scene), scene, sequence_stream("independent", pass_key(0, 0, 1)), 0, m, STORE_ALL)
    assert len(ph) > 4 * m and isinstance(ph, Photons)
    assert (np.diff(ph.depth) >= 0).all()
    first = ph.depth == 1
    assert first.sum() == m
    assert ph.power[first].astype(np.float64).sum(axis=0) == pytest.approx([math.pi * 6 * 2.0 * 2.0 * m] * 3,
                                                                           rel=1e-5)


def test_walk_to_diffuse_leaves_the_callers_rays_and_walks_them_as_the_camera_pass_does():
    """walk_to_diffuse traces a copy of the caller's rays (never writes them); from camera rays it gives
    the camera pass's light and visible points bit for bit (through glass and a mirror: several bounces)."""
    scene = resolve_scene("cornell-box-caustics").with_resolution(16, 16)
    geom, cam, stream = SceneGeometry(scene), scene.camera, sequence_stream("independent", pass_key(0, 0, 3))
    rays = ray_buffer(512)
    camera_rays(camera_basis(cam), cam.width, cam.height, 100, 256, stream, rays)
    before = [a.copy() for a in rays]
    L, vp = walk_to_diffuse(geom, scene, rays, stream, 100)
    assert all(np.array_equal(a, b) for a, b in zip(rays, before))
    L_cam, vp_cam = camera_visible_points(geom, scene, 100, 612, 256, stream)
    assert np.array_equal(L, L_cam) and all(np.array_equal(a, b) for a, b in zip(vp, vp_cam))
    assert vp.found.sum() > 400 and (vp.depth[vp.found] > 1).any()

def test_caustic_map_holds_only_photons_that_came_through_specular_surfaces():
    scene = resolve_scene("cornell-box-caustics").with_resolution(8, 8)
    geom = SceneGeometry(scene)
    ph, emitted = shoot(geom, scene, pass_key(0, 0, 2), 2000, STORE_CAUSTIC, threads=2, stored=True)
    assert len(ph) >= 2000 and emitted > len(ph)
    assert ph.caustic.all() and (ph.depth >= 2).all()
    # Stored on diffuse surfaces only: none on the spheres.
    for s in scene.spheres:
        gap = np.linalg.norm(ph.position - np.asarray(s.center), axis=1) - s.radius
        assert np.abs(gap).min() > 1e-4


@pytest.mark.parametrize("mode", [STORE_ALL, STORE_CAUSTIC, STORE_INDIRECT])
def test_no_photon_is_stored_on_a_black_surface(mode):
    """The mirrored light's panel is black (ρ = 0) and faces the mirror: photons coming back from the
    mirror land on it, where no estimate can use them (issue 34: 83% of a map there). None is stored,
    in any map, so the stored count is the floor's; the flux per photon is still the power over the
    photons emitted (photons on the floor directly under the mirror's image carry the same flux as
    before)."""
    scene = mirrored_light_scene(8)
    geom = SceneGeometry(scene)
    ph, emitted = shoot(geom, scene, pass_key(0, 0, 1), 4000, mode, threads=2, stored=True)
    assert len(ph) >= 4000 and emitted >= len(ph)
    on_panel = np.abs(ph.position[:, 2] - MIRROR_LIGHT_H) < 1e-3
    assert on_panel.sum() == 0
    assert (np.abs(ph.position[:, 2]) < 1e-3).all()  # every one on the floor, the only surface that reflects
    # max_depth 3: every one came light → mirror → floor, with flux π·Le·A / emitted, over the mirror's
    # roulette probability (ρ = 1, capped at Q_MAX).
    assert (ph.depth == 2).all()
    area = 4 * LIGHT_A * LIGHT_B
    assert ph.power[:, 0].astype(np.float64) == pytest.approx(math.pi * LIGHT_LE * area / (emitted * Q_MAX), rel=1e-5)


def test_photonmap_counts_stored_photons_and_records_the_emitted():
    """``caustic_photons`` counts stored photons (all on the floor, none on the black panel); the photons
    emitted to store them are in the render's info."""
    scene = mirrored_light_scene(8)
    res = PhotonMapper(threads=2).render(scene, 1, 0, settings={"caustic_photons": 3000, "global_photons": 0})
    assert 3000 <= res.info["caustic_stored"] < 3000 + (1 << 14)
    assert res.info["caustic_emitted"] > res.info["caustic_stored"]


def mirror_lit_patch(mirror_half: float, res: int = 24):
    """The mirrored light's scene cut to a small floor patch (x in [1.1, 1.5], |y| ≤ 0.2) seen from above
    by a narrow camera, lit through the mirror only. The mirror spans x, y in ±``mirror_half``
    around (0, 0), or, with ``mirror_half`` = 0, only x in [0, 0.65], |y| ≤ 0.25: what light from the
    panel's mirror image to the patch crosses."""
    base = mirrored_light_scene(res)
    floor, panel, mirror = base.meshes
    patch = np.array([[1.1, -0.2, 0.0], [1.5, -0.2, 0.0], [1.5, 0.2, 0.0], [1.1, 0.2, 0.0]])
    if mirror_half:
        m = mirror_half
        cover = np.array([[-m, -m, 0.0], [-m, m, 0.0], [m, m, 0.0], [m, -m, 0.0]])
    else:
        cover = np.array([[0.0, -0.25, 0.0], [0.0, 0.25, 0.0], [0.65, 0.25, 0.0], [0.65, -0.25, 0.0]])
    cover[:, 2] = mirror.vertices[0, 2]
    camera = Camera(position=(1.3, 0.0, 0.6), look_at=(1.3, 0.0, 0.0), up=(0.0, 1.0, 0.0), fov_deg=30.0,
                    fov_axis="smaller", width=res, height=res)
    return dataclasses.replace(base, camera=camera, meshes=(dataclasses.replace(floor, vertices=patch), panel,
                                                            dataclasses.replace(mirror, vertices=cover)))


def test_sppm_radius_ignores_geometry_the_camera_does_not_see():
    """A small patch lit through a mirror that reaches far off-screen (±4: the scene's bounding sphere
    is 5.7 across, and the old radius, 2 pixel widths at the distance of its centre, was 19 pixel widths
    at the patch) converges as fast as with the mirror cut to what lights the patch: SPPM's radius starts
    from each visible point's pixel footprint, which the off-screen mirror does not change (issue 34:
    the error at 64 iterations within 2×). The error is the patch's mean relative error against the
    polygon formula (the issue's figure: the bias a large start leaves; the per-pixel noise is the
    same in both scenes, as the same photons land on the patch).

    Measured (seed 0, 24², 20 000 photons per iteration, 64 iterations): far mirror -2.11%, cut -2.22%
    (RMS over the pixels 18.7% both); from the old radius (``initial_radius_world`` set to it) -14.8%
    and -1.76%, a factor 8.4 (RMS 18.5% and 9.4%: the cut scene's old radius, 4 pixel widths, was twice
    the new one). A radius of 2 scene units instead of 2 footprints: -92% in both.
    """
    errors = []
    for half in (4.0, 0.0):
        scene = mirror_lit_patch(half)
        exact, mask = mirrored_light_image(scene)
        assert mask.all()
        res = SPPM(threads=2).render(scene, 64, 0, settings={"photons_per_iteration": 20000})
        errors.append(float(np.mean(res.image.astype(np.float64)[..., 0] / exact[..., 0] - 1)))
    far, cut = errors
    assert abs(far) <= 2.0 * abs(cut), errors
    assert abs(far) < 0.05, errors


@pytest.mark.parametrize("look_up", [False, True], ids=["direct", "through-the-mirror"])
def test_sppm_initial_radius_is_pixel_footprints_along_the_camera_path(look_up):
    """The patch seen from 0.6 above, straight down or in the mirror 0.9 above the camera (a path of
    0.9 + 1.5 = 2.4): a pixel's radius starts at 2 footprints, 2 · length · 2 tan(15°)/8 at an 8² image's
    centre (√Ω a little less off the axis: cos^(3/2) θ, θ ≤ 9°); initial_radius_world overrides it."""
    scene = mirror_lit_patch(4.0, res=8)
    if look_up:
        scene = dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, look_at=(1.3, 0.0, 1.5)))
    length = 2.4 if look_up else 0.6
    res = SPPM(threads=2).render(scene, 1, 0, settings={"photons_per_iteration": 1000})
    assert res.info["initial_radius_median"] == pytest.approx(2 * length * 2 * math.tan(math.radians(15)) / 8,
                                                              rel=0.03)
    res = SPPM(threads=2).render(scene, 1, 0, settings={"photons_per_iteration": 1000, "initial_radius_world": 0.05})
    assert res.info["initial_radius_median"] == 0.05


def test_normal_test_keeps_wall_photons_off_the_floor():
    """At a corner, photons on the wall (normal +x) within the lookup radius of a floor point (normal +y)
    must not count there: the floor's irradiance from wall photons alone is 0 (Jensen §7.2.3). Photons
    on the floor itself count, and a floor photon that arrived from below the floor does not."""
    rng = np.random.default_rng(1)
    n = 2000
    wall = np.column_stack([np.zeros(n), rng.uniform(0, 0.2, n), rng.uniform(-0.2, 0.2, n)])
    floor = np.column_stack([rng.uniform(0, 0.2, n), np.zeros(n), rng.uniform(-0.2, 0.2, n)])
    up, right = np.tile([0.0, 1.0, 0.0], (n, 1)), np.tile([1.0, 0.0, 0.0], (n, 1))
    incoming = np.tile(np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0), (n, 1))  # above both surfaces

    def photon_map(pos, normal, direction):
        return PhotonMap(Photons(pos.astype(np.float32), np.full((n, 3), 1e-3, np.float32),
                                 direction.astype(np.float32), normal.astype(np.float32),
                                 np.ones(n, np.int16), np.zeros(n, bool)), n)

    query = np.array([[0.01, 0.0, 0.0]])
    args = (np.tile([0.0, 1.0, 0.0], (1, 1)), np.array([5]), 30, 0.1, "cone")
    assert photon_map(wall, right, incoming).irradiance(query, *args)[0].max() == 0.0
    assert photon_map(floor, up, incoming).irradiance(query, *args)[0].min() > 0.0
    assert photon_map(floor, up, -incoming).irradiance(query, *args)[0].max() == 0.0


# -- the analytic case: direct irradiance from a rectangle light ---------------------------

@pytest.mark.parametrize("sampler", SAMPLERS)
def test_photon_map_irradiance_tends_to_the_polygon_formula(tmp_path, sampler):
    """The photon map's estimate of direct irradiance on the floor under a rectangular emitter converges to
    Lambert's polygon formula as photons grow and the radius shrinks.

    k grows as √N, so r² ∝ k/N ∝ N^(-1/2) (the blur's bias) and the relative noise ∝ 1/√k ∝ N^(-1/4): the
    RMS relative error over 144 floor points must fall at each step with a log-log slope between
    -0.6 and -0.15 (measured: 0.341, 0.232, 0.165 at N = 16k, 64k, 256k; slope -0.26: the noise's -1/4
    dominates the bias's -1/2 at these k). pmj02: 0.332, 0.212, 0.130 (slope -0.34); sobol: 0.291, 0.195,
    0.129 (-0.29). A photon whose direction reuses its emission point's numbers (the mutant
    photon_direction_reuses_point_dims) stalls at 0.52, 0.48, 0.47 (slope -0.04).
    """
    scene = rectangle_light_scene(tmp_path)
    geom = SceneGeometry(scene)
    g = np.linspace(-0.7, 0.7, 12)
    pts = np.array([(x, y, 0.0) for x in g for y in g])
    a, b, h = LIGHT_A, LIGHT_B, LIGHT_H
    poly = np.array([[-a, -b, h], [a, -b, h], [a, b, h], [-a, b, h]], float)
    exact = polygon_irradiance(pts, np.array([0, 0, 1.0]), poly, LIGHT_LE)
    errors, counts = [], [16_000, 64_000, 256_000]
    for n, k in zip(counts, (16, 32, 64)):
        ph, emitted = shoot(geom, scene, pass_key(0, 0, 1), n, STORE_ALL, threads=2, sampler=sampler)
        pmap = PhotonMap(ph, emitted)
        E, radius = pmap.irradiance(pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1)), np.ones(len(pts), int), k,
                                    0.5, "cone")
        assert (radius < 0.3).all()  # k photons found within 0.3 < 1 - 0.7: the disc never leaves the floor
        errors.append(float(np.sqrt(np.mean((E[:, 0] / exact - 1) ** 2))))
    assert errors[0] > errors[1] > errors[2], errors
    assert -0.6 <= loglog_slope(counts, errors) <= -0.15, errors


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_sppm_and_photonmap_converge_to_the_mirrored_lights_polygon_formula(sampler):
    """A floor lit only through a mirror (its light is all a caustic, which NEE cannot sample): SPPM's
    image converges to the polygon formula for the light's mirror image, and the photon mapper's
    caustic map gets closer with more photons. Pixels within 0.15 of the floor's edge or of the panel's
    shadow boundary are left out (a density estimate blurs across both).

    Measured (seed 0, 24², 130 pixels): SPPM's RMS relative error 9.7%, 6.1%, 3.5% after 4, 16, 64
    iterations of 20 000 photons, mean +0.19% at 64; photonmap at 16 spp: 11.5% with 62 500 caustic
    photons, 8.2% with 250 000. pmj02: SPPM 9.7%, 6.4%, 3.8% (mean +0.3%), photonmap 11.3%, 7.5%; sobol:
    SPPM 7.3%, 4.4%, 3.4% (mean +0.2%), photonmap 8.9%, 6.6%. (Issue 34: SPPM's radius starts at 2
    footprints at each floor point, 0.16 units median, against 0.23 from the scene's centre before,
    which gave 5.2%, 3.4%, 1.9% with more bias in the early iterations; the photon mapper's maps no
    longer hold photons on the panel's black top, so the same stored count is all on the floor, 2.7
    times as many emitted (688 128 for 250 000 stored), and less noisy: 13.0% and 8.3% before.)
    """
    scene = mirrored_light_scene(24)
    exact, mask = mirrored_light_image(scene, margin=0.15)
    assert mask.sum() > 100
    y = exact[mask][:, 0]

    def error(image):
        x = image.astype(np.float64)[mask][:, 0]
        return float(np.sqrt(np.mean((x / y - 1) ** 2))), float(x.mean() / y.mean() - 1)

    res = SPPM(threads=2).render(scene, 64, 0, checkpoints=(4, 16, 64),
                                 settings={"photons_per_iteration": 20000, "sampler": sampler})
    rms = [error(c.image)[0] for c in res.checkpoints]
    assert rms[0] > rms[1] > rms[2] and rms[2] < 0.045, rms
    assert abs(error(res.image)[1]) < 0.01
    pm = [error(PhotonMapper(threads=2).render(scene, 16, 0, settings={"caustic_photons": n, "global_photons": 0,
                                                                       "sampler": sampler}).image)[0]
          for n in (62_500, 250_000)]
    assert pm[1] < 0.8 * pm[0] and pm[1] < 0.12, pm


# -- the white furnace ---------------------------------------------------------------------

@pytest.mark.parametrize("sampler", SAMPLERS)
def test_photonmap_in_the_white_furnace(sampler):
    """photonmap agrees with Le/(1-ρ) = 2 (ρ = 0.5) in the furnace's interior pixels within 3%, and its
    bias is where the density estimate's disc leaves a face: at the cube's edges and corners the disc
    is partly empty (photons of the other faces fail the normal test), so edge pixels read low.

    Measured (seed 0, 16 spp, 100k photons): interior mean +1.8%, border -4.4% (gather 1); with the
    global map seen directly (gather 0): interior +2.2%, border -5.0%. The same budgets hold for every
    sampler: pmj02 +0.1%/-4.5% (gather 1) and +0.3%/-4.5% (gather 0), sobol -0.9%/-4.9% and -0.7%/-5.2%
    (stratified photons lie more evenly than independent ones, which changes the k-nearest estimate's
    bias; not investigated further).
    """
    scene = furnace_scene(0.5, 1.0, res=16)
    expected = furnace_radiance(0.5, 1.0, -1)
    r = PhotonMapper(threads=2)
    inner = np.zeros((16, 16), bool)
    inner[4:12, 4:12] = True
    for gather, interior_budget in ((1, 0.03), (0, 0.04)):
        img = r.render(scene, 16, 0, settings={"gather_rays": gather, "global_photons": 100_000, "caustic_photons": 0,
                                              "sampler": sampler}).image.astype(np.float64).mean(axis=2)
        err_in = img[inner].mean() / expected - 1
        err_border = img[~inner].mean() / expected - 1
        assert abs(err_in) < interior_budget, (gather, err_in)
        assert err_border < err_in + 0.01, (gather, err_in, err_border)  # corners and edges read low


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_sppm_in_the_white_furnace(sampler):
    """SPPM converges to Le/(1-ρ) = 2 (ρ = 0.5) in the furnace. Its bias sits at the cube's edges and
    corners (the gather disc leaves the face) and shrinks with the radius: the border pixels' error must
    fall from 4 to 16 to 64 iterations (pmj02, whose border starts above the answer: be smaller after 64
    than after 4 and 16), the interior stay within 1% and the whole image end within 3%, for every sampler.

    Measured (seed 0, 32², 8192 photons per iteration, initial radius 1 footprint at each wall point,
    0.063 units median): border -3.7%, -3.66%, -2.2% after 4, 16, 64 iterations; interior -0.96%,
    -0.33%, -0.08%; image -3.0% → -1.7%. pmj02: border +4.1%, -2.2%, -0.57%, interior +0.07% and image
    -0.41% at 64; sobol: border -5.0%, -2.4%, -2.1%, interior -0.24%, image -1.6%. (Before issue 34, from
    1 footprint at the bounding sphere's radius, 1.73 away: border -5.3%, -4.6%, -3.0%.) (Stratified photons and visible points are sub-Poisson, so the radius
    update's counts, hence the border's bias, differ from the independent sampler's: not investigated
    further.)
    """
    scene = furnace_scene(0.5, 1.0, res=32)
    inner = np.zeros((32, 32), bool)
    inner[8:24, 8:24] = True
    res = SPPM(threads=2).render(scene, 64, 0, checkpoints=(4, 16, 64),
                                 settings={"photons_per_iteration": 8192, "initial_radius": 1.0, "sampler": sampler})
    expected = furnace_radiance(0.5, 1.0, -1)
    img = {c.spp: c.image.astype(np.float64).mean(axis=2) / expected - 1 for c in res.checkpoints}
    border = [abs(img[n][~inner].mean()) for n in (4, 16, 64)]
    if sampler == "pmj02":
        assert border[2] < min(border[0], border[1]), border
    elif sampler == "pmj02table":  # border 11%, 1.0%, 2.1%: falls from the start, not monotone (sub-Poisson)
        assert border[2] < border[0], border
    else:
        assert border[0] > border[1] > border[2], border
    assert abs(img[64][inner].mean()) < 0.01 and abs(img[64].mean()) < 0.03
    # α = 2/3: the radius shrinks (N' = N + αM); with α left out it would stay at its start.
    assert res.info["final_radius_median"] < 0.8 * res.info["initial_radius_median"], res.info


# -- determinism -------------------------------------------------------------------------------

@pytest.mark.parametrize("sampler", SAMPLERS)
@pytest.mark.parametrize("renderer, settings", [(PhotonMapper, {"global_photons": 20_000, "caustic_photons": 5_000}),
                                                (SPPM, {})])
def test_bit_identical_whatever_the_thread_count(renderer, settings, sampler):
    settings = {**settings, "sampler": sampler}
    scene = resolve_scene("cornell-box-caustics").with_resolution(24, 24)
    images = [renderer(threads=t).render(scene, 4, seed=3, settings=settings).image for t in (1, 2, 3)]
    assert all(np.array_equal(images[0], im) for im in images[1:])
    other = renderer(threads=2).render(scene, 4, seed=4, settings=settings).image
    assert not np.array_equal(images[0], other)

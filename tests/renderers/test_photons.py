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

from harness.adapters.seeds import pass_key
from harness.evaluate.convergence import loglog_slope
from harness.scenes.analytic import (LIGHT_A, LIGHT_B, LIGHT_H, LIGHT_LE, furnace_radiance, furnace_scene,
                                     mirrored_light_image, mirrored_light_scene, polygon_irradiance,
                                     rectangle_light_scene)
from harness.scenes.library import resolve_scene

pytest.importorskip("embreex")

from renderers.core.geometry import SceneGeometry  # noqa: E402
from renderers.core.photon_map import KERNELS, PhotonMap, kernel_weight  # noqa: E402
from renderers.core.photons import STORE_ALL, STORE_CAUSTIC, Photons, shoot  # noqa: E402
from renderers.core.sampler import SAMPLERS  # noqa: E402
from renderers.photonmap import PhotonMapper  # noqa: E402
from renderers.sppm import SPPM  # noqa: E402


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
    """In a black closed box every photon lands on a wall at once: their flux sums to π·Le·A (exactly,
    up to float32), whatever was emitted."""
    scene = furnace_scene(0.0, 1.0, res=4)
    geom = SceneGeometry(scene)
    ph, emitted = shoot(geom, scene, pass_key(0, 0, 1), 5000, STORE_ALL, threads=2, sampler=sampler)
    assert emitted == 5000 and len(ph) == 5000 and (ph.depth == 1).all() and not ph.caustic.any()
    area = 6 * 2.0 * 2.0
    assert ph.power.astype(np.float64).sum(axis=0) == pytest.approx([math.pi * area] * 3, rel=1e-5)


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

    Measured (seed 0, 24², 130 pixels): SPPM's RMS relative error 5.2%, 3.4%, 1.9% after 4, 16, 64
    iterations of 20 000 photons, mean -0.04% at 64; photonmap at 16 spp: 13.0% with 62 500 caustic
    photons, 8.3% with 250 000. pmj02: SPPM 4.4%, 3.0%, 2.1% (mean +0.2%), photonmap 14.0%, 7.6%; sobol:
    SPPM 2.8%, 2.3%, 1.6% (mean -0.06%), photonmap 9.7%, 7.4%.
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
    assert rms[0] > rms[1] > rms[2] and rms[2] < 0.03, rms
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

    Measured (seed 0, 32², 8192 photons per iteration, initial radius 1 footprint): border -5.3%, -4.6%,
    -3.0% after 4, 16, 64 iterations; interior -0.63%, -0.32%, -0.14%; image -4.1% → -2.2%. pmj02: border
    +2.9%, -3.5%, -1.4%, interior -0.07% and image -1.1% at 64; sobol: border -6.6%, -3.6%, -2.9%,
    interior -0.12%, image -2.2%. (Stratified photons and visible points are sub-Poisson, so the radius
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
    else:
        assert border[0] > border[1] > border[2], border
    assert abs(img[64][inner].mean()) < 0.01 and abs(img[64].mean()) < 0.03
    # α = 2/3: the radius shrinks (N' = N + αM); with α left out it would stay at its start.
    assert res.info["final_radius_median"] < 0.8 * res.info["initial_radius_world"], res.info


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

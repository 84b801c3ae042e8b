"""Our ambient occlusion renderer (src/cornell_harness/renderers/ao.py) against analytic answers, and the runner's refusals.

Statistics. Every sample's estimate is V ∈ {0, 1} (the AO weight over the
pdf is 1 for both weightings), so a pixel's count of unoccluded samples is
exactly Binomial(n, Ā), Ā the mean of A over the pixel's footprint. The
analytic checks therefore test each pixel with the exact two-sided binomial
test (twice the smaller tail), and each case's total count with a z-test
(a sum of over 10^4 samples where it is random: the normal approximation is
good to far below the level used), at a family-wise false-alarm rate :data:`ALPHA` = 1e-3 over
every pixel and case of all cases together (Šidák,
:func:`cornell_harness.evaluate.agreement.sidak_level`). The render's own variance
is checked to be the Bernoulli one, Ā(1 − Ā)/(n − 1) of its mean; it is not
the test's variance because it is 0 wherever every sample agreed (the open
plane, the strip beyond the maximum distance), where a z-test would divide
0 by 0 or a near-zero difference by 0, and because pixels near A = 1 are
too skewed for a normal approximation at the Šidák level. All seeds are
fixed, so a pass is reproducible; α says how often a correct renderer would
fail over fresh seeds.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from scipy.stats import binom, norm

from tests import mutants
from cornell_harness.adapters.registry import RendererEntry, missing_features, resolve
from cornell_harness.evaluate.agreement import sidak_level
from cornell_harness.scenes.analytic_ao import ao_beside_walls, cosine_ao_beside_wall
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Camera, Diffuse, Mesh, Scene, Sphere
from cornell_harness.scenes.quantities import AmbientOcclusion
from cornell_harness.workflows.runner import RunRecord
from cornell_harness.renderers.ao import AORenderer
from cornell_harness.renderers.core.sampler import SAMPLERS
from cornell_harness.renderers.pathtracer import PathTracer

pytest.importorskip("embreex")

#: Family-wise false-alarm rate of :func:`analytic_failures`, over all its tests.
ALPHA = 1e-3
SEED = 7
#: Half-size of the walls and of the floor beside them: "infinite" next to max_distance (1) and the
#: distances seen (< 1.5). With max_distance inf, a finite wall lets through the directions that pass
#: its ends, at most an azimuth wedge of 2·d/(L - 0.2) from each (cosine or uniform weight Δφ/2π),
#: and those over its top ((d/L)² at most): :data:`LEAK` bounds both, for two walls, per sample.
L = 1000.0
LEAK = 2.0 * (1.5 / (math.pi * (L - 1.5)) + (1.5 / L) ** 2)
#: Sub-samples of a footprint per axis (Gauss-Legendre): A is smooth on each side of d = max_distance,
#: where the footprint is split, so this is exact to ~1e-12.
GL_NODES = 16
#: Sphere case: radius and centre height above the floor, the camera's height.
SPHERE_R, SPHERE_H, SPHERE_CAM = 0.3, 0.5, 3.0


class Case(NamedTuple):
    walls: tuple[str, ...]  # "x": the plane x = 0; "z": the plane z = 0; "sphere": a sphere over the origin
    max_distance: float
    weighting: str
    floor_up: bool  # the floor's front side faces the camera (False: the camera sees its back)
    width: int
    height: int
    pixel: float  # footprint side on the floor, scene units
    corner: tuple[float, float]  # floor (x, z) of the image's top-left corner
    spp: int


#: The analytic cases. Walls and floor are as large as L; the camera looks straight down, so every
#: pixel's footprint is an exact axis-aligned square of the floor (x along columns, z along rows).
#: Some floors face away from the camera, so the hemisphere must be turned towards it.
CASES: dict[str, Case] = {
    # One wall, max distance 1: A from 1/2 at the wall to 1 beyond distance 1 (cosine_ao_beside_wall).
    "one-wall": Case(("x",), 1.0, "cosine", True, 32, 8, 0.05, (-0.11, -0.2), 256),
    # The same with uniform weighting: the obscurance (ao_beside_walls; it is (1 + d)/2 below 1).
    "one-wall-uniform": Case(("x",), 1.0, "uniform", True, 32, 8, 0.05, (-0.11, -0.2), 256),
    # No limit: A = 1/2 exactly at every floor point; the floor seen from its back.
    "one-wall-unbounded": Case(("x",), math.inf, "cosine", False, 32, 8, 0.05, (-0.11, -0.2), 64),
    # The open plane: A = 1 exactly, every sample unoccluded (zero variance); seen from its back.
    "open-plane": Case((), math.inf, "cosine", False, 16, 16, 0.1, (-0.8, -0.8), 4),
    # The corner of two walls, no limit: A = 1/4 exactly; seen from its back.
    "corner": Case(("x", "z"), math.inf, "cosine", False, 16, 16, 0.1, (-0.11, -0.11), 64),
    # A sphere of radius r centred at height h over the origin, no limit: A = 1 − r² h / (ρ² + h²)^(3/2)
    # at horizontal distance ρ (the sphere's form factor, (r/D)² cos θ_c, whole above the horizon).
    "sphere": Case(("sphere",), math.inf, "cosine", True, 16, 16, 0.15, (-1.2, -1.2), 64),
}


def _quad(name: str, corners) -> Mesh:
    """A quad (two triangles), front side by the right-hand rule over ``corners``."""
    return Mesh(name, np.asarray(corners, dtype=np.float64), np.array([[0, 1, 2], [0, 2, 3]]), "grey")


def floor_scene(case: Case) -> Scene:
    """The case's floor (y = 0), walls or sphere, and a camera looking straight down at the floor."""
    x0, z0 = case.corner
    half_w, half_h = case.width * case.pixel / 2, case.height * case.pixel / 2
    cx, cz = x0 + half_w, z0 + half_h
    sphere = "sphere" in case.walls
    cam_h = SPHERE_CAM if sphere else 2.0
    # Floors: the half-space x ≥ 0 beside one wall, the quadrant in a corner; ±2 under the sphere, small
    # so that the scene-scaled ray offset (1e-5 of the scene) stays far below the sphere's distances.
    size = 2.0 if sphere else L
    fx0 = 0.0 if "x" in case.walls else -size
    fz0 = 0.0 if "z" in case.walls else -size
    up = [(fx0, 0, fz0), (fx0, 0, size), (size, 0, size), (size, 0, fz0)]  # (e1 × e2) = +y
    meshes = [_quad("floor", up if case.floor_up else up[::-1])]
    if "x" in case.walls:
        meshes.append(_quad("wall-x", [(0, 0, -L), (0, 0, L), (0, L, L), (0, L, -L)]))
    if "z" in case.walls:
        meshes.append(_quad("wall-z", [(-L, 0, 0), (-L, L, 0), (L, L, 0), (L, 0, 0)]))
    spheres = (Sphere("ball", (0.0, SPHERE_H, 0.0), SPHERE_R, "grey"),) if sphere else ()
    features = {"triangle_mesh", "diffuse", "pinhole_camera", "box_filter"} | ({"sphere"} if sphere else set())
    camera = Camera(position=(cx, cam_h, cz), look_at=(cx, 0.0, cz), up=(0.0, 0.0, -1.0),
                    fov_deg=2.0 * math.degrees(math.atan(half_w / cam_h)), fov_axis="x",
                    width=case.width, height=case.height)
    return Scene(name="ao-analytic", path=Path("tests") / "ao-analytic.toml", features=frozenset(features),
                 camera=camera, materials={"grey": Diffuse("grey", (0.5, 0.5, 0.5))}, meshes=tuple(meshes),
                 max_depth=-1, pixel_filter="box", spheres=spheres, quantity="ambient_occlusion",
                 ambient_occlusion=AmbientOcclusion(case.max_distance, case.weighting, "geometric", 0.0))


def _footprints(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Floor x at the column edges (W + 1) and z at the row edges (H + 1), from the camera's own rays."""
    cam = scene.camera
    assert np.allclose(cam.frame()[2], (0.0, -1.0, 0.0)), "the footprints are squares only looking straight down"
    h = cam.position[1]
    cols, rows = np.arange(cam.width + 1.0), np.arange(cam.height + 1.0)
    dx = cam.directions(cols, np.zeros_like(cols))
    dz = cam.directions(np.zeros_like(rows), rows)
    return cam.position[0] + h * dx[:, 0] / -dx[:, 1], cam.position[2] + h * dz[:, 2] / -dz[:, 1]


def _gauss(a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights (summing to 1) on [a, b]."""
    t, w = np.polynomial.legendre.leggauss(GL_NODES)
    return a + (b - a) * (t + 1.0) / 2.0, w / 2.0


def _wall_mean(a_of_d, x0: float, x1: float, reach: float) -> float:
    """Mean of A(d) over the footprint [x0, x1] beside one wall; A = 1 from ``reach`` on (split there)."""
    total = 0.0
    if x0 < reach:
        d, w = _gauss(x0, min(x1, reach))
        total += (min(x1, reach) - x0) * float(np.sum(w * a_of_d(d)))
    if x1 > reach:
        total += x1 - max(x0, reach)
    return total / (x1 - x0)


@functools.lru_cache(maxsize=None)
def expected_image(name: str) -> tuple[np.ndarray, float]:
    """(H, W) footprint means of A for case ``name`` (NaN where the pixel sees a wall or the sphere), and the
    most the finite scene may differ from them per sample (:data:`LEAK`, or 0)."""
    case = CASES[name]
    xs, zs = _footprints(floor_scene(case))
    out = np.full((case.height, case.width), np.nan)
    R = case.max_distance
    if case.walls == ():
        out[:] = 1.0
        return out, 0.0
    if case.walls == ("sphere",):
        # The camera (straight over the centre) sees the sphere where a floor point lies within ρ_s of the axis.
        beta = math.asin(SPHERE_R / (SPHERE_CAM - SPHERE_H))
        rho_s = SPHERE_CAM * math.tan(beta)
        for i in range(case.height):
            for j in range(case.width):
                near_x, near_z = max(xs[j], 0.0, -xs[j + 1]), max(zs[i], 0.0, -zs[i + 1])  # nearest to the axis
                if math.hypot(near_x, near_z) <= rho_s * 1.001:
                    continue
                x, wx = _gauss(xs[j], xs[j + 1])
                z, wz = _gauss(zs[i], zs[i + 1])
                rho2 = x[:, None] ** 2 + z[None, :] ** 2
                a = 1.0 - SPHERE_R ** 2 * SPHERE_H / (rho2 + SPHERE_H ** 2) ** 1.5
                out[i, j] = float(np.sum(wx[:, None] * wz[None, :] * a))
        return out, 0.0
    leak = LEAK if math.isinf(R) else 0.0  # finite R (1) is far inside the walls: nothing passes them
    if case.walls == ("x", "z"):
        assert math.isinf(R), "the corner's footprint mean is its point value only without a limit"
        quarter = ao_beside_walls([(1.0, 0.0), (1.0, math.pi / 2)], R, case.weighting)
        out[np.ix_(zs[:-1] > 0.0, xs[:-1] > 0.0)] = quarter
        return out, leak
    if case.weighting == "cosine":
        def a_of_d(d):
            return cosine_ao_beside_wall(d, R)
    else:
        def a_of_d(d):
            return np.array([ao_beside_walls([(float(v), 0.0)], R, "uniform") for v in d])
    for j in range(case.width):
        if xs[j] > 0.0:
            out[:, j] = _wall_mean(a_of_d, xs[j], xs[j + 1], R)
    return out, leak


def _binomial_p(k: np.ndarray, n: int, p: np.ndarray, slack: float) -> np.ndarray:
    """Two-sided exact binomial p-values of counts ``k`` of ``n`` against means within ``slack`` of ``p``."""
    low = binom.cdf(k, n, np.minimum(1.0, p + slack))
    high = binom.sf(k - 1, n, np.maximum(0.0, p - slack))
    return np.minimum(1.0, 2.0 * np.minimum(low, high))


def _sample_failures(name: str, result, spp: int, independent: bool = True) -> list[str]:
    """What says the samples were not each 0 or 1 (grey, counts of n, the Bernoulli variance)."""
    img = result.image.astype(np.float64)
    out = []
    if not (np.array_equal(img[..., 0], img[..., 1]) and np.array_equal(img[..., 0], img[..., 2])):
        out.append(f"{name}: samples: the channels differ (AO is grey)")
    if not (np.all(img >= 0.0) and np.all(img <= 1.0)):
        out.append(f"{name}: samples: values outside [0, 1]: {img.min()} .. {img.max()}")
    counts = img[..., 0] * spp
    if np.abs(counts - np.rint(counts)).max() > 1e-3:
        out.append(f"{name}: samples: a pixel is not a count of unoccluded samples over {spp}")
    if result.variance is not None and independent:  # a low-discrepancy sampler's variance is its batches'
        mean = img[..., 0]
        bernoulli = mean * (1.0 - mean) / (spp - 1)
        if np.abs(result.variance[..., 0] - bernoulli).max() > 1e-6:
            out.append(f"{name}: samples: the render's variance is not the Bernoulli one")
    return out


def analytic_failures(renderer, sampler: str = "independent") -> list[str]:
    """Every analytic case rendered by ``renderer`` at seed :data:`SEED`; what disagrees (empty: all agree).

    Per pixel, an exact binomial test; per case, a z-test of the total count
    (module docstring); at family-wise rate :data:`ALPHA` over all of them.
    A check that fails reads ``"<case>: agreement ..."``; a failure of the
    samples' form (not 0 or 1, not grey) reads ``"<case>: samples ..."``.
    """
    # Exact binomial tests are for independent samples, which a renderer with a sampler setting is asked for
    # by default; a low-discrepancy sampler's counts vary less, so the same tests hold for it, conservatively.
    declared = {s.name: s.default for s in getattr(renderer, "settings", ())}
    kw = {"settings": declared | {"sampler": sampler}} if "sampler" in declared else {}
    renders = {name: renderer.render(floor_scene(c), c.spp, seed=SEED, **kw) for name, c in CASES.items()}
    expected = {name: expected_image(name) for name in CASES}
    tests = sum(int(np.isfinite(e).sum()) + 1 for e, _ in expected.values())
    level = sidak_level(ALPHA, tests)
    failures = []
    for name, case in CASES.items():
        result, (exp, slack) = renders[name], expected[name]
        failures += _sample_failures(name, result, case.spp, sampler == "independent")
        seen = np.isfinite(exp)
        k = np.rint(result.image[..., 0].astype(np.float64) * case.spp)[seen]
        p = _binomial_p(k, case.spp, exp[seen], slack)
        if (p < level).any():
            worst = int(np.argmin(p))
            row, col = np.argwhere(seen)[worst]
            failures.append(f"{name}: agreement: {(p < level).sum()} of {p.size} pixels, worst ({row}, {col}): "
                            f"{k[worst] / case.spp:.4f} against {exp[seen][worst]:.4f} (p = {p[worst]:.2g}, "
                            f"level {level:.2g})")
        n = case.spp * k.size
        diff = abs(k.sum() - case.spp * exp[seen].sum()) - slack * n
        var = case.spp * float(np.sum(exp[seen] * (1.0 - exp[seen])))
        p_total = 1.0 if diff <= 0.0 else (0.0 if var == 0.0 else 2.0 * norm.sf(diff / math.sqrt(var)))
        if p_total < level:
            failures.append(f"{name}: agreement: the mean {k.sum() / n:.5f} against {exp[seen].mean():.5f} "
                            f"(p = {p_total:.2g}, level {level:.2g})")
    return failures


# -- the analytic answers themselves ----------------------------------------------------

def test_analytic_ao_known_values():
    """src/cornell_harness/scenes/analytic_ao.py: A = 1 in the open, 1/2 beside a wall and 1/4 in a corner without a limit
    (whatever the distances, either weighting); its quadrature agrees with the one-wall closed form; and the
    uniform one-wall value is (1 + d/R)/2 (the wall hides the band of the hemisphere it spans, linear in d)."""
    for w in ("cosine", "uniform"):
        assert ao_beside_walls([], 0.7, w) == pytest.approx(1.0, abs=1e-12)
        assert ao_beside_walls([(0.3, 1.0)], math.inf, w) == pytest.approx(0.5, abs=1e-10)
        assert ao_beside_walls([(0.3, 0.0), (2.0, math.pi / 2)], math.inf, w) == pytest.approx(0.25, abs=1e-10)
    for d in (0.0, 0.05, 0.3, 0.77, 0.999, 1.0, 1.4):
        assert ao_beside_walls([(d, 0.2)], 1.0, "cosine") == pytest.approx(float(cosine_ao_beside_wall(d, 1.0)),
                                                                           abs=1e-10)
        assert ao_beside_walls([(d, 0.2)], 1.0, "uniform") == pytest.approx((1.0 + min(d, 1.0)) / 2.0, abs=1e-9)


def test_expected_images_cover_the_floor():
    """The masks leave most of each image to test, and only the pixels that see a wall or the sphere out."""
    for name, case in CASES.items():
        exp, _ = expected_image(name)
        seen = np.isfinite(exp)
        assert seen.sum() >= 0.6 * exp.size, name
        assert np.all((exp[seen] >= 0.25 - 1e-12) & (exp[seen] <= 1.0)), name
    assert np.all(expected_image("open-plane")[0] == 1.0)
    one_wall = expected_image("one-wall")[0]
    assert np.isnan(one_wall[:, :3]).all() and np.isfinite(one_wall[:, 3:]).all()
    assert one_wall[0, 3] < 0.56 and one_wall[0, -1] == 1.0  # near the wall, and beyond reach


# -- the renderer against them ------------------------------------------------------------

@pytest.mark.parametrize("sampler", SAMPLERS)
def test_ao_matches_the_analytic_cases(sampler):
    """Every analytic case (:data:`CASES`) within the tests of :func:`analytic_failures`: α = 1e-3 overall,
    with each sampler."""
    assert analytic_failures(AORenderer(), sampler) == []


AO_MUTANTS = [m.name for m in mutants.MUTANTS if m.renderer == "ao"]
#: The case each mutant must fail at least: tfar = inf darkens the finite cases, uniform directions turn
#: cosine AO into obscurance, a flipped normal looks through the floor into the void below it.
MUTANT_CASES = {"ao_uniform_as_cosine": "one-wall", "ao_max_distance_ignored": "one-wall",
                "ao_normal_flipped": "one-wall"}


@pytest.mark.parametrize("name", AO_MUTANTS)
def test_mutant_fails_the_analytic_cases(name, tmp_path_factory):
    """Each ao mutant of tests/mutants/ambient_occlusion.py fails :func:`analytic_failures` on agreement (not only on
    the samples' form), at least in the case it must break."""
    assert set(AO_MUTANTS) == set(MUTANT_CASES)
    entry = mutants.load_mutant(name, tmp_path_factory.mktemp("ao-mutants"))
    failures = analytic_failures(entry.renderer)
    assert any(f.startswith(f"{MUTANT_CASES[name]}: agreement") for f in failures), (name, failures)


# -- determinism and progress ---------------------------------------------------------------

def render(scene: Scene, spp: int, seed: int, threads: int = 2, checkpoints=(), **overrides):
    """:class:`AORenderer`'s render with its complete settings, as the render path hands them (defaults
    but for ``overrides``)."""
    settings = {s.name: s.default for s in AORenderer.settings} | overrides
    return AORenderer(threads=threads).render(scene, spp, seed, checkpoints, settings=settings)


@pytest.fixture(scope="module")
def cornell_ao() -> Scene:
    return resolve_scene("cornell-box-ao").with_resolution(64, 64)


@pytest.mark.parametrize("sampler", SAMPLERS)
def test_bit_identical_for_any_thread_count_and_seed_dependent(cornell_ao, sampler):
    """Same seed: the same image and variance bit for bit on 1 and 2 threads (16 spp at 64² cuts the last pass
    into 2 and 4 work units); another seed: another image. With each sampler."""
    a, b = (render(cornell_ao, 16, 3, threads=t, sampler=sampler) for t in (1, 2))
    assert a.image.tobytes() == b.image.tobytes() and a.variance.tobytes() == b.variance.tobytes()
    c = render(cornell_ao, 16, 4, sampler=sampler)
    assert not np.array_equal(a.image, c.image)


def test_checkpoints_are_the_smaller_renders(cornell_ao):
    """Progressive: the 4-spp checkpoint of an 8-spp render is the 4-spp render, bit for bit."""
    full = render(cornell_ao, 8, 1, checkpoints=[4, 8])
    assert [c.spp for c in full.checkpoints] == [4, 8]
    assert full.checkpoints[0].image.tobytes() == render(cornell_ao, 4, 1, threads=1).image.tobytes()


# -- the stored AO scene ------------------------------------------------------------------

def _pixels_inside(cam: Camera, lo, hi, z: float) -> np.ndarray:
    """(H, W) mask of the pixels whose whole footprint is inside the rectangle [lo, hi] (x, y) of the plane z."""
    corners = np.array([[lo[0], lo[1], z], [hi[0], hi[1], z]])
    (c0, r1), (c1, r0) = cam.project_to_pixels(corners)  # x grows with columns, y against rows
    cols, rows = np.arange(cam.width), np.arange(cam.height)
    return ((rows >= r0) & (rows + 1 <= r1))[:, None] & ((cols >= c0) & (cols + 1 <= c1))[None, :]


def test_cornell_box_ao_borders_open_wall_and_range(cornell_ao):
    """cornell-box-ao at 64², 64 spp.

    - Pixels whose footprint lies wholly outside the box's open front (x, y ∈ [-1, 1] at z = 1, which the
      whole box projects inside) see nothing: exactly the miss value, 0, and again with miss_value 0.25.
    - The back wall (z = -1) for x ∈ [0.3, 0.45], y ∈ [-0.35, 0.35] has nothing within max_distance 0.5:
      0.55 to the green wall, 0.65 to floor and ceiling, ≥ 0.556 to the large box's nearest edge (x = -0.139,
      z = -0.659); every sample is unoccluded, so exactly 1, and its reported variance no more than the
      half-sample one of cornell_harness.renderers.ao.pooled_variance, (½/65)(64.5/65)/64 = 1.2e-4, times a stratification gain
      below 1 (0 where the whole 5×5 window about it is exact).
    - Every value in [0, 1], grey. No statistics: each assertion is exact.
    """
    cam = cornell_ao.camera
    r = render(cornell_ao, 64, 2)
    img = r.image
    assert np.all((img >= 0.0) & (img <= 1.0)) and np.array_equal(img[..., 0], img[..., 2])
    (c0, r1), (c1, r0) = cam.project_to_pixels(np.array([[-1.0, -1.0, 1.0], [1.0, 1.0, 1.0]]))
    cols, rows = np.arange(cam.width), np.arange(cam.height)
    border = ~(((rows + 1 > r0) & (rows < r1))[:, None] & ((cols + 1 > c0) & (cols < c1))[None, :])
    assert border.sum() >= 4 * 63  # at 64², the outer ring of pixels
    assert np.all(img[border] == 0.0) and np.all(r.variance[border] == 0.0)
    open_wall = _pixels_inside(cam, (0.3, -0.35), (0.45, 0.35), -1.0)
    assert open_wall.sum() >= 10
    assert np.all(img[open_wall] == 1.0) and np.all(r.variance[open_wall] < 1.2e-4)
    assert img[~border].mean() < 0.95  # the box's edges and corners are occluded
    ao = cornell_ao.ambient_occlusion
    grey = dataclasses.replace(cornell_ao, ambient_occlusion=dataclasses.replace(ao, miss_value=0.25))
    assert np.all(render(grey, 4, 2).image[border] == np.float32(0.25))


# -- the runner's refusals and the registration -------------------------------------------------

def test_runner_refuses_the_other_quantity():
    """ao on a radiance scene, and a radiance renderer on the AO scene, are skipped before rendering."""
    cornell, cornell_ao = resolve_scene("cornell-box"), resolve_scene("cornell-box-ao")
    ao, pt = AORenderer(), PathTracer()
    assert missing_features(ao, cornell) == ["the quantity radiance"]
    assert missing_features(pt, cornell_ao) == ["the quantity ambient_occlusion"]
    assert missing_features(ao, cornell_ao) == []
    for scene, renderer, reason in ((cornell, ao, "does not model the quantity radiance"),
                                    (cornell_ao, pt, "does not model the quantity ambient_occlusion")):
        rec = RunRecord.new(scene, RendererEntry(renderer.name, renderer.name, renderer, None), 4, 0)
        assert (rec.status, rec.reason) == ("skipped", reason)
    with pytest.raises(ValueError, match="quantity is radiance"):
        ao.render(cornell.with_resolution(4, 4), 1, seed=0)


def test_registered_as_ao():
    """The entry point of pyproject.toml (`pip install -e .` installs it) names this adapter."""
    (entry,) = resolve(["ao"])
    assert entry.available and type(entry.renderer) is AORenderer
    assert (entry.renderer.estimator, entry.renderer.quantities) == ("unbiased", ("ambient_occlusion",))

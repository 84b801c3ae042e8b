"""The ambient renderer (src/cornell_harness/renderers/ambient.py): direct light + ρ·La·AO, with La from radiosity, an oracle, or none.

Statistics. Direct light (``ambient = none``) is an unbiased estimate of the
path tracer's image at max_depth 2 and of the analytic rectangle-light image:
those comparisons are tiled z-tests (:func:`cornell_harness.evaluate.agreement.agreement_test`,
Šidák-corrected to a family-wise false-alarm rate of :data:`ALPHA` per test,
using both renders' own variances; the analytic image has none). Everything
else is exact: with the same seed the direct part of every sample is the same
whatever the ambient, so differences between renders are the ambient term
alone, sample by sample (checked to float32 rounding, relative 1e-5), and the
radiosity ambient and the oracle's least squares are closed forms. All seeds
are fixed, so a pass is reproducible.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cbox
from cornell_harness.adapters.registry import RendererEntry, missing_features, resolve
from cornell_harness.evaluate.agreement import agreement_test
from cornell_harness.evaluate.reference_fit import least_squares_constant
from cornell_harness.scenes.analytic import furnace_scene
from cornell_harness.scenes.polygon_light import FLOOR_RHO, LIGHT_A, LIGHT_B, LIGHT_LE, rectangle_light_image, rectangle_light_scene
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Camera, Diffuse, Mesh, Scene
from cornell_harness.store.references import ReferenceError, load_reference
from cornell_harness.workflows.render import render_checked
from cornell_harness.workflows.runner import run_one
from cornell_harness.renderers.ambient import AOAmbient
from cornell_harness.renderers.core.ambient_radiance import interreflection_sum
from cornell_harness.renderers.core.sampler import SAMPLERS
from cornell_harness.renderers.pathtracer import PathTracer

pytest.importorskip("embreex")

#: Family-wise false-alarm rate of each z-test family.
ALPHA = 1e-3
#: float32 rounding of an image value, relative.
F32 = 1e-5


def render(scene: Scene, spp: int, seed: int, threads: int = 2, checkpoints=(), **overrides):
    """:class:`AOAmbient`'s render with its complete settings, as the render path hands them (defaults but for
    ``overrides``)."""
    settings = {s.name: s.default for s in AOAmbient.settings} | overrides
    return AOAmbient(threads=threads).render(scene, spp, seed, checkpoints, settings=settings)


@pytest.fixture(scope="module")
def cornell() -> Scene:
    return resolve_scene("cornell-box")


# -- direct light ----------------------------------------------------------------------------------

def test_none_is_the_path_tracers_direct_light(cornell):
    """``ambient = none`` on cornell-box (unbounded depth) against the path tracer at max_depth 2 (emission and
    direct light only), 32², 64 spp each: 8×8-pixel tiles and the whole image, per channel, z-tests with both
    variances, α = 1e-3 family-wise over the 51 tests."""
    small = cornell.with_resolution(32, 32)
    ours = render(small, 64, seed=11, ambient="none")
    pt = PathTracer(threads=2).render(small.with_max_depth(2), 64, seed=12)
    agr = agreement_test(ours.image, ours.variance, pt.image, pt.variance, tile=8, alpha=ALPHA)
    assert agr.passed, agr.message()
    assert ours.info["ambient_radiance"] == [0.0, 0.0, 0.0]


def test_max_depth_2_has_no_ambient_and_max_depth_1_is_emission(cornell):
    """With max_depth 2 no bounce is left for ambient light: the radiosity image is the direct-only one, bit for
    bit (no occlusion ray is traced). With max_depth 1 there is no direct light either: emission seen only (the
    light's pixels), the same for every ambient."""
    small = cornell.with_resolution(32, 32)
    for depth in (2, 1):
        scene = small.with_max_depth(depth)
        none, rad = render(scene, 4, seed=3, ambient="none"), render(scene, 4, seed=3)
        assert rad.image.tobytes() == none.image.tobytes(), depth
        assert rad.info["ambient_radiance"] == [0.0, 0.0, 0.0]
    lit = rad.image.max(axis=2) > 0.0
    assert 0 < lit.sum() < 0.02 * lit.size  # the light covers about 0.5% of the image
    assert rad.image.max() <= np.float32(18.387)  # Le's red: nothing but emission


def test_direct_light_matches_the_rectangle_light_formula(tmp_path):
    """``ambient = none`` on the analytic rectangle-light scene (direct light exact from Lambert's polygon
    formula), 16², 64 spp: 4×4-pixel tiles and the whole image z-tested with our variance, α = 1e-3 over 51."""
    scene = rectangle_light_scene(tmp_path, res=16)
    ours = render(scene, 64, seed=5, ambient="none")
    exact = rectangle_light_image(scene, sub=64)
    agr = agreement_test(ours.image, ours.variance, exact, np.zeros_like(exact), tile=4, alpha=ALPHA)
    assert agr.passed, agr.message()


# -- the ambient term ------------------------------------------------------------------------------

@pytest.mark.parametrize("sampler", SAMPLERS)
def test_occlusion_shadows_the_ambient_term(cornell, sampler):
    """The ambient term is shadowed by AO: with the same seed, the default AO distance (0.5 on cornell-box)
    never adds more than a distance too short for anything to occlude (the same directions, some rays
    blocked), and in all it adds 0.7-0.9 of it (measured 0.80 at 32², 16 spp: the Cornell box's AO within
    0.5, weighted by albedo; 1 if occlusion were ignored, the mutant ambient_not_occluded). With each sampler."""
    small = cornell.with_resolution(32, 32)
    none, full, open_ = (render(small, 16, seed=3, sampler=sampler, **s).image.astype(np.float64)
                         for s in ({"ambient": "none"}, {}, {"ao_max_distance": 1e-6}))
    shadowed, unshadowed = full - none, open_ - none
    assert (shadowed <= unshadowed + 1e-6).all()
    assert 0.7 < shadowed.mean() / unshadowed.mean() < 0.9


def rectangle_light_la() -> float:
    """Cohen et al.'s ambient of the rectangle-light scene by hand: a floor 2×2 of ρ 0.75 and a black light
    0.6×0.4 of Le 5 (one-sided): ρ̄ = 0.75·4/4.24, Φ = π·5·0.24, La = ρ̄/(1 − ρ̄)·Φ/(π·4.24)."""
    floor, light = 4.0, (2 * LIGHT_A) * (2 * LIGHT_B)
    total = floor + light
    rho_bar = FLOOR_RHO * floor / total
    return rho_bar / (1.0 - rho_bar) * (math.pi * LIGHT_LE * light) / (math.pi * total)


@pytest.mark.parametrize("ao_samples, sampler", [(1, "independent"), (3, "independent"), (3, "pmj02"),
                                                 (3, "sobol")])
def test_open_floor_adds_exactly_rho_la(tmp_path, ao_samples, sampler):
    """The rectangle-light floor with the occlusion rays' reach 0.3 (0.1 of the scene's size 3), below the
    light (height 1): nothing occludes, A = 1 in every sample, so the radiosity image minus the direct-only one
    (same seed) is exactly ρ·La wherever a pixel sees only floor, between 0 and that where it also sees the
    light's black back, to float32 rounding. With each sampler."""
    scene = rectangle_light_scene(tmp_path, res=16)
    none = render(scene, 16, seed=5, ambient="none", ao_max_distance=0.1, sampler=sampler)
    rad = render(scene, 16, seed=5, ao_max_distance=0.1, ao_samples=ao_samples, sampler=sampler)
    la = rectangle_light_la()
    assert rad.info["ambient_radiance"] == pytest.approx([la] * 3, rel=1e-12)
    assert rad.info["ao_max_distance_units"] == pytest.approx(0.3, rel=1e-12)
    diff = rad.image.astype(np.float64) - none.image
    full = FLOOR_RHO * la
    assert np.all(diff >= -F32 * full) and np.all(diff <= full * (1 + F32)), (diff.min(), diff.max(), full)
    exact = np.abs(diff - full) <= F32 * (full + none.image)
    assert exact.mean() >= 0.6, exact.mean()  # the light's back hides about a fifth of the image


def test_radiosity_ambient_of_two_quads():
    """Cohen et al.'s ambient for two quads, by hand: a floor 2×2 of ρ (0.5, 0.25, 0.1) under an emitter
    1×0.5 of ρ (0.9, 0.8, 0.7), Le (2, 3, 4). A_total = 4.5, ρ̄ = (49/90, 14/45, 1/6), Φ/(π A_total) =
    (2/9, 1/3, 4/9), so La = ρ̄/(1 − ρ̄)·Φ/(π A_total) = (98/369, 14/93, 4/45). With max_depth 4 the camera's first
    hit keeps K = 2 bounces: La = (ρ̄ + ρ̄²)·Φ/(π A_total)."""
    floor = Mesh("floor", np.array([[-1, 0, -1], [-1, 0, 1], [1, 0, 1], [1, 0, -1]], np.float64),
                 np.array([[0, 1, 2], [0, 2, 3]]), "floor")
    light = Mesh("light", np.array([[-0.5, 1, -0.25], [0.5, 1, -0.25], [0.5, 1, 0.25], [-0.5, 1, 0.25]],
                                   np.float64), np.array([[0, 1, 2], [0, 2, 3]]), "lamp", (2.0, 3.0, 4.0))
    camera = Camera(position=(0.0, 3.0, 0.0), look_at=(0.0, 0.0, 0.0), up=(0.0, 0.0, -1.0), fov_deg=40.0,
                    fov_axis="smaller", width=4, height=4)
    scene = Scene(name="two-quads", path=Path("tests") / "two-quads.toml",
                  features=frozenset({"triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"}),
                  camera=camera, materials={"floor": Diffuse("floor", (0.5, 0.25, 0.1)),
                                            "lamp": Diffuse("lamp", (0.9, 0.8, 0.7))},
                  meshes=(floor, light), max_depth=-1, pixel_filter="box")
    info = render(scene, 1, seed=0).info
    assert info["total_area"] == pytest.approx(4.5, rel=1e-12)
    rho_bar = np.array([49 / 90, 14 / 45, 1 / 6])
    assert info["mean_reflectance"] == pytest.approx(rho_bar.tolist(), rel=1e-12)
    assert info["emitted_power"] == pytest.approx([math.pi * 1.0, math.pi * 1.5, math.pi * 2.0], rel=1e-12)
    assert info["ambient_radiance"] == pytest.approx([98 / 369, 14 / 93, 4 / 45], rel=1e-12)
    bounded = render(scene.with_max_depth(4), 1, seed=0).info
    scale = np.array([2 / 9, 1 / 3, 4 / 9])
    assert bounded["ambient_radiance"] == pytest.approx(((rho_bar + rho_bar ** 2) * scale).tolist(), rel=1e-12)


def test_interreflection_sum_and_divergence():
    """Σ_{k=1..K} ρ^k: the closed form, K itself at ρ = 1, inf unbounded; the radiosity ambient of a white
    furnace (ρ̄ = 1) with unbounded depth is refused, and with max_depth 4 it is 2·Le (K = 2 at the first hit)."""
    rho = np.array([0.0, 0.5, 0.9, 1.0])
    for k in (0, 1, 2, 7):
        assert interreflection_sum(rho, k) == pytest.approx([sum(r ** j for j in range(1, k + 1)) for r in rho],
                                                            rel=1e-12)
    assert interreflection_sum(rho, math.inf).tolist() == pytest.approx([0.0, 1.0, 9.0, math.inf])
    with pytest.raises(ValueError, match="diverges"):
        render(furnace_scene(1.0, res=4), 1, seed=0)
    bounded = render(furnace_scene(1.0, res=4, max_depth=4), 1, seed=0)  # K = 2 at the first hit: La = 2 Le
    assert bounded.info["ambient_radiance"] == pytest.approx([2.0] * 3)


# -- the oracle ------------------------------------------------------------------------------------

def oracle(scene: Scene, spp: int, seed: int, threads: int = 2, checkpoints=()):
    """The oracle as the harness renders it: through the render path, which fits it (the renderer refuses)."""
    entry = RendererEntry("ambient", "cornell_harness.renderers.ambient:AOAmbient", AOAmbient(threads), None, {"ambient": "oracle"})
    return render_checked(entry, scene, spp, seed, checkpoints)


def test_oracle_ambient_is_least_squares():
    """The oracle's fit against numpy's least squares, per channel, on random images; 0 where B is all 0."""
    gen = np.random.default_rng(0)
    d, b, r = gen.random((3, 8, 8, 3))
    b[..., 2] = 0.0
    c = least_squares_constant(d, b, r)
    for ch in range(2):
        want = np.linalg.lstsq(b[..., ch].reshape(-1, 1), (r - d)[..., ch].ravel(), rcond=None)[0][0]
        assert c[ch] == pytest.approx(want, rel=1e-12)
    assert c[2] == 0.0


def test_oracle_minimises_the_error_against_the_reference(cornell, monkeypatch):
    """cornell-box at the reference's 256², 1 spp, seed 9: the oracle's image is D + c·B, D the direct-only
    render of the same seed, B = (image − D)/c its ambient part; ±10% on c raises the MSE against the reference
    in every channel, and c recomputed from D and B agrees with the recorded one (relative 1e-3: B from float32
    images); B is the render at ambient = constant, La = 1, minus D. Another resolution has no reference: refused
    before rendering; the renderer itself refuses the oracle (the harness fits it)."""
    ref = load_reference(cornell).image.astype(np.float64)
    fitted = oracle(cornell, 1, seed=9)
    direct = render(cornell, 1, seed=9, ambient="none")
    c = np.array(fitted.info["ambient_radiance"])
    assert np.all(c > 0.0) and "oracle" in fitted.info["oracle"] and fitted.variance is None
    assert fitted.info["ambient"] == "oracle"
    d = direct.image.astype(np.float64)
    b = (fitted.image - d) / c

    def mse(k):
        return ((d + k * c * b - ref) ** 2).mean(axis=(0, 1))

    assert np.all(mse(1.1) > mse(1.0)) and np.all(mse(0.9) > mse(1.0)), (mse(0.9), mse(1.0), mse(1.1))
    assert least_squares_constant(d, b, ref) / c == pytest.approx(np.ones(3), rel=1e-3)
    unit = render(cornell, 1, seed=9, ambient="constant", ambient_radiance=1.0).image - d
    np.testing.assert_allclose(d + c * unit, fitted.image, rtol=F32, atol=1e-7)
    with pytest.raises(ValueError, match="fitted to the stored reference by the harness"):
        render(cornell, 1, seed=9, ambient="oracle")
    monkeypatch.setattr(AOAmbient, "render", lambda *a, **k: pytest.fail("rendered before refusing"))
    with pytest.raises(ReferenceError):
        oracle(cornell.with_resolution(32, 32), 1, seed=9)


# -- determinism, progress, registration, the CLI -------------------------------------------------

@pytest.mark.parametrize("sampler", ["pmj02", "sobol"])
def test_low_discrepancy_samplers_are_bit_identical_for_any_thread_count_and_progressive(cornell, sampler):
    """As :func:`test_bit_identical_for_any_thread_count_and_progressive` (radiosity) with a low-discrepancy
    sampler: the same image and variance on 1 and 2 threads, another seed another image, the 4-spp checkpoint
    of an 8-spp render the 4-spp render; and not the independent sampler's image."""
    small = cornell.with_resolution(32, 32)
    a, b = (render(small, 16, seed=3, threads=t, ao_samples=2, sampler=sampler) for t in (1, 2))
    assert a.image.tobytes() == b.image.tobytes() and a.variance.tobytes() == b.variance.tobytes()
    assert not np.array_equal(a.image, render(small, 16, seed=4, ao_samples=2, sampler=sampler).image)
    assert not np.array_equal(a.image, render(small, 16, seed=3, ao_samples=2).image)
    full = render(small, 8, seed=1, checkpoints=[4, 8], sampler=sampler)
    assert full.checkpoints[0].image.tobytes() == render(small, 4, seed=1, threads=1, sampler=sampler).image.tobytes()


def test_bit_identical_for_any_thread_count_and_progressive(cornell):
    """64², 16 spp, 2 occlusion rays per sample: the same image and variance bit for bit on 1 and 2 threads
    (the last pass is 2 and 4 work units), another seed another image; the 4-spp checkpoint of an 8-spp render
    is the 4-spp render. The oracle (256², 2 spp, checkpoint 1) is thread-independent too."""
    small = cornell.with_resolution(64, 64)
    a, b = (render(small, 16, seed=3, threads=t, ao_samples=2) for t in (1, 2))
    assert a.image.tobytes() == b.image.tobytes() and a.variance.tobytes() == b.variance.tobytes()
    assert not np.array_equal(a.image, render(small, 16, seed=4, ao_samples=2).image)
    full = render(small, 8, seed=1, checkpoints=[4, 8])
    assert [c.spp for c in full.checkpoints] == [4, 8]
    assert full.checkpoints[0].image.tobytes() == render(small, 4, seed=1, threads=1).image.tobytes()
    o1, o2 = (oracle(cornell, 2, seed=1, threads=t, checkpoints=[1, 2]) for t in (1, 2))
    assert o1.image.tobytes() == o2.image.tobytes()
    assert [c.image.tobytes() for c in o1.checkpoints] == [c.image.tobytes() for c in o2.checkpoints]


def test_registered_as_ambient_radiance_biased(cornell):
    """The entry point names this adapter: biased, radiance; refused on the AO scene. A run is scored with
    per-region metrics (in process, 4 spp)."""
    (entry,) = resolve(["ambient"])
    assert entry.available and type(entry.renderer) is AOAmbient and entry.renderer.estimator == "biased"
    assert missing_features(entry.renderer, cornell) == []
    assert missing_features(entry.renderer, resolve_scene("cornell-box-ao")) == ["the quantity ambient_occlusion"]
    rec = run_one(entry, cornell, 4, 0, load_reference(cornell))
    assert rec.status == "ok", rec.reason
    assert {"walls", "boxes", "floor"} <= set(rec.regions)
    assert all(math.isfinite(r["delta_e2000_mean"]) for r in rec.regions.values())


@pytest.mark.slow
def test_cli_compare_with_the_path_tracer(tmp_path):
    """`cbox compare --scene cornell-box -r ambient -r pathtracer --spp 16 --json` (about 15 s on 2 cores):
    both runs ok, each with per-region metrics; the ambient record carries La."""
    proc = run_cbox("compare", "--scene", "cornell-box", "-r", "ambient", "-r", "pathtracer", "--spp", "16",
                    "--json", "--out", str(tmp_path / "out"))
    assert proc.returncode == 0, proc.stderr[-2000:]
    records = {r["renderer"]: r for r in map(json.loads, proc.stdout.strip().splitlines())}
    assert set(records) == {"ambient", "pathtracer"}
    for rec in records.values():
        assert rec["status"] == "ok" and {"walls", "boxes", "floor", "light"} <= set(rec["regions"])
        assert math.isfinite(rec["regions"]["floor"]["delta_e2000_mean"])
    assert len(json.loads(records["ambient"]["info_ambient_radiance"])) == 3

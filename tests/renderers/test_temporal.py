"""The temporal stages: exponential accumulation (src/cornell_harness/renderers/temporal.py) and SVGF (svgf.py).

Closed forms: frames of independent noise of variance σ², blended by an
exponential moving average with new-frame weight α, settle at variance
α/(2 − α)·σ²; SVGF's moments, blended alike, estimate the luminance variance
as μ₂ − μ₁², whose mean is σ²·(1 − α/(2 − α)) = 2(1 − α)/(2 − α)·σ² (the
moving mean's own variance taken off). Sequences come from the stand-in of
``tests/renderers/sequences.py`` (the animated scene's contract).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from cornell_harness.adapters.api import attribute, frame_seed
from cornell_harness.renderers import svgf, temporal
from cornell_harness.renderers.pathtracer import PathTracer
from cornell_harness.scenes.library import resolve_scene
from tests.renderers.sequences import still_sequence

pytest.importorskip("embreex")


@pytest.fixture(scope="module")
def box():
    return resolve_scene("cornell-box").with_resolution(16, 16)


@pytest.mark.parametrize("alpha", [0.1, 0.5])
def test_accumulation_variance_tends_to_alpha_over_two_minus_alpha(alpha):
    """Independent unit-variance frames through :func:`temporal.accumulate` (every pixel keeping its history):
    after 200 frames the variance over 128² pixels is α/(2 − α) within 5% (its estimate's sd is 1.1%)."""
    rng = np.random.default_rng(1)
    h = rng.standard_normal((128, 128, 1))
    valid = np.ones((128, 128), bool)
    for _ in range(200):
        h = temporal.accumulate(rng.standard_normal((128, 128, 1)), h, valid, alpha)
    assert h.var() == pytest.approx(alpha / (2 - alpha), rel=0.05)


def test_stage_on_a_static_scene_settles_at_alpha_over_two_minus_alpha(box):
    """``pathtracer+temporal`` on a still Cornell box (clamping off, α = 0.5): over frames 10-89 the per-pixel
    variance of its images, summed over pixels, is 1/3 of the path tracer's frames' within 15% (the sample
    variance of an AR(1) series of 80 frames runs ~4% low at lag correlation 1/2)."""
    stage = temporal.PathTracerTemporal(threads=2)
    settings = {"alpha": 0.5, "clamp": "none"}
    seq = stage.render_sequence(still_sequence(box, 90), 2, 5, settings)
    frames = np.stack([PathTracer(threads=2).render(box, 2, frame_seed(5, i)).image for i in range(10, 90)])
    out = np.stack([r.image for r in seq.frames[10:]])
    ratio = out.var(axis=0).sum() / frames.var(axis=0).sum()
    assert ratio == pytest.approx(1 / 3, rel=0.15)


def test_sequence_api(box):
    """Frames asked for are returned in order (the history built from frame 0 anyway); frame i of the
    wrapped renderer is rendered with frame_seed(seed, i); frame 0 has no history, so it is that render; the
    still image is the wrapped renderer's with the seed itself; the stage declares sequences, and biased."""
    stage = temporal.PathTracerTemporal(threads=2)
    seq = stage.render_sequence(still_sequence(box, 4), 2, 3, frames=[3, 0])
    assert [r.info["frame"] for r in seq.frames] == [0, 3]
    assert [r.seed for r in seq.frames] == [frame_seed(3, 0), frame_seed(3, 3)]
    first = PathTracer(threads=2).render(box, 2, frame_seed(3, 0))
    np.testing.assert_array_equal(seq.frames[0].image, first.image)
    assert seq.frames[1].info["history_fraction"] > 0.9 and seq.frames[1].time_s > 0
    assert seq.state == {"stage": "temporal", "alpha": 0.1, "clamp": "minmax", "clip_gamma": 1.0}
    still = stage.render(box, 2, 3)
    np.testing.assert_array_equal(still.image, PathTracer(threads=2).render(box, 2, 3).image)
    assert attribute(stage, "sequences") and attribute(stage, "estimator") == "biased"
    assert stage.name == "pathtracer+temporal" and {"alpha", "rr_depth"} <= {s.name for s in stage.settings}
    with pytest.raises(ValueError, match="out of range"):
        stage.render_sequence(still_sequence(box, 2), 2, 3, frames=[2])


def test_clamping_limits_the_history_to_the_neighbourhood_box():
    """A history far off the current frame is pulled into the box of its 3 × 3 neighbourhood: minmax (Karis)
    to the neighbours' extremes, variance (Salvi) to mean ± γ·sd; none leaves it."""
    current = np.zeros((3, 3, 1))
    current[0, 0] = 2.0
    history = np.full((3, 3, 1), 10.0)
    assert temporal.clamp_history(history, current, "minmax")[1, 1, 0] == 2.0
    n = np.zeros(9)
    n[0] = 2.0
    assert temporal.clamp_history(history, current, "variance", 2.0)[1, 1, 0] == pytest.approx(n.mean() + 2 * n.std())
    assert temporal.clamp_history(history, current, "none")[1, 1, 0] == 10.0


# -- SVGF ----------------------------------------------------------------------------------------------------------

def flat_gbuffer(h: int, w: int):
    """A plane facing the camera at depth 1, seen by every pixel."""
    return SimpleNamespace(depth=np.ones((h, w)), normal=np.broadcast_to([0.0, 0.0, -1.0], (h, w, 3)),
                           object=np.zeros((h, w), np.int64), position=np.zeros((h, w, 3)))


def check_svgf_variance(module) -> None:
    """Grey frames of luminance noise σ = 0.5 on a still plane through SVGF's temporal step (α = 0.2): after 60
    frames the variance estimate averages 2(1 − α)/(2 − α)·σ² within 5%, and spatial (young history) estimates
    are used only in the first frames."""
    rng = np.random.default_rng(2)
    h = w = 64
    g = flat_gbuffer(h, w)
    valid = np.ones((h, w), bool)
    illum, moments, length = np.zeros((h, w, 3)), np.zeros((h, w, 2)), np.zeros((h, w))
    estimates = []
    for i in range(60):
        frame = np.repeat(1.0 + 0.5 * rng.standard_normal((h, w, 1)), 3, axis=-1)
        illum, moments, length = module.accumulate_moments(frame, illum, moments, length, valid if i else ~valid,
                                                           0.2, 0.2)
        estimates.append(module.variance_estimate(moments, length, g, 1.0, 128.0).mean())
    assert estimates[-1] == pytest.approx(0.25 * 2 * 0.8 / 1.8, rel=0.05), estimates[-5:]
    assert estimates[0] == pytest.approx(0.25, rel=0.1)  # frame 0: the 7 × 7 neighbourhood's moments


def test_svgf_variance_estimate_has_its_closed_form():
    check_svgf_variance(svgf)


def test_svgf_filters_noise_away_and_keeps_the_mean(box):
    """``pathtracer+svgf`` on a still box at 1 spp: by frame 7 its error against a 1024-spp render is under
    40% of a raw frame's (RMS over pixels) and its mean within 3% of the reference's, away from the light's
    rim (pixels whose footprint straddles the emitter's edge: at 1 spp each is the light or the ceiling, and no
    filter of their G-buffer, which sees one of the two at the pixel's centre, can tell)."""
    from cornell_harness.renderers.core.gbuffer import gbuffer

    scene = box.with_resolution(32, 32)
    reference = PathTracer(threads=2).render(scene, 1024, 0).image
    seq = svgf.PathTracerSVGF(threads=2).render_sequence(still_sequence(scene, 8), 1, 9)
    raw = PathTracer(threads=2).render(scene, 1, frame_seed(9, 7)).image
    g = gbuffer(scene)
    light = g.object == scene.object_names().index("light")
    rim = np.zeros_like(light)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            rim |= np.roll(np.roll(light, dy, 0), dx, 1)
    keep = ~rim

    def rms(image):
        return float(np.sqrt(np.mean((image - reference)[keep] ** 2)))

    out = seq.frames[-1].image
    assert rms(out) < 0.4 * rms(raw), (rms(out), rms(raw))
    assert out[keep].mean() == pytest.approx(reference[keep].mean(), rel=0.03)
    assert seq.frames[-1].info["history_fraction"] > 0.85  # all but the pixels that see nothing

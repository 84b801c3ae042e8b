"""The probes over frames (src/cornell_harness/renderers/probes.py, "Sequences"): one bounce per frame, hysteresis.

In a white furnace of albedo ρ whose walls emit L, every probe sees the same
field, so a probe update maps the probes' indirect irradiance E to
T(E) = πρL + ρE (the one-bounce gather: reflected direct light ρL, plus ρ/π
times the previous probes' E, times π); blended with hysteresis h, frame i
gives E_i = h·E_{i−1} + (1 − h)·T(E_{i−1}). Hence the closed forms: frame 0
(black probes, nothing blended) holds one bounce, πρL; the frames converge to
the infinite-bounce πρL/(1 − ρ); and after a step change of L the error left
after k frames is λ^k of the step's, λ = h + (1 − h)ρ (the hysteresis's h^k
as ρ → 0). Irradiance is blended linearly here (``gamma_blending`` off): the
closed forms are of linear blending.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.adapters.api import frame_seed
from cornell_harness.renderers import probes
from cornell_harness.renderers.core.settings import with_defaults
from cornell_harness.scenes.analytic import furnace_scene
from tests.renderers.sequences import StandIn

pytest.importorskip("embreex")

SETTINGS = {"grid": 2, "rays_per_probe": 64, "gamma_blending": False, "warm_start": False}


def furnace_frames(albedo: float, radiances: list[float]) -> StandIn:
    return StandIn([furnace_scene(albedo, L, res=8) for L in radiances])


def mean_irradiance(module, scene, hysteresis: float) -> np.ndarray:
    """The probes' mean irradiance after each frame (linear texels, borders excluded)."""
    s = with_defaults(probes.IrradianceProbes.settings, {**SETTINGS, "hysteresis": hysteresis})
    return np.array([v.irradiance[:, 1:-1, 1:-1].mean()
                     for _, _, _, v, _, _ in module.probe_frames(scene, 4, s, 2, scene.frame_count)])


def check_step_decay(module, hysteresis: float, albedo: float) -> None:
    """After the walls' emission steps from 1 to 0.25 at frame 5, the error against the new fixed point
    πρ·0.25/(1 − ρ) shrinks by λ = h + (1 − h)ρ a frame: the slope of log error over frames 6-15 within 0.01."""
    step = 5
    e = mean_irradiance(module, furnace_frames(albedo, [1.0] * step + [0.25] * 12), hysteresis)
    target = math.pi * albedo * 0.25 / (1 - albedo)
    k = np.arange(step + 1, step + 11)
    slope = np.polyfit(k, np.log(np.abs(e[k] - target)), 1)[0]
    expected = hysteresis + (1 - hysteresis) * albedo
    assert math.exp(slope) == pytest.approx(expected, abs=0.01), (math.exp(slope), expected, e)


@pytest.mark.parametrize("hysteresis, albedo", [(0.8, 0.5), (0.9, 0.2)])
def test_step_change_decays_as_the_hysteresis_with_one_bounce_a_frame(hysteresis, albedo):
    check_step_decay(probes, hysteresis, albedo)


def test_one_bounce_per_frame_reaches_the_infinite_bounce_result():
    """Frame 0 (black probes) holds one bounce, πρL; 30 frames later (λ = 0.75: 2e-4 of the gap left) the
    infinite-bounce πρL/(1 − ρ); both within 2%."""
    albedo = 0.5
    e = mean_irradiance(probes, furnace_frames(albedo, [1.0] * 31), 0.5)
    assert e[0] == pytest.approx(math.pi * albedo, rel=0.02)
    assert e[1] == pytest.approx(math.pi * albedo * (1 + 0.5 * albedo), rel=0.02)  # h·E0 + (1 − h)·T(E0)
    assert e[-1] == pytest.approx(math.pi * albedo / (1 - albedo), rel=0.02)


def test_render_sequence_gives_each_frame_its_seed_and_the_state():
    """Frames asked for come back in order, each seeded with frame_seed(seed, i) and recording its update's
    time; the state says the hysteresis and one update per frame; the images brighten as bounces accumulate."""
    scene = furnace_frames(0.5, [1.0] * 4)
    seq = probes.IrradianceProbes(threads=2).render_sequence(scene, 16, 7, {**SETTINGS, "hysteresis": 0.5},
                                                             frames=[3, 0])
    assert [r.info["frame"] for r in seq.frames] == [0, 3]
    assert [r.seed for r in seq.frames] == [frame_seed(7, 0), frame_seed(7, 3)]
    assert seq.state == {"hysteresis": 0.5, "averaging": "ema", "updates_per_frame": 1}
    assert all(r.time_s >= r.info["probes_s"] > 0 for r in seq.frames)
    assert seq.frames[1].image.mean() > seq.frames[0].image.mean()


def test_a_warm_start_begins_at_the_still_render_and_stays_there():
    """With ``warm_start`` frame 0's probes are a still render's (8 bounces, then blended iterations): in a
    furnace of albedo 0.5 already the infinite-bounce πρL/(1 − ρ) within 2%, and no frame after it climbs."""
    albedo = 0.5
    s = with_defaults(probes.IrradianceProbes.settings, {**SETTINGS, "warm_start": True, "hysteresis": 0.9})
    frames = list(probes.probe_frames(furnace_frames(albedo, [1.0] * 3), 4, s, 2, 3))
    e = np.array([v.irradiance[:, 1:-1, 1:-1].mean() for _, _, _, v, _, _ in frames])
    assert e == pytest.approx(math.pi * albedo / (1 - albedo), rel=0.02)
    assert [f[0] for f in frames] == [0, 1, 2] and frames[0][4] == 0.0 and frames[1][4] > 0.0

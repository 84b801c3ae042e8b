"""Temporal metrics: flicker against its closed-form floor and the exponential history's closed form, lag after a
change, ghosting on disoccluded pixels, and the disocclusion masks of a moving object."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.evaluate import temporal
from cornell_harness.evaluate.disocclusion import disocclusion_mask, disocclusion_masks, pixel_centre_hits
from cornell_harness.evaluate.registry import METRICS, TEMPORAL_METRICS
from cornell_harness.adapters.registry import resolve
from cornell_harness.workflows.sequence import render_sequence
from tests.sequence_fakes import SIGMA, moving_light, truth


def test_registry_defines_each_temporal_metric_once():
    assert set(TEMPORAL_METRICS) == {"flicker", "lag", "ghosting"}
    assert all(METRICS[k].better == "low" and not METRICS[k].per_image for k in TEMPORAL_METRICS)
    assert "flicker_floor" in METRICS and "frame" in METRICS


def test_flicker_of_two_independent_reference_sequences_is_the_closed_form_floor():
    rng = np.random.default_rng(0)
    v = rng.uniform(0.5, 2.0, size=(6, 32, 32, 3)) * 1e-4  # the reference's variance, per frame and pixel
    a = np.sqrt(v) * rng.standard_normal(v.shape)
    b = np.sqrt(v) * rng.standard_normal(v.shape)
    assert temporal.flicker(a, b) == pytest.approx(temporal.flicker_floor(v), rel=0.02)
    assert temporal.flicker(a[:1], b[:1]) != temporal.flicker(a[:1], b[:1])  # NaN: one frame has no change


def test_exponential_history_on_a_still_scene_flickers_as_its_closed_form():
    # History weight h, new frame weight a = 1 - h: stationary variance a/(2 - a)·σ², lag-1 correlation h, so the
    # frame-to-frame change has mean square 2·(1 - h)·a/(2 - a)·σ² = 2·a²/(2 - a)·σ².
    scene = moving_light(frames=120, stop=0, size=16)  # nothing moves
    (e,) = resolve(["tests.sequence_fakes:ExponentialTruth"])
    for h in (0.5, 0.8):
        frames = render_sequence(e.with_settings({"hysteresis": h}), scene, 1, 11).frames
        images = np.stack([f.image for f in frames[40:]])  # past the start-up
        refs = np.broadcast_to(truth(scene.at_frame(0)), images.shape)
        a = 1.0 - h
        expected = math.sqrt(2.0 * a * a / (2.0 - a)) * SIGMA
        assert temporal.flicker(images, refs) == pytest.approx(expected, rel=0.05)


def test_lag_counts_the_frames_until_the_error_is_back_in_its_steady_band():
    rng = np.random.default_rng(3)
    steady = 1.0 + 0.01 * rng.standard_normal(60)
    lo, hi, first = temporal.steady_band(steady)
    assert first == 40 and lo < 1.0 < hi
    excess = np.zeros(60)
    excess[20:] = 0.5 ** np.arange(40)  # an error that halves every frame after frame 20
    lags = temporal.lag(steady + excess, 20)
    assert 5 <= lags <= 7  # 0.5^k falls below the band's half-width (about 0.02) at k ≈ 6
    assert temporal.lag(steady, 20) == 0
    slower = np.zeros(60)
    slower[20:] = 0.8 ** np.arange(40)
    assert temporal.lag(steady + slower, 20) > lags
    assert math.isnan(temporal.lag(steady, 45))  # a change inside the steady frames has nothing to settle to


@pytest.mark.parametrize("decay, expected", [(0.7, 13), (0.75, 15)])
def test_lag_of_an_exponential_decay_is_where_the_band_predicts(decay, expected):
    """e_i = A·λ^(i−c) + σ·(−1)^i after the change c = 12, 96 frames: the steady frames (the last 32, where the
    decay is below 4e-7) have mean 0 and sd σ·sqrt(32/31), so the band's half-width is w = 2σ·sqrt(32/31). A
    frame at +σ is inside once A·λ^k ≤ w − σ, from k₊ = ceil(ln((w − σ)/A)/ln λ); one at −σ once A·λ^k ≤ w + σ.
    So the lag is k₊, or k₊ − 1 where frame c + k₊ is at +σ (then k₊ − 1 is at −σ) and A·λ^(k₊−1) ≤ w + σ."""
    a, sigma, c, frames = 1.0, 0.01, 12, 96
    i = np.arange(frames)
    e = np.where(i >= c, a * decay ** np.maximum(i - c, 0), a) + sigma * (-1.0) ** i
    w = 2.0 * sigma * math.sqrt(32 / 31)
    lo, hi, first = temporal.steady_band(e)
    assert first == 64 and (hi - lo) / 2 == pytest.approx(w, rel=1e-6)
    k_plus = math.ceil(math.log((w - sigma) / a) / math.log(decay))
    plus_at_k_plus = (c + k_plus) % 2 == 0
    predicted = k_plus - 1 if plus_at_k_plus and a * decay ** (k_plus - 1) <= w + sigma else k_plus
    assert temporal.lag(e, c) == predicted == expected  # both branches: 13 = k₊ (λ 0.7), 15 = k₊ − 1 (λ 0.75)
    assert not temporal.steady_trend(e)[1]


def test_a_tail_still_falling_has_not_settled():
    """A decay of 0.98 a frame (a long history) still falls by 0.16 across frames 64-95 of 96, more than the band's
    half-width (0.10: 2 sd of a tail whose spread is mostly that fall; σ = 0.01): the band is no steady state, and
    the lag is inf, not the frame at which the error enters a band drawn on a moving tail."""
    c, frames = 12, 96
    i = np.arange(frames)
    e = 1.0 + np.where(i >= c, 0.98 ** np.maximum(i - c, 0), 1.0)
    e += 0.01 * np.random.default_rng(5).standard_normal(frames)
    drift, trending = temporal.steady_trend(e, c)
    lo, hi, _ = temporal.steady_band(e)
    assert trending and drift == pytest.approx(0.98 ** 83 - 0.98 ** 52, rel=0.1) and -drift > (hi - lo) / 2
    assert temporal.lag(e, c) == math.inf
    assert temporal.lag_bound(frames, c) == 83
    # the same decay over a rest long enough for it (0.98^400 ≈ 3e-4 at the steady frames) settles
    long = 1.0 + 0.98 ** np.arange(1200) + 0.01 * np.random.default_rng(5).standard_normal(1200)
    assert math.isfinite(temporal.lag(long, 0))


def test_a_stateless_series_has_lag_0_up_to_its_false_alarm_rate():
    """Independent Gaussian frames (96, change 12): a frame is inside a band estimated from 32 frames with
    probability about 0.943, the first three with 0.84 (20,000 series: 0.840), so lag 0 in 168 of 200 fixed seeds
    on average (sd 5); a lag above 0 is short (mean 0.4 frames, above 5 in 0.8%); inf (the tail trending by
    chance) in none of 10,000 series."""
    lags = np.array([temporal.lag(1.0 + 0.01 * np.random.default_rng(seed).standard_normal(96), 12)
                     for seed in range(200)])
    assert 150 <= int(np.sum(lags == 0)) <= 186
    assert not np.any(np.isinf(lags)) and np.max(lags) <= 10


def test_a_historys_correlated_noise_is_rarely_taken_for_a_trend():
    """AR(1) noise of lag-1 correlation 0.8, as temporal accumulation's per-frame error has here: its tail wanders,
    and a t over single frames calls 12% of tails trending; over batch means it is 1.4% (10,000 series of 144
    frames), so about 3 of 200 fixed seeds (more than 8: below 0.5%)."""
    def series(seed):
        z = np.random.default_rng(seed).standard_normal(344)
        e = np.zeros(344)
        for k in range(1, 344):
            e[k] = 0.8 * e[k - 1] + z[k]
        e = 1.0 + 0.01 * e[200:]
        e[:13] += 1.0  # the change at 12 put the error above its steady state
        return e
    trending = sum(temporal.steady_trend(series(seed), 12)[1] for seed in range(200))
    assert trending <= 8


def test_a_tail_moving_away_from_where_the_change_put_it_is_no_return():
    """The error falls back after the change and then rises by 0.1 across the steady frames, five times their noise:
    a trend, but away from where the change put the error (above), so not a return the lag waits for; without a
    change to say the direction it counts."""
    i = np.arange(144)
    e = 1.0 + np.where(i <= 12, 2.0, 0.0) + np.where(i >= 96, 0.1 * (i - 96) / 47, 0.0)
    e += 0.005 * np.random.default_rng(2).standard_normal(144)
    assert temporal.steady_trend(e)[1] and not temporal.steady_trend(e, 12)[1]
    assert temporal.lag(e, 12) < 96 - 12
    falling = 1.0 + np.where(i <= 12, 2.0, 0.0) - np.where(i >= 96, 0.1 * (i - 96) / 47, 0.0)
    falling += 0.005 * np.random.default_rng(2).standard_normal(144)
    assert temporal.steady_trend(falling, 12)[1] and temporal.lag(falling, 12) == math.inf


def test_the_mean_lag_over_seeds_is_inf_when_one_seed_did_not_settle():
    assert temporal.lag_over_seeds([4.0, 6.0, math.nan])[0] == 5.0  # NaN: no change to follow, left out
    mean, half = temporal.lag_over_seeds([4.0, math.inf, 6.0])
    assert mean == math.inf and math.isnan(half)
    assert all(math.isnan(v) for v in temporal.lag_over_seeds([math.nan]))


def test_change_frames_are_where_motion_ends_or_a_switch_happens():
    x = np.array([0, 1, 2, 3, 4, 4, 4, 4, 4, 4, 4, 4], dtype=float)
    on = np.array([1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0], dtype=float)
    assert temporal.settle_frames(np.stack([x, on], axis=1)) == [4, 8]
    assert temporal.settle_frames(np.zeros((5, 2))) == []


def test_ghosting_is_the_rmse_over_the_uncovered_pixels_only():
    refs = np.zeros((3, 4, 4, 3))
    images = refs + 0.1
    masks = np.zeros((3, 4, 4), dtype=bool)
    assert math.isnan(temporal.ghosting(images, refs, masks))
    masks[1, 0, 0] = masks[2, 3, 3] = True
    images[1, 0, 0] = 2.0
    assert temporal.ghosting(images, refs, masks) == pytest.approx(math.sqrt((4.0 * 3 + 0.01 * 3) / 6))


def test_disocclusion_of_a_moving_box_is_where_it_was():
    scene = moving_light(frames=4, stop=2, size=32, step=(0, 0, 0), others=(("small-box", (0.15, 0, 0), 2),))
    names = scene.object_names()
    before, after = scene.at_frame(0), scene.at_frame(1)
    mask = disocclusion_mask(before, after)
    prev_obj, _ = pixel_centre_hits(before)
    now_obj, _ = pixel_centre_hits(after)
    box = names.index("small-box")
    assert mask.sum() >= 5
    # uncovered: pixels the box hid before and no longer does (or its own sides turning into view)
    assert np.all((prev_obj[mask] == box) | (now_obj[mask] == box))
    assert np.any((prev_obj == box) & (now_obj != box) & mask)
    assert not disocclusion_mask(before, before).any()
    masks = disocclusion_masks([scene.at_frame(i) for i in range(4)])
    assert masks.shape == (4, 32, 32) and not masks[0].any() and masks[2].any()
    assert not masks[3].any()  # the box rests from frame 2 on

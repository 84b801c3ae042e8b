"""The missing-light figures (bias, missing share, their standard errors over seeds) and the study's regions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.evaluate import missing_light as ml
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.library import resolve_scene


def test_missing_light_of_identical_seeds_has_only_the_references_error():
    m = ml.missing_light([-0.25, -0.25, -0.25], ref_mean=2.0, ref_rel_se=0.01)
    assert (m.bias, m.share, m.seeds) == (pytest.approx(-0.5), pytest.approx(0.25), 3)
    assert m.bias_se == pytest.approx(2.0 * 0.01)
    assert m.share_se == pytest.approx(0.75 * 0.01)  # (1 + mean r) · ρ: the reference's error scaled


def test_missing_light_adds_the_seed_spread():
    r = [-0.1, -0.3]  # mean −0.2, sample variance 0.02, over n = 2: 0.01
    m = ml.missing_light(r, ref_mean=1.0, ref_rel_se=0.0)
    assert m.share == pytest.approx(0.2) and m.share_se == pytest.approx(0.1)
    assert m.bias == pytest.approx(-0.2) and m.bias_se == pytest.approx(0.1)


def test_missing_light_drops_failed_seeds_and_is_nan_without_any():
    assert ml.missing_light([0.1, None, math.nan], 1.0, 0.0).seeds == 1
    none = ml.missing_light([None], 1.0, 0.0)
    assert none.seeds == 0 and math.isnan(none.share) and math.isnan(none.bias_se)


def test_region_table_groups_seeds_per_renderer():
    rows = [{"renderer": "a", "status": "ok", "spp": 4, "time_s": t, "region.floor.mean_radiance_rel_error": r,
             "region.floor.delta_e2000_mean": de} for t, r, de in ((1.0, -0.5, 2.0), (3.0, -0.5, 4.0))]
    rows.append({"renderer": "b", "status": "failed", "spp": 4, "time_s": 1.0})
    (row,) = ml.region_table(rows, ["floor"], {"floor": {"mean": 0.2, "mean_rel_se": 0.0}})
    assert row["renderer"] == "a" and row["region"] == "floor" and row["seeds"] == 2
    assert row["share"] == pytest.approx(0.5) and row["bias"] == pytest.approx(-0.1)
    assert row["delta_e"] == pytest.approx(3.0) and row["time_s"] == pytest.approx(2.0)


def test_emitter_samples_cover_the_light_evenly():
    sc = resolve_scene("cornell-box")
    points, w = ml.emitter_samples(sc, n=4)
    (light,) = sc.emitters
    assert len(points) == 2 * 16 and w.sum() == pytest.approx(1.0)
    assert np.allclose(points[:, 1], light.vertices[:, 1].mean())  # on the light's plane
    # Equal-area pieces of a quad: the weighted centroid is the quad's centroid.
    assert np.allclose(w @ points, light.vertices.mean(axis=0), atol=1e-12)


def test_light_visibility_is_one_in_the_open_zero_under_a_box_and_between_at_a_shadow_edge():
    sc = resolve_scene("cornell-box")
    vis = ml.light_visibility(sc, np.array([[-0.9, -1.0, 0.9], [0.335, -1.0, 0.38]]))
    assert vis[0] == pytest.approx(1.0) and vis[1] == 0.0
    pen = ml.penumbra_mask(sc)
    floor = region_masks(sc)["floor"]
    assert 500 < pen.sum() < floor.sum()
    # The penumbra is the floor (its pixel centres): almost all of it inside the floor's all-rays mask.
    assert (pen & ~floor).sum() < 0.2 * pen.sum()


def test_study_masks_add_regions_without_changing_the_scene():
    caustics = resolve_scene("cornell-box-caustics")
    extended = ml.with_study_regions(caustics)
    assert extended.content_hash() == caustics.content_hash()
    assert list(extended.regions)[-2:] == ["floor", "back-edge"] and "floor" not in caustics.regions
    masks = ml.study_masks(caustics)
    assert "penumbra" not in masks and masks["back-edge"].sum() > 50
    assert not (masks["caustic"] & ~masks["floor"]).any()  # the caustic lies on the floor
    assert "penumbra" in ml.study_masks(resolve_scene("cornell-box"))


def test_study_columns_score_only_the_regions_the_scene_lacks():
    from cornell_harness.store.references import load_reference

    sc = resolve_scene("cornell-box-caustics")
    ref = load_reference(sc)
    cols = ml.study_columns(sc, ref.image * 0.5, ref, spp=4)
    assert {k.split(".")[1] for k in cols} == {"floor", "back-edge"}
    assert cols["region.floor.mean_radiance_rel_error"] == pytest.approx(-0.5)

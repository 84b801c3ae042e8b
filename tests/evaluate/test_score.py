"""The one scorer (cornell_harness.evaluate.score): one image gets the same numbers from every command that scores.

Three paths: a run (``cbox compare``, ``converge`` and the gate's runs: ``runner.run_one``), ``cbox compare-image``
(the workflow, on the render written as an EXR file) and the gate's own scoring of checkpoints and bias-limit
renders (``metric_value``, one metric at a time). Equal, not close: the same functions on the same arrays.
"""

from __future__ import annotations

import numpy as np
import pytest

from cornell_harness.adapters.api import RenderResult
from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate import regions as named_regions
from cornell_harness.evaluate.score import metric_value, score_image
from cornell_harness.evaluate.thresholds import parse_threshold
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.exr import write_exr
from cornell_harness.store.image_files import SPP_ATTRIBUTE
from cornell_harness.store.references import load_reference
from tests.user_renderers import FlatGrey

SPP = 16


class NoisyReference(FlatGrey):
    """The stored reference with seeded noise and one NaN, one +Inf and one negative pixel; no variance of its
    own, so a region's ``mean_z`` takes the noise model's on every path."""

    name = "noisy-reference"

    def render(self, scene, spp, seed, checkpoints=()):
        ref = load_reference(scene).image.astype(np.float64)
        noise = np.random.default_rng(seed).standard_normal(ref.shape) * 0.2 * ref / np.sqrt(spp)
        img = (ref + noise).astype(np.float32)
        img[3, 5, 0], img[10, 7, 2], img[20, 9, 1] = np.nan, np.inf, -0.1
        return RenderResult(img, 0.01, spp, seed)


@pytest.fixture(scope="module")
def scored(tmp_path_factory):
    """The image as a run scored it: its row's metrics, yardsticks and region columns."""
    from cornell_harness.workflows import runner

    scene = resolve_scene("cornell-box")
    reference = load_reference(scene)
    (entry,) = resolve([f"{__name__}:NoisyReference"])
    rec = runner.run_one(entry, scene, SPP, 7, reference)
    assert rec.status == "ok", rec.reason
    run = {**rec.metrics, **named_regions.region_columns(rec.regions)}
    exr = tmp_path_factory.mktemp("one-scorer") / "noisy.exr"
    write_exr(exr, rec.image, {SPP_ATTRIBUTE: str(SPP)})
    return {"scene": scene, "reference": reference, "image": rec.image, "run": run, "exr": exr}


def test_one_image_three_paths_equal_metrics(scored):
    from cornell_harness.workflows import compare_image as ci

    run = scored["run"]
    assert {"flip_mean", "noise_delta_e2000_mean", "nan_count", "region.walls.mean_z"} <= set(run)
    assert run["nan_count"] == 1 and run["inf_count"] == 1 and run["negative_count"] == 1
    (checked,) = ci.compare_images([scored["exr"]], scored["scene"], with_flip=True).images
    file = checked.score.row()
    masks = named_regions.region_masks(scored["scene"])
    gate = {k: metric_value(scored["image"], scored["reference"], SPP, k, masks) for k in run}
    np.testing.assert_equal(file, run)
    np.testing.assert_equal(gate, run)


def test_a_check_scores_its_subset_with_the_same_values(scored):
    """compare-image as a check scores what its thresholds name and the cheap metrics: each value the run's."""
    from cornell_harness.workflows import compare_image as ci

    checks = ci.Checks([parse_threshold("ssim=0.1", "warn"), parse_threshold("region.floor.rmse=1", "fail")])
    (checked,) = ci.compare_images([scored["exr"]], scored["scene"], checks=checks).images
    row = checked.score.row()
    assert "ssim" in row and "rmse" in row and "delta_e2000_mean" not in row and "flip_mean" not in row
    assert "region.walls.delta_e2000_mean" in row  # a region threshold scores every region, as the table shows
    assert row == {k: scored["run"][k] for k in row}
    assert checked.verdict["status"] == "pass" and checked.broken == []


def test_keys_compute_only_what_they_name(scored):
    s = score_image(scored["image"], scored["reference"], SPP, keys=("rmse", "region.floor.rel_mse"),
                    masks=named_regions.region_masks(scored["scene"]))
    assert set(s.metrics) == {"rmse", "mse"} and s.noise is None and s.delta_e_map is None
    assert s.regions == {"floor": {"pixels": scored["run"]["region.floor.pixels"],
                                   "rel_mse": scored["run"]["region.floor.rel_mse"]}}


def test_no_spp_or_variance_no_yardsticks_and_why(scored):
    ref = scored["reference"]
    assert score_image(scored["image"], ref, None).noise_note == "no spp"
    bare = type(ref)(ref.image, None, None, {}, ref.folder, ref.quantity)
    s = score_image(scored["image"], bare, SPP)
    assert s.noise is None and s.noise_note == "no reference variance"
    assert s.metrics == {k: v for k, v in scored["run"].items() if k in s.metrics}


def test_a_region_without_a_mask_is_refused(scored):
    with pytest.raises(KeyError, match="no mask for region 'nowhere'"):
        metric_value(scored["image"], scored["reference"], SPP, "region.nowhere.rmse", {})

"""cornell_harness.reports.compare_image's error-map file: a palette PNG whose decoded pixels are the viewer's colours."""

from __future__ import annotations

import numpy as np
from PIL import Image

from cornell_harness.evaluate.image_scores import ImageScore, InputImage, Target
from cornell_harness.store.references import Reference
from cornell_harness.reports.compare_image import colormap_indices, delta_e_png, write_error_map
from cornell_harness.reports.images import DELTA_E_RANGE, MAP_COLORMAPS, apply_colormap


def test_indices_follow_apply_colormap():
    values = np.array([[-1.0, 0.0, 0.02, 5.0], [9.99, 10.0, 1e9, np.nan]])
    idx = colormap_indices(values, *DELTA_E_RANGE)
    assert idx.tolist() == [[0, 0, 1, 128], [255, 255, 255, 255]]
    rgb = apply_colormap(values, *DELTA_E_RANGE, cmap=MAP_COLORMAPS["de"])
    np.testing.assert_array_equal(np.asarray(Image.fromarray(rgb)), rgb)


def test_error_map_file_decodes_to_the_viewer_colours(tmp_path):
    rng = np.random.default_rng(2)
    ref = rng.lognormal(-1.0, 1.0, (32, 48, 3))
    img = ref * rng.lognormal(0.0, 0.6, ref.shape)
    img[3, 4, 1] = np.nan
    target = Target(Reference(ref, None, None, {}, tmp_path, "radiance"), tmp_path / "ref.exr")
    score = ImageScore(InputImage(tmp_path / "a.exr", "a", img, None), {}, None, None, {}, None, None)
    path = write_error_map(tmp_path, score, target)
    decoded = Image.open(path)
    assert decoded.mode == "P" and decoded.size == (48, 32)
    np.testing.assert_array_equal(np.asarray(decoded.convert("RGB")), delta_e_png(img, ref))

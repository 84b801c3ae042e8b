"""Reference store: mean and variance from batches, provenance, refusal of stale references."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.conftest import CORNELL, MINIMAL_SCENE
from cornell_harness.adapters.registry import resolve
from cornell_harness.store.references import REFERENCE_SEED_BASE, ReferenceError, load_reference
from cornell_harness.workflows.reference_build import build_reference
from cornell_harness.scenes.loader import load_scene
from tests.user_renderers import SeededNoise


def _entry():
    (entry,) = resolve(["tests.user_renderers:SeededNoise"])
    return entry


def test_build_stores_mean_variance_and_provenance(write_scene, tmp_path):
    scene = load_scene(write_scene())
    r = SeededNoise()
    ref = build_reference(scene, spp=8, batches=4, entry=_entry())
    np.testing.assert_array_equal(ref.noise, r.render(scene, 2, REFERENCE_SEED_BASE + 4).image)
    batches = np.stack([r.render(scene, 2, REFERENCE_SEED_BASE + b).image.astype(np.float64) for b in range(4)])
    np.testing.assert_allclose(ref.image, batches.mean(0), rtol=1e-6)
    np.testing.assert_allclose(ref.variance, batches.var(0, ddof=1) / 4, rtol=1e-5)
    loaded = load_reference(scene)
    np.testing.assert_array_equal(loaded.image, ref.image)
    np.testing.assert_array_equal(loaded.variance, ref.variance)
    prov = json.loads((tmp_path / "provenance.json").read_text())
    for key in ("renderer", "renderer_version", "variant", "spp", "seeds", "wall_time_s", "scene_hash", "date"):
        assert key in prov, key
    assert prov["spp"] == 8 and prov["seeds"] == [REFERENCE_SEED_BASE + b for b in range(4)]
    assert prov["scene_hash"] == scene.content_hash()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["noise.exr", "provenance.json", "reference.exr", "scene.toml",
                                                   "variance.exr"]


def test_changed_scene_is_refused_with_rebuild_command(write_scene, tmp_path):
    scene = load_scene(write_scene())
    build_reference(scene, spp=4, batches=2, entry=_entry())
    changed = load_scene(write_scene(MINIMAL_SCENE.replace("0.8, 0.8, 0.8", "0.7, 0.8, 0.8")))
    with pytest.raises(ReferenceError) as exc:
        load_reference(changed)
    msg = str(exc.value)
    assert "scene hash" in msg and f"cbox reference build --scene {tmp_path} --spp 4" in msg


def test_missing_reference_says_how_to_build(write_scene):
    with pytest.raises(ReferenceError, match="cbox reference build"):
        load_reference(load_scene(write_scene()))


def test_bad_batches():
    scene = load_scene(CORNELL)
    with pytest.raises(ValueError, match="multiple"):
        build_reference(scene, spp=10, batches=4, entry=_entry(), folder="/nonexistent")


def test_stored_cornell_reference_is_current_and_converged():
    """The committed reference matches the committed scene and is well converged."""
    ref = load_reference(load_scene(CORNELL))
    assert ref.spp >= 16384 and ref.image.shape == (256, 256, 3)
    assert np.all(np.isfinite(ref.image)) and ref.image.min() >= 0
    assert np.all(ref.variance >= 0)
    # Relative standard error of the whole-image mean: tiny at 16k spp.
    sem = np.sqrt(ref.variance.sum()) / ref.variance.size
    assert sem / ref.image.mean() < 1e-3

"""Per-frame references of an animated scene: built, stored in frames/NNNN/, loaded by ``scene.at_frame(i)``."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.conftest import MINIMAL_SCENE, cbox_in_process, run_cbox
from tests.scenes.test_animation import ANIMATED, RESTING
from tests.user_renderers import SeededNoise
from cornell_harness.adapters.registry import resolve
from cornell_harness.adapters.seeds import frame_seed
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.loader import load_scene
from cornell_harness.store.references import REFERENCE_SEED_BASE, ReferenceError, load_reference
from cornell_harness.workflows.reference_build import build_reference
from cornell_harness.workflows.sequence_run import sequence_references
from cornell_harness.cli.reference import frame_scenes


def _entry():
    (entry,) = resolve(["tests.user_renderers:SeededNoise"])
    return entry


def test_each_frame_has_its_own_reference_with_its_own_seeds(write_scene, tmp_path):
    scene = load_scene(write_scene(ANIMATED))
    refs = {i: build_reference(scene.at_frame(i), spp=8, batches=4, entry=_entry()) for i in (0, 4)}
    for i, ref in refs.items():
        assert ref.folder == tmp_path / "frames" / f"{i:04d}"
        seeds = [frame_seed(REFERENCE_SEED_BASE + b, i) for b in range(4)]
        assert ref.provenance["seeds"] == seeds and ref.provenance["frame"] == i
        assert ref.provenance["noise_seed"] == frame_seed(REFERENCE_SEED_BASE + 4, i)
        assert ref.provenance["scene_hash"] == scene.at_frame(i).content_hash()
        batches = np.stack([SeededNoise().render(scene, 2, s).image.astype(np.float64) for s in seeds])
        loaded = load_reference(scene.at_frame(i))
        assert loaded.folder == ref.folder and loaded.provenance["frame"] == i
        # A frame's images are half floats: the mean to within half's rounding, exactly what the build returned.
        np.testing.assert_allclose(loaded.image, batches.mean(0), rtol=2**-11, atol=2**-24)
        np.testing.assert_array_equal(loaded.image, ref.image)
        np.testing.assert_array_equal(loaded.noise, ref.noise)
        np.testing.assert_allclose(loaded.variance, batches.var(0, ddof=1) / 4, rtol=1e-5)  # float32
        assert ref.provenance["pixel_types"] == {"reference.exr": "half", "variance.exr": "float",
                                                 "noise.exr": "half"}
    assert not np.array_equal(refs[0].image, refs[4].image)  # independent seeds
    with pytest.raises(ReferenceError) as exc:
        load_reference(scene.at_frame(2))
    assert "frame 2" in str(exc.value) and "--frames 2" in str(exc.value)
    with pytest.raises(ReferenceError, match="animation: minimal is animated .9 frames. and has one reference per"):
        load_reference(scene)


def test_a_frames_reference_is_refused_for_another_frame(write_scene, tmp_path):
    """Frames 5 and 6 have the same light and camera, not the same hash: a reference copied over is refused."""
    scene = load_scene(write_scene(ANIMATED))
    build_reference(scene.at_frame(6), spp=4, batches=2, entry=_entry())
    (tmp_path / "frames" / "0006").rename(tmp_path / "frames" / "0007")
    with pytest.raises(ReferenceError, match="scene hash"):
        load_reference(scene.at_frame(7))


def test_a_still_scenes_reference_stays_float_and_where_it_was(write_scene, tmp_path):
    scene = load_scene(write_scene(MINIMAL_SCENE))
    ref = build_reference(scene, spp=4, batches=2, entry=_entry())
    assert ref.folder == tmp_path and "frame" not in ref.provenance
    assert ref.provenance["seeds"] == [REFERENCE_SEED_BASE, REFERENCE_SEED_BASE + 1]
    assert set(ref.provenance["pixel_types"].values()) == {"float"}


def test_cbox_reference_build_and_show_frames(write_scene, tmp_path):
    """Mitsuba, tiny: --frames builds those frames only, show prints them by frame."""
    path = write_scene(ANIMATED)
    proc = run_cbox("reference", "build", "--scene", str(tmp_path), "--frames", "3,5-6", "--spp", "4", "--batches", "2")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == ["0003", "0005", "0006"]
    scene = load_scene(path)
    off, on = load_reference(scene.at_frame(3)), load_reference(scene.at_frame(5))
    assert np.all(off.image == 0) and off.image.shape == (6, 8, 3)  # the light is off in frame 3: nothing lit
    assert on.image.max() > 0
    shown = run_cbox("reference", "show", "--scene", str(tmp_path), "--frames", "5-6")
    assert shown.returncode == 0, shown.stderr
    prov = json.loads(shown.stdout)
    assert list(prov) == ["5", "6"] and prov["6"]["frame"] == 6 and prov["6"]["wall_time_s"] > 0
    verified = run_cbox("reference", "verify", "--scene", str(tmp_path), "--frames", "5-6", "--engine", "mitsuba",
                        "--spp", "4", "--batches", "2")
    assert verified.returncode in (0, 3), verified.stderr + verified.stdout  # tiny: agree, or not resolved
    assert "minimal frame 5: reference" in verified.stdout and "minimal frame 6: reference" in verified.stdout
    for i in (5, 6):  # each frame's verdict on its own reference
        assert "mitsuba" in json.loads((tmp_path / "frames" / f"{i:04d}" / "verdicts.json").read_text())
    assert not (tmp_path / "frames" / "0003" / "verdicts.json").exists()
    missing = run_cbox("reference", "show", "--scene", str(tmp_path))
    assert missing.returncode == 2 and "frame 0" in missing.stderr and "--frames 0" in missing.stderr


@pytest.mark.parametrize("scene, frames, words", [
    ("cornell-box", "0", "--frames: scene 'cornell-box' is not animated"),
    ("cornell-box-orbit", "24", "--frames: '24': frames are 0..23"),
    ("cornell-box-orbit", "2-x", "is not a frame or a range"),
])
def test_bad_frames_are_a_usage_error(capsys, scene, frames, words):
    for command in ("build", "verify", "show"):
        code, out, err = cbox_in_process(capsys, "reference", command, "--scene", scene, "--frames", frames)
        assert code == 2 and words in err, (command, err)


@pytest.mark.parametrize("name, shared", [("cornell-box-moving-light", 12), ("cornell-box-orbit", None)])
def test_the_stored_animated_scenes_have_every_frames_reference(name, shared):
    """Every frame reads a valid stored reference: its own, or (the moving light at rest, from frame 12 on) the
    one of the earliest frame at its state; the package stores exactly the distinct ones."""
    scene = resolve_scene(name)
    distinct = scene.animation.reference_frames()
    assert distinct == list(range(13 if shared else scene.frame_count))
    folders = scene.path.parent / "frames"
    assert sorted(p.name for p in folders.iterdir()) == [f"{j:04d}" for j in distinct]
    refs = [load_reference(scene.at_frame(i)) for i in range(scene.frame_count)]
    for i, ref in enumerate(refs):
        j = i if shared is None else min(i, shared)
        assert ref.provenance["frame"] == j and ref.provenance["renderer"] == "mitsuba"
        assert ref.folder == folders / f"{j:04d}"  # the package's stored reference
        assert ref.provenance["scene_hash"] == scene.at_frame(j).content_hash()
        assert ref.image.shape == (128, 128, 3) and ref.provenance["wall_time_s"] > 0
        assert np.all(np.isfinite(ref.image)) and np.all(ref.variance >= 0)
    assert len({ref.provenance["noise_seed"] for ref in refs}) == len(distinct)


def test_a_frame_at_rest_reads_the_reference_of_the_first_frame_at_rest():
    scene = resolve_scene("cornell-box-moving-light")
    ref = load_reference(scene.at_frame(40))
    assert ref.folder == scene.path.parent / "frames" / "0012" and ref.provenance["frame"] == 12
    frames = sequence_references(scene, [11, 12, 40, scene.frame_count - 1])
    assert [r.provenance["frame"] for r in frames] == [11, 12, 12, 12] and frames[1] is frames[3]  # loaded once


def test_a_shared_reference_is_built_once_under_the_earliest_frame(write_scene, tmp_path, capsys):
    """RESTING: frames 2-4 and 7-9 read frames/0002, built from frame 2's still scene whichever frame asks."""
    scene = load_scene(write_scene(RESTING.replace("MOVED", "")))
    ref = build_reference(scene.at_frame(8), spp=4, batches=2, entry=_entry())
    assert ref.folder == tmp_path / "frames" / "0002" and ref.provenance["frame"] == 2
    assert ref.provenance["scene_hash"] == scene.at_frame(2).content_hash() != scene.at_frame(8).content_hash()
    assert ref.provenance["seeds"] == [frame_seed(REFERENCE_SEED_BASE + b, 2) for b in range(2)]
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == ["0002"]
    for i in (2, 3, 4, 7, 8, 9):
        assert load_reference(scene.at_frame(i)).folder == ref.folder
    with pytest.raises(ReferenceError) as exc:
        load_reference(scene.at_frame(6))  # off: frame 5's, not built
    assert "frame 6 (which shares frame 5's reference)" in str(exc.value) and "--frames 5 " in str(exc.value)
    assert [f.frame for f in frame_scenes(scene, "3-6,9")] == [2, 5]  # each reference once, by its frame
    assert [f.frame for f in frame_scenes(scene, None)] == [0, 1, 2, 5]
    code, out, err = cbox_in_process(capsys, "reference", "show", "--scene", str(tmp_path), "--frames", "3,8-9")
    assert code == 0, err
    assert list(json.loads(out)) == ["2"]


def test_a_missing_frame_is_built_as_the_others_were(write_scene, tmp_path):
    """The command for a missing frame keeps the spp and batches of a frame built beside it, timed from it."""
    scene = load_scene(write_scene(ANIMATED))
    build_reference(scene.at_frame(1), spp=8, batches=4, entry=_entry())
    with pytest.raises(ReferenceError) as exc:
        load_reference(scene.at_frame(2))
    assert f"cbox reference build --scene {tmp_path} --frames 2 --spp 8 --batches 4 (about" in str(exc.value)
    assert "the reference of minimal frame 1 took" in str(exc.value)

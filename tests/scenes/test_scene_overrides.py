"""``--set KEY=VALUE``: derived scenes, their validation, hash, name, reference and the commands that take them."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from tests.conftest import CORNELL, MINIMAL_SCENE, ROOT, run_cbox
from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.model import SceneError
from cornell_harness.scenes.overrides import format_value, load_derived_scene, parse_value
from cornell_harness.store.exr import read_exr
from cornell_harness.store.image_files import read_image_file
from cornell_harness.store.references import (DERIVED_FOLDER, PROVENANCE_FILE, ReferenceError, build_seconds,
                                      load_reference, reference_folder)
from cornell_harness.workflows.reference_build import build_reference


@pytest.mark.parametrize("text, value", [
    ("3", 3), ("-1", -1), ("0.5", 0.5), ('"x"', "x"), ("box", "box"), ("true", True),
    ("[64,64]", [64, 64]), ("[64, 64]", [64, 64]), ("64,64", [64, 64]), ("0.5, 0.5,1", [0.5, 0.5, 1]),
    ('"a,b"', "a,b"), ("3\nx = 4", "3\nx = 4"),  # two TOML keys are not a value: left to the loader as text
])
def test_values_parse_as_toml_or_comma_lists(text, value):
    parsed = parse_value(text)
    assert parsed == value and type(parsed) is type(value)
    assert parse_value(format_value(parsed)) == parsed  # the canonical form in names and commands reads back


# (assignments, texts the one-line error must contain)
BAD = [
    (["render.max_depth=-5"], ["--set render.max_depth=-5: render.max_depth: out of range: must be -1 (unbounded) or in [1, 2147483647], got -5"]),
    (["render.max_depth=abc"], ["--set render.max_depth=abc: render.max_depth: expected an integer, got str"]),
    (["render.max_depth=2.5"], ["render.max_depth: expected an integer, got float"]),
    (["camera.resolution=64"], ["--set camera.resolution=64: camera.resolution: expected a list, got int"]),
    (["camera.resolution=0,8"], ["camera.resolution[0]: out of range: must be >= 1, got 0"]),
    (["materials.white.reflectance=0.5,0.5,2"], ["materials.white.reflectance[2]: out of range: must be in [0, 1], got 2"]),
    (["render.max_dept=3"], ["--set: render.max_dept: not a key", "did you mean 'render.max_depth'?",
                             "valid keys: camera.type", "camera.resolution", "materials.white.reflectance"]),
    (["meshes.floor.material=white"], ["not a key", "valid keys:"]),
    (["render.max_depth"], ["--set: 'render.max_depth': expected KEY=VALUE"]),
    (["render.max_depth="], ["expected KEY=VALUE"]),
    (["render.max_depth=3", "render.max_depth=4"], ["render.max_depth: given twice"]),
    # Not one key's fault: every --set is named.
    (["camera.position=0,0,0", "render.max_depth=3"], ["--set camera.position=0,0,0 --set render.max_depth=3: "
                                                       "camera.look_at: equals camera.position"]),
]


@pytest.mark.parametrize("assignments, texts", BAD)
def test_bad_override_is_one_line_naming_the_set(write_scene, assignments, texts):
    with pytest.raises(SceneError) as exc:
        load_derived_scene(write_scene(), assignments)
    msg = str(exc.value)
    assert "\n" not in msg
    for text in texts:
        assert text in msg


def test_the_file_own_error_names_the_file_not_the_set(write_scene):
    path = write_scene(MINIMAL_SCENE.replace("max_depth = -1", "max_depth = 0"))
    with pytest.raises(SceneError) as exc:
        load_derived_scene(path, ["camera.resolution=4,4"])
    assert str(exc.value).startswith(f"{path}: render.max_depth: ")


def test_derived_scene_is_the_edited_file_with_a_stable_hash_and_name(write_scene):
    base = load_scene(write_scene())
    derived = load_derived_scene(base.path, ["render.max_depth=3", "camera.resolution=16,12"])
    assert (derived.camera.width, derived.camera.height, derived.max_depth) == (16, 12, 3)
    assert derived.content_hash() != base.content_hash()
    # The same as editing a copy of the file; any order or spelling of the same overrides gives the same scene.
    edited = load_scene(write_scene(MINIMAL_SCENE.replace("max_depth = -1", "max_depth = 3")
                                    .replace("resolution = [8, 6]", "resolution = [16, 12]"), "edited.toml"))
    again = load_derived_scene(base.path, ["camera.resolution=[16, 12]", "render.max_depth=3"])
    assert derived.content_hash() == edited.content_hash() == again.content_hash()
    assert derived.name == again.name == "minimal[camera.resolution=[16,12],render.max_depth=3]"
    assert derived.overrides == ("camera.resolution=[16,12]", "render.max_depth=3")
    assert derived.path == base.path


def test_override_that_changes_nothing_is_the_scene_itself(write_scene):
    base = load_scene(write_scene())
    same = load_derived_scene(base.path, ["render.max_depth=-1"])
    assert (same.name, same.overrides, same.content_hash()) == ("minimal", (), base.content_hash())
    assert reference_folder(same) == base.path.parent


def _entry():
    (entry,) = resolve(["tests.user_renderers:SeededNoise"])
    return entry


def test_derived_reference_is_stored_apart_and_the_base_is_untouched(write_scene, tmp_path):
    base = load_scene(write_scene())
    build_reference(base, spp=4, batches=2, entry=_entry())
    base_files = {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()}
    derived = load_derived_scene(base.path, ["render.max_depth=3", "camera.resolution=16,12"])
    with pytest.raises(ReferenceError) as exc:
        load_reference(derived)
    msg = str(exc.value)
    assert f"--scene {tmp_path} --set 'camera.resolution=[16,12]' --set render.max_depth=3 --spp 4 --batches 2" in msg
    # About how long, from the base's build time, scaled to 4x the pixels; max_depth changed: only an estimate.
    wall = json.loads((tmp_path / PROVENANCE_FILE).read_text())["wall_time_s"]
    assert f"the reference of minimal took {wall:.0f} s at 8x6, 4 spp" in msg and "scaled to 16x12" in msg
    assert "max_depth 3 instead of -1" in msg and "only an estimate" in msg

    built = build_reference(derived, spp=4, batches=2, entry=_entry())
    assert built.folder == tmp_path / DERIVED_FOLDER / derived.content_hash().removeprefix("sha256:")[:16]
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir() if p.is_file()} == base_files
    loaded = load_reference(derived)
    assert loaded.image.shape == (12, 16, 3) and loaded.provenance["overrides"] == list(derived.overrides)
    assert loaded.provenance["scene"] == derived.name
    assert load_reference(base).image.shape == (6, 8, 3)


def test_build_seconds_scales_by_pixels_and_spp():
    prov = {"wall_time_s": 500.0, "resolution": [256, 256], "spp": 16384}
    assert build_seconds(prov, 64, 64, 16384) == pytest.approx(500 / 16)
    assert build_seconds(prov, 256, 128, 32768) == pytest.approx(500)
    assert build_seconds({"spp": 16384}, 64, 64, 16384) is None


def test_missing_reference_says_how_long_from_the_stored_references(write_scene):
    with pytest.raises(ReferenceError) as exc:
        load_reference(load_scene(write_scene()))
    msg = str(exc.value)
    assert "cbox reference build --scene" in msg and "--spp 16384 (about " in msg
    assert "µs per pixel-sample" in msg and "\n" not in msg


def test_render_with_set_resolution_writes_that_size(tmp_path):
    out = tmp_path / "x.exr"
    proc = run_cbox("render", "--scene", "cornell-box", "--set", "camera.resolution=16,12", "-r",
                    "tests.user_renderers:FlatGrey", "--spp", "1", "--out", str(out), env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert read_exr(out).shape == (12, 16, 3)
    derived = load_derived_scene(CORNELL, ["camera.resolution=16,12"])
    assert read_image_file(out).metadata["cbox:scene_hash"] == derived.content_hash() != load_scene(CORNELL).content_hash()


@pytest.fixture
def stored_cornell(tmp_path, monkeypatch):
    """A references folder with the Cornell box's scene and provenance only: nothing the tests do touches ours."""
    folder = tmp_path / "references" / "cornell-box"
    folder.mkdir(parents=True)
    for name in ("scene.toml", PROVENANCE_FILE):
        shutil.copy(CORNELL.parent / name, folder / name)
    monkeypatch.setenv("CBOX_REFERENCES", str(folder.parent))
    return folder


def test_compare_with_set_and_no_reference_gives_the_build_command(stored_cornell, tmp_path):
    proc = run_cbox("compare", "--scene", "cornell-box", "--set", "render.max_depth=3", "-r",
                    "tests.user_renderers:FlatGrey", "--spp", "1", "--out", str(tmp_path / "out"), env_path=ROOT)
    assert proc.returncode == 2
    assert proc.stderr.startswith("cbox: error: ") and len(proc.stderr.strip().splitlines()) == 1
    assert "no reference for scene 'cornell-box[render.max_depth=3]'" in proc.stderr
    assert "cbox reference build --scene cornell-box --set render.max_depth=3 --spp 16384 --batches 128" in proc.stderr
    wall = json.loads((stored_cornell / PROVENANCE_FILE).read_text())["wall_time_s"]
    assert f"the reference of cornell-box took {wall:.0f} s at 256x256, 16384 spp" in proc.stderr
    assert "only an estimate" in proc.stderr
    assert sorted(p.name for p in stored_cornell.iterdir()) == [PROVENANCE_FILE, "scene.toml"]


def test_compare_with_set_scores_against_the_derived_reference_and_report_rebuilds(write_scene, tmp_path):
    path = write_scene(MINIMAL_SCENE.replace("resolution = [8, 6]", "resolution = [16, 12]"))
    derived = load_derived_scene(path, ["render.max_depth=3"])
    build_reference(derived, spp=4, batches=2, entry=_entry())  # only the derived scene has a reference
    out = tmp_path / "out"
    proc = run_cbox("compare", "--scene", str(path), "--set", "render.max_depth=3", "-r", "tests.user_renderers:FlatGrey",
                    "--spp", "1", "--json", "--out", str(out), env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    (rec,) = map(json.loads, proc.stdout.strip().splitlines())
    assert rec["status"] == "ok" and rec["scene"] == derived.name
    # The experiment is of the derived scene: its report is rebuilt only with the same --set.
    plain = run_cbox("report", str(out), env_path=ROOT)
    assert plain.returncode == 2 and "give the --set it was run with" in plain.stderr
    again = run_cbox("report", str(out), "--set", "render.max_depth=3", env_path=ROOT)
    assert again.returncode == 0, again.stderr


def test_reference_build_with_set_stores_apart_from_the_scene(write_scene, tmp_path):
    """The command the error gives, run for real (Mitsuba, tiny): the derived reference, the scene's untouched."""
    path = write_scene()
    proc = run_cbox("reference", "build", "--scene", str(tmp_path), "--set", "render.max_depth=3", "--spp", "4",
                    "--batches", "2")
    assert proc.returncode == 0, proc.stderr
    derived = load_derived_scene(path, ["render.max_depth=3"])
    assert sorted(p.name for p in tmp_path.iterdir()) == [DERIVED_FOLDER, "scene.toml"]
    assert load_reference(derived).folder == reference_folder(derived) != tmp_path
    shown = run_cbox("reference", "show", "--scene", str(tmp_path), "--set", "render.max_depth=3")
    assert shown.returncode == 0, shown.stderr
    prov = json.loads(shown.stdout)
    assert prov["scene_hash"] == derived.content_hash() and prov["overrides"] == ["render.max_depth=3"]


def test_unknown_set_key_on_the_command_line(tmp_path):
    proc = run_cbox("render", "--scene", "cornell-box", "--set", "render.maxdepth=3", "-r", "pathtracer",
                    "--out", str(tmp_path / "x.exr"))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert proc.stderr.startswith("cbox: error: --set: render.maxdepth: ") and "'render.max_depth'" in proc.stderr
    assert not (tmp_path / "x.exr").exists()


GATE = """\
alpha = 0.01
baseline = "base.json"

[[expect]]
scene = "{scene}"
renderer = "tests.user_renderers:SeededNoise"
spp = 4
max = {{ delta_e2000_mean = 1e9 }}
"""


def test_gate_set_derives_every_scene_and_skips_the_baseline(write_scene, tmp_path):
    from cornell_harness.gate.config import load_config
    from cornell_harness.gate.run import run_gate

    path = write_scene(MINIMAL_SCENE.replace("resolution = [8, 6]", "resolution = [16, 12]"))
    base = load_scene(path)
    derived = load_derived_scene(path, ["render.max_depth=3"])
    for scene in (base, derived):
        build_reference(scene, spp=4, batches=2, entry=_entry())
    cfg_path = tmp_path / "gate.toml"
    cfg_path.write_text(GATE.format(scene=path))
    name = load_config(cfg_path).expectations[0].name
    # A baseline no run can meet: compared on the config's own scene, ignored on the derived one.
    (tmp_path / "base.json").write_text(json.dumps({"expectations": {name: {"delta_e2000_mean": 0.0}},
                                                    "seeds": {name: 0}}))
    (own,) = run_gate(load_config(cfg_path), sandbox=False)
    assert own.record.scene == "minimal" and not own.passed
    assert any(c.name.startswith("baseline.") and not c.passed for c in own.checks)
    (moved,) = run_gate(load_config(cfg_path), sandbox=False, scene_overrides=["render.max_depth=3"])
    assert moved.record.scene == derived.name and moved.record.scene_hash == derived.content_hash()
    assert moved.passed and not any(c.name.startswith("baseline.") for c in moved.checks)
    (skipped,) = [c for c in moved.checks if c.name == "baseline"]
    assert skipped.skipped and "not on scenes derived with --set" in skipped.message
    assert np.asarray(moved.record.image).shape == (12, 16, 3)


def test_gate_set_refuses_update_baseline(tmp_path):
    cfg_path = tmp_path / "gate.toml"
    cfg_path.write_text(GATE.format(scene="cornell-box"))
    proc = run_cbox("gate", "--config", str(cfg_path), "--set", "render.max_depth=3", "--update-baseline",
                    "--out", str(tmp_path / "out"))
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1
    assert "--set" in proc.stderr and "--update-baseline" in proc.stderr
    assert not (tmp_path / "base.json").exists()

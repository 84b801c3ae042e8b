"""Adapter registry, capability matching and skipping, and user renderers given as module:Class."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from tests.conftest import CORNELL, ROOT, run_cbox
from tests.user_renderers import FlatGrey
from cornell_harness.workflows import runner
from cornell_harness.adapters.api import Setting, SettingsError
from cornell_harness.adapters.registry import RendererError, discover, load_spec, resolve
from cornell_harness.scenes.loader import load_scene



def test_builtin_renderers_are_registered_as_entry_points():
    names = set(discover())
    assert {"mitsuba", "pyrender"} <= names


def test_load_spec_module_class():
    r = load_spec("tests.user_renderers:FlatGrey")
    assert r.name == "flat-grey" and r.unavailable_reason() is None


@pytest.mark.parametrize("spec, words", [
    ("tests.user_renderers:Nope", "has no attribute 'Nope'"),
    ("no_such_module_xyz:Thing", "cannot import no_such_module_xyz"),
    ("user_renderers", "expected a registered name or package.module:ClassName"),
    ("tests.user_renderers:BadEstimator", "estimator = 'unbaised' is not one of unbiased, consistent, biased "
                                    r"\(did you mean 'unbiased'\?\)"),
])
def test_load_spec_errors(spec, words):
    with pytest.raises(RendererError, match=words):
        load_spec(spec)


def test_estimator_is_declared_checked_and_recorded():
    """No ``estimator``: unbiased; a declared one is recorded in every row; a bad one is refused by the accessor too."""
    from cornell_harness.adapters.registry import ESTIMATORS, estimator_of
    from tests.user_renderers import BadEstimator, FlatGrey

    assert ESTIMATORS == ("unbiased", "consistent", "biased")
    assert estimator_of(FlatGrey()) == "unbiased"
    (entry,) = resolve(["tests.user_renderers:ShrinkingBias"])
    assert estimator_of(entry.renderer) == "consistent"
    scene = load_scene(CORNELL)
    assert runner.RunRecord.new(scene, entry, 1, 0).row()["estimator"] == "consistent"
    with pytest.raises(RendererError, match="'bad-estimator': estimator = 'unbaised'"):
        estimator_of(BadEstimator())


def test_unknown_name_is_a_usage_error():
    with pytest.raises(RendererError, match="unknown renderer 'povray'"):
        resolve(["povray"])


def test_unknown_name_suggests_the_closest():
    with pytest.raises(RendererError, match=r"unknown renderer 'pathtracr' \(did you mean 'pathtracer'\?\)"):
        resolve(["pathtracr"])


@pytest.mark.parametrize("spec, words", [("no_such_module_xyz:Thing", "cannot import"),
                                         ("tests.user_renderers:Nope", "has no attribute 'Nope'")])
def test_a_named_module_class_that_cannot_load_is_a_usage_error(spec, words):
    """Never "unavailable": a CI running `compare` on a typo must not go green."""
    with pytest.raises(RendererError, match=words):
        resolve([spec])


@pytest.mark.parametrize("command", [["compare", "--spp", "1"], ["converge", "--spp", "1", "--seeds", "1"],
                                     ["render", "--spp", "1", "--out", "x.exr"]])
def test_module_class_typo_exits_2_in_every_command(tmp_path, command):
    cmd, *rest = command
    out = ["--out", str(tmp_path / "o")] if "--out" not in rest else []
    if "--out" in rest:
        rest[rest.index("--out") + 1] = str(tmp_path / "x.exr")
    proc = run_cbox(cmd, "--scene", "cornell-box", "-r", "tests.user_renderers:Nope", *rest, *out, env_path=ROOT)
    assert proc.returncode == 2 and "has no attribute 'Nope'" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_module_class_is_found_in_the_current_folder(tmp_path):
    """As `python -m` does: the console script alone would not put the current folder on the path."""
    (tmp_path / "here_renderer.py").write_text("from tests.user_renderers import FlatGrey as Here\n")
    import os
    import subprocess
    cbox = Path(sys.executable).with_name("cbox")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.run([str(cbox), "render", "--scene", "cornell-box", "-r", "here_renderer:Here", "--spp", "1",
                           "--out", str(tmp_path / "x.exr")], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr


def test_runner_statuses_and_reasons():
    scene = load_scene(CORNELL).with_resolution(8, 8)
    entries = resolve(["tests.user_renderers:FlatGrey", "tests.user_renderers:MeshOnly", "tests.user_renderers:NeedsGPU",
                       "tests.user_renderers:Crashes", "tests.user_renderers:WrongShape"])
    recs = {r.renderer: r for r in (runner.run_one(e, scene, 1, 0, None) for e in entries)}
    assert recs["flat-grey"].status == "ok" and recs["flat-grey"].image.shape == (8, 8, 3)
    assert recs["mesh-only"].status == "skipped"
    assert recs["mesh-only"].reason == "does not model area_light, box_filter, diffuse"
    assert recs["needs-gpu"].status == "unavailable" and recs["needs-gpu"].reason == "no CUDA device found"
    assert recs["crashes"].status == "failed" and "segfault simulator" in recs["crashes"].reason
    assert recs["wrong-shape"].status == "failed" and "shape (2, 2, 3)" in recs["wrong-shape"].reason
    assert recs["mesh-only"].image is None and recs["mesh-only"].metrics == {}


def test_cli_render_with_user_renderer(tmp_path):
    out = tmp_path / "grey.exr"
    proc = run_cbox("render", "--scene", "cornell-box", "--renderer", "tests.user_renderers:FlatGrey",
                    "--spp", "1", "--out", str(out), env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    from cornell_harness.store.exr import read_exr

    img = read_exr(out)
    assert img.shape == (256, 256, 3) and float(img.mean()) == pytest.approx(0.25)


def test_cli_render_refuses_renderer_lacking_a_feature(tmp_path):
    proc = run_cbox("render", "--scene", "cornell-box", "--renderer", "tests.user_renderers:MeshOnly",
                    "--out", str(tmp_path / "x.exr"), env_path=ROOT)
    assert proc.returncode == 2
    assert proc.stderr.strip() == ("cbox: error: renderer 'mesh-only' does not model area_light, box_filter, "
                                   "diffuse, which cornell-box uses")


def test_cli_renderers_lists_availability():
    proc = run_cbox("renderers")
    assert proc.returncode == 0, proc.stderr
    assert "mitsuba" in proc.stdout and "pyrender" in proc.stdout
    assert "available" in proc.stdout


def test_pyrender_is_skipped_on_the_caustics_scene_without_rendering():
    """pyrender models no spheres, mirrors or glass: the runner skips it on cornell-box-caustics, naming them.

    The entry is built as if pyrender were available (no GPU needed): the
    skip comes from the features alone, before any render is attempted.
    """
    from cornell_harness.adapters.registry import RendererEntry, missing_features
    from cornell_harness.renderers.mitsuba3 import Mitsuba3
    from cornell_harness.renderers.pathtracer import PathTracer
    from cornell_harness.renderers.raster.pyrender_adapter import Pyrender

    scene = load_scene(CORNELL.parent.parent / "cornell-box-caustics" / "scene.toml").with_resolution(8, 8)
    renderer = Pyrender()
    renderer.render = None  # a render attempt would fail the record, not skip it
    entry = RendererEntry("pyrender", "pyrender", renderer, None)
    assert entry.available
    assert missing_features(renderer, scene) == ["dielectric", "mirror", "sphere"]
    for rec in (runner.RunRecord.new(scene, entry, 1, 0), runner.run_one(entry, scene, 1, 0, None)):
        assert rec.status == "skipped"
        assert rec.reason == "does not model dielectric, mirror, sphere"
        assert rec.image is None and rec.metrics == {}
    assert missing_features(PathTracer(), scene) == [] and missing_features(Mitsuba3(), scene) == []


class Recorder(FlatGrey):
    """Declares one setting of each kind and records what ``render`` was handed."""

    name = "recorder"
    settings = (Setting("count", int, 2, "an integer", low=1, high=9),
                Setting("gain", float, 0.5, "a number", low=0.0),
                Setting("flag", bool, False, "a switch"),
                Setting("mode", str, "plain", "a word", choices=("plain", "fancy")))
    seen: list = []

    def render(self, scene, spp, seed, checkpoints=(), *, settings):
        type(self).seen.append(dict(settings))
        return super().render(scene, spp, seed, checkpoints)


def test_the_render_path_hands_every_setting_validated_typed_and_defaulted():
    """However the entry was made (from a spec, or by hand with text values), the renderer gets every declared
    setting, typed, defaults filled; a bad value is refused before it renders; one declaring none gets none."""
    from cornell_harness.adapters.registry import RendererEntry
    from cornell_harness.workflows.render import render_checked

    scene = load_scene(CORNELL).with_resolution(4, 4)
    Recorder.seen.clear()
    (entry,) = resolve(["tests.adapters.test_adapters:Recorder[count=3, flag=true]"])
    render_checked(entry, scene, 1, 0)
    by_hand = RendererEntry("recorder", "tests.adapters.test_adapters:Recorder", Recorder(), None, {"gain": "2", "mode": "fancy"})
    render_checked(by_hand, scene, 1, 0)
    assert Recorder.seen == [{"count": 3, "gain": 0.5, "flag": True, "mode": "plain"},
                             {"count": 2, "gain": 2.0, "flag": False, "mode": "fancy"}]
    assert [[type(v) for v in s.values()] for s in Recorder.seen] == [[int, float, bool, str]] * 2
    with pytest.raises(SettingsError, match=r"setting count=0: expected an integer in \[1, 9\]"):
        render_checked(RendererEntry("recorder", "x", Recorder(), None, {"count": 0}), scene, 1, 0)
    assert len(Recorder.seen) == 2
    (plain,) = resolve(["tests.user_renderers:FlatGrey"])  # its render takes no settings keyword
    assert render_checked(plain, scene, 1, 0).image.shape == (4, 4, 3)


def test_declarations_are_read_in_one_place():
    """attribute(): a declaration's default when a renderer declares nothing (or None), sequences as tuples; a
    name that is not a declaration is an error, not a silent default."""
    from cornell_harness.adapters.api import DECLARATIONS, attribute

    bare = object()
    assert {k: attribute(bare, k) for k in ("aovs", "estimator", "deterministic", "quantities", "settings",
                                              "approximations")} == {
        "aovs": (), "estimator": "unbiased", "deterministic": False, "quantities": ("radiance",), "settings": (),
        "approximations": ()}
    assert attribute(FlatGrey(), "approximations") == ("everything is grey",)
    assert attribute(Recorder(), "settings") == Recorder.settings and DECLARATIONS.estimator == "unbiased"

    class Lists:
        aovs, quantities, settings = ["albedo"], ["ambient_occlusion"], None

    assert attribute(Lists(), "aovs") == ("albedo",) and attribute(Lists(), "quantities") == ("ambient_occlusion",)
    assert attribute(Lists(), "settings") == ()
    with pytest.raises(KeyError, match="'feature' is not a renderer declaration"):
        attribute(bare, "feature")

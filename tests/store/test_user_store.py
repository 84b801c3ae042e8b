"""The user store: where what is built or recorded for the stored scenes goes, the package's files staying as
they are; where a reference is looked for; which recorded verdicts are shown."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.overrides import load_derived_scene
from cornell_harness.store.home import home_source, user_home
from cornell_harness.store.references import (VERDICTS_FILE, ReferenceError, load_reference, record_verdict,
                                              recorded_verdicts, reference_folder, reference_folders)
from cornell_harness.workflows.reference_build import build_reference
from tests.conftest import CORNELL, MINIMAL_SCENE, cbox_in_process


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


def test_the_store_is_the_option_else_the_variable_else_the_platforms(monkeypatch, tmp_path, user_store):
    assert user_home(tmp_path / "given") == tmp_path / "given" and home_source(tmp_path) == "--home"
    assert user_home() == user_store and home_source() == "$CBOX_HOME"
    monkeypatch.delenv("CBOX_HOME")
    if sys.platform.startswith("linux"):  # platformdirs follows the XDG base directories there
        monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
        assert user_home() == tmp_path / "data" / "cornell-harness"
    assert user_home().name == "cornell-harness" and home_source() == "the platform's user data folder"


def test_a_stored_scene_is_read_from_the_package_and_built_and_recorded_in_the_user_store(user_store, tmp_path):
    scene = load_scene(CORNELL)
    mine = user_store / "references" / "cornell-box"
    assert reference_folders(scene) == [CORNELL.parent, mine] and reference_folder(scene) == mine
    assert reference_folder(scene, tmp_path / "h") == tmp_path / "h" / "references" / "cornell-box"
    derived = load_derived_scene(CORNELL, ["camera.resolution=8,8"])
    assert reference_folder(derived) == mine / "derived" / derived.content_hash().removeprefix("sha256:")[:16]

    package = _files(CORNELL.parent)
    record = {"engine": "an-engine", "passed": True, "max_abs_z": 0.5, "regions": {"walls": {}}, "spp": 4}
    assert record_verdict(CORNELL.parent, record) == mine / VERDICTS_FILE
    assert _files(CORNELL.parent) == package  # the package's files as they were
    ref = load_reference(scene)
    assert ref.folder == CORNELL.parent and "an-engine" not in ref.provenance.get("verified", {})
    assert recorded_verdicts(ref.folder)["an-engine"]["max_abs_z"] == 0.5
    assert recorded_verdicts(ref.folder, tmp_path / "elsewhere") == {}


def test_a_stale_stored_reference_gives_way_to_the_user_stores_and_a_build_it_would_shadow_is_refused(
        tmp_path, monkeypatch, user_store, capsys):
    stored = tmp_path / "refs" / "minimal"  # a stored references folder of one scene
    stored.mkdir(parents=True)
    (stored / "scene.toml").write_text(MINIMAL_SCENE)
    monkeypatch.setenv("CBOX_REFERENCES", str(stored.parent))
    (entry,) = resolve(["tests.user_renderers:SeededNoise"])
    build_reference(resolve_scene("minimal"), spp=4, batches=2, entry=entry, folder=stored)
    assert load_reference(resolve_scene("minimal")).folder == stored
    code, out, err = cbox_in_process(capsys, "reference", "build", "--scene", "minimal", "--spp", "4",
                                     "--batches", "2")
    assert code == 2 and "is the one every command reads" in err and "would never be read" in err, err

    (stored / "scene.toml").write_text(MINIMAL_SCENE.replace("0.8, 0.8, 0.8", "0.7, 0.8, 0.8"))
    package = _files(stored)
    changed = resolve_scene("minimal")
    with pytest.raises(ReferenceError, match=f"{stored}.*scene hash.*cbox reference build --scene minimal"):
        load_reference(changed)
    built = build_reference(changed, spp=4, batches=2, entry=entry)
    assert built.folder == user_store / "references" / "minimal" and _files(stored) == package
    assert load_reference(changed).folder == built.folder
    code, out, err = cbox_in_process(capsys, "scenes", "--json")
    (listed,) = json.loads(out)
    assert code == 0 and listed["reference"]["in_user_store"] and listed["reference"]["spp"] == 4
    code, out, err = cbox_in_process(capsys, "scenes")
    assert "reference 4 spp (user store)" in out

"""Renderer settings as data: declared, validated, handed to render, recorded, swept."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from tests.conftest import ROOT, run_cbox
from cornell_harness.adapters.registry import resolve
from cornell_harness.adapters.settings import Setting, SettingsError, label, parse_sweep, split_spec
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.workflows import runner


def test_spec_with_settings_is_split_and_validated():
    assert split_spec("pathtracer[rr_depth=3, x = y]") == ("pathtracer", {"rr_depth": "3", "x": "y"})
    assert split_spec("pkg.mod:Cls") == ("pkg.mod:Cls", {})
    (entry,) = resolve(["tests.user_renderers:Tunable[level=2]"])
    assert entry.settings == {"level": 2.0, "mode": "plain"} and entry.name == "tunable[level=2.0]"
    with pytest.raises(SettingsError, match=r"unknown setting 'levl' \(did you mean 'level'\?\)"):
        resolve(["tests.user_renderers:Tunable[levl=2]"])
    with pytest.raises(SettingsError, match=r"level='11': expected a number in \[0, 10\]"):
        resolve(["tests.user_renderers:Tunable[level=11]"])
    with pytest.raises(SettingsError, match="one of plain, fancy"):
        resolve(["tests.user_renderers:Tunable[mode=odd]"])


@pytest.mark.parametrize("kind, raw, ok", [(int, "3", 3), (int, 3.0, 3), (int, "3.5", None), (int, True, None),
                                           (float, "1e-2", 0.01), (float, "nan", None), (bool, "true", True),
                                           (bool, 1, None)])
def test_setting_types(kind, raw, ok):
    s = Setting("x", kind, kind(), "doc")
    if ok is None:
        with pytest.raises(SettingsError):
            s.coerce(raw, "r")
    else:
        assert s.coerce(raw, "r") == ok


def test_sweep_and_label_syntax():
    assert parse_sweep("pathtracer.rr_depth=3,5,8") == ("pathtracer", "rr_depth", ["3", "5", "8"])
    assert parse_sweep("tests.user_renderers:Tunable.level=1,2") == ("tests.user_renderers:Tunable", "level", ["1", "2"])
    with pytest.raises(SettingsError):
        parse_sweep("pathtracer=3")
    assert label("pt", {"a": 1, "b": 2}, {"a": 1, "b": 3}) == "pt[b=2]"


def test_settings_reach_render_and_every_row():
    scene = resolve_scene("cornell-box").with_resolution(4, 4)
    (entry,) = resolve(["tests.user_renderers:Tunable[level=2,mode=fancy]"])
    rec = runner.run_one(entry, scene, 1, 0, None)
    assert rec.status == "ok" and rec.info["seen_settings"] == {"level": 2.0, "mode": "fancy"}
    assert abs(float(rec.image.mean()) - 2.0) < 0.5
    row = rec.row()
    assert json.loads(row["settings"]) == {"level": 2.0, "mode": "fancy"}
    assert json.loads(row["scene_settings"])["width"] == 4


def test_pathtracer_declares_rr_depth():
    (entry,) = resolve(["pathtracer[rr_depth=3]"])
    assert entry.settings["rr_depth"] == 3 and entry.name == "pathtracer[rr_depth=3]"
    with pytest.raises(SettingsError, match="rr_depth"):
        resolve(["pathtracer[rr_depth=0]"])


def test_cli_bad_setting_is_one_line_exit_2(tmp_path):
    proc = run_cbox("compare", "--scene", "cornell-box", "-r", "tests.user_renderers:Tunable[level=-1]", "--out",
                    str(tmp_path), env_path=ROOT)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().count("\n") == 0 and "setting level=" in proc.stderr


def test_renderers_lists_settings():
    proc = run_cbox("renderers", "--settings")
    assert proc.returncode == 0, proc.stderr
    assert "rr_depth = 5" in proc.stdout


def test_converge_sweep_gives_one_series_per_value(tmp_path):
    out = tmp_path / "sweep"
    proc = run_cbox("converge", "--scene", "cornell-box", "-r", "tests.user_renderers:Tunable", "--sweep",
                    "tests.user_renderers:Tunable.level=0.25,0.5", "--spp", "1,2", "--seeds", "2", "--out", str(out),
                    env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    runs = pd.read_parquet(out / "results.parquet")
    assert set(runs["renderer"]) == {"tunable", "tunable[level=0.5]"}
    by = {r: json.loads(g["settings"].iloc[0])["level"] for r, g in runs.groupby("renderer")}
    assert by == {"tunable": 0.25, "tunable[level=0.5]": 0.5}
    assert len(runs) == 2 * 2 * 2
    assert "tunable[level=0.5]" in (out / "report.html").read_text()


def test_converge_records_a_wrong_shaped_image_as_a_failed_cell(tmp_path):
    """As compare does: the cell fails with the reason, and the run goes on."""
    out = tmp_path / "bad"
    proc = run_cbox("converge", "--scene", "cornell-box", "-r", "tests.user_renderers:WrongShape", "-r",
                    "tests.user_renderers:SeededNoise", "--spp", "1,2", "--seeds", "1", "--out", str(out), env_path=ROOT)
    assert proc.returncode == 1, proc.stderr  # a failed renderer, as in compare
    assert "Traceback" not in proc.stderr
    runs = pd.read_parquet(out / "results.parquet")
    bad = runs[runs["renderer"] == "wrong-shape"]
    assert list(bad["status"]) == ["failed"] and "shape (2, 2, 3)" in bad["reason"].iloc[0]
    assert (runs[runs["renderer"] == "seeded-noise"]["status"] == "ok").all()


def test_gate_expectation_settings(tmp_path):
    cfg = tmp_path / "gate.toml"
    cfg.write_text('[[expect]]\nscene = "cornell-box"\nrenderer = "tests.user_renderers:Tunable"\nspp = 1\n'
                   'settings = { levl = 2 }\nmax = { delta_e2000_mean = 100 }\n')
    proc = run_cbox("gate", "--config", str(cfg), "--out", str(tmp_path / "o"), env_path=ROOT)
    assert proc.returncode == 2 and "levl" in proc.stderr, proc.stderr
    cfg.write_text(cfg.read_text().replace("levl", "level"))
    proc = run_cbox("gate", "--config", str(cfg), "--out", str(tmp_path / "o"), env_path=ROOT)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Tunable[level=2]@1spp" in proc.stdout
    runs = pd.read_parquet(tmp_path / "o" / "results.parquet")
    assert list(runs["renderer"]) == ["tunable[level=2.0]"] and json.loads(runs["settings"][0])["level"] == 2.0

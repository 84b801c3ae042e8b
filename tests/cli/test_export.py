"""``cbox export``: writes the main file and prints its path; an unknown format or a refused scene is one line, exit 2."""

from __future__ import annotations

import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from tests.conftest import cbox_in_process as cbox, run_cbox
from cornell_harness.scenes.export import FORMATS


@pytest.mark.parametrize("fmt, main_file", [("mitsuba", "scene.xml"), ("pbrt-v4", "scene.pbrt")])
def test_export_writes_the_scene_and_prints_its_main_file(capsys, tmp_path, fmt, main_file):
    out = tmp_path / "d"
    code, stdout, err = cbox(capsys, "export", "--scene", "cornell-box-caustics", "--format", fmt, "--out", str(out),
                             "--set", "camera.resolution=24,16")
    assert code == 0, err
    assert stdout.strip() == str(out / main_file) and (out / main_file).is_file()
    assert not [p for p in out.iterdir() if p.name.startswith(".export-")]  # the staging folder is gone
    text = (out / main_file).read_text(encoding="utf-8")
    if fmt == "mitsuba":
        defaults = {d.get("name"): d.get("value") for d in ET.fromstring(text).findall("default")}
        assert (defaults["resx"], defaults["resy"]) == ("24", "16")
        assert len(list((out / "meshes").glob("*.ply"))) == 6
    else:
        assert '"integer xresolution" [ 24 ] "integer yresolution" [ 16 ]' in text


def test_an_ambient_occlusion_scene_is_refused_in_one_line(capsys, tmp_path):
    code, stdout, err = cbox(capsys, "export", "-s", "cornell-box-ao", "-f", "mitsuba", "-o", str(tmp_path / "d"))
    (line,) = err.splitlines()
    assert code == 2 and stdout == ""
    assert line.startswith("cbox: error: ") and "cornell-box-ao/scene.toml: quantity: " in line
    assert not (tmp_path / "d").exists()


def test_the_json_format_exports_an_ambient_occlusion_scene(capsys, tmp_path):
    code, stdout, err = cbox(capsys, "export", "-s", "cornell-box-ao", "-f", "json", "-o", str(tmp_path / "d"))
    assert code == 0, err
    doc = json.loads(Path(stdout.strip()).read_text(encoding="utf-8"))
    assert doc["quantity"] == "ambient_occlusion" and doc["ambient_occlusion"]["max_distance"] == 0.5


def test_an_unknown_format_is_refused_with_a_suggestion(capsys, tmp_path):
    code, stdout, err = cbox(capsys, "export", "-s", "cornell-box", "-f", "pbrt", "-o", str(tmp_path / "d"))
    (line,) = err.splitlines()
    assert code == 2 and line.startswith("cbox: error: --format: unknown export format 'pbrt'")
    assert "(did you mean 'pbrt-v4'?)" in line and ", ".join(FORMATS) in line
    assert not (tmp_path / "d").exists()


def test_help_names_every_format(capsys):
    code, stdout, _ = cbox(capsys, "export", "--help")
    assert code == 0
    text = " ".join(stdout.split())
    for name in FORMATS:
        assert name in text
    assert "--scene" in text and "--format" in text and "--out" in text and "--set" in text


@pytest.mark.slow
def test_the_mitsuba_executable_on_an_export_scores_as_the_adapter(tmp_path):
    """The issue's check: `cbox export ... && mitsuba d/scene.xml -o x.exr -D spp=64`, scored by `cbox compare-image`,
    scores as the adapter's 64-spp render (another seed: ΔE and relative MSE within 5%, mean within 1%)."""
    proc = run_cbox("export", "--scene", "cornell-box-caustics", "--format", "mitsuba", "--out", str(tmp_path / "d"))
    assert proc.returncode == 0, proc.stderr
    exe = Path(sys.executable).parent / "mitsuba"
    run = subprocess.run([str(exe), proc.stdout.strip(), "-o", str(tmp_path / "x.exr"), "-D", "spp=64"],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    proc = run_cbox("render", "--scene", "cornell-box-caustics", "--renderer", "mitsuba", "--spp", "64", "--seed", "1",
                    "--out", str(tmp_path / "y.exr"))
    assert proc.returncode == 0, proc.stderr
    proc = run_cbox("compare-image", str(tmp_path / "x.exr"), str(tmp_path / "y.exr"), "--scene", "cornell-box-caustics",
                    "--spp", "64", "--json", "--out", str(tmp_path / "scores"))
    assert proc.returncode == 0, proc.stderr
    x, y = (json.loads(line)["metrics"] for line in proc.stdout.strip().splitlines())
    assert x["delta_e2000_mean"] == pytest.approx(y["delta_e2000_mean"], rel=0.05)
    assert x["rel_mse"] == pytest.approx(y["rel_mse"], rel=0.05)
    assert abs(x["mean_radiance_rel_error"]) < 0.01 and x["nan_count"] == 0


def test_a_spectral_mitsuba_export_prints_the_variant_to_render_it_with(capsys, tmp_path):
    """stdout stays the main file alone; stderr names the spectral variant (an RGB one fails on the spectra)."""
    out = tmp_path / "d"
    code, stdout, err = cbox(capsys, "export", "-s", "cornell-box-measured", "-f", "mitsuba", "-o", str(out),
                             "--set", "camera.resolution=8,8")
    assert code == 0, err
    assert stdout.strip() == str(out / "scene.xml")
    (line,) = err.splitlines()
    assert line.startswith(f"cbox: render it with: mitsuba -m llvm_ad_spectral {out / 'scene.xml'} -o ")
    code, _, err = cbox(capsys, "export", "-s", "cornell-box", "-f", "mitsuba", "-o", str(tmp_path / "rgb"))
    assert code == 0 and "-m " not in err

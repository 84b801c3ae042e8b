"""``cbox render --variance-out``: the per-pixel variance of the image's mean, where the renderer gives one."""

from __future__ import annotations

import numpy as np

from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.exr import read_exr
from tests.conftest import run_cbox

SMALL = "camera.resolution=16,12"


def test_variance_out_writes_the_renderers_variance(tmp_path):
    """The path tracer's variance at 16x12, 8 spp, seed 3: the file holds exactly what the renderer returns
    (same seed, bit-identical render), positive where the image is lit and a variance of the mean, not of one
    sample (8 samples in 8 pmj02 batches: each a batch mean)."""
    out, var_out = tmp_path / "x.exr", tmp_path / "x-var.exr"
    proc = run_cbox("render", "--scene", "cornell-box", "--set", SMALL, "-r", "pathtracer", "--spp", "8",
                    "--seed", "3", "--out", str(out), "--variance-out", str(var_out))
    assert proc.returncode == 0, proc.stderr
    assert f"wrote {var_out}" in proc.stderr
    var = read_exr(var_out)
    scene = resolve_scene("cornell-box", [SMALL])
    expected = resolve(["pathtracer"])[0].renderer.render(scene, 8, 3).variance
    assert var.shape == (12, 16, 3) and np.array_equal(var, expected)
    img = read_exr(out)
    assert np.all(var >= 0) and np.all(var[img.max(axis=-1) > 0].max(axis=-1) > 0)


def test_variance_out_says_in_one_line_when_there_is_none(tmp_path):
    """A renderer that reports no variance: the image is written, one stderr line says why the variance is not,
    and no variance file appears."""
    out, var_out = tmp_path / "x.exr", tmp_path / "x-var.exr"
    proc = run_cbox("render", "--scene", "cornell-box", "--set", SMALL, "-r", "tests.user_renderers:FlatGrey",
                    "--spp", "1", "--out", str(out), "--variance-out", str(var_out))
    assert proc.returncode == 0, proc.stderr
    lines = [line for line in proc.stderr.splitlines() if "no variance" in line]
    assert lines == [f"cbox: no variance written: renderer 'flat-grey' reports no variance of "
                     f"its image at 1 spp, so {var_out} was not written"], proc.stderr
    assert out.exists() and not var_out.exists()


def test_variance_out_is_checked_before_rendering(tmp_path):
    """A variance file name that is not .exr, or the image's own, is refused before anything renders."""
    out = tmp_path / "x.exr"
    for bad, words in ((tmp_path / "v.png", "unsupported extension '.png'"), (out, "is the --out file too")):
        proc = run_cbox("render", "--scene", "cornell-box", "-r", "pathtracer", "--spp", "1", "--out", str(out),
                        "--variance-out", str(bad))
        assert proc.returncode == 2 and "--variance-out" in proc.stderr and words in proc.stderr, proc.stderr
        assert not out.exists()

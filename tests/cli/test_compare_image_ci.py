"""`cbox compare-image` for CI (issue 31): --fail/--warn/--fail-percent give exit 0 pass, 1 fail, 2 bad input,
each broken threshold printed with its value; --exposure for display-referred input; the clipping warning."""

from __future__ import annotations

import json

import numpy as np
import pytest
from PIL import Image

from tests.conftest import ROOT, cbox_in_process as cbox, run_cbox
from cornell_harness.store.exr import write_exr
from cornell_harness.evaluate.ciede2000 import srgb_eotf


@pytest.fixture(scope="module")
def render16(tmp_path_factory):
    """A 16-spp Mitsuba render of cornell-box by `cbox render` (256², the reference's size; ~1 s)."""
    exr = tmp_path_factory.mktemp("ci") / "m16.exr"
    proc = run_cbox("render", "--scene", "cornell-box", "-r", "mitsuba", "--spp", "16", "--seed", "0",
                    "--out", str(exr))
    assert proc.returncode == 0, proc.stderr
    return exr


def _compare(capsys, tmp_path, image, *extra):
    return cbox(capsys, "compare-image", str(image), "--scene", "cornell-box", "--out", str(tmp_path / "o"),
                "--json", *extra)


def test_the_issue_case_fails_with_exit_1(render16, tmp_path):
    """`compare-image --fail delta_e2000_mean=0.1` on a 16-spp render: exit 1, the failed threshold and its value
    on stderr (a fresh process, as CI runs it)."""
    proc = run_cbox("compare-image", str(render16), "--scene", "cornell-box", "--fail", "delta_e2000_mean=0.1",
                    "--out", str(tmp_path))
    assert proc.returncode == 1, proc.stderr
    (line,) = [x for x in proc.stderr.splitlines() if x.startswith("cbox: fail: ")]
    assert line.startswith("cbox: fail: m16: delta_e2000_mean = ") and line.endswith(" > 0.1 (--fail)")
    assert float(line.split(" = ")[1].split()[0]) > 1  # 16 spp: ΔE ~5, far above 0.1


def test_pass_warn_and_fail(render16, tmp_path, capsys):
    code, out, err = _compare(capsys, tmp_path, render16, "--fail", "delta_e2000_mean=20", "--fail", "psnr=10")
    assert code == 0 and "cbox: fail" not in err and "warning" not in err, err
    assert json.loads(out)["verdict"]["status"] == "pass"
    # A broken --warn: one warning line, exit 0; ssim is higher-better, so it warns below its value.
    code, out, err = _compare(capsys, tmp_path, render16, "--fail", "delta_e2000_mean=20", "--warn", "ssim=0.99")
    (warning,) = [x for x in err.splitlines() if "warning" in x]
    assert code == 0 and warning.startswith("cbox: warning: m16: ssim = ") and warning.endswith("< 0.99 (--warn)")
    verdict = json.loads(out)["verdict"]
    assert verdict["status"] == "warn" and [c["broken"] for c in verdict["checks"]] == [False, True]
    code, out, err = _compare(capsys, tmp_path, render16, "--fail", "psnr=60", "--warn", "ssim=0.99")
    assert code == 1 and "cbox: fail: m16: psnr = " in err and json.loads(out)["verdict"]["status"] == "fail"
    # A region's metric, of a region the scene names.
    code, out, err = _compare(capsys, tmp_path, render16, "--fail", "region.walls.rmse=1e-6")
    assert code == 1 and "cbox: fail: m16: region.walls.rmse = " in err
    # Thresholds at the ends of their metric's range are accepted (and these can only pass).
    code, out, err = _compare(capsys, tmp_path, render16, "--fail", "ssim=-1", "--warn", "delta_e2000_frac_gt_2_3=1")
    assert code == 0 and err == "" and json.loads(out)["verdict"]["status"] == "pass"


def test_fail_percent_counts_pixels_above_the_delta_e_threshold(render16, tmp_path, capsys):
    code, out, err = _compare(capsys, tmp_path, render16, "--fail-percent", "5", "--pixel-threshold", "2.3")
    rec = json.loads(out)
    (check,) = rec["verdict"]["checks"]
    # The same pixels delta_e2000_frac_gt_2_3 counts (ΔE00 at the display exposure), as a percentage.
    assert check["value"] == pytest.approx(100 * rec["metrics"]["delta_e2000_frac_gt_2_3"])
    assert code == 1 and f"cbox: fail: m16: {check['value']:.4g}% of the pixels have ΔE00 > 2.3" in err
    code, out, err = _compare(capsys, tmp_path, render16, "--fail-percent", "99.9", "--pixel-threshold", "2.3")
    assert code == 0 and json.loads(out)["verdict"]["status"] == "pass"


@pytest.mark.parametrize("extra, words", [
    (("--fail", "delta_e200_mean=0.1"), ["--fail", "unknown metric", "did you mean 'delta_e2000_mean'?"]),
    (("--warn", "rmse"), ["--warn", "expected METRIC=VALUE"]),
    (("--fail", "region.causti.rmse=1"), ["--fail", "no region 'causti'", "did you mean 'caustic'?"]),
    (("--fail", "delta_e2000_mean=-1"), ["--fail", "delta_e2000_mean is at least 0"]),
    (("--warn", "ssim=1.5"), ["--warn", "ssim is between -1 and 1"]),
    (("--fail", "ssim_mean=1.5"), ["--fail", "unknown metric 'ssim_mean'", "metrics: "]),
    (("--fail", "rmse=-0.1"), ["--fail", "rmse is at least 0"]),
    (("--fail", "rel_mse=-1"), ["--fail", "rel_mse is at least 0"]),
    (("--warn", "flip_mean=-1"), ["--warn", "flip_mean is between 0 and 1"]),
    (("--fail", "negative_count=-1"), ["--fail", "negative_count is at least 0"]),
    (("--fail-percent", "5"), ["--fail-percent", "--pixel-threshold", "together"]),
    (("--fail-percent", "101", "--pixel-threshold", "1"), ["--fail-percent"]),
    (("--exposure", "1"), ["--exposure", "display-referred"]),
    (("--input-transfer", "sRBG"), ["--input-transfer", "did you mean 'srgb'?"]),
])
def test_bad_input_is_exit_2_naming_the_option(render16, tmp_path, capsys, extra, words):
    scene = "cornell-box-caustics" if "causti" in " ".join(extra) else "cornell-box"
    code, out, err = cbox(capsys, "compare-image", str(render16), "--scene", scene, "--out", str(tmp_path / "o"),
                          *extra)
    (line,) = err.strip().splitlines()
    assert code == 2 and line.startswith("cbox: error: ") and all(w in line for w in words), line
    assert not (tmp_path / "o").exists()


AO_REFERENCE = ROOT / "src" / "cornell_harness" / "references" / "cornell-box-ao" / "reference.exr"


@pytest.mark.parametrize("extra", [("--fail", "delta_e2000_mean=1"), ("--warn", "flip_mean=0.5"),
                                   ("--fail", "region.walls.delta_e2000_mean=3"),
                                   ("--warn", "noise_delta_e2000_mean=1")])
def test_a_colour_threshold_on_a_scene_without_colour_is_exit_2(tmp_path, capsys, extra):
    """On cornell-box-ao (one value per pixel) ΔE00 and HDR-FLIP are not defined: a threshold on them is
    refused naming the option and the quantity, where it used to fail a correct image ("n/a > 1")."""
    code, out, err = cbox(capsys, "compare-image", str(AO_REFERENCE), "--scene", "cornell-box-ao",
                          "--out", str(tmp_path / "o"), *extra)
    (line,) = err.strip().splitlines()
    assert code == 2 and line.startswith(f"cbox: error: {extra[0]}: ") and "ambient_occlusion" in line, line
    assert "no colour" in line and out == "" and not (tmp_path / "o").exists()


def test_a_scene_without_colour_takes_the_thresholds_it_defines(tmp_path, capsys):
    code, out, err = cbox(capsys, "compare-image", str(AO_REFERENCE), "--scene", "cornell-box-ao", "--json",
                          "--out", str(tmp_path / "o"), "--fail", "rmse=1e-9", "--fail", "ssim=0.999")
    assert code == 0 and json.loads(out)["verdict"]["status"] == "pass", err


def test_fail_percent_on_a_scene_without_colour_counts_the_absolute_difference(tmp_path, capsys):
    """--fail-percent on cornell-box-ao counts pixels by |image − reference| of the AO value: the correct image
    passes (it used to be "100% of the pixels have ΔE00 > 5"); one off by 0.2 in its top half breaks 40%."""
    from cornell_harness.store.exr import read_exr

    def run(image, percent):
        return cbox(capsys, "compare-image", str(image), "--scene", "cornell-box-ao", "--json", "--out",
                    str(tmp_path / "o"), "--fail-percent", percent, "--pixel-threshold", "0.1")

    code, out, err = run(AO_REFERENCE, "50")
    (check,) = json.loads(out)["verdict"]["checks"]
    assert code == 0 and check["metric"] == "percent_pixels_abs_error_above" and check["value"] == 0.0, err
    off = np.array(read_exr(AO_REFERENCE), dtype=np.float32)
    off[:128] += 0.2
    write_exr(tmp_path / "off.exr", off)
    code, out, err = run(tmp_path / "off.exr", "40")
    assert code == 1 and json.loads(out)["verdict"]["checks"][0]["value"] == pytest.approx(50.0)
    assert "cbox: fail: off: 50% of the pixels have |Δ| > 0.1 (--fail-percent 40)" in err
    assert run(tmp_path / "off.exr", "60")[0] == 0


def _synthetic(tmp_path, clip_fraction=0.0):
    """A linear reference in [0.02, 0.45] and the 8-bit sRGB PNG of it shown one stop up (× 2, no clipping),
    with ``clip_fraction`` of its pixels then set to white."""
    rng = np.random.default_rng(3)
    ref = rng.uniform(0.02, 0.45, (64, 64, 3)).astype(np.float32)
    write_exr(tmp_path / "ref.exr", ref)
    shown = 2.0 * ref.astype(np.float64)
    code = np.where(shown <= 0.0031308, 12.92 * shown, 1.055 * shown ** (1 / 2.4) - 0.055)  # sRGB OETF
    png = np.round(255 * code).astype(np.uint8)
    png.reshape(-1, 3)[:int(round(clip_fraction * 64 * 64))] = 255
    Image.fromarray(png).save(tmp_path / "shot.png")
    assert np.allclose(srgb_eotf(code), shown)
    return tmp_path / "ref.exr", tmp_path / "shot.png"


def test_exposure_undoes_a_tonemapped_png(tmp_path, capsys):
    ref, png = _synthetic(tmp_path)
    args = ("compare-image", str(png), "--reference", str(ref), "--input-transfer", "sRGB", "--json",
            "--out", str(tmp_path / "o"))
    code, out, err = cbox(capsys, *args, "--exposure", "1")
    m = json.loads(out)["metrics"]
    assert code == 0 and "clipped" not in err, err
    # 8-bit steps only: well below a just-noticeable difference, the mean radiance right to 1%.
    assert m["delta_e2000_mean"] < 0.5 and abs(m["mean_radiance_rel_error"]) < 0.01
    code, out, err = cbox(capsys, *args)  # without it: scored as if shown at radiance, twice too bright
    assert code == 0 and json.loads(out)["metrics"]["mean_radiance_rel_error"] == pytest.approx(1.0, abs=0.02)


@pytest.mark.parametrize("fraction, warned", [(0.0008, False), (0.003, True)])
def test_clipping_warning_above_a_tenth_of_a_percent(tmp_path, capsys, fraction, warned):
    ref, png = _synthetic(tmp_path, fraction)
    code, out, err = cbox(capsys, "compare-image", str(png), "--reference", str(ref), "--input-transfer", "srgb",
                          "--exposure", "1", "--out", str(tmp_path / "o"), "-q")
    lines = [x for x in err.splitlines() if "clipped" in x]
    assert code == 0 and len(lines) == warned, err
    if warned:
        assert lines[0].startswith(f"cbox: warning: {png}: 0.293% of the pixels are clipped")


def test_a_display_referred_reference_is_warned_of_too(tmp_path, capsys):
    ref, png = _synthetic(tmp_path, 0.003)
    code, out, err = cbox(capsys, "compare-image", str(ref), "--reference", str(png), "--input-transfer", "SRGB",
                          "--exposure", "1", "--out", str(tmp_path / "o"), "--json")
    (line,) = [x for x in err.splitlines() if "clipped" in x]
    assert code == 0 and line.startswith(f"cbox: warning: {png}: 0.293% of the pixels are clipped")
    assert abs(json.loads(out)["metrics"]["mean_radiance_rel_error"]) < 0.02  # --exposure applied to it


def test_flip_only_when_asked_for(render16, tmp_path, capsys):
    """HDR-FLIP costs more than every other metric together: scored with --flip or a threshold on it, not by
    default; the same value either way."""
    code, out, _ = _compare(capsys, tmp_path, render16)
    assert code == 0 and "flip_mean" not in json.loads(out)["metrics"]
    code, out, _ = _compare(capsys, tmp_path, render16, "--flip")
    flip_mean = json.loads(out)["metrics"]["flip_mean"]
    assert code == 0 and 0 < flip_mean < 1
    code, out, err = _compare(capsys, tmp_path, render16, "--fail", f"flip_mean={flip_mean / 2}")
    assert code == 1 and json.loads(out)["metrics"]["flip_mean"] == flip_mean and "flip_mean = " in err


def test_a_check_scores_what_it_names_and_the_cheap_metrics(render16, tmp_path, capsys):
    """With thresholds, the named metrics and the cheap ones are scored (a ΔE00 statistic brings the others
    of its map); SSIM, PSNR, the noise yardsticks and the regions only when named; --all-metrics scores every
    one. Each value is the same either way."""
    from cornell_harness.evaluate.metrics import DELTA_E_KEYS
    from cornell_harness.evaluate.registry import CHEAP_METRICS

    code, out, _ = _compare(capsys, tmp_path, render16, "--fail", "delta_e2000_mean=0.1")
    lean = json.loads(out)
    assert code == 1 and set(lean["metrics"]) == {*CHEAP_METRICS, *DELTA_E_KEYS}
    assert lean["noise"] is None and lean["noise_note"] is None and lean["regions"] == {}
    code, out, _ = _compare(capsys, tmp_path, render16, "--fail", "rmse=1")
    assert code == 0 and set(json.loads(out)["metrics"]) == set(CHEAP_METRICS)  # no ΔE00 map at all
    code, out, _ = _compare(capsys, tmp_path, render16, "--fail", "delta_e2000_mean=0.1", "--all-metrics")
    full = json.loads(out)
    assert code == 1 and {"ssim", "psnr", "rel_mse_trimmed"} <= set(full["metrics"]) and full["regions"]
    assert full["noise"]["noise_delta_e2000_mean"] > 0
    assert all(full["metrics"][k] == v for k, v in lean["metrics"].items())
    code, out, _ = _compare(capsys, tmp_path, render16, "--warn", "ssim=0.1", "--warn", "noise_delta_e2000_mean=100",
                            "--warn", "region.walls.rmse=10")
    named = json.loads(out)
    assert code == 0 and named["verdict"]["status"] == "pass"
    assert named["metrics"]["ssim"] == full["metrics"]["ssim"] and "psnr" not in named["metrics"]
    assert named["noise"] == full["noise"] and named["regions"] == full["regions"]


def test_a_check_against_a_reference_file_reads_its_noise_files_only_when_named(render16, tmp_path, capsys):
    """A reference folder's reference.exr: its variance and noise batch are read for a noise threshold (the
    yardsticks then as against the scene), not for a check that names none; the table shows the named metric."""
    from cornell_harness.store.references import REFERENCE_FILE, load_reference
    from cornell_harness.scenes.library import resolve_scene

    reference = load_reference(resolve_scene("cornell-box")).folder / REFERENCE_FILE
    args = ("compare-image", str(render16), "--reference", str(reference), "--out", str(tmp_path / "o"))
    code, out, _ = cbox(capsys, *args, "--json", "--fail", "rmse=1")
    rec = json.loads(out)
    assert code == 0 and rec["noise"] is None and rec["noise_note"] is None
    code, out, _ = cbox(capsys, *args, "--json", "--fail", "noise_rmse=1")
    on_file = json.loads(out)["noise"]
    code, out, _ = _compare(capsys, tmp_path, render16, "--fail", "noise_rmse=1")
    assert code == 0 and on_file == json.loads(out)["noise"] and on_file["noise_rmse"] > 0
    code, out, _ = cbox(capsys, *args, "--warn", "psnr=100")
    header = out.splitlines()[0].split()
    assert code == 0 and "psnr" in header and "ssim" not in header


def test_a_check_writes_the_error_map_only_when_asked(render16, tmp_path, capsys):
    """Without thresholds the error map is written (and --no-error-map leaves it out); a check writes it with
    --error-map only, which also brings the ΔE00 statistics of the map."""
    from cornell_harness.evaluate.metrics import DELTA_E_KEYS

    written = tmp_path / "o" / "m16.delta_e.png"
    code, out, _ = _compare(capsys, tmp_path, render16, "--no-error-map")
    assert code == 0 and json.loads(out)["error_map"] is None and not written.exists()
    code, out, _ = _compare(capsys, tmp_path, render16, "--fail", "rmse=1")
    assert code == 0 and json.loads(out)["error_map"] is None and not written.exists()
    code, out, _ = _compare(capsys, tmp_path, render16, "--fail", "rmse=1", "--error-map")
    rec = json.loads(out)
    assert code == 0 and rec["error_map"] == str(written) and written.is_file()
    assert set(DELTA_E_KEYS) <= set(rec["metrics"]) and "ssim" not in rec["metrics"]
    written.unlink()
    code, out, _ = _compare(capsys, tmp_path, render16)
    assert code == 0 and json.loads(out)["error_map"] == str(written) and written.is_file()


def test_nan_pixels_print_no_numpy_warning(render16, tmp_path):
    """Images with some NaN pixels and with nothing but NaN, scored with every metric and the noise yardsticks
    (whose mean-radiance z skips NaN pixels), in a fresh interpreter as a user's shell sees it: numpy's
    RuntimeWarning lines ("Mean of empty slice") do not reach stderr; the NaN pixels are counted."""
    from cornell_harness.store.exr import read_exr

    image = np.array(read_exr(render16), dtype=np.float32)
    some, every = image.copy(), np.full_like(image, np.nan)
    some[10:20, 10:20] = np.nan
    write_exr(tmp_path / "some.exr", some)
    write_exr(tmp_path / "every.exr", every)
    proc = run_cbox("compare-image", str(tmp_path / "some.exr"), str(tmp_path / "every.exr"), "--scene",
                    "cornell-box", "--spp", "16", "--all-metrics", "--fail", "rmse=10", "--json",
                    "--out", str(tmp_path / "o"))
    assert proc.returncode == 0, proc.stderr
    assert "Warning" not in proc.stderr and "numpy" not in proc.stderr, proc.stderr
    records = [json.loads(line) for line in proc.stdout.splitlines()]
    assert [r["metrics"]["nan_count"] for r in records] == [100, 256 * 256]
    assert records[0]["noise"]["noise_mean_radiance_z"] is not None


def test_unknown_spp_and_an_upside_down_pfm_are_said_in_the_result(tmp_path, capsys):
    """Under the table, kept by --quiet: why an image without spp has no yardsticks or region z, and that an
    image looks flipped (also a warning on stderr); with --spp the yardsticks come back."""
    from cornell_harness.store.exr import read_exr

    pixels = read_exr(ROOT / "src" / "cornell_harness" / "references" / "cornell-box" / "noise.exr")
    write_exr(tmp_path / "right.exr", pixels)
    h, w, _ = pixels.shape
    (tmp_path / "wrong.pfm").write_bytes(b"PF\n%d %d\n-1.0\n" % (w, h) + pixels.astype("<f4").tobytes())  # top first
    code, out, err = cbox(capsys, "compare-image", str(tmp_path / "right.exr"), str(tmp_path / "wrong.pfm"),
                          "--scene", "cornell-box", "--out", str(tmp_path / "o"), "-q")
    notes = out.split("\nnotes:\n")[1].splitlines()
    assert code == 0 and "mean_z" not in out.split("\nnotes:\n")[0]
    assert notes[0].startswith("right: noise yardsticks skipped: no spp: ") and "--spp N" in notes[0]
    assert notes[-1].startswith("wrong: image looks flipped vertically: ") and len(notes) == 3
    assert f"cbox: warning: {tmp_path / 'wrong.pfm'}: image looks flipped vertically" in err
    code, out, err = cbox(capsys, "compare-image", str(tmp_path / "right.exr"), "--scene", "cornell-box",
                          "--spp", "128", "--out", str(tmp_path / "o"), "-q")
    assert code == 0 and "notes:" not in out and "mean_z" in out and "noise_delta_e2000_mean" in out

"""``cbox stress``: the variant builders, the checks, and a cheap end-to-end run.

The full suite (every variant, our path tracer and Mitsuba, ~2 minutes) is
not run here; a subset for our path tracer is, plus user renderers that break
each check (NaN/Inf/negative pixels, the time bound, the memory bound, a crash).
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pandas as pd
import pytest

from tests.conftest import CORNELL, ROOT, run_cbox
from tests.user_renderers import MemoryHog
from cornell_harness.scenes import analytic, transforms
from cornell_harness.scenes.loader import load_scene
from cornell_harness.store.references import load_reference
from cornell_harness.stress import expectations, judge, suite, variants
from cornell_harness.workflows import sandbox

pytest.importorskip("embreex")



@pytest.fixture(scope="module")
def cornell():
    return load_scene(CORNELL)


# --- builders ------------------------------------------------------------------------


def test_variant_names_are_unique_and_documented():
    names = variants.variant_names()
    assert len(names) == len(set(names)) == 12
    doc = variants.__doc__
    for name in names:
        assert re.search(rf"^{re.escape(name)}\s", doc, re.M), f"{name} missing from the module docstring's table"
    for v in variants.VARIANTS:
        assert v.time_bound_s > 0 and v.rss_bound_mb > 0 and v.spp >= 1 and v.stresses and v.expected_note
        assert v.expected in ("furnace", "reference", "variant-reference", "none")


def test_unknown_variant_names_the_known_ones():
    with pytest.raises(ValueError, match=r"unknown stress variant\(s\) 'nope'; known: albedo-0, "):
        variants.select_variants(["albedo-0.5", "nope"])
    assert [v.name for v in variants.select_variants(["spp-1", "albedo-0"])] == ["albedo-0", "spp-1"]
    assert len(variants.select_variants(None)) == len(variants.VARIANTS)


def test_furnace_is_a_closed_inward_facing_emitting_box():
    """Every face of the furnace faces its centre (where the camera is) and emits; it is closed."""
    for albedo in (0.0, 0.5, 0.99, 1.0):
        built = analytic.furnace_scene(albedo, 1.0, -1, res=16)
        (mesh,) = built.meshes
        a, b, c = (mesh.vertices[mesh.triangles[:, k]] for k in range(3))
        normals = np.cross(b - a, c - a)
        assert np.all(np.einsum("ij,ij->i", normals, -(a + b + c) / 3) > 0)
        assert len(mesh.triangles) == 12 and mesh.radiance == (1.0, 1.0, 1.0)
        assert built.materials[mesh.material].reflectance == (albedo,) * 3
        edges = np.sort(np.concatenate([mesh.triangles[:, [0, 1]], mesh.triangles[:, [1, 2]],
                                        mesh.triangles[:, [2, 0]]]), axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        assert np.all(counts == 2)  # every edge shared by two triangles: closed
    assert analytic.furnace_radiance(0.5, 1.0, -1) == 2.0
    assert analytic.furnace_radiance(0.99, 2.0, -1) == pytest.approx(200.0)
    assert analytic.furnace_radiance(1.0, 1.0, -1) == math.inf
    assert analytic.furnace_radiance(0.5, 1.0, 3) == 1.75


def test_small_light_has_1e4_less_area_and_equal_power(cornell):
    small = transforms.shrink_lights(cornell, 1e-4)
    assert transforms.emitter_area(small) / transforms.emitter_area(cornell) == pytest.approx(1e-4, rel=1e-9)
    np.testing.assert_allclose(transforms.emitter_power(small), transforms.emitter_power(cornell), rtol=1e-9)
    (before,), (after,) = cornell.emitters, small.emitters
    np.testing.assert_allclose(after.vertices.mean(axis=0), before.vertices.mean(axis=0), atol=1e-15)
    np.testing.assert_allclose(after.radiance, np.multiply(before.radiance, 1e4))
    # Only the emitter changed.
    assert [m.name for m in small.meshes] == [m.name for m in cornell.meshes]
    for a, b in zip(small.meshes, cornell.meshes):
        if not b.is_emitter:
            assert a is b


def test_small_light_footprint_covers_the_light(cornell):
    small = transforms.shrink_lights(cornell, 1e-4)
    mask = transforms.emitter_footprint(small)
    (col, row), = small.camera.project_to_pixels(small.emitters[0].vertices.mean(axis=0)[None])
    assert mask[int(row), int(col)]
    assert 1 <= mask.sum() <= 25  # a sub-pixel light: its pixel and the 1-pixel margin
    keep = ~variants._small_light_exclude(small)
    assert not keep[transforms.emitter_footprint(cornell)].any()  # the original light's pixels are out too


def test_radiance_variant_scale(cornell):
    scaled, s = transforms.scale_radiance(cornell, 1e6)
    (light,) = scaled.emitters
    assert max(light.radiance) == pytest.approx(1e6, rel=1e-12)
    assert s == pytest.approx(1e6 / max(cornell.emitters[0].radiance), rel=1e-12)
    np.testing.assert_allclose(light.radiance, np.multiply(cornell.emitters[0].radiance, s), rtol=1e-12)
    assert variants._radiance_scale() == pytest.approx(s, rel=1e-12)


@pytest.mark.parametrize("s", variants.SCALES)
def test_scaled_geometry(cornell, s):
    scaled = transforms.scale_geometry(cornell, s)
    for a, b in zip(scaled.meshes, cornell.meshes):
        np.testing.assert_allclose(a.vertices, b.vertices * s)
    np.testing.assert_allclose(scaled.camera.position, np.multiply(cornell.camera.position, s))
    np.testing.assert_allclose(scaled.camera.look_at, np.multiply(cornell.camera.look_at, s))
    assert scaled.extent() == pytest.approx(cornell.extent() * s, rel=1e-12)
    for u, v in zip(scaled.camera.frame(), cornell.camera.frame()):
        np.testing.assert_allclose(u, v, atol=1e-12)
    assert (scaled.camera.fov_deg, scaled.camera.width) == (cornell.camera.fov_deg, cornell.camera.width)


def test_grazing_camera_looks_along_the_back_wall(cornell):
    g = transforms.grazing_camera(cornell, 128)
    pos = np.asarray(g.camera.position)
    assert pos[2] - (-1.0) == pytest.approx(transforms.GRAZING_DISTANCE)
    assert np.all(np.abs(pos) < 1.0)  # inside the box
    _, _, forward = g.camera.frame()
    # Angle between the view direction and the wall's plane (normal +z), towards the wall.
    assert math.degrees(math.asin(-forward[2])) == pytest.approx(transforms.GRAZING_ANGLE_DEG)
    assert g.meshes is cornell.meshes and (g.camera.width, g.camera.height) == (128, 128)


def test_1x1_expected_value_is_the_reference_mean(cornell):
    ref = load_reference(cornell)
    (v,) = variants.select_variants(["res-1x1"])
    exp = expectations._reference_expectation(v, v.build(), ref)
    assert exp.value == pytest.approx(np.asarray(ref.image, np.float64).mean(), rel=1e-13)
    assert exp.keep is None and exp.model_se_1spp > 0
    # Per-sample sd of a 1x1 pixel: the spread of the reference's pixels plus its per-pixel noise.
    pix = np.asarray(ref.image, np.float64).mean(axis=-1)
    assert exp.model_se_1spp >= pix.std()


def test_radiance_expected_is_reference_times_scale(cornell):
    ref = load_reference(cornell)
    (v,) = variants.select_variants(["radiance-1e6"])
    exp = expectations._reference_expectation(v, v.build(), ref)
    _, s = transforms.scale_radiance(cornell, variants.PEAK_RADIANCE)
    assert exp.value == pytest.approx(np.asarray(ref.image, np.float64).mean() * s, rel=1e-12)
    assert exp.scale == pytest.approx(s)


# --- end to end --------------------------------------------------------------------------


def test_cheap_subset_passes_for_pathtracer():
    seen = []
    table = suite.run_stress(["pathtracer"], ["albedo-0.5", "albedo-1", "spp-1", "res-1x1"],
                              progress=lambda done, total, label: seen.append((done, total)))
    assert list(table.columns) == list(judge.COLUMNS)
    assert list(table["variant"]) == ["albedo-0.5", "albedo-1", "spp-1", "res-1x1"]
    assert (table["renderer"] == "pathtracer").all()
    assert (table["status"] == "pass").all(), table[["variant", "status", "message"]].to_string()
    assert seen == [(0, 4), (1, 4), (2, 4), (3, 4), (4, 4)]  # as the runs start, then after each
    for col in ("time_check", "rss_check", "finite_check"):
        assert (table[col] == "pass").all()
    assert (table["time_s"] > 0).all() and (table["time_s"] <= table["time_bound_s"]).all()
    assert (table["peak_rss_mb"] > 20).all() and (table["peak_rss_mb"] <= table["rss_bound_mb"]).all()
    assert (table[["nan_count", "inf_count", "negative_count"]] == 0).all().all()
    by = table.set_index("variant")
    assert by.loc["albedo-1", "mean_check"].startswith("n/a (radiance is infinite")
    assert np.isfinite(by.loc["albedo-1", "mean"]) and by.loc["albedo-1", "mean"] > 1.0
    for name in ("albedo-0.5", "spp-1", "res-1x1"):
        r = by.loc[name]
        assert r["mean_check"] == "pass"
        assert abs(r["mean"] - r["expected"]) <= r["tolerance"]
        assert r["rel_error"] == pytest.approx(r["mean"] / r["expected"] - 1)
        assert "≤" in r["checks"] and r["tolerance_basis"]
    assert by.loc["albedo-0.5", "expected"] == 2.0
    assert by.loc["res-1x1", "resolution"] == "1x1"


def test_broken_renderers_fail_and_cbox_stress_exits_1(tmp_path):
    """Through the CLI, as a user runs it: the suite writes stress.csv, the CLI stress.html."""
    out = tmp_path / "out"
    args = ["stress", "-r", "tests.user_renderers:BrokenPixels", "-r", "tests.user_renderers:Crashes",
            "-r", "tests.user_renderers:MeshOnly", "-r", "tests.user_renderers:NeedsGPU", "-v", "albedo-0", "-v", "spp-1",
            "--out", str(out)]
    proc = run_cbox(*args, env_path=ROOT)
    assert proc.returncode == 1, proc.stderr
    assert f"wrote {out / 'stress.csv'} and {out / 'stress.html'}" in proc.stdout
    table = pd.read_csv(out / "stress.csv")
    assert list(table.columns) == list(judge.COLUMNS)
    assert len(table) == 8
    status = {(r.variant, r.renderer): r.status for r in table.itertuples()}
    for variant in ("albedo-0", "spp-1"):
        assert status[(variant, "broken-pixels")] == "fail"
        assert status[(variant, "crashes")] == "error"
        assert status[(variant, "mesh-only")] == "skipped"
        assert status[(variant, "needs-gpu")] == "skipped"
    broken = table[table["renderer"] == "broken-pixels"].iloc[0]
    assert (broken.nan_count, broken.inf_count, broken.negative_count) == (1, 1, 1)
    assert broken.finite_check == "fail" and "1 NaN, 1 Inf, 1 negative" in broken.message
    assert broken.mean_check.startswith("n/a (approximates: everything is grey")
    crash = table[table["renderer"] == "crashes"].iloc[0]
    assert "segfault simulator" in crash.message
    skipped = table[table["renderer"] == "needs-gpu"].iloc[0]
    assert "no CUDA device found" in skipped.message
    assert "does not model" in table[table["renderer"] == "mesh-only"].iloc[0].message

    html = (out / "stress.html").read_text()
    for r in table.itertuples():
        assert re.search(rf'<td class="variant">{re.escape(r.variant)}</td>\s*<td>{re.escape(r.renderer)}</td>', html)
    assert html.count('<tr data-status="') == len(table)
    assert 'class="num fail"' in html and 'class="num pass"' in html
    assert 'id="verdict">fail<' in html and "cbox stress -r tests.user_renderers:BrokenPixels" in html
    # Self-contained: no external resources.
    assert not re.search(r'(src|href)="(https?:)?//', html)
    assert "<style>" in html and "--pass-bg" in html  # report.css inlined


def test_a_passing_run_exits_0(tmp_path, capsys):
    run = suite.run_suite(["tests.user_renderers:FlatGrey"], ["albedo-0"], tmp_path)
    assert run.exit_code == 0 and run.csv_path == tmp_path / "stress.csv"
    assert run.provenance["seed"] == variants.SEED and run.provenance["kind"] == "stress"
    assert suite.print_summary(run) == 0
    assert "1 pass in " in capsys.readouterr().out
    table = pd.read_csv(tmp_path / "stress.csv")
    assert list(table["status"]) == ["pass"]
    assert table["mean_check"][0].startswith("n/a (approximates:")


def _stress_with_bounds(monkeypatch, spec: str, time_bound_s: float, rss_bound_mb: float):
    """``spec`` through the stress suite on albedo-0 with these bounds: its one row."""
    bounded = [dataclasses.replace(v, time_bound_s=time_bound_s, rss_bound_mb=rss_bound_mb)
               if v.name == "albedo-0" else v for v in variants.VARIANTS]
    monkeypatch.setattr(variants, "VARIANTS", bounded)
    return suite.run_stress([spec], ["albedo-0"]).iloc[0]


def test_time_bound_kills_the_run(monkeypatch):
    """Killed at the 3 s bound, not after the renderer's 120 s sleep. Each bound is checked in a run of its
    own, the other bound out of reach: under load (two CPU burners on two cores) the sandbox's start alone
    can take seconds, so a shared run let the time bound kill the memory hog first."""
    slow = _stress_with_bounds(monkeypatch, "tests.user_renderers:Slow", 3.0, math.inf)
    assert slow.status == "fail" and slow.time_check == "fail"
    assert "did not end within the 3 s bound" in slow.message
    assert 3.0 < slow.time_s < 120.0


def test_memory_bound_kills_the_run(monkeypatch):
    """Killed when its resident set passes 600 MB, long before its sleep ends or the (generous) time bound."""
    hog = _stress_with_bounds(monkeypatch, "tests.user_renderers:MemoryHog", MemoryHog.SLEEP_S + 60.0, 600.0)
    assert hog.status == "fail" and hog.rss_check == "fail" and hog.time_check != "fail"
    assert "600 MB bound" in hog.message and hog.peak_rss_mb > 600.0
    assert hog.time_s < MemoryHog.SLEEP_S


def test_sandbox_returns_each_render_and_checks_its_shape():
    """The sandbox on its own, as the gate uses it: images in order, each checked against its scene."""
    small, large = analytic.furnace_scene(0.5, res=4), analytic.furnace_scene(0.5, res=8)
    out = sandbox.run_sandboxed("tests.user_renderers:FlatGrey", [(small, 1, 0), (large, 1, 1)], time_bound_s=60.0)
    assert out.ended == "ok" and out.problem() is None, out.message
    assert [np.shape(i) for i in out.images] == [(4, 4, 3), (8, 8, 3)] and len(out.render_times) == 2
    assert 0 < out.time_s < 60.0 and out.peak_rss_mb > 20
    out.shapes[1] = (9, 9, 3)
    assert out.problem() == "image has shape (8, 8, 3), expected (9, 9, 3)"
    bad = sandbox.run_sandboxed("no-such-renderer", [(small, 1, 0)], time_bound_s=60.0)
    assert bad.ended == "error" and "unknown renderer" in bad.message and bad.problem() == bad.message
    # The child's own traceback comes back, down to where it raised (the gate shows it: tests/gate/test_gate_ci.py).
    assert bad.traceback.startswith("Traceback") and "_render_job" in bad.traceback
    assert "unknown renderer" in bad.traceback.splitlines()[-1]


def test_unknown_renderer_is_a_usage_error():
    from cornell_harness.adapters.registry import RendererError

    with pytest.raises(RendererError, match="unknown renderer"):
        suite.run_stress(["no-such-renderer"], ["albedo-0"])


def test_report_from_a_table_alone(tmp_path):
    from cornell_harness.reports.stress import write_stress_report

    rows = [dict.fromkeys(judge.COLUMNS) for _ in range(2)]
    rows[0].update(variant="albedo-0.5", renderer="x", status="pass", spp=4, resolution="16x16", time_s=1.0,
                   time_bound_s=60.0, peak_rss_mb=100.0, rss_bound_mb=4096.0, nan_count=0, inf_count=0,
                   negative_count=0, mean=2.0, expected=2.0, tolerance=0.01, rel_error=0.0, z=0.0,
                   time_check="pass", rss_check="pass", finite_check="pass", mean_check="pass",
                   linearity_check="n/a", checks="all good", expected_source="formula", tolerance_basis="z")
    rows[1].update(variant="albedo-0.5", renderer="y <b>", status="skipped", message="unavailable: <none>",
                   spp=4, resolution="16x16", time_bound_s=60.0, rss_bound_mb=4096.0)
    path = write_stress_report(tmp_path / "s.html", pd.DataFrame(rows, columns=list(judge.COLUMNS)),
                               {"versions": {"numpy": "2"}, "machine": "m"}, "cmd")
    html = path.read_text()
    assert "y &lt;b&gt;" in html and "unavailable: &lt;none&gt;" in html  # escaped
    assert 'id="verdict">pass<' in html and "2 ≤ 60 s" not in html and "1 ≤ 60 s" in html


def test_unknown_variants_are_rejected_before_running(tmp_path):
    with pytest.raises(ValueError, match="known: albedo-0"):
        suite.run_suite(["pathtracer"], ["albedo-7"], tmp_path / "out")
    assert not (tmp_path / "out").exists()
    proc = run_cbox("stress", "-r", "pathtracer", "-v", "albedo-7", "--out", str(tmp_path / "out"))
    assert proc.returncode == 2 and "albedo-7" in proc.stderr
    assert not (tmp_path / "out").exists()


def test_the_reference_renderer_is_the_callers():
    """The suite names no renderer: the variant references are rendered by the one its caller gives (cbox
    stress: the CLI's REFERENCE_RENDERER), and without one the variant-reference rows say why not."""
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.cli.common import REFERENCE_RENDERER

    (grazing,) = [v for v in variants.VARIANTS if v.expected == "variant-reference"]
    assert REFERENCE_RENDERER not in grazing.expected_note
    assert suite._reference_entry([], None) == (None, "no reference renderer was given")
    (entry,) = resolve(["tests.user_renderers:FlatGrey"])
    assert suite._reference_entry([entry], "tests.user_renderers:FlatGrey") == (entry, None)
    exp = expectations.expectation_for(grazing, grazing.build(), None, None, "not needed",
                                       reference_renderer="pathtracer")
    assert exp.value is None
    assert exp.source.startswith(f"no variant reference (pathtracer, {variants.REFERENCE_BATCHES} × 256 spp)")

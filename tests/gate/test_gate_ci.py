"""The gate as a CI step: strict configs, safe baselines, time limits, and outputs CI can read.

Each test runs `cbox gate` (or its config loader) on a small config; the
renderers are the test renderers of `user_renderers.py`, so nothing here is
statistical: every assertion is exact.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import pytest

from tests.conftest import ROOT, run_cbox
from cornell_harness.adapters.registry import registered_names
from cornell_harness.gate.config import GateConfigError, load_config

#: The issue's example: every key misspelt; it used to pass a flat-grey renderer (ΔE 45) with exit 0. Its
#: renderer is a grey one (seeded noise around 0.25) that logs each render, so a test can count renders.
TYPO_CONFIG = '''alpah = 0.5
basline = "b.json"
[[expect]]
scene = "cornell-box"
renderer = "tests.user_renderers:CountingNoise"
spp = 16
maxx = { delta_e2000_mean = 1.0 }
'''

GREY = '[[expect]]\nscene = "cornell-box"\nrenderer = "tests.user_renderers:{cls}"\nspp = 1\n{extra}\n'


def _write(tmp_path, text: str, name: str = "gate.toml") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def _render_log(tmp_path) -> dict[str, str]:
    """The environment that has the test renderers log each render (CountingNoise, LoggedNoise) to a file."""
    return {"CBOX_TEST_RENDER_LOG": str(tmp_path / "renders.log")}


def test_typo_config_exits_2_without_rendering(tmp_path):
    """Refused before anything renders: counted in the renderer's own log, not timed (a wall-clock bound
    flipped on a busy machine)."""
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _write(tmp_path, TYPO_CONFIG), "--out", str(out), env_path=ROOT,
                    env_extra=_render_log(tmp_path))
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [f"cbox: error: {tmp_path / 'gate.toml'}: alpah: unknown key "
                                                "(did you mean 'alpha'?)"]
    assert not (tmp_path / "renders.log").exists()  # no render started
    assert not (out / "report.html").exists()
    junit = ET.parse(out / "gate-junit.xml").getroot()
    assert junit.find("testsuite").get("errors") == "1" and junit.find(".//error") is not None
    assert "config error" in (out / "gate-summary.md").read_text()


@pytest.mark.parametrize("text, field", [
    (GREY.format(cls="FlatGrey", extra="unbaised = true"), "expect[0].unbaised: unknown key (did you mean "
                                                           "'unbiased'?)"),
    (GREY.format(cls="FlatGrey", extra="maxx = { ssim = 1 }"), "expect[0].maxx: unknown key (did you mean 'max'?)"),
    (GREY.format(cls="FlatGrey", extra="max = { delta_e_mean = 1 }"),
     "expect[0].max.delta_e_mean: unknown metric (did you mean"),
    ('regression_metrics = ["ssim", "psnrr"]\n' + GREY.format(cls="FlatGrey", extra="unbiased = true"),
     "regression_metrics: psnrr: unknown metric (did you mean 'psnr'?)"),
    (GREY.format(cls="FlatGrey", extra=""), "expect[0]: no accuracy check"),
    (GREY.format(cls="FlatGrey", extra='time_limit = "soon"\nunbiased = true'), "expect[0].time_limit: time budget"),
])
def test_strict_config(tmp_path, text, field):
    path = _write(tmp_path, text)
    with pytest.raises(GateConfigError) as err:
        load_config(path)
    assert str(err.value).startswith(f"{path}: {field}"), str(err.value)


def test_finite_only_must_be_said(tmp_path):
    cfg = load_config(_write(tmp_path, GREY.format(cls="FlatGrey", extra="finite_only = true")))
    assert cfg.expectations[0].name == "cornell-box/tests.user_renderers:FlatGrey@1spp"


def test_unknown_renderer_is_found_before_anything_renders(tmp_path):
    """The second expectation's typo stops the gate before the first renders (its renderer logs every render it
    starts: none); JUnit is written."""
    text = GREY.format(cls="CountingNoise", extra="finite_only = true") + \
        GREY.format(cls="FlatGrey", extra="finite_only = true").replace("tests.user_renderers:FlatGrey", "pathtracr")
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _write(tmp_path, text), "--out", str(out), env_path=ROOT,
                    env_extra=_render_log(tmp_path))
    assert proc.returncode == 2
    assert not (tmp_path / "renders.log").exists()  # the first expectation did not render
    assert proc.stderr.strip().splitlines()[-1].endswith(
        "expect[1].renderer: unknown renderer 'pathtracr' (did you mean 'pathtracer'?); registered: "
        f"{', '.join(registered_names())}; or give package.module:ClassName, or declare it in a renderers file "
        "(--renderers FILE)")
    assert len(proc.stderr.strip().splitlines()) == 1
    assert (out / "gate-junit.xml").exists() and (out / "gate-summary.md").exists()


def test_time_limit_kills_a_hanging_renderer_and_fails_with_its_time(tmp_path):
    """Slow sleeps 120 s: killed at the 5 s limit, so it ran at least 5 s and less than its sleep. How much
    past 5 s depends on the machine's load (the watcher polls), so only those two ends are asserted."""
    text = GREY.format(cls="Slow", extra='finite_only = true\ntime_limit = "5s"')
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _write(tmp_path, text), "--out", str(out), env_path=ROOT)
    assert proc.returncode == 1, proc.stderr
    ran = re.search(r"FAIL  cornell-box/tests\.user_renderers:Slow@1spp  time_limit: killed at its time limit of "
                    r"5 s \(ran ([0-9.]+) s\)", proc.stdout)
    assert ran and 5.0 <= float(ran[1]) < 120.0, proc.stdout
    junit = ET.parse(out / "gate-junit.xml").getroot()
    (case,) = junit.iter("testcase")  # the render, killed: its failure, not a pass
    assert case.get("name") == "render" and case.find("error") is None
    assert case.find("failure").get("message").startswith("killed at its time limit of 5 s")


def test_junit_errors_failures_and_honest_times(tmp_path):
    """A crash is an <error>, a failed check a <failure>; the render time is counted once per expectation."""
    text = GREY.format(cls="Crashes", extra="finite_only = true") + \
        GREY.format(cls="FlatGrey", extra="max = { delta_e2000_mean = 1.0 }")
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _write(tmp_path, text), "--out", str(out), env_path=ROOT)
    assert proc.returncode == 1
    suite = ET.parse(out / "gate-junit.xml").getroot().find("testsuite")
    cases = {(c.get("classname").split("/")[1], c.get("name")): c for c in suite.iter("testcase")}
    assert cases[("tests.user_renderers:Crashes@1spp", "render")].find("error") is not None
    assert cases[("tests.user_renderers:FlatGrey@1spp", "max.delta_e2000_mean")].find("failure") is not None
    assert suite.get("errors") == "1" and suite.get("failures") == "1"
    check_times = [float(c.get("time")) for (_, name), c in cases.items() if name != "render"]
    assert check_times and all(t == 0.0 for t in check_times)
    render_times = [float(c.get("time")) for (_, name), c in cases.items() if name == "render"]
    assert float(suite.get("time")) == pytest.approx(sum(render_times), abs=2e-3)
    assert "ERROR  cornell-box/tests.user_renderers:Crashes@1spp  run" in proc.stdout
    assert "Traceback" not in proc.stderr  # by default the ERROR line alone; -v adds the traceback


def test_crash_traceback_in_the_log_junit_error_and_report(tmp_path):
    """The sandboxed child's own traceback, down to the renderer's raise, comes back to the parent: in the JUnit
    <error> body (not a <failure>), in the HTML report and the Markdown, and on stderr with -v."""
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _write(tmp_path, GREY.format(cls="Crashes", extra="finite_only = true")),
                    "--out", str(out), "-v", env_path=ROOT)
    assert proc.returncode == 1, proc.stderr
    raise_line = 'raise RuntimeError("segfault simulator")'  # tests/user_renderers.py, Crashes.render
    case = next(c for c in ET.parse(out / "gate-junit.xml").getroot().iter("testcase") if c.get("name") == "render")
    assert case.find("failure") is None
    body = case.find("error").text
    assert body.startswith("failed: RenderError: renderer raised RuntimeError: segfault simulator\n\nTraceback")
    assert "user_renderers.py" in body and raise_line in body and "_worker_main" in body  # the child's frames
    assert raise_line in proc.stderr and "Traceback (most recent call last)" in proc.stderr
    assert raise_line.replace('"', "&quot;") in (out / "report.html").read_text()
    assert raise_line in (out / "gate-summary.md").read_text()


def test_a_skipped_check_is_skipped_not_passed(tmp_path):
    """FlatGrey reports no variance, so its variance check is not made: <skipped/> in JUnit, SKIP on stdout,
    "skipped" in the Markdown and the report; the verdict is the other checks' (agreement fails a flat grey)."""
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _write(tmp_path, GREY.format(cls="FlatGrey", extra="unbiased = true")),
                    "--out", str(out), env_path=ROOT)
    assert proc.returncode == 1, proc.stderr
    suite = ET.parse(out / "gate-junit.xml").getroot().find("testsuite")
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    skipped = cases["variance"].find("skipped")
    assert skipped is not None and skipped.get("message").startswith("skipped: the renderer reports no variance")
    assert cases["variance"].find("failure") is None and cases["variance"].find("system-out") is None
    assert suite.get("skipped") == "1" and suite.get("failures") == "2"  # agreement, outliers
    assert cases["finite"].find("skipped") is None
    assert "SKIP  cornell-box/tests.user_renderers:FlatGrey@1spp  variance: skipped" in proc.stdout
    assert proc.stdout.splitlines()[-1] == "gate failed: 2 check(s) (1 skipped)"
    md = (out / "gate-summary.md").read_text()
    assert "| variance | skipped |" in md and "| variance | pass |" not in md
    html = (out / "report.html").read_text()
    assert '<tr class="skipped"><td>variance</td><td>skipped</td>' in html


def test_missing_baseline_is_exit_2_unless_update_baseline_creates_it(tmp_path):
    """A baseline named but missing (a typo, or never recorded) would compare with nothing and pass in silence:
    exit 2 and one line naming the config and the field, before anything renders."""
    text = 'baseline = "base.json"\n' + GREY.format(cls="CountingNoise", extra="finite_only = true")
    path = _write(tmp_path, text)
    proc = run_cbox("gate", "--config", path, "--out", str(tmp_path / "a"), env_path=ROOT,
                    env_extra=_render_log(tmp_path))
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [f"cbox: error: {path}: baseline: {tmp_path / 'base.json'}: no such "
                                                "file; record it with cbox gate --update-baseline"]
    assert not (tmp_path / "renders.log").exists()
    assert ET.parse(tmp_path / "a" / "gate-junit.xml").getroot().find(".//error") is not None
    made = run_cbox("gate", "--config", path, "--out", str(tmp_path / "b"), "--update-baseline", env_path=ROOT,
                    env_extra=_render_log(tmp_path))
    assert made.returncode == 0, made.stderr
    assert list(json.loads((tmp_path / "base.json").read_text())["expectations"]) == [
        "cornell-box/tests.user_renderers:CountingNoise@1spp"]
    again = run_cbox("gate", "--config", path, "--out", str(tmp_path / "c"), env_path=ROOT,
                     env_extra=_render_log(tmp_path))
    assert again.returncode == 0, again.stderr


def test_update_baseline_refuses_a_failing_run(tmp_path):
    text = 'baseline = "base.json"\n' + GREY.format(cls="FlatGrey", extra="max = { delta_e2000_mean = 1.0 }")
    path = _write(tmp_path, text)
    (tmp_path / "base.json").write_text('{"expectations": {}, "seeds": {}}')
    before = (tmp_path / "base.json").read_bytes()
    proc = run_cbox("gate", "--config", path, "--out", str(tmp_path / "a"), "--update-baseline", env_path=ROOT)
    assert proc.returncode == 1
    assert "baseline not updated: 1 check(s) failed" in proc.stderr and "--force" in proc.stderr
    assert (tmp_path / "base.json").read_bytes() == before
    forced = run_cbox("gate", "--config", path, "--out", str(tmp_path / "b"), "--update-baseline", "--force",
                      env_path=ROOT)
    assert forced.returncode == 1  # the check still failed; the baseline is written all the same
    assert "delta_e2000_mean: (none) → " in forced.stderr
    assert json.loads((tmp_path / "base.json").read_text())["expectations"]


def test_update_baseline_without_a_baseline_file_is_a_config_error(tmp_path):
    proc = run_cbox("gate", "--config", _write(tmp_path, GREY.format(cls="FlatGrey", extra="finite_only = true")),
                    "--out", str(tmp_path / "o"), "--update-baseline", env_path=ROOT)
    assert proc.returncode == 2 and "baseline: --update-baseline needs baseline" in proc.stderr


def test_multi_scene_gate_writes_an_index(tmp_path):
    text = GREY.format(cls="FlatGrey", extra="finite_only = true") + \
        GREY.format(cls="FlatGrey", extra="finite_only = true").replace("cornell-box", "furnace")
    out = tmp_path / "out"
    proc = run_cbox("gate", "--config", _write(tmp_path, text), "--out", str(out), env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    index = (out / "index.html").read_text()
    assert 'href="cornell-box/report.html"' in index and 'href="furnace/report.html"' in index
    assert (out / "cornell-box" / "report.html").exists() and (out / "furnace" / "report.html").exists()
    # PASS lines stream as each expectation ends, before the verdict.
    lines = proc.stdout.splitlines()
    assert lines[-1] == "gate passed" and sum(ln.startswith("PASS  ") for ln in lines) == 2

"""Convergence experiments: the stored table, resuming after a kill, equal-time and equal-quality modes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pandas as pd
import pytest

from tests.conftest import ROOT, run_cbox

SEEDS = 6


def _converge_cmd(out, seeds=SEEDS):
    return [sys.executable, "-m", "cornell_harness", "converge", "--scene", "cornell-box", "--renderer",
            "tests.user_renderers:CountingNoise", "--spp", "1,2", "--seeds", str(seeds), "--out", str(out)]


def _env(log, **extra):
    return dict(os.environ, PYTHONPATH=str(ROOT), CBOX_TEST_RENDER_LOG=str(log), **extra)


def _rendered_seeds(lines):
    return {int(line.split()[0]) for line in lines}


def test_killed_run_resumes_without_losing_or_repeating_cells(tmp_path):
    """SIGKILL a converge run after two cells; the rerun keeps them and renders only the rest.

    The renderer holds (unlogged) once four renders, two cells of spp 1 and 2, are logged, so the kill
    lands after exactly two cells whenever this test gets to send it (it once raced a 0.4 s sleep per render).
    The 300 s wait only guards against a hang: the two cells take seconds."""
    out, log = tmp_path / "exp", tmp_path / "renders.log"
    proc = subprocess.Popen(_converge_cmd(out), cwd=ROOT, env=_env(log, CBOX_TEST_RENDER_HOLD_AFTER="4"),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    cells = out / "cells"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and len(list(cells.glob("*.parquet"))) < 2 and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = {int(p.stem.rsplit("seed", 1)[1]) for p in cells.glob("*.parquet")}
    assert len(finished) == 2, finished
    before = {s: pd.read_parquet(cells / f"counting-noise__seed{s}.parquet") for s in finished}
    first_run = log.read_text().splitlines()
    assert len(first_run) == 4 and _rendered_seeds(first_run) == finished, first_run  # the held render: unlogged

    again = subprocess.run(_converge_cmd(out), cwd=ROOT, env=_env(log), capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    second_run = log.read_text().splitlines()[len(first_run):]
    assert not (_rendered_seeds(second_run) & finished), "a finished cell was rendered again"
    assert _rendered_seeds(first_run) | _rendered_seeds(second_run) == set(range(SEEDS))

    results = pd.read_parquet(out / "results.parquet")
    assert sorted(zip(results["seed"], results["spp"])) == [(s, p) for s in range(SEEDS) for p in (1, 2)]
    assert (results["status"] == "ok").all()
    for s, rows in before.items():  # nothing finished was lost or changed
        kept = results[results["seed"] == s].reset_index(drop=True)
        pd.testing.assert_frame_equal(kept[rows.columns], rows, check_dtype=False)
    assert all((out / f).exists() for f in ("report.html", "summary.parquet", "summary.csv", "summary.tex"))


def test_results_table_is_tidy_and_report_rebuilds(tmp_path):
    out, log = tmp_path / "exp", tmp_path / "renders.log"
    proc = subprocess.run(_converge_cmd(out, seeds=2), cwd=ROOT, env=_env(log), capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    runs = pd.read_parquet(out / "results.parquet")
    key = ["scene", "renderer", "settings", "seed", "spp"]
    assert not runs.duplicated(key).any()
    for col in key + ["time_s", "version", "rmse", "rel_mse", "ssim", "delta_e2000_mean", "efficiency"]:
        assert col in runs, col
    assert json.loads(runs["scene_settings"].iloc[0]) == {"height": 256, "max_depth": -1, "pixel_filter": "box",
                                                           "width": 256}
    assert json.loads(runs["settings"].iloc[0]) == {}  # the renderer declares no settings
    config = json.loads((out / "experiment.json").read_text())
    assert config["spp"] == [1, 2] and config["seeds"] == [0, 1] and "converge" in config["command"]
    assert set(runs["estimator"]) == {"unbiased"}  # the adapter declares none
    # cornell-box names regions: the summary splits bias and variance per region too, and the console shows it.
    summary = pd.read_parquet(out / "summary.parquet")
    for region in ("walls", "boxes", "floor", "light"):
        for key in ("bias2", "variance", "bias2_fraction"):
            assert f"region.{region}.{key}" in summary, (region, key)
    assert "bias² and variance per region (95% intervals):" in proc.stdout and "region.walls" not in proc.stdout
    assert 'id="region-bias-variance-table"' in (out / "report.html").read_text()
    # A second run renders nothing, and `cbox report` rebuilds the report without rendering.
    n_renders = len(log.read_text().splitlines())
    (out / "report.html").unlink()
    rebuilt = run_cbox("report", str(out), env_path=ROOT)
    assert rebuilt.returncode == 0, rebuilt.stderr
    assert (out / "report.html").exists() and len(log.read_text().splitlines()) == n_renders


def test_report_of_missing_folder_is_a_clear_error(tmp_path):
    proc = run_cbox("report", str(tmp_path / "nothing"))
    assert proc.returncode == 2 and "experiment.json: not found" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_equal_time_mode_reports_spp_and_respects_the_budget(tmp_path):
    """Each renderer gets the spp that its two calibration renders say fills the budget, and reports its final
    render's time. Clocked reports a clock of its own (0.25 s + 1/16 s per spp), so its spp and time are exact:
    (2 - 0.25) / (1/16) = 28 spp, 2.0 s. The real renderers' wall times are not bounded: calibration and final
    render see different loads on a shared machine (a 1-4 s bound on them flipped under two CPU burners)."""
    proc = run_cbox("compare", "--scene", "cornell-box", "--renderer", "pathtracer", "--renderer", "mitsuba",
                    "--renderer", "tests.user_renderers:Clocked", "--time-budget", "2s", "--time-basis", "wall", "--json",
                    "--out", str(tmp_path), env_path=ROOT)
    assert proc.returncode == 0, proc.stderr
    recs = {r["renderer"]: r for r in map(json.loads, proc.stdout.splitlines())}
    assert set(recs) == {"pathtracer", "mitsuba", "clocked"}, list(recs)
    for r in recs.values():
        assert r["status"] == "ok" and r["spp"] >= 1 and r["info_time_budget_s"] == 2.0 and r["time_s"] > 0, r
        # By default three calibration rounds and three timings: medians with their intervals (whatever the load).
        assert r["time_repeats"] == 3 and len(r["time_samples_s"]) == 3, r
        assert r["time_s_low"] <= r["time_s"] <= r["time_s_high"] and r["info_spp_low"] <= r["spp"] <= r["info_spp_high"]
    assert recs["clocked"]["spp"] == 28 and recs["clocked"]["time_s"] == 2.0, recs["clocked"]


def test_time_budget_calibration_survives_a_stalled_render():
    """A 1-spp calibration render that reads longer than the 4-spp one (load stalled it): the per-sample cost
    falls back to t4 / 4 = 1/8 s, so a 2 s budget buys 16 spp (it once bought 2·10⁹: a render without end).
    Clocked's consistent clock still gives (2 - 0.25) / (1/16) = 28."""
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.workflows.compare import spp_for_time_budget

    scene = resolve_scene("cornell-box").with_resolution(8, 8)
    stalled, clocked = resolve(["tests.user_renderers:Stalled", "tests.user_renderers:Clocked"])
    assert spp_for_time_budget(stalled, scene, 2.0, 0) == 16
    assert spp_for_time_budget(clocked, scene, 2.0, 0) == 28


def test_equal_quality_mode_reports_time_to_target(tmp_path):
    proc = run_cbox("compare", "--scene", "cornell-box", "--renderer", "mitsuba", "--target-error",
                    "delta_e2000_mean=6", "--json", "--out", str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    (rec,) = [json.loads(line) for line in proc.stdout.splitlines()]
    assert rec["info_target_reached"] is True and rec["delta_e2000_mean"] <= 6
    # The previous power of two did not reach it (ΔE ~ 1/sqrt(spp)): the first spp that does.
    assert 4 <= rec["spp"] <= 64 and rec["time_s"] > 0


@pytest.mark.parametrize("args, words", [
    (["--time-budget", "soon"], "time budget 'soon'"),
    (["--target-error", "ssim>=0.9"], "target error"),
    (["--time-budget", "1s", "--target-error", "1"], "not both"),
])
def test_bad_mode_options(tmp_path, args, words):
    proc = run_cbox("compare", "--scene", "cornell-box", "--renderer", "mitsuba", *args, "--out", str(tmp_path))
    assert proc.returncode == 2 and words in proc.stderr


def test_converge_region_target_must_name_a_region_of_the_scene(tmp_path):
    """``--target region.<name>.<metric>=v`` is checked against the scene before anything renders."""
    proc = run_cbox("converge", "--scene", "light-panel", "-r", "pathtracer", "--spp", "1", "--seeds", "1",
                    "--target", "region.caustic.rel_mse=0.05", "--out", str(tmp_path / "x"))
    assert proc.returncode == 2
    assert "scene 'light-panel' has no region 'caustic'; its regions: (none)" in proc.stderr
    assert not (tmp_path / "x").exists()


def _converge(out, log, spp, monkeypatch, command=None):
    """``cbox converge`` of CountingNoise on cornell-box, seed 0, in this process (the workflow the command
    runs, without a second interpreter's start-up): the results table."""
    from cornell_harness.adapters.registry import resolve
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.store.references import load_reference
    from cornell_harness.workflows.converge import run_experiment
    from cornell_harness.workflows.spp_list import parse_spp_list

    monkeypatch.setenv("CBOX_TEST_RENDER_LOG", str(log))
    scene = resolve_scene("cornell-box")
    return run_experiment(out, scene, load_reference(scene), resolve(["tests.user_renderers:CountingNoise"]),
                          parse_spp_list(spp), [0], command or f"cbox converge --spp {spp}")


def _rendered_spps(log, since):
    return [line.split()[1] for line in log.read_text().splitlines()[since:]] if log.exists() else []


def test_changed_spp_list_renders_only_the_missing_checkpoints(tmp_path, monkeypatch):
    """A longer spp list renders only the new spp; rows already stored are kept unchanged; a shorter list
    renders only its new highest spp (the stored image must be at the highest), and keeps the stored rows."""
    out, log = tmp_path / "exp", tmp_path / "renders.log"
    first = _converge(out, log, "1,2", monkeypatch)
    n = len(log.read_text().splitlines())
    longer = _converge(out, log, "1,2,4", monkeypatch)
    assert _rendered_spps(log, n) == ["4"]
    assert sorted(longer["spp"]) == [1, 2, 4]
    pd.testing.assert_frame_equal(longer[longer["spp"] <= 2].reset_index(drop=True)[first.columns], first,
                                  check_dtype=False)
    n = len(log.read_text().splitlines())
    shorter = _converge(out, log, "1,2", monkeypatch)
    assert _rendered_spps(log, n) == ["2"]
    assert sorted(shorter["spp"]) == [1, 2]
    n = len(log.read_text().splitlines())
    _converge(out, log, "1,2", monkeypatch)  # nothing missing: nothing rendered
    assert _rendered_spps(log, n) == []


def test_resume_keeps_the_first_date_and_lists_each_resume(tmp_path, monkeypatch):
    out, log = tmp_path / "exp", tmp_path / "renders.log"
    _converge(out, log, "1", monkeypatch)
    first = json.loads((out / "experiment.json").read_text())
    assert first["resumed"] == []
    _converge(out, log, "1,2", monkeypatch)
    again = json.loads((out / "experiment.json").read_text())
    assert again["date"] == first["date"] and again["spp"] == [1, 2]
    assert len(again["resumed"]) == 1 and again["resumed"][0]["command"] == "cbox converge --spp 1,2"


def test_second_run_on_a_locked_folder_stops_naming_the_holder(tmp_path, monkeypatch):
    """flock conflicts between two opens of the file even in one process, so one process can play both runs;
    the CLI prints an ExperimentError as its one line with exit code 2, as for every user error."""
    from cornell_harness.store.experiments import ExperimentError, experiment_lock

    out, log = tmp_path / "exp", tmp_path / "renders.log"
    with experiment_lock(out, "cbox converge --holder-marker"):
        with pytest.raises(ExperimentError) as err:
            _converge(out, log, "1", monkeypatch)
    assert not log.exists()  # stopped before any rendering
    assert f"pid {os.getpid()}" in str(err.value) and "--holder-marker" in str(err.value)
    assert "\n" not in str(err.value)
    _converge(out, log, "1", monkeypatch)  # released on exit: the same run then goes ahead

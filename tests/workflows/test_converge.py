"""Convergence experiments with repeated timings: the final checkpoint re-timed in rounds after the cells,
stored as each repeat arrives (a rerun keeps them), and the time basis carried to the summary. The
renderers report clocks of their own (tests.user_renderers.Jittery): no verdict reads the wall clock."""

from __future__ import annotations

import json
import math

import pandas as pd
import pytest

from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows import converge
from cornell_harness.workflows import runner
from tests.user_renderers import Jittery, JitteryToo

RENDERERS = ["tests.user_renderers:Jittery", "tests.user_renderers:JitteryToo"]


@pytest.fixture(scope="module")
def cornell():
    scene = resolve_scene("furnace")  # 32 x 32: scoring takes no time
    return scene, load_reference(scene)


@pytest.fixture
def log(tmp_path, monkeypatch):
    """The renders so far as (name, spp, seed), in order (Jittery logs them); the clocks' counts reset."""
    path = tmp_path / "renders.log"
    monkeypatch.setenv("CBOX_TEST_RENDER_LOG", str(path))
    Jittery.calls = JitteryToo.calls = 0
    return lambda: [tuple(line.split()) for line in path.read_text().splitlines()] if path.exists() else []


def _run(out, cornell, k, **kw):
    scene, ref = cornell
    return converge.run_experiment(out, scene, ref, resolve(RENDERERS), [1, 2], [0, 1], "cbox converge",
                                   time_repeats=k, **kw)


def test_final_checkpoint_is_retimed_in_rounds_after_the_cells(tmp_path, cornell, log):
    runs = _run(tmp_path / "exp", cornell, 3)
    cells = log()[:8]  # each cell renders 2 spp (with its checkpoints), then 1 spp: Jittery is not progressive
    assert [(n, s) for n, _, s in cells[::2]] == [("jittery", "0"), ("jittery", "1"), ("jittery-too", "0"),
                                                  ("jittery-too", "1")]
    one_round = [("jittery", "2", "0"), ("jittery", "2", "1"), ("jittery-too", "2", "0"), ("jittery-too", "2", "1")]
    assert log()[8:] == one_round * 2
    top, rest = runs[runs["spp"] == 2], runs[runs["spp"] == 1]
    assert (top["time_repeats"] == 3).all() and (rest["time_repeats"] == 1).all()
    assert rest["time_s_low"].isna().all() and top["time_s_low"].notna().all()
    for _, row in top.iterrows():
        samples = json.loads(row["time_samples_s"])
        assert len(samples) == 3 and row["time_s"] == pytest.approx(sorted(samples)[1], abs=1e-4)
        assert row["time_s_low"] <= row["time_s"] <= row["time_s_high"]
        assert row["efficiency"] == pytest.approx(1.0 / (row["mse"] * row["time_s"]))
        assert "info_repeat_images_differ" not in row or pd.isna(row["info_repeat_images_differ"])
    # The cells' own files hold the repeats (what a rerun reads), and the experiment records K and the basis.
    stored = pd.read_parquet(tmp_path / "exp" / "cells" / "jittery__seed0.parquet")
    assert stored[stored["spp"] == 2]["time_repeats"].tolist() == [3]
    config = json.loads((tmp_path / "exp" / "experiment.json").read_text())
    assert config["time_repeats"] == 3 and config["time_basis"] == "wall"


def test_rerun_keeps_the_repeats_done_and_renders_only_the_rest(tmp_path, cornell, log):
    """A run stopped after its first repeat (each repeat is stored as it arrives) is resumed: the cells and
    that repeat are not rendered again, and the stored timing is kept. A rerun with a smaller K renders
    nothing and keeps the timings it has."""
    out, done = tmp_path / "exp", []

    def stop_after_one(name, stored):
        done.append(name)
        raise KeyboardInterrupt  # as a user's Ctrl-C after the first repeat

    with pytest.raises(KeyboardInterrupt):
        _run(out, cornell, 3, on_repeat=stop_after_one)
    first = pd.read_parquet(out / "cells" / "jittery__seed0.parquet")
    kept = json.loads(first[first["spp"] == 2]["time_samples_s"].iloc[0])
    assert done == ["jittery__seed0"] and len(kept) == 2
    before = len(log())
    runs = _run(out, cornell, 3)
    assert log()[before:] == [("jittery", "2", "1"), ("jittery-too", "2", "0"), ("jittery-too", "2", "1"),
                              ("jittery", "2", "0"), ("jittery", "2", "1"), ("jittery-too", "2", "0"),
                              ("jittery-too", "2", "1")]
    row = runs[(runs["renderer"] == "jittery") & (runs["seed"] == 0) & (runs["spp"] == 2)].iloc[0]
    assert json.loads(row["time_samples_s"])[:2] == kept and row["time_repeats"] == 3
    before = len(log())
    again = _run(out, cornell, 2)
    assert log()[before:] == [] and (again[again["spp"] == 2]["time_repeats"] == 3).all()


def _row(**changes):
    scene = resolve_scene("furnace")
    (entry,) = resolve(["tests.user_renderers:Jittery"])
    rec = runner.RunRecord.new(scene, entry, 4, 0, time_s=1.0, metrics={"mse": 0.5})
    return pd.DataFrame([rec.row()]).assign(**changes)


def test_add_timing_updates_the_median_interval_and_efficiency():
    rows = converge.add_timing(_row(), 4, (3.0, None, "a", None), "a")
    rows = converge.add_timing(rows, 4, (2.0, None, "b", None), "a")
    row = rows.iloc[0]
    assert json.loads(row["time_samples_s"]) == [1.0, 3.0, 2.0] and row["time_repeats"] == 3
    assert row["time_s"] == 2.0 and row["time_s_low"] < 2.0 < row["time_s_high"]
    assert row["efficiency"] == pytest.approx(1.0 / (0.5 * 2.0))
    assert row["info_repeat_images_differ"] == 1  # the second repeat's image was not the first's
    assert json.loads(row["cpu_time_samples_s"]) == [] and math.isnan(row["cpu_time_s_low"])
    failed = converge.add_timing(rows, 4, (None, None, None, "RuntimeError: boom"), "a").iloc[0]
    assert failed["info_time_repeat_error"] == "RuntimeError: boom" and failed["time_repeats"] == 3


def test_add_timing_to_a_row_written_before_repeats_were_recorded():
    """An older results row has time_s (and maybe cpu_time_s) but no samples: it counts as one timing."""
    old = _row(cpu_time_s=2.0).drop(columns=["time_samples_s", "cpu_time_samples_s", "time_repeats"])
    row = converge.add_timing(old, 4, (1.0, 2.0, "a", None), "a").iloc[0]
    assert json.loads(row["time_samples_s"]) == [1.0, 1.0] and json.loads(row["cpu_time_samples_s"]) == [2.0, 2.0]
    assert row["cpu_time_s"] == 2.0 and row["time_repeats"] == 2


def test_time_basis_is_recorded_and_reaches_the_summary(tmp_path, cornell, monkeypatch):
    """experiment.json records --time-basis; experiment_results passes its column to summary_table, and an
    explicit basis (cbox report --time-basis) wins over the recorded one."""
    scene, ref = cornell
    out = tmp_path / "exp"
    converge.run_experiment(out, scene, ref, resolve(RENDERERS[:1]), [1], [0], "cbox converge", time_basis="cpu")
    assert json.loads((out / "experiment.json").read_text())["time_basis"] == "cpu"
    seen = []

    def summary_table(runs, images, reference, scene, targets=(), deterministic=(), time_column="time_s"):
        seen.append(time_column)
        assert time_column in runs  # results without CPU times get the column as NaN, never a KeyError
        return pd.DataFrame()

    monkeypatch.setattr(converge, "summary_table", summary_table)
    assert converge.experiment_results(out, scene, ref).config["time_basis"] == "cpu"
    assert converge.experiment_results(out, scene, ref, time_basis="wall").config["time_basis"] == "wall"
    assert seen == ["cpu_time_s", "time_s"]


def test_cpu_basis_summary_reads_cpu_time(tmp_path, cornell):
    """End to end: with the cpu basis the efficiency is 1 / (MSE · CPU s)."""
    scene, ref = cornell
    out = tmp_path / "exp"
    converge.run_experiment(out, scene, ref, resolve(RENDERERS[:1]), [1, 2], [0], "cbox converge", time_basis="cpu")
    runs = pd.read_parquet(out / "results.parquet")
    runs["cpu_time_s"] = runs["time_s"] * 4.0  # four busy threads, say
    runs.to_parquet(out / "results.parquet")
    cpu = converge.experiment_results(out, scene, ref).summary
    wall = converge.experiment_results(out, scene, ref, time_basis="wall").summary
    assert cpu["efficiency"].iloc[0] == pytest.approx(wall["efficiency"].iloc[0] / 4.0)


def test_repeat_task_loads_its_renderer_as_a_worker_does(cornell):
    """On a worker a repeat gets no renderer object: it loads the cell's spec, renders the same render as the
    cell's first and sends back its timing and the image's digest (the image itself stays there)."""
    from cornell_harness.workflows.cells import Cell

    scene, _ = cornell
    (entry,) = resolve(["tests.user_renderers:Clocked"])
    cell = Cell("clocked__seed3", entry.spec, {}, 3, (1, 4), scene.content_hash())
    wall, cpu, digest, error = converge.repeat_cell_task(cell, scene)
    first = runner.run_one(entry, scene, 4, 3, None, checkpoints=(1, 4))
    assert error is None and wall == 0.25 + 4 / 16 and digest == converge.image_digest(first.image)
    assert cpu is None or cpu >= 0
    crashed = Cell("crashes__seed0", "tests.user_renderers:Crashes", {}, 0, (1,), scene.content_hash())
    assert converge.repeat_cell_task(crashed, scene) == (None, None, None, "RuntimeError: segfault simulator")

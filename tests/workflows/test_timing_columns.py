"""The timing columns (cornell_harness.evaluate.timing_quality.TIMING_COLUMNS) in every results row: RunRecord.row(),
``compare --json`` and a converge's results.parquet; a renderer that gives no CPU time gets its call's."""

from __future__ import annotations

import json

import pandas as pd

from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate.timing_quality import TIMING_COLUMNS
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.workflows import runner
from tests.conftest import cbox_in_process as cbox


def _timed(row: dict) -> None:
    """The six columns, top-level, with values a real measurement gives."""
    assert set(TIMING_COLUMNS) <= set(row), sorted(row)
    assert row["cpu_time_s"] >= 0 and (row["setup_s"] is None or row["setup_s"] >= 0)
    assert isinstance(row["threads"], int) and row["threads"] >= 1
    assert row["load_before"] >= 1 and row["load_after"] >= 1  # the measuring thread at least
    assert 0 < row["calibration_s"] < 2


def test_a_user_renderer_without_cpu_time_gets_its_calls(tmp_path):
    """SeededNoise measures nothing: its row's CPU time is that of the whole render call, and says so."""
    (entry,) = resolve(["tests.user_renderers:SeededNoise"])
    rec = runner.run_one(entry, resolve_scene("furnace"), 2, 0, None)
    row = rec.row()
    _timed(row)
    assert row["info_cpu_time_of"] == runner.CALL_CPU_NOTE and row["setup_s"] is None


def test_columns_in_compare_json_and_results_parquet(tmp_path, capsys):
    code, out, err = cbox(capsys, "compare", "--scene", "furnace", "-r", "tests.user_renderers:SeededNoise",
                          "--spp", "2", "--json", "--out", str(tmp_path / "compare"))
    assert code == 0, err
    (row,) = [json.loads(line) for line in out.splitlines() if line.strip()]
    _timed(row)
    stored = pd.read_parquet(tmp_path / "compare" / "results.parquet")
    assert set(TIMING_COLUMNS) <= set(stored.columns)  # setup_s None: this renderer reports no set-up
    assert stored[[c for c in TIMING_COLUMNS if c != "setup_s"]].notna().all().all()

    code, out, err = cbox(capsys, "converge", "--scene", "furnace", "-r", "tests.user_renderers:SeededNoise",
                          "--spp", "1,2", "--seeds", "2", "--out", str(tmp_path / "converge"))
    assert code == 0, err
    (path,) = (tmp_path / "converge").rglob("results.parquet")
    runs = pd.read_parquet(path)
    assert set(TIMING_COLUMNS) <= set(runs.columns)
    for _, cell in runs.groupby("seed"):  # the cell's machine figures on each of its checkpoint rows
        assert cell[["threads", "load_before", "load_after", "calibration_s"]].nunique().max() == 1
        assert cell["calibration_s"].notna().all()

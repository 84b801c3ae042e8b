"""``cbox converge`` and ``cbox report`` with repeated timings and a time basis. The renderers report clocks of
their own (tests.user_renderers.Jittery): no verdict here depends on the machine's speed or load."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from cornell_harness.workflows import converge
from tests.conftest import cbox_in_process as cbox
from tests.user_renderers import Jittery, JitteryToo


@pytest.fixture
def time_columns(monkeypatch):
    """The time column each summary was asked to read."""
    seen, real = [], converge.summary_table

    def summary_table(*args, time_column="time_s", **kwargs):
        seen.append(time_column)
        return real(*args, time_column=time_column, **kwargs)

    monkeypatch.setattr(converge, "summary_table", summary_table)
    return seen


def _converge(out, *extra):
    return ["converge", "-s", "furnace", "-r", "tests.user_renderers:Jittery", "-r",
            "tests.user_renderers:JitteryToo", "--spp", "1,2", "--seeds", "1", "--out", str(out), *extra]


def test_converge_repeats_and_basis_reach_the_table_and_the_report(tmp_path, capsys, time_columns):
    Jittery.calls = JitteryToo.calls = 0
    code, out, err = cbox(capsys, *_converge(tmp_path, "--time-repeats", "3", "--time-basis", "cpu"))
    assert code == 0, err
    # A unit of progress is a timing: each cell's first, then its repeats.
    assert "converge furnace: 6/6 timings, jittery-too seed 0 repeat" in err, err
    runs = pd.read_parquet(tmp_path / "results.parquet")
    assert runs.sort_values(["renderer", "spp"])["time_repeats"].tolist() == [1, 3, 1, 3]
    config = json.loads((tmp_path / "experiment.json").read_text())
    assert (config["time_repeats"], config["time_basis"]) == (3, "cpu")
    assert time_columns == ["cpu_time_s"]
    # cbox report redraws with the recorded basis (experiment_results' default: tests/workflows/test_converge.py)
    # or the one given.
    code, _, err = cbox(capsys, "report", str(tmp_path), "--time-basis", "wall")
    assert code == 0 and time_columns == ["cpu_time_s", "time_s"], err


def test_report_refuses_a_bad_time_basis(tmp_path, capsys):
    code, _, err = cbox(capsys, "report", str(tmp_path), "--time-basis", "wal")
    assert code == 2 and "--time-basis" in err and "did you mean 'wall'?" in err and len(err.splitlines()) == 1

"""``cbox compare`` with repeated timings: --time-repeats, --time-basis, and the spp a time budget buys printed
with its interval. The renderers report clocks of their own (tests.user_renderers.Jittery): no verdict here
depends on the machine's speed or load."""

from __future__ import annotations

import json
import re

import pytest

from cornell_harness.workflows import runner
from tests.conftest import cbox_in_process as cbox
from tests.user_renderers import Jittery, JitteryToo

JITTERY = ["-r", "tests.user_renderers:Jittery", "-r", "tests.user_renderers:JitteryToo"]


@pytest.fixture
def log(tmp_path, monkeypatch):
    path = tmp_path / "renders.log"
    monkeypatch.setenv("CBOX_TEST_RENDER_LOG", str(path))
    Jittery.calls = JitteryToo.calls = 0
    return lambda: [tuple(line.split()[:2]) for line in path.read_text().splitlines()] if path.exists() else []


def test_time_budget_prints_each_renderers_spp_and_time_with_an_interval(tmp_path, capsys, log):
    """The Done-when of issue 30 on renderers with exact clocks: 3 interleaved calibration rounds (the
    default) buy 28 spp at the median clock, with the rounds' spread as its interval; the final render is
    timed 3 times, its median and interval printed beside it. In wall seconds, as asked (auto would follow the
    machine's load)."""
    code, out, err = cbox(capsys, "compare", "-s", "furnace", *JITTERY, "--time-budget", "2s", "--time-basis", "wall",
                          "--out", str(tmp_path / "out"))
    assert code == 0, err
    rows = {m.group(1): m.groups()[1:] for m in re.finditer(
        r"^\s*(jittery(?:-too)?)\s+ok\s+(\d+) \[(\d+), (\d+)\]\s+([\d.]+) \[([\d.]+), ([\d.]+)\]", out, re.M)}
    assert set(rows) == {"jittery", "jittery-too"}, out
    for spp, low, high, t, t_low, t_high in rows.values():
        assert int(spp) == 28 and int(low) <= 21 and int(high) >= 36
        assert float(t_low) <= float(t) <= float(t_high)
    assert "median of 3 timings [95% interval]" in out and "spp [95% interval" in out
    calibration = [("jittery", "1"), ("jittery", "4"), ("jittery-too", "1"), ("jittery-too", "4")] * 3
    assert log() == calibration + [("jittery", "28"), ("jittery-too", "28")] * 3
    config = json.loads((tmp_path / "out" / "experiment.json").read_text())
    assert config["time_repeats"] == 3 and config["time_basis"] == "wall"


def test_json_rows_carry_the_repeats_and_the_spp_interval(tmp_path, capsys, log):
    code, out, err = cbox(capsys, "compare", "-s", "furnace", *JITTERY[:2], "--time-budget", "2s",
                          "--time-basis", "wall", "--time-repeats", "2", "--json", "--out", str(tmp_path))
    assert code == 0, err
    (row,) = [json.loads(line) for line in out.splitlines()]
    assert row["time_repeats"] == 2 and len(row["time_samples_s"]) == 2  # a list: no JSON inside a string
    assert row["time_s_low"] <= row["time_s"] <= row["time_s_high"]
    assert row["info_time_budget_basis"] == "wall" and row["info_spp_low"] <= row["spp"] <= row["info_spp_high"]
    assert row["cpu_time_samples_s"] == [] or len(row["cpu_time_samples_s"]) == 2


def test_plain_compare_times_once_unless_asked(tmp_path, capsys, log):
    code, out, err = cbox(capsys, "compare", "-s", "furnace", *JITTERY, "--spp", "4", "--json",
                          "--out", str(tmp_path / "a"))
    assert code == 0, err
    assert [json.loads(line)["time_repeats"] for line in out.splitlines()] == [1, 1]
    assert log() == [("jittery", "4"), ("jittery-too", "4")]
    code, out, err = cbox(capsys, "compare", "-s", "furnace", *JITTERY, "--spp", "4", "--time-repeats", "2",
                          "--out", str(tmp_path / "b"))
    assert code == 0, err
    assert log()[2:] == [("jittery", "4"), ("jittery-too", "4")] * 2  # interleaved: A B A B
    assert "median of 2 timings" in out


@pytest.mark.parametrize("command", [["compare", "-s", "furnace"], ["converge", "-s", "furnace", "--spp", "1"]])
@pytest.mark.parametrize("option, value, words", [("--time-repeats", "0", "give 1 or more"),
                                                  ("--time-repeats", "-2", "give 1 or more"),
                                                  ("--time-basis", "cpus", "give wall or cpu or auto (did you mean 'cpu'?)")])
def test_bad_timing_options_are_refused_before_anything_runs(tmp_path, capsys, log, command, option, value, words):
    code, out, err = cbox(capsys, *command, *JITTERY[:2], option, value, "--out", str(tmp_path / "x"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and option in err and words in err, err
    assert log() == [] and not (tmp_path / "x").exists()


def test_cpu_basis_is_recorded_for_the_report(tmp_path, capsys, log):
    """--time-basis cpu: experiment.json says so (cbox report redraws with it), and the budget is spent in CPU
    seconds (these renderers measure none of their own: the whole render call's stands in)."""
    code, out, err = cbox(capsys, "compare", "-s", "furnace", *JITTERY[:2], "--time-budget", "2s",
                          "--time-repeats", "1", "--time-basis", "cpu", "--json", "--out", str(tmp_path))
    assert code == 0, err
    (row,) = [json.loads(line) for line in out.splitlines()]
    assert json.loads((tmp_path / "experiment.json").read_text())["time_basis"] == "cpu"
    assert row["info_time_budget_basis"] == "cpu" and row["info_cpu_time_of"] == runner.CALL_CPU_NOTE
    assert row["info_spp_low"] is None and row["time_repeats"] == 1


def test_compare_table_shows_cpu_time_with_the_cpu_basis():
    """With CPU times in the rows (the capture of issue 30 records them), --time-basis cpu prints them beside
    wall time, each with its interval; a renderer that did not run shows NaN, not an interval."""
    from cornell_harness.cli.run import compare_table

    nan = float("nan")
    rows = [{"renderer": "a", "status": "ok", "spp": 28, "time_s": 2.0, "time_s_low": 1.5, "time_s_high": 2.5,
             "time_repeats": 3, "cpu_time_s": 3.9, "cpu_time_s_low": 3.5, "cpu_time_s_high": 4.2,
             "info_spp_low": 21, "info_spp_high": 37},
            {"renderer": "b", "status": "unavailable", "spp": 64, "time_s": None, "time_s_low": nan,
             "time_s_high": nan, "time_repeats": 0, "cpu_time_s": None, "cpu_time_s_low": nan,
             "cpu_time_s_high": nan, "info_spp_low": None, "info_spp_high": None}]
    cpu = compare_table(rows, "cpu").splitlines()
    assert cpu[1].split() == ["a", "ok", "28", "[21,", "37]", "2", "[1.5,", "2.5]", "3.9", "[3.5,", "4.2]"]
    assert cpu[2].split() == ["b", "unavailable", "64", "NaN", "NaN"]
    assert "cpu_time_s: median of 3 timings [95% interval]" in cpu
    assert cpu[-1] == "time basis: cpu, times in CPU seconds (cpu_time_s)"
    assert "cpu_time_s" not in compare_table(rows)
    budget = [{**r, "info_time_budget_s": 10.0} for r in rows]
    assert compare_table(budget, "cpu", auto=True).splitlines()[-1] == (
        "time basis: cpu, the budget and times in CPU seconds (cpu_time_s) (--time-basis auto: other processes took "
        "cores from the calibration renders)")
    assert compare_table(budget, "wall", auto=True).splitlines()[-1] == (
        "time basis: wall, the budget and times in wall seconds (time_s) (--time-basis auto: no other work beside "
        "the calibration renders)")


def test_target_error_retimes_the_render_that_reached_it(tmp_path, capsys, log):
    """--target-error: the doublings run once, then the last render (here at --max-spp: noise never reaches
    ΔE 0.001) is timed twice more, by default; its time is the median of the three."""
    code, out, err = cbox(capsys, "compare", "-s", "furnace", *JITTERY[:2], "--target-error",
                          "delta_e2000_mean=0.001", "--max-spp", "4", "--json", "--out", str(tmp_path))
    assert code == 0, err
    (row,) = [json.loads(line) for line in out.splitlines()]
    assert log() == [("jittery", "1"), ("jittery", "2"), ("jittery", "4"), ("jittery", "4"), ("jittery", "4")]
    assert row["spp"] == 4 and row["info_target_reached"] is False and row["time_repeats"] == 3
    assert row["time_s"] == sorted(row["time_samples_s"])[1]

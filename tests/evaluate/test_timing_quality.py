"""The timing-quality verdict: other processes' CPU beside the render's threads; without that figure, the load and
the calibration kernel's slowdown."""

import math

import pandas as pd

from cornell_harness.evaluate.timing_quality import timing_quality


def _rows(loads, cals, threads=2):
    return pd.DataFrame({"status": "ok", "time_s": 1.0, "cpu_time_s": 2.0, "setup_s": 0.1, "threads": threads,
                         "load_before": loads, "load_after": loads, "calibration_s": cals})


def test_a_quiet_run_is_good():
    q = timing_quality(_rows([1.0, 1.0, 1.4], [0.020, 0.021, 0.022]), cores=2)
    assert q.known and q.ok and q.contended == 0
    assert q.line().startswith("timing quality good")


def test_two_burners_beside_a_two_thread_render_on_two_cores_is_contended():
    # Two burners and the measuring thread: 3 runnable; during the render 2 + 2 threads on 2 cores.
    q = timing_quality(_rows([3.0, 3.0], [0.020, 0.021]), cores=2)
    assert not q.ok and q.contended == 2 and q.max_load == 3.0
    assert q.line().startswith("warning:") and "2 of 2" in q.line()


def test_a_calibration_kernel_slowed_by_more_than_20_percent_is_contended():
    q = timing_quality(_rows([1.0, 1.0, 1.0], [0.020, 0.0239, 0.0245]), cores=2)
    assert q.contended == 1 and math.isclose(q.calibration_slowdown, 0.0245 / 0.020)


def test_results_without_the_figures_are_unknown_not_contended():
    q = timing_quality(pd.DataFrame({"status": ["ok"], "time_s": [1.0]}), cores=2)
    assert not q.known and q.ok and "unknown" in q.line()


def test_failed_rows_are_not_judged():
    rows = _rows([5.0, 1.0], [0.02, 0.02])
    rows.loc[0, "status"] = "failed"
    assert timing_quality(rows, cores=2).ok


def test_the_commands_own_work_is_not_contention():
    """A demo on a quiet machine: its own processes raised the load and slowed the calibration kernel, but
    others used almost no CPU beside its renders (foreign_cpu): good; the figures name the foreign CPU."""
    rows = _rows([1.2, 3.0, 1.0], [0.020, 0.031, 0.021]).assign(foreign_cpu=[0.02, 0.3, 0.0])
    q = timing_quality(rows, cores=2)
    assert q.ok and q.contended == 0 and q.max_foreign == 0.3
    assert "other processes used up to 0.30 cores" in q.line()


def test_other_processes_cpu_beside_a_render_is_contention():
    # 2 render threads on 2 cores: more than half a core of others' CPU is a competitor, less is not.
    rows = _rows([1.0, 1.0, 1.0], [0.020] * 3).assign(foreign_cpu=[0.49, 0.51, 1.6])
    q = timing_quality(rows, cores=2)
    assert q.contended == 2 and not q.ok and "2 of 3" in q.line()
    # A one-thread render leaves a core to others.
    assert timing_quality(rows.assign(threads=1), cores=2).contended == 1


def test_rows_without_the_foreign_figure_keep_the_load_and_calibration_verdict():
    rows = _rows([3.0, 1.0, 1.0], [0.020, 0.020, 0.030]).assign(foreign_cpu=[math.nan, math.nan, 0.0])
    q = timing_quality(rows, cores=2)
    assert q.contended == 1  # the load of the first; the third's slow kernel is overruled by its foreign figure
    assert math.isnan(q.max_foreign) and "load up to 3.0" in q.line()


def test_auto_basis_is_cpu_only_where_a_row_was_contended():
    from cornell_harness.evaluate.timing_quality import auto_basis

    quiet = _rows([1.0, 1.0], [0.020, 0.020]).assign(foreign_cpu=[0.0, 0.1])
    assert auto_basis(quiet, cores=2) == "wall"
    assert auto_basis(quiet.assign(foreign_cpu=[0.0, 1.2]), cores=2) == "cpu"
    assert auto_basis(pd.DataFrame({"status": ["ok"], "time_s": [1.0]}), cores=2) == "wall"  # nothing known

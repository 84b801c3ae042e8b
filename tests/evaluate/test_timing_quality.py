"""The timing-quality verdict: load beside the render's threads, and the calibration kernel's slowdown."""

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

"""summary.csv (readable) and summary.tex / summary-wide.tex (booktabs table floats) from an experiment's summary
(src/cornell_harness/reports/summary_files.py).

The summary is :func:`cornell_harness.evaluate.summary.summary_table`'s on the synthetic runs of tests/report_fixtures.py:
every figure with its 95% bounds, four times to a target. The TeX is parsed (balanced braces, cells per row,
a clearly best value per column in bold, escaped names) and, where ``pdflatex`` is installed, compiled; whether it
fits a two-column page: tests/reports/test_summary_tex_fits.py.
"""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from cornell_harness.evaluate.summary import summary_table
from cornell_harness.reports import latex
from cornell_harness.reports.summary_columns import best_rows, clear_best_rows, decisive_columns, spec
from cornell_harness.reports.summary_files import readable_summary, write_summary_files
from tests import report_fixtures as rf

NAMES = ("alpha-tracer", "beta-photons", "gamma-raster")
#: A display label with every character LaTeX treats specially.
LABELS = {"alpha-tracer": 'pathtracer[sampler="independent"] & 5% #1_x'}


@pytest.fixture(scope="module")
def summary():
    case = rf.make_case(16, 16, not_run=False)
    images = {n: [case["raw"][n, s, 64] for s in (0, 1, 2)] for n in NAMES}
    return summary_table(case["runs"], images, case["reference"], case["scene"])


@pytest.fixture(scope="module")
def written(summary, tmp_path_factory):
    folder = tmp_path_factory.mktemp("summary")
    paths = write_summary_files(folder, [(None, summary)], LABELS)
    assert [p.name for p in paths] == ["summary.csv", "summary.tex", "summary-wide.tex"]
    return folder


# --------------------------------------------------------------------------
# summary.csv
# --------------------------------------------------------------------------


def test_csv_has_readable_headers_units_and_interval_columns(summary, written):
    csv = pd.read_csv(written / "summary.csv")
    assert list(csv["renderer"]) == [LABELS["alpha-tracer"], "beta-photons", "gamma-raster"]
    assert list(csv["recorded name"]) == list(NAMES)  # a label hides the name runs are recorded under
    for header in ("time to mean ΔE00 ≤ 1 (s)", "time to relMSE ≤ 0.001 (s)", "efficiency, 1/(MSE·s)",
                   "slope of RMSE against time (log-log)", "bias share (%)", "time at the highest spp (s)"):
        assert header in csv.columns and f"{header} 95% low" in csv.columns and f"{header} 95% high" in csv.columns
    assert not [c for c in csv.columns if "_" in c], "a raw column name is left"
    assert csv["clock"].tolist() == ["wall"] * 3
    share = csv.set_index("recorded name")["bias share (%)"]
    assert share["gamma-raster"] == pytest.approx(100 * summary.set_index("renderer").loc["gamma-raster",
                                                                                           "bias2_fraction"], rel=1e-3)


def test_csv_numbers_have_at_most_four_significant_digits(written):
    text = (written / "summary.csv").read_text(encoding="utf-8")
    numbers = re.findall(r"(?<![\w.])-?\d+\.\d+(?:e[-+]?\d+)?", text)
    assert numbers
    for n in numbers:
        mantissa = n.lstrip("-").split("e")[0].replace(".", "").strip("0")
        assert len(mantissa) <= 4, n


def test_region_columns_name_the_region_before_the_unit():
    assert spec("region.walls.bias2").text == "bias² in walls (radiance²)"
    assert spec("time_to_region.caustic.rel_mse_le_0.01").text == "time to relMSE in caustic ≤ 0.01 (s)"


# --------------------------------------------------------------------------
# summary.tex
# --------------------------------------------------------------------------


def _top_level(text: str, sep: str) -> list[str]:
    """``text`` split at ``sep`` outside braces; escaped characters (``\\&``, ``\\{``) are not separators."""
    parts, depth, i, start = [], 0, 0, 0
    while i < len(text):
        if depth == 0 and text.startswith(sep, i):
            parts.append(text[start:i])
            i = start = i + len(sep)
            continue
        if text[i] == "\\":
            i += 2
            continue
        depth += {"{": 1, "}": -1}.get(text[i], 0)
        assert depth >= 0, f"a closing brace without its opening one: {text[:i + 1]!r}"
        i += 1
    assert depth == 0, f"unbalanced braces in {text!r}"
    return parts + [text[start:]]


def _table(tex: str) -> tuple[list[str], list[list[str]]]:
    """(header cells, rows of cells) of the one tabular in ``tex``."""
    body = tex[tex.index("\\toprule") + len("\\toprule"):tex.index("\\bottomrule")]
    head, rows = body.split("\\midrule")
    header = _top_level(head.strip().removesuffix("\\\\").strip(), "&")
    rows = [_top_level(r.strip(), "&") for r in _top_level(rows.strip(), "\\\\") if r.strip()]
    return [h.strip() for h in header], [[c.strip() for c in r] for r in rows]


@pytest.mark.parametrize("name, float_env", [("summary.tex", "table"), ("summary-wide.tex", "table*")])
def test_tex_is_a_booktabs_float_with_a_cell_per_column(written, name, float_env):
    tex = (written / name).read_text(encoding="utf-8")
    _top_level(tex.split("\n", 3)[-1], "\0")  # braces balanced in the whole table
    assert tex.count("\\toprule") == tex.count("\\midrule") == tex.count("\\bottomrule") == 1
    assert f"\\begin{{{float_env}}}[tbp]" in tex and tex.rstrip().endswith(f"\\end{{{float_env}}}")
    header, rows = _table(tex)
    assert len(rows) == 3 and all(len(r) == len(header) for r in rows), (header, rows)
    assert 1 < len(header) <= 9  # a renderer column and at most 8 figures
    assert re.search(r"\\begin\{tabular\}\{l(r+)\}", tex).group(1) == "r" * (len(header) - 1)
    assert "efficiency\\\\1/(MSE$\\cdot$s)" in tex


def test_the_wide_table_has_more_figures_with_their_headers(written):
    narrow, _ = _table((written / "summary.tex").read_text(encoding="utf-8"))
    wide, _ = _table((written / "summary-wide.tex").read_text(encoding="utf-8"))
    assert len(wide) > len(narrow) >= 3
    assert "{\\begin{tabular}[b]{@{}c@{}}time to\\\\mean $\\Delta E_{00}$\\\\$\\le 2$ (s)\\end{tabular}}" in wide


def test_tex_escapes_names_and_wraps_long_ones(written):
    _, rows = _table((written / "summary.tex").read_text(encoding="utf-8"))
    assert rows[0][0] == (r"{\begin{tabular}[t]{@{}l@{}}pathtracer{[} \\ sampler= \\ "
                          r"{\ttfamily\char34}independent{\ttfamily\char34}{]} \\ \& 5\% \#1\_x\end{tabular}}")
    assert [r[0] for r in rows[1:]] == ["beta-photons", "gamma-raster"]


def test_tex_bolds_a_best_value_only_where_its_interval_overlaps_no_other(summary, written):
    tex = (written / "summary-wide.tex").read_text(encoding="utf-8")
    header, rows = _table(tex)
    keys = [k for k in decisive_columns(list(summary.columns)) if latex.header_cell(spec(k).tex) in header]
    assert keys[0] == "slope_rmse_spp" and "efficiency" in keys and len(keys) == len(header) - 1
    directed = 0
    for j, key in enumerate(keys, start=1):
        bold = {i for i, r in enumerate(rows) if "\\textbf" in r[j]}
        assert bold == clear_best_rows(list(summary[key]), list(summary[key + "_low"]), list(summary[key + "_high"]),
                                       spec(key).better), key
        assert bold <= best_rows(list(summary[key]), spec(key).better), key
        directed += spec(key).better is not None
    assert directed >= 3
    assert "Bold: a column's best value where its 95\\% interval overlaps no other renderer's." in tex


def test_clear_best_needs_an_interval_apart_from_every_other():
    assert clear_best_rows([1.0, 2.0, 3.0], [0.5, 1.5, 2.0], [1.4, 2.5, 4.0], "low") == {0}
    assert clear_best_rows([1.0, 2.0, 3.0], [0.5, 1.5, 2.0], [1.6, 2.5, 4.0], "low") == set()  # meets the next
    assert clear_best_rows([1.0, 2.0, 9.0], [0.5, 1.5, 0.9], [1.4, 2.5, 20.0], "low") == set()  # a wide third
    assert clear_best_rows([1.0, 2.0, None], [0.5, 1.5, None], [1.4, 2.5, None], "low") == {0}  # no value: no say
    assert clear_best_rows([3.0, 2.0], [None, None], [None, None], "high") == {0}  # no intervals: the points
    assert clear_best_rows([2.0, 2.0], [2.0, 2.0], [2.0, 2.0], "high") == set()  # a tie
    assert clear_best_rows([2.0], [1.0], [3.0], "high") == set()  # nothing to be better than
    assert clear_best_rows([1.0, 5.0], [0.9, 4.0], [1.1, 6.0], None) == set()  # no direction


def test_a_column_no_row_has_a_value_of_is_left_out(summary, tmp_path):
    s = summary.copy()
    s["efficiency"] = np.nan
    write_summary_files(tmp_path, [(None, s)])
    for name in ("summary.tex", "summary-wide.tex"):
        header, rows = _table((tmp_path / name).read_text(encoding="utf-8"))
        assert not [h for h in header if "efficiency" in h] and all(len(r) == len(header) for r in rows)
    assert "efficiency, 1/(MSE·s)" in pd.read_csv(tmp_path / "summary.csv").columns  # the CSV keeps every column


def test_tex_intervals_are_shown(written):
    _, rows = _table((written / "summary.tex").read_text(encoding="utf-8"))
    cells = [c for r in rows for c in r[1:]]
    assert any("\\pm" in c for c in cells)  # slopes: symmetric
    assert any(re.search(r"\^\{\+[^}]+\}_\{-[^}]+\}", c) for c in cells)  # bootstrapped times: asymmetric


def test_decisive_columns_keep_the_first_in_priority_when_too_many():
    cols = ["renderer", "slope_rmse_spp", "slope_rmse_spp_low", "slope_rmse_spp_high", "slope_rmse_time",
            *[f"time_to_rel_mse_le_{v}" for v in (0.1, 0.01, 0.001)], "efficiency", "bias2_fraction"]
    assert decisive_columns(cols, 4) == ["slope_rmse_spp", "time_to_rel_mse_le_0.1", "efficiency", "bias2_fraction"]


@pytest.mark.skipif(shutil.which("pdflatex") is None,
                    reason="pdflatex is not installed (scripts/setup.sh --tests installs texlive-latex-base and "
                           "texlive-latex-recommended)")
def test_tex_compiles_with_pdflatex(written, tmp_path):
    doc = tmp_path / "paper.tex"
    doc.write_text("\\documentclass{article}\n\\usepackage{booktabs}\n\\usepackage{graphicx}\n\\begin{document}\n"
                   f"\\input{{{(written / 'summary.tex').as_posix()}}}\n"
                   f"\\input{{{(written / 'summary-wide.tex').as_posix()}}}\n\\end{{document}}\n", encoding="utf-8")
    proc = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "-no-shell-escape", doc.name],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    log = (tmp_path / "paper.log").read_text(errors="replace") if (tmp_path / "paper.log").exists() else ""
    assert proc.returncode == 0 and (tmp_path / "paper.pdf").stat().st_size > 1000, proc.stdout[-3000:]
    assert "Missing character" not in log, "a character the font cannot print (escaping)"


def test_a_summary_of_single_images_shows_their_errors(tmp_path):
    """compare-image's summary has no convergence figures: its image errors make the table, best in bold."""
    summary = pd.DataFrame({"renderer": ["a", "b"], "delta_e2000_mean": [1.5, 0.7], "psnr": [30.0, 28.0],
                            "nan_count": [0, 0]})
    write_summary_files(tmp_path, [(None, summary)])
    header, rows = _table((tmp_path / "summary.tex").read_text(encoding="utf-8"))
    assert header == ["renderer", "mean $\\Delta E_{00}$", "PSNR (dB)"]
    assert rows == [["a", "$1.50$", "\\textbf{\\boldmath$30.0$}"], ["b", "\\textbf{\\boldmath$0.700$}", "$28.0$"]]
    assert pd.read_csv(tmp_path / "summary.csv").columns.tolist() == ["renderer", "mean ΔE00", "PSNR (dB)", "NaN px"]


def test_merged_tables_have_an_experiment_column_and_a_table_each(summary, tmp_path):
    write_summary_files(tmp_path, [("run A_1", summary), ("run B", summary.iloc[:1]), ("empty", summary.iloc[0:0])])
    csv = pd.read_csv(tmp_path / "summary.csv")
    assert csv.columns[0] == "experiment" and csv["experiment"].tolist() == ["run A_1"] * 3 + ["run B"]
    tex = (tmp_path / "summary.tex").read_text(encoding="utf-8")
    assert tex.count("\\begin{tabular}{l") == 2 and "\\textbf{run A\\_1}" in tex and "empty" not in tex
    assert readable_summary(summary.iloc[:1]).columns.tolist()[0] == "renderer"  # no labels: no recorded name
    assert "recorded name" not in readable_summary(summary).columns

"""summary.tex and summary-wide.tex drop into a two-column paper: compiled by pdflatex, no overfull box, not shrunk.

The summary is a realistic one: the demo's columns (a slope with its Student-t interval, four times to a target
of which one no renderer reached, efficiencies up to 10^4, bias shares some of which are not significant) for
twelve renderers, some with long names and settings. The check is shown able to fail: the same table as a bare
``tabular`` of all its columns (what summary.tex was before it became a float laid out for its width) is
overfull in the same document.
"""

from __future__ import annotations

import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from cornell_harness.reports import latex
from cornell_harness.reports.summary_columns import decisive_columns, spec
from cornell_harness.reports.summary_files import TEX_LAYOUTS, write_summary_files

pytestmark = pytest.mark.skipif(
    shutil.which("pdflatex") is None,
    reason="pdflatex is not installed (scripts/setup.sh --tests installs texlive-latex-base and "
           "texlive-latex-recommended)")

NAMES = ["ambient", "luxcore[engine=BIDIRCPU,sampler=SOBOL]", "mitsuba", "mitsuba+oidn",
         'pathtracer[sampler="independent",max_depth=12]', "pathtracer+oidn", "photonmap[photons=200000]",
         "probes", "pyrender", "sppm[radius=0.05,alpha=0.7]", "whitted", "my-own-renderer-v2"]
TARGETS = ("time_to_delta_e2000_mean_le_2", "time_to_delta_e2000_mean_le_1", "time_to_rel_mse_le_0.01",
           "time_to_rel_mse_le_0.001")


def realistic_summary(seed: int = 7) -> pd.DataFrame:
    """A summary with the demo's columns and spreads of values (fixed seed)."""
    rng = np.random.default_rng(seed)
    n = len(NAMES)
    out = {"renderer": NAMES, "seeds": [4] * n, "max_spp": [64] * n, "time_column": ["time_s"] * n}

    def bootstrapped(key, centre, spread, missing=0.0):
        v = centre * np.exp(rng.normal(0, spread, n))
        v[rng.random(n) < missing] = np.nan
        out[key], out[key + "_low"], out[key + "_high"] = v, v / np.exp(rng.uniform(0.05, 2, n)), \
            v * np.exp(rng.uniform(0.05, 2.5, n))

    for key in ("slope_rmse_spp", "slope_rmse_time"):
        v, ci = -rng.uniform(0.04, 0.62, n), rng.uniform(0.03, 0.22, n)
        out[key], out[key + "_ci"], out[key + "_low"], out[key + "_high"] = v, ci, v - ci, v + ci
    for key, missing in zip(TARGETS, (0.5, 0.8, 0.3, 0.0)):
        bootstrapped(key, 3.0, 1.0, missing)
    out["time_to_rel_mse_le_0.001"] = np.full(n, np.nan)  # no renderer reached it: its column is dropped
    bootstrapped("efficiency", 2000.0, 1.5)
    bootstrapped("time_at_max_spp", 4.0, 0.8)
    share = rng.uniform(0.0, 1.0, n)
    out["bias2_fraction"], out["bias2_fraction_low"] = share, np.where(share < 0.5, 0.0, share * 0.8)
    out["bias2_fraction_high"] = np.minimum(share * 1.2, 1.0)
    return pd.DataFrame(out)


DOCUMENT = ("\\documentclass[twocolumn]{article}\n\\usepackage{booktabs}\n\\usepackage{graphicx}\n"
            "\\begin{document}\nSome text of the paper.\n%s\n\\end{document}\n")


def compile_log(folder, body: str) -> str:
    """pdflatex's log of a two-column article with ``body``; the run must succeed."""
    (folder / "paper.tex").write_text(DOCUMENT % body, encoding="utf-8")
    proc = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "-no-shell-escape",
                           "paper.tex"], cwd=folder, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout[-3000:]
    return (folder / "paper.log").read_text(errors="replace")


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fits")
    write_summary_files(folder, [(None, realistic_summary())])
    return folder


def test_both_tables_fit_a_two_column_article_unshrunk(written):
    log = compile_log(written, "\\input{summary.tex}\n\\input{summary-wide.tex}")
    assert "Overfull" not in log, re.findall(r"Overfull.*", log)
    assert "scaled down" not in log, "laid out wider than the column or text width it is made for"
    assert "Missing character" not in log
    tex, wide = ((written / f).read_text(encoding="utf-8") for f in ("summary.tex", "summary-wide.tex"))
    assert "\\begin{table}[" in tex and "\\begin{table*}[" in wide
    assert "$\\le 0.01$" in wide and "$\\le 0.001$" not in wide  # the target no renderer reached: no column


def test_a_merged_summary_fits_too(tmp_path):
    s = realistic_summary(11)
    write_summary_files(tmp_path, [("caustics, 4 seeds", s), ("the plain box", s.iloc[::2])])
    log = compile_log(tmp_path, "\\input{summary.tex}\n\\input{summary-wide.tex}")
    assert "Overfull" not in log and "scaled down" not in log
    assert "\\label{tab:cbox-summary-2}" in (tmp_path / "summary.tex").read_text()


def test_the_check_fails_on_the_table_as_it_was(tmp_path):
    """The same figures as one bare tabular of every decisive column at the body's size run into the margin."""
    s = realistic_summary()
    keys = decisive_columns(list(s.columns))
    rows = [[latex.escape(r["renderer"])] + [latex.value_cell(r[k], r.get(k + "_low"), r.get(k + "_high"))
                                             for k in keys] for r in s.to_dict("records")]
    table = latex.tabular(["renderer"] + [spec(k).tex for k in keys], rows, "l" + "r" * len(keys))
    assert "Overfull \\hbox" in compile_log(tmp_path, table)


def test_narrower_pages_shrink_the_table_instead_of_overflowing(written):
    """A page narrower than the layout's (a 6 cm column) gets the table scaled to fit, and the log says so."""
    log = compile_log(written, "\\setlength{\\columnwidth}{6cm}\\setlength{\\linewidth}{6cm}\n"
                               "\\input{summary.tex}")
    assert "scaled down" in log and "Overfull" not in log


def test_layouts_are_a_column_and_the_text_width():
    assert [(lay.file, lay.wide) for lay in TEX_LAYOUTS] == [("summary.tex", False), ("summary-wide.tex", True)]

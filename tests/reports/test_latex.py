"""src/cornell_harness/reports/latex.py: escaping, numbers with their 95% intervals, the booktabs tabular."""

from __future__ import annotations

import math

import pytest

from cornell_harness.reports import latex


@pytest.mark.parametrize("text, tex", [
    ('pathtracer[sampler="independent"]', r"pathtracer{[}sampler={\ttfamily\char34}independent{\ttfamily\char34}{]}"),
    ("a_b & 5% #1 $x {y} ~^\\", r"a\_b \& 5\% \#1 \$x \{y\} \textasciitilde{}\textasciicircum{}\textbackslash{}"),
    ("ΔE ≤ 1 — fast", r"$\Delta$E $\le$ 1 --- fast"),
    ("plain-name.v2", "plain-name.v2"),
])
def test_escape(text, tex):
    assert latex.escape(text) == tex


@pytest.mark.parametrize("v, text", [
    (0.0, "0"), (-0.4981, "-0.498"), (0.012345, "0.0123"), (491.3, "491"), (9996.0, "1.00\\times10^{4}"),
    (1.234e5, "1.23\\times10^{5}"), (1.2e-5, "1.20\\times10^{-5}"), (0.00012, "0.000120"),
])
def test_number_has_three_significant_digits(v, text):
    assert latex.number(v) == text


@pytest.mark.parametrize("args, cell", [
    ((-0.498, -0.51, -0.486), r"$-0.498 \pm 0.012$"),  # symmetric: ± the half-width
    ((491.3, 480.0, 520.0), r"$491^{+29}_{-11}$"),  # asymmetric (a log-scale interval): + and − apart
    ((1.234e5, 1.1e5, 1.5e5), r"$(1.23^{+0.27}_{-0.13})\times10^{5}$"),  # one exponent for the value and its interval
    ((6e-16, -0.01, 0.01), r"$0.000 \pm 0.010$"),  # no finer than the interval
    ((2.0, 2.5, 3.0), r"$2.00\ [2.50, 3.00]$"),  # a value outside its interval: the bounds as they are
    ((0.05, None, None), r"$0.0500$"),
    ((2501.0, 1970.0, 3170.0), r"$2500^{+670}_{-530}$"),
    ((5.78e-16, 5.78e-16, 5.78e-16), r"$5.78\times10^{-16}$"),  # no spread: the value alone
    ((math.nan, 1.0, 2.0), latex.MISSING),
    ((None,), latex.MISSING),
])
def test_value_cell(args, cell):
    assert latex.value_cell(*args) == cell


def test_bold_cell_is_textbf_with_bold_maths():
    assert latex.value_cell(0.2, 0.1, 0.3, bold=True) == r"\textbf{\boldmath$0.20 \pm 0.10$}"


def test_tabular_is_booktabs_and_checks_its_shape():
    text = latex.tabular(["renderer", r"time to\\target (s)"], [["a", "$1$"], ["b", "---"]], "lr")
    lines = text.splitlines()
    assert lines[:2] == [r"\begin{tabular}{lr}", r"\toprule"] and lines[-2:] == [r"\bottomrule", r"\end{tabular}"]
    assert lines[2] == r"renderer & {\begin{tabular}[b]{@{}c@{}}time to\\target (s)\end{tabular}} \\"
    assert lines[3] == r"\midrule" and lines[4] == r"a & $1$ \\"
    with pytest.raises(ValueError, match="2 alignments"):
        latex.tabular(["a", "b"], [["1"]], "lr")

"""LaTeX pieces for paper tables: escaping, numbers with 95% intervals, and a booktabs ``tabular``.

Needs only the ``booktabs`` package (``\\toprule``, ``\\midrule``,
``\\bottomrule``); numbers are plain math (no ``siunitx``), so a table
compiles with a small TeX install (Debian's ``texlive-latex-base`` and
``texlive-latex-recommended``, which ships ``booktabs.sty``). What a summary's
table holds is :func:`cornell_harness.reports.summary_files.summary_tex`'s.

Numbers (:func:`value_cell`): the value at 3 significant digits, in fixed
notation from 0.0001 to 9999, else as mantissa × 10^e; a 95% interval's
distances from the value at 2 significant digits (the usual precision of an
uncertainty), and the value then no finer than they are (``37^{+66}_{-24}``,
not ``37.4``; ``0.000 ± 0.010`` for a slope of 6e-16). The interval is written

- ``v ± h`` when it is symmetric about the value to within 10% of its width
  (slopes are: mean ± Student-t half-width), ``h`` the half-width;
- ``v^{+a}_{-b}`` otherwise (intervals of times and efficiencies are
  bootstrapped on the log scale: asymmetric is normal), ``a = high − v``,
  ``b = v − low``;
- ``v [low, high]`` in the odd case of a value outside its own interval.

A value outside the fixed range shares its exponent with its interval:
``(1.23 ± 0.05) × 10^{5}``.

A table drops into a paper as a float (:func:`table_float`): ``table`` for one
column of a two-column page, ``table*`` for the full text width. Its layout is
chosen to fit those widths in a standard two-column ``article``; in a narrower
document the float shrinks the table to the line width (``\\resizebox``, from
``graphicx``) rather than letting it run into the margin, and says so in the log.
"""

from __future__ import annotations

import math
import re
from typing import Sequence

#: Characters special to LaTeX (or set wrongly in the default OT1 encoding) → what prints them as themselves.
_ESCAPES = {
    "\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_", "{": r"\{",
    "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}",
    # [ ] read as an optional argument after \\ or at a cell's start; braced they are plain brackets.
    "[": "{[}", "]": "{]}",
    # OT1 text fonts put other glyphs (¡ ¿ —) at < > | and a closing quote at ": math and typewriter have them.
    "<": r"$<$", ">": r"$>$", "|": r"$|$", '"': r"{\ttfamily\char34}",
    # A few characters of labels and headers that a LaTeX without a Unicode font cannot typeset.
    "Δ": r"$\Delta$", "²": r"$^2$", "·": r"$\cdot$", "×": r"$\times$", "≤": r"$\le$", "≥": r"$\ge$",
    "−": r"$-$", "–": "--", "—": "---", "…": r"\dots{}", "±": r"$\pm$",
}

#: A missing value (no number, or a target never reached).
MISSING = "---"
_FIXED = (1e-4, 1e4)  # |v| in [low, high): fixed notation


def escape(text: str) -> str:
    """``text`` as LaTeX that prints it as it is (``pathtracer[sampler="independent"]``, ``a_b & 5%``)."""
    return "".join(_ESCAPES.get(ch, ch) for ch in str(text))


def round_sig(v: float, sig: int) -> float:
    """``v`` rounded to ``sig`` significant digits (as printing it in e-notation does)."""
    return float(f"{v:.{sig - 1}e}")


def _exponent(v: float) -> int:
    return 0 if v == 0 else math.floor(math.log10(abs(v)))


def number(v: float, sig: int = 3) -> str:
    """``v`` at ``sig`` significant digits as math-mode text (no ``$``): ``0.0123``, ``-0.498``,
    ``1.23\\times10^{5}``."""
    r = round_sig(float(v), sig)
    if r == 0:
        return "0"
    e = _exponent(r)
    if _FIXED[0] <= abs(r) < _FIXED[1]:
        return f"{r:.{max(sig - 1 - e, 0)}f}"
    return f"{r / 10 ** e:.{sig - 1}f}\\times10^{{{e}}}"


def _to_precision(v: float, error: float) -> str:
    """``v`` at 3 significant digits, but no finer than the last of ``error``'s 2 (``0.000`` for 6e-16 ± 0.01);
    in fixed notation where that range allows, else as :func:`number` writes it."""
    r = round_sig(v, 3)
    if not (_FIXED[0] <= error < _FIXED[1] and abs(r) < _FIXED[1]):
        return number(v)
    own = 2 - _exponent(r) if abs(r) >= _FIXED[0] else 99  # a value too small for fixed notation: the error's
    if own < 0:  # 2501 → 2500: 3 significant digits in an integer
        return f"{round(v, own):.0f}"
    decimals = max(min(own, 1 - _exponent(round_sig(error, 2))), 0)
    text = f"{v:.{decimals}f}"
    return text[1:] if text.startswith("-") and float(text) == 0 else text


def _finite(v) -> bool:
    try:
        return math.isfinite(float(v))
    except (TypeError, ValueError):
        return False


def value_cell(v, low=None, high=None, bold: bool = False) -> str:
    """A table cell for ``v`` with its 95% interval ``[low, high]`` where both are finite (see the module's
    rule); :data:`MISSING` for no value; ``\\textbf`` (and bold maths) when ``bold``."""
    if not _finite(v):
        return MISSING
    v = float(v)
    if _finite(low) and _finite(high):
        lo, hi = float(low), float(high)
        a, b = hi - v, v - lo
        if a < 0 or b < 0:
            body = f"{number(v)}\\ [{number(lo)}, {number(hi)}]"
        elif a + b == 0:  # no spread at all (a deterministic renderer): the value alone
            body = number(v)
        else:
            top = round_sig(max(abs(v), a, b), 3)
            e = _exponent(top) if top and not _FIXED[0] <= top < _FIXED[1] else 0
            s = 10.0 ** e
            m = _to_precision(v / s, min(x for x in (a / s, b / s) if x > 0) if a + b > 0 else 0.0)
            if abs(a - b) <= 0.1 * (a + b):
                inner = f"{m} \\pm {number((a + b) / 2 / s, 2)}"
            else:
                inner = f"{m}^{{+{number(a / s, 2)}}}_{{-{number(b / s, 2)}}}"
            body = f"({inner})\\times10^{{{e}}}" if e else inner
    else:
        body = number(v)
    cell = f"${body}$"
    return f"\\textbf{{\\boldmath{cell}}}" if bold else cell


def header_cell(tex: str) -> str:
    """A header; a ``\\\\`` in it breaks the line (a braced, nested one-column tabular)."""
    if "\\\\" not in tex:
        return tex
    return f"{{\\begin{{tabular}}[b]{{@{{}}c@{{}}}}{tex}\\end{{tabular}}}}"


_SCRIPTS = re.compile(r"\^\{([^{}]*)\}(?:_\{([^{}]*)\})?")


def approx_width(tex: str, font_pt: float) -> float:
    """A generous estimate, in pt, of how wide one line of ``tex`` (a cell of this module's) sets at ``font_pt``:
    half an em a character, a command as one character, a superscript over a subscript as the wider of the
    two at script size, bold a tenth wider. Enough to lay out a table for a width; the float's guard catches the rest."""
    bold = 1.1 if tex.startswith("\\textbf") else 1.0
    tex = tex.replace("\\textbf{\\boldmath", "").replace("{\\ttfamily\\char34}", '"')
    scripts = sum(0.75 * max(len(m.group(1)), len(m.group(2) or "")) for m in _SCRIPTS.finditer(tex))
    plain = re.sub(r"\\[a-zA-Z]+\s?", "x", _SCRIPTS.sub("", tex))
    plain = re.sub(r"[{}$]|\\(?=[^a-zA-Z])", "", plain)
    return 0.55 * font_pt * bold * (len(plain) + scripts)


def break_lines(text: str, width: int) -> list[str]:
    """``text`` in lines of at most about ``width`` characters, broken only after a space or one of ``[,=+-_/`` (a
    renderer's name and its settings); a piece longer than ``width`` stays whole."""
    pieces, start = [], 0
    for i, ch in enumerate(text):
        if ch in " [,=+-_/" and i + 1 < len(text):
            pieces.append(text[start:i + 1])
            start = i + 1
    pieces.append(text[start:])
    lines = [""]
    for piece in pieces:
        if lines[-1] and len(lines[-1]) + len(piece.rstrip()) > width:
            lines.append("")
        lines[-1] += piece
    return [line.rstrip() for line in lines]


def stacked_cell(lines: Sequence[str], align: str = "t") -> str:
    """Cells (already LaTeX) stacked in one cell, a braced one-column tabular aligned at its top (``t``) or
    bottom (``b``) line; one line as it is."""
    if len(lines) == 1:
        return lines[0]
    body = " \\\\ ".join(lines)
    return f"{{\\begin{{tabular}}[{align}]{{@{{}}l@{{}}}}{body}\\end{{tabular}}}}"


def table_float(tabular_tex: str, caption: str, label: str, wide: bool, size: str = "footnotesize") -> str:
    """``tabular_tex`` as a ``table`` (``wide``: ``table*``) float with ``caption`` above it and ``label``, set in
    ``size`` with narrow column gaps; scaled down to the line width only where it would not fit (see the
    module)."""
    env = "table*" if wide else "table"
    return (f"\\begin{{{env}}}[tbp]\n\\centering\n\\caption{{{caption}}}\\label{{{label}}}\n"
            f"\\{size}\\setlength{{\\tabcolsep}}{{3pt}}\n\\sbox0{{%\n{tabular_tex}}}%\n"
            f"\\ifdim\\wd0>\\linewidth\\typeout{{cbox: table {label} scaled down to the line width}}%\n"
            "\\resizebox{\\linewidth}{!}{\\usebox0}\\else\\usebox0\\fi\n"
            f"\\end{{{env}}}\n")


def tabular(header: Sequence[str], rows: Sequence[Sequence[str]], align: str) -> str:
    """A booktabs ``tabular`` of LaTeX cells (already escaped), one ``align`` letter per column."""
    if len(align) != len(header) or any(len(r) != len(header) for r in rows):
        raise ValueError(f"tabular: {len(align)} alignments and {len(header)} header cells; rows of "
                         f"{sorted({len(r) for r in rows})} cells")
    lines = [f"\\begin{{tabular}}{{{align}}}", "\\toprule", " & ".join(header_cell(h) for h in header) + " \\\\",
             "\\midrule"]
    lines += [" & ".join(r) + " \\\\" for r in rows]
    lines += ["\\bottomrule", "\\end{tabular}"]
    return "\n".join(lines) + "\n"

"""The tutorials (``docs/tutorials/*.md``) run as written: each page's commands and files, in page order, in an
empty folder, with this checkout's ``cbox`` on ``PATH``.

A page is read as a reader follows it: a fenced block with a ``title="FILE"`` is written to FILE (a later block
of the same title replaces it, as a reader edits the file); each ``$ `` line of a ``console`` block is a command,
run by bash in that folder. A command must exit 0, unless the page follows it with ``$ echo $?`` and the code
that shows (a command line is the key: a page repeats none with another code). The tests then check what each page says
its commands make.

All three run in the default suite (CI runs them): about two minutes together on 2 loaded cores.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import tomllib
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
TUTORIALS = ROOT / "docs" / "tutorials"
FENCE = re.compile(r"^```(\w*)([^\n]*)\n(.*?)^```\s*$", re.M | re.S)


@dataclass
class Block:
    lang: str
    title: str | None
    body: str


@dataclass
class Command:
    line: str
    shown: list[str]  # the output lines the page shows under it


def blocks(page: str) -> list[Block]:
    """The page's fenced blocks, in order."""
    found = []
    for m in FENCE.finditer((TUTORIALS / page).read_text(encoding="utf-8")):
        title = re.search(r'title="([^"]+)"', m.group(2))
        found.append(Block(m.group(1), title.group(1) if title else None, m.group(3)))
    return found


def commands(block: Block) -> list[Command]:
    out: list[Command] = []
    for line in block.body.splitlines():
        if line.startswith("$ "):
            out.append(Command(line[2:], []))
        elif out:
            out[-1].shown.append(line)
    return out


def checked_codes(page: str) -> dict[str, int]:
    """The exit code the page shows for each command followed by ``$ echo $?``; every other command must
    exit 0."""
    codes, previous = {}, None
    for block in blocks(page):
        for command in commands(block) if block.lang == "console" else []:
            if command.line == "echo $?":
                codes[previous] = int(command.shown[0])
            else:
                codes.setdefault(command.line, 0)
                previous = command.line
    return codes


def follow(page: str, folder: Path) -> dict[str, str]:
    """Run ``page`` in ``folder`` and check every command's exit code against the page; returns each
    command's output."""
    env = {**os.environ, "PATH": os.pathsep.join([str(Path(sys.executable).parent), os.environ["PATH"]]),
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT / "src"), os.environ.get("PYTHONPATH")])),
           "COLUMNS": "250"}
    env.pop("GITHUB_STEP_SUMMARY", None)
    codes = checked_codes(page)
    outputs = {}
    for block in blocks(page):
        if block.title:
            (folder / block.title).write_text(block.body, encoding="utf-8")
        for command in commands(block) if block.lang == "console" else []:
            if command.line == "echo $?":
                continue
            proc = subprocess.run(["bash", "-c", command.line], cwd=folder, env=env, capture_output=True,
                                  text=True, timeout=300)
            outputs[command.line] = proc.stdout + proc.stderr
            assert proc.returncode == codes[command.line], (
                f"{page}: `{command.line}` exited {proc.returncode}, the page says {codes[command.line]}:\n"
                f"{outputs[command.line][-3000:]}")
    return outputs


def test_every_tutorial_is_in_the_nav_and_tested_here():
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    pages = sorted(p.name for p in TUTORIALS.glob("*.md"))
    assert pages == ["convergence.md", "gate-your-renderer.md", "paper-figures.md"]
    assert all(f"tutorials/{p}" in nav for p in pages)
    assert all(f'"{p}"' in Path(__file__).read_text(encoding="utf-8") for p in pages)


def test_reading_a_page_finds_its_files_commands_and_exit_codes():
    gate = blocks("gate-your-renderer.md")
    assert [b.title for b in gate if b.title] == ["gate.toml", "gate.toml"]
    codes = checked_codes("gate-your-renderer.md")
    assert codes["make -C examples/c-renderer"] == 0
    assert sorted(set(codes.values())) == [0, 3]


# --- gate your own renderer ------------------------------------------------------------------------------------

def test_gate_your_own_renderer(tmp_path):
    """The C renderer built, exported for, compared, gated: inconclusive at its first margin (exit 3), planned,
    and passing with the margin the page settles on; the CI job runs the page's own commands."""
    if shutil.which("cc") is None or shutil.which("make") is None:
        pytest.fail("no C compiler or make on PATH: scripts/setup.sh --tests installs them")
    shutil.copytree(ROOT / "examples", tmp_path / "examples",
                    ignore=shutil.ignore_patterns("ao", "*.o"))
    outputs = follow("gate-your-renderer.md", tmp_path)
    assert (tmp_path / "examples" / "c-renderer" / "ao").is_file()
    assert list((tmp_path / "scene").glob("*.json"))
    plan = next(out for line, out in outputs.items() if "--plan" in line)
    need = re.search(r"back-edge: margin ±5% .*: about (\d+) spp", plan)
    assert need and 64 < int(need.group(1)) <= 256, plan  # the page: "about twice the budget"
    first = next(out for line, out in outputs.items() if line.startswith("cbox gate --config") and "--junit" not in line)
    assert re.search(r"INCONCLUSIVE .*equivalence: inconclusive: 1 of \d+ region\(s\) unresolved .*back-edge", first), first
    junit = (tmp_path / "gate-out" / "gate-junit.xml").read_text(encoding="utf-8")
    assert 'failures="0"' in junit and 'errors="0"' in junit and "equivalence" in junit

    page = blocks("gate-your-renderer.md")
    # The declaration the page shows is the example file's.
    shown = tomllib.loads(next(b.body for b in page if b.lang == "toml" and not b.title))
    assert shown["renderer"]["c-ao"] == tomllib.loads(
        (ROOT / "examples" / "renderers.toml").read_text(encoding="utf-8"))["renderer"]["c-ao"]
    # The CI job runs what this test ran (but the install).
    job = yaml.safe_load(next(b.body for b in page if b.lang == "yaml"))
    steps = [s["run"] for s in job["jobs"]["gate"]["steps"] if "run" in s]
    assert steps[0].startswith("pip install cornell-harness")
    assert steps[1:] and set(steps[1:]) <= set(outputs), set(steps[1:]) - set(outputs)
    assert any("--junit" in s for s in steps)


# --- a paper's figures and table -------------------------------------------------------------------------------

def test_paper_figures(tmp_path):
    """The experiment's tables and figures, relabelled without rendering, compile in a two-column article."""
    if shutil.which("pdflatex") is None:
        pytest.skip("pdflatex is not installed (scripts/setup.sh --tests installs texlive-latex-base and "
                    "texlive-latex-recommended)")
    follow("paper-figures.md", tmp_path)
    tex = (tmp_path / "paper" / "summary.tex").read_text(encoding="utf-8")
    assert "PT (pmj02)" in tex and "(independent)" in tex  # the report's relabelling reached the table
    assert (tmp_path / "paper.pdf").stat().st_size > 10_000
    log = (tmp_path / "paper.log").read_text(errors="replace")
    assert "Overfull" not in log and "LaTeX Warning: File" not in log, re.findall(r"(Overfull.*|LaTeX Warn.*)", log)
    options = (tmp_path / "paper" / "report-options.json").read_text(encoding="utf-8")
    assert "96" in options and "PT (pmj02)" in options


# --- a convergence experiment and its slopes --------------------------------------------------------------------

#: A figure with its interval as the table prints it: ``-0.5398 (-0.552–-0.5276)``.
FIGURE = re.compile(r"-?\d+\.\d+(?:e[+-]\d+)? \(-?\d+\.?\d*(?:e[+-]\d+)?–-?\d+\.?\d*(?:e[+-]\d+)?\)")


def test_convergence(tmp_path):
    """The slopes and bias share the page shows (a pure function of the seeds) are the ones the run prints,
    and the page's reading of them holds: about −0.5 for the path tracer, flatter for ``ambient``."""
    outputs = follow("convergence.md", tmp_path)
    (block,) = [b for b in blocks("convergence.md") if b.lang == "console"]
    (command,) = commands(block)
    shown = FIGURE.findall("\n".join(command.shown))
    assert len(shown) == 3, shown
    assert [s for s in shown if s not in outputs[command.line]] == []
    import pandas as pd

    summary = pd.read_parquet(tmp_path / "conv" / "summary.parquet").set_index("renderer")
    assert -0.6 < summary.loc["pathtracer", "slope_rmse_spp"] < -0.45
    assert summary.loc["pathtracer", "slope_rmse_spp"] < summary.loc["ambient", "slope_rmse_spp"] < -0.1
    assert summary.loc["ambient", "bias2_fraction_low"] > 0.5

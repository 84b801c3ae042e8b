"""The docs site's gallery (``scripts/gallery.py``) and the figures' manifest it reads
(``benchmarks/figure_manifest.py``): every figure of ``docs/images/`` is recorded with the command that made it;
each command runs a script that records its figures (and each ``cbox`` command it came from exists, options
too); the gallery shows every figure under its own command, and the Whitted and spectral tables under the command
their markers name.
"""

from __future__ import annotations

import ast
import json
import re
import shlex
from pathlib import Path

import pytest

from benchmarks import figure_manifest, markdown_blocks
from benchmarks.markdown_blocks import script_words
from scripts import gallery
from tests.test_docs import page_problems

ROOT = Path(__file__).resolve().parent.parent
IMAGES = ROOT / "docs" / "images"


def _imported_scripts(script: Path) -> list[Path]:
    """The script and the scripts of ``benchmarks/`` it imports by name (``from irradiance_probes import ...``)."""
    out = [script]
    for node in ast.walk(ast.parse(script.read_text(encoding="utf-8"))):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
            [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
        out += [script.parent / f"{n}.py" for n in names if (script.parent / f"{n}.py").is_file()]
    return out


def script_problems(command: str, root: Path = ROOT) -> list[str]:
    """What is wrong with a figure's command: it must run a script of ``benchmarks/`` that exists and records the
    figures it writes (itself or through a script it imports)."""
    words = script_words(command)
    if len(words) < 2 or words[0] != ".venv/bin/python" or not words[1].startswith("benchmarks/"):
        return [f"names no script (want `.venv/bin/python benchmarks/<script>.py ...`): {command!r}"]
    script = root / words[1]
    if not script.is_file():
        return [f"its script {words[1]} does not exist"]
    if not any("figure_manifest.record" in s.read_text(encoding="utf-8") for s in _imported_scripts(script)):
        return [f"{words[1]} does not record its figures (figure_manifest.record)"]
    return []


def source_problems(source: str) -> list[str]:
    """What is wrong with the ``cbox`` command a figure came from: a command, and options, that ``cbox`` has."""
    import cornell_harness.cli.app  # noqa: F401  (registers every command)
    from cornell_harness.cli.common import command_tree

    words = shlex.split(source)
    if len(words) < 2 or words[0] != "cbox":
        return [f"not a cbox command: {source!r}"]
    command = command_tree().commands.get(words[1])
    if command is None:
        return [f"cbox has no command {words[1]!r}"]
    options = {o for p in command.params for o in (*p.opts, *p.secondary_opts)}
    unknown = sorted({w.split("=")[0] for w in words[2:] if w.startswith("-")} - options)
    return [f"cbox {words[1]} has no option {', '.join(unknown)}"] if unknown else []


def manifest_problems(images: Path, root: Path = ROOT) -> list[str]:
    recorded = figure_manifest.read(images)
    files = {p.name for p in images.iterdir() if p.suffix in figure_manifest.FIGURE_SUFFIXES}
    problems = [f"{n}: not in {figure_manifest.MANIFEST}" for n in sorted(files - set(recorded))]
    problems += [f"{n}: recorded, but there is no such file" for n in sorted(set(recorded) - files)]
    for name, entry in sorted(recorded.items()):
        problems += [f"{name}: {p}" for p in script_problems(entry["command"], root)]
        problems += [f"{name}: {p}" for p in (source_problems(entry["source"]) if entry.get("source") else [])]
        if not re.fullmatch(r"[0-9a-f]{40}(-dirty)?", entry.get("commit") or ""):
            problems.append(f"{name}: no commit ({entry.get('commit')!r})")
    return problems


def test_every_figure_of_the_docs_is_recorded_with_the_command_that_made_it():
    assert manifest_problems(IMAGES) == []


def _write(folder: Path, name: str) -> Path:
    (folder / name).write_bytes(b"x")
    return folder / name


@pytest.mark.parametrize("command, source, problem", [
    (None, None, "not in manifest.json"),
    ("cbox demo", None, "names no script"),
    (".venv/bin/python benchmarks/nothing.py", None, "does not exist"),
    (".venv/bin/python benchmarks/timing.py", None, "does not record its figures"),
    (".venv/bin/python benchmarks/paper_outputs.py", "cbox no-such-command", "has no command"),
    (".venv/bin/python benchmarks/paper_outputs.py", "cbox converge --no-such-option 3", "has no option"),
])
def test_an_unrecorded_figure_or_a_wrong_command_fails(tmp_path, command, source, problem):
    good = _write(tmp_path, "good.svg")
    figure_manifest.record([good], ".venv/bin/python benchmarks/whitted.py", commit="0" * 40)
    figure = _write(tmp_path, "figure.png")
    if command is not None:
        figure_manifest.record([figure], command, source=source, commit="0" * 40)
    problems = manifest_problems(tmp_path)
    assert len(problems) == 1 and problems[0].startswith("figure.png: ") and problem in problems[0], problems


def test_recording_a_figure_keeps_the_others_and_refuses_a_missing_one(tmp_path):
    a, b = _write(tmp_path, "a.svg"), _write(tmp_path, "b.png")
    figure_manifest.record([a, b], "OLD", commit="1" * 40)
    figure_manifest.record([b], "NEW", source="cbox demo", captions={"b.png": "the b"})
    recorded = figure_manifest.read(tmp_path)
    assert recorded["a.svg"] == {"file": "a.svg", "command": "OLD", "source": None, "commit": "1" * 40}
    assert recorded["b.png"]["command"] == "NEW" and recorded["b.png"]["caption"] == "the b"
    assert re.fullmatch(r"[0-9a-f]{40}(-dirty)?", recorded["b.png"]["commit"])  # this checkout's
    assert [e["file"] for e in json.loads((tmp_path / "manifest.json").read_text())["figures"]] == ["a.svg", "b.png"]
    with pytest.raises(FileNotFoundError, match="c.svg"):
        figure_manifest.record([tmp_path / "c.svg"], "NEW")


def _shown_under(page: str) -> dict[str, str]:
    """Each image the page shows, with the command of the last ``sh`` block above it."""
    out, command, lines = {}, None, page.splitlines()
    for i, line in enumerate(lines):
        if line == "```sh":
            command = lines[i + 1]
        for name in re.findall(r"!\[[^\]]*\]\(images/([^)]+)\)", line):
            out[name] = command
    return out


def test_the_gallery_shows_every_figure_under_the_command_that_made_it():
    page = gallery.gallery_page()
    shown = _shown_under(page)
    recorded = figure_manifest.read(IMAGES)
    assert set(shown) == set(recorded)
    assert all((IMAGES / name).is_file() for name in shown)
    assert {name: recorded[name]["command"] for name in shown} == shown
    assert "images/paper-images.png" in page  # the image grid
    assert page.index("## A paper's figures") < page.index("## The Whitted and spectral tables")


@pytest.mark.parametrize("page, block", gallery.TABLES)
def test_the_gallery_holds_the_whitted_and_spectral_tables_under_their_command(page, block):
    text = (ROOT / "docs" / page).read_text(encoding="utf-8")
    head, blocks = markdown_blocks.parse(text)
    command = head if block is None else next(b.command for b in blocks if b.name == block)
    _, _, tables = gallery.page_tables(page, block)
    assert tables and all(t[1].startswith("|---") for _, t in tables)
    shown = gallery.gallery_page()
    section = shown[shown.index(f"]({page})"):]
    assert section.index(f"```sh\n{command}\n```") < section.index("\n|")
    assert all("\n".join(t) in section for _, t in tables)
    assert page_problems(f"docs/{page}", text) == []  # the marker's command is one test_docs accepts


def test_the_demo_section_says_how_its_figures_are_made_until_they_are(tmp_path):
    assert "```sh\n.venv/bin/python benchmarks/demo_figures.py\n```" in gallery.gallery_page(tmp_path)
    grid = _write(tmp_path, "demo-images.png")
    figure_manifest.record([grid], ".venv/bin/python benchmarks/demo_figures.py", source="cbox demo --out out/demo",
                           captions={"demo-images.png": "the demo's grid"})
    page = gallery.gallery_page(tmp_path)
    demo = page[page.index("## The demo"):page.index("## The Whitted")]
    assert _shown_under(demo) == {"demo-images.png": ".venv/bin/python benchmarks/demo_figures.py"}
    assert "from the output of `cbox demo --out out/demo`" in demo and "*the demo's grid*" in demo

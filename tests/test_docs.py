"""The docs' generated parts are written one way, between markers that name the command writing them; and
every file and module the docs name exists.

The convention and the writer are ``benchmarks/markdown_blocks.py``. For every marker in ``docs/**/*.md``,
``BENCHMARKS.md`` and ``README.md``: it parses, begin and end pair up, the command is
``.venv/bin/python benchmarks/<script>.py ...`` (or ``.venv/bin/python -m benchmarks.<script> ...``, for a
script that imports ``tests``) with a script that exists, writes through ``markdown_blocks``
and names the block, and a block's command names this very file (``--markdown <file>``).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from benchmarks import markdown_blocks
from benchmarks.markdown_blocks import script_words

ROOT = Path(__file__).resolve().parent.parent
PAGES = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "BENCHMARKS.md", ROOT / "README.md"]


def command_problems(rel: str, name: str | None, command: str, root: Path = ROOT) -> list[str]:
    """What is wrong with the command a marker names (``name`` None: a whole page's)."""
    what = f"{rel}: block {name!r}" if name else f"{rel}: page"
    words = script_words(command)
    if len(words) < 2 or words[0] != ".venv/bin/python" or not words[1].startswith("benchmarks/"):
        return [f"{what} names no script (want `.venv/bin/python benchmarks/<script>.py ...`): {command!r}"]
    script = root / words[1]
    if not script.is_file():
        return [f"{what}: its script {words[1]} does not exist"]
    source = script.read_text(encoding="utf-8")
    problems = []
    if "markdown_blocks" not in source:
        problems.append(f"{what}: {words[1]} does not write through markdown_blocks")
    if name is None:
        if "write_page" not in source:
            problems.append(f"{what}: {words[1]} writes no page (markdown_blocks.write_page)")
    else:
        if f'"{name}"' not in source:
            problems.append(f"{what}: {words[1]} has no block named \"{name}\"")
        if rel not in words[2:]:  # --markdown FILE, or another option naming the file (denoising.py --summary)
            problems.append(f"{what}: its command does not write this file (no `--markdown {rel}`)")
    return problems


def page_problems(rel: str, text: str, root: Path = ROOT) -> list[str]:
    try:
        page, blocks = markdown_blocks.parse(text)
    except markdown_blocks.MarkerError as e:
        return [f"{rel}: {e}"]
    problems = command_problems(rel, None, page, root) if page is not None else []
    for b in blocks:
        problems += command_problems(rel, b.name, b.command, root)
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_marked_block_names_the_command_that_writes_it(page):
    rel = str(page.relative_to(ROOT))
    assert page_problems(rel, page.read_text(encoding="utf-8")) == []


def test_the_generated_pages_and_blocks_are_marked():
    """The pages and blocks that scripts write today carry their markers (a marker lost in an edit is caught)."""
    found = {}
    for page in PAGES:
        head, blocks = markdown_blocks.parse(page.read_text(encoding="utf-8"))
        found[str(page.relative_to(ROOT))] = ({"page"} if head else set()) | {b.name for b in blocks}
    assert "page" in found["docs/denoising.md"]
    assert {"gate_power.py", "gate_checks.py"} <= found["docs/gate-detection.md"]


#: Scripts a page names whose output is not written into it, and why.
WRITES_NO_BLOCK = {"benchmarks/embree_direct.py": "BENCHMARKS.md keeps its first run, of a kernel since replaced, "
                                                  "as a record; the script prints the current kernel's table"}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_page_that_names_a_benchmark_holds_what_it_writes(page):
    """A page that says `.venv/bin/python benchmarks/x.py` holds a block (or is the page) that x.py writes: a
    benchmark's figures pasted by hand, with no marker at all, fail here."""
    text = page.read_text(encoding="utf-8")
    head, blocks = markdown_blocks.parse(text)
    writers = {script_words(c)[1] for c in [head, *(b.command for b in blocks)] if c}
    named = {f"benchmarks/{m}.py" for m in re.findall(r"\.venv/bin/python (?:benchmarks/|-m benchmarks\.)(\w+)", text)}
    named -= set(WRITES_NO_BLOCK)
    assert named <= writers, f"named but writing no block here: {sorted(named - writers)}"


GOOD = "benchmarks/gate_power.py"


@pytest.mark.parametrize("text, problem", [
    ("<!-- : begin, written by .venv/bin/python benchmarks/gate_power.py -->\nx\n<!-- : end -->\n",
     "not a marker"),  # no name
    ("<!-- gate_power.py: begin -->\nx\n<!-- gate_power.py: end -->\n", "not a marker"),  # no command
    (f"<!-- gate_power.py: begin, written by .venv/bin/python {GOOD} --markdown docs/x.md -->\nx\n",
     "no end marker"),
    ("x\n<!-- gate_power.py: end -->\n", "without its begin"),
    ("<!-- a: begin, written by .venv/bin/python benchmarks/a.py --markdown docs/x.md -->\n"
     "<!-- b: begin, written by .venv/bin/python benchmarks/a.py --markdown docs/x.md -->\n", "begins inside"),
    ("<!-- gate_power.py: begin, written by cbox converge --markdown docs/x.md -->\n<!-- gate_power.py: end -->\n",
     "names no script"),
    ("<!-- gate_power.py: begin, written by .venv/bin/python benchmarks/nothing.py --markdown docs/x.md -->\n"
     "<!-- gate_power.py: end -->\n", "does not exist"),
    (f"<!-- no-such-block: begin, written by .venv/bin/python {GOOD} --markdown docs/x.md -->\n"
     "<!-- no-such-block: end -->\n", "has no block named"),
    (f"<!-- gate_power.py: begin, written by .venv/bin/python {GOOD} --markdown docs/other.md -->\n"
     "<!-- gate_power.py: end -->\n", "does not write this file"),
    ("# title\n<!-- page, written by .venv/bin/python benchmarks/denoising.py -->\n", "first line"),
])
def test_a_nameless_unpaired_or_orphaned_block_fails(text, problem):
    problems = page_problems("docs/x.md", text)
    assert len(problems) == 1 and problem in problems[0], problems


def test_writing_a_block_keeps_everything_outside_it(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n\nProse.\n<!-- a: begin, written by OLD -->\nold a\n<!-- a: end -->\n\nMore prose.\n"
                    "<!-- b: begin, written by OLD -->\nold b\n<!-- b: end -->\n", encoding="utf-8")
    other = tmp_path / "other.md"
    markdown_blocks.write_blocks([page, other], {"a": "| new | a |\n|---|---|\n", "c": "new c"}, "NEW")
    assert page.read_text(encoding="utf-8") == (
        "# Title\n\nProse.\n<!-- a: begin, written by NEW -->\n| new | a |\n|---|---|\n<!-- a: end -->\n\n"
        "More prose.\n<!-- b: begin, written by OLD -->\nold b\n<!-- b: end -->\n\n"
        "<!-- c: begin, written by NEW -->\nnew c\n<!-- c: end -->\n")
    assert not other.exists()  # it holds none of the blocks: not written
    assert markdown_blocks.parse(page.read_text(encoding="utf-8"))[1][0].command == "NEW"


def test_a_block_is_written_in_the_file_that_holds_it(tmp_path):
    first, second = tmp_path / "first.md", tmp_path / "second.md"
    first.write_text("# First\n", encoding="utf-8")
    second.write_text("<!-- b: begin, written by OLD -->\nold\n<!-- b: end -->\n", encoding="utf-8")
    markdown_blocks.write_blocks([first, second], {"b": "new"}, "NEW")
    assert first.read_text(encoding="utf-8") == "# First\n"
    assert second.read_text(encoding="utf-8") == "<!-- b: begin, written by NEW -->\nnew\n<!-- b: end -->\n"


def test_a_page_names_its_command_on_its_first_line(tmp_path):
    page = tmp_path / "page.md"
    markdown_blocks.write_page(page, "# Title\n\nBody.\n", ".venv/bin/python benchmarks/denoising.py")
    head, blocks = markdown_blocks.parse(page.read_text(encoding="utf-8"))
    assert head == ".venv/bin/python benchmarks/denoising.py" and blocks == []
    assert page.read_text(encoding="utf-8").splitlines()[1] == "# Title"


def test_command_line_names_the_script_from_the_repository_root():
    argv = [str(ROOT / "benchmarks" / "caustics.py"), "--seeds", "5", "--markdown", "BENCHMARKS.md"]
    assert markdown_blocks.command_line(argv) == (
        ".venv/bin/python benchmarks/caustics.py --seeds 5 --markdown BENCHMARKS.md")


#: A repository path in the docs (``src/cornell_harness/workflows/converge.py``, ``src/cornell_harness/renderers/core/``).
_FILE = re.compile(r"(?<![\w/.])(?:src/cornell_harness|tests|benchmarks|scripts|docs)/[\w./*{},-]*")


def file_paths(text: str) -> list[str]:
    """The repository paths ``text`` names, globs (``probes-*``, ``{a,b}``) left out."""
    paths = (m.rstrip(".,") for m in _FILE.findall(text))
    return [p for p in paths if not set("*{}") & set(p)]


#: A dotted name in our packages (``cornell_harness.workflows.converge.run_experiment``).
DOTTED = re.compile(r"(?<![\w/.])(cornell_harness(?:\.\w+)+)")


def _names(tree) -> dict[str, ast.AST]:
    """A module's or class's own names: functions, classes, assignments, imports."""
    out = {}
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out[node.name] = node
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for t in node.targets if isinstance(node, ast.Assign) else [node.target]:
                for n in ast.walk(t):
                    if isinstance(n, ast.Name):
                        out[n.id] = node
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            for a in node.names:
                out[(a.asname or a.name).split(".")[0]] = node
    return out


def missing_name(dotted: str, root: Path = ROOT / "src") -> str | None:
    """Why ``dotted`` names nothing in the tree (None if it does): the longest prefix that is a module or package,
    then its attribute (and a class's attribute) by the module's source."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        base = root.joinpath(*parts[:k])
        source = base.with_suffix(".py") if base.with_suffix(".py").is_file() else base / "__init__.py"
        if source.is_file():
            rest = parts[k:]
            scope = ast.parse(source.read_text(encoding="utf-8"))
            for depth, name in enumerate(rest[:2]):
                found = _names(scope).get(name)
                if found is None:
                    return f"{'.'.join(parts[:k + depth])} has no {name!r}"
                if not isinstance(found, ast.ClassDef):
                    break
                scope = found
            return None
    return f"no module {parts[0]}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_file_and_module_the_docs_name_exists(page):
    text = page.read_text(encoding="utf-8")
    missing = [p for p in file_paths(text) if not (ROOT / p).exists()]
    missing += [f"{d}: {why}" for d in sorted(set(DOTTED.findall(text))) if (why := missing_name(d))]
    assert missing == []


def test_a_moved_module_or_name_is_caught():
    assert missing_name("cornell_harness.workflows.converge.run_experiment") is None
    assert missing_name("cornell_harness.workflows.executor.DaskExecutor.run") is None
    assert "has no 'summary'" in missing_name("cornell_harness.workflows.converge.summary")
    assert "has no 'no_such_method'" in missing_name("cornell_harness.workflows.executor.DaskExecutor.no_such_method")
    assert file_paths("see `src/cornell_harness/nothing.py`, docs/images/probes-* and docs/images/probes-{a,b}.svg.") == [
        "src/cornell_harness/nothing.py"]


def test_the_demos_spectral_headline_is_the_one_docs_spectral_md_measured():
    """`cbox demo` ends with issue 33's headline (src/cornell_harness/cli/run.py): its three figures are those of the
    table benchmarks/spectral.py wrote into docs/spectral.md (whole image: illuminant_E, scene_light, floor)."""
    from cornell_harness.cli.run import SPECTRAL_HEADLINE

    row = re.search(r"^\| whole image \| \*\*([\d.]+)\*\* \| ([\d.]+) \| ([\d.]+) \|$",
                    (ROOT / "docs" / "spectral.md").read_text(), re.M)
    assert row, "docs/spectral.md has no per-pixel row for the whole image"
    assert re.findall(r"\d+\.\d+", SPECTRAL_HEADLINE) == list(row.groups())

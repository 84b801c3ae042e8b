"""The docs site's gallery page, written while the site builds (``scripts/docs_site.py``): every figure the
project's scripts commit to ``docs/images/``, each under the command that made it, and the Whitted and spectral
tables, each under the command that wrote it. Nothing is rendered here: the page only collects what is in git,
so the build stays fast.

- **Figures** and their commands: ``docs/images/manifest.json``, which the script that makes a figure writes
  beside it (``benchmarks/figure_manifest.py``). A figure's caption is its alt text where a docs page (or the
  README) shows it, and the page is linked; else the caption its script recorded; else its file name.
- **Tables**: those of the pages and blocks :data:`TABLES` names, read from ``docs/*.md`` between the markers of
  ``benchmarks/markdown_blocks.py``, whose command the marker names.
"""

from __future__ import annotations

import re
from pathlib import Path

from benchmarks import figure_manifest, markdown_blocks
from benchmarks.markdown_blocks import script_words

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
IMAGES = DOCS / "images"
PAGE = "gallery.md"
#: The tables shown: (page under docs/, its block's name, or None for a page its script writes whole).
TABLES = (("whitted.md", None), ("spectral.md", "spectral.py"))
#: The figures' sections that open the page, by the script that made them, with their headings; every other
#: script's figures follow the tables, headed by the title of the docs page that shows them.
DEMO = "benchmarks/demo_figures.py"
FIRST = {DEMO: "The demo", "benchmarks/paper_outputs.py": "A paper's figures: the image grid and a convergence chart"}
#: Where the demo's figures are not in the manifest yet: what makes them.
NO_DEMO = ["## The demo", "", "`cbox demo` writes its figures into its own folder, out of git; this makes its "
           "report's charts and image grid and records them here:", "", "```sh", f".venv/bin/python {DEMO}", "```", ""]
_IMAGE = re.compile(r"!\[([^\]]*)\]\((?:\.\./)*(?:docs/)?images/([^)\s]+)\)")


def _title(text: str, fallback: str) -> str:
    """A page's first ``# `` heading."""
    return next((line[2:].strip() for line in text.splitlines() if line.startswith("# ")), fallback)


def shown_in() -> dict[str, tuple[str, str | None, str | None]]:
    """Each figure's (alt text, docs page showing it, that page's title), by file name; the README gives a caption
    but no link (it is not part of the site)."""
    out: dict[str, tuple[str, str | None, str | None]] = {}
    for path in [*sorted(DOCS.rglob("*.md")), ROOT / "README.md"]:
        if not path.is_file():
            continue
        text = path.read_text(encoding="utf-8")
        page = path.relative_to(DOCS).as_posix() if path.is_relative_to(DOCS) else None
        for alt, name in _IMAGE.findall(text):
            if name not in out or out[name][1] is None and page is not None:
                out[name] = (alt, page, _title(text, page or "") if page else None)
    return out


def _figure_lines(entry: dict, shown: dict) -> list[str]:
    name = entry["file"]
    alt, page, title = shown.get(name, (entry.get("caption") or name, None, None))
    where = f"; shown in [{title}]({page})" if page else ""
    return [f"![{alt}](images/{name}){{ loading=lazy }}", "",
            f"*{alt}*: `docs/images/{name}`, sources at commit `{entry['commit'][:12]}`{where}.", ""]


def _made_by(command: str, source: str | None, what: str = "Made by") -> list[str]:
    lines = [f"{what}:", "", "```sh", command, "```", ""]
    return lines + ([f"from the output of `{source}`.", ""] if source else [])


def figure_sections(entries: list[dict], shown: dict) -> dict[str, list[str]]:
    """Each script's section of figures, its figures grouped under the command (and source) that made them."""
    by_script: dict[str, dict[tuple[str, str | None], list[dict]]] = {}
    for e in entries:
        words = script_words(e["command"])
        script = words[1] if len(words) > 1 else e["command"]
        by_script.setdefault(script, {}).setdefault((e["command"], e.get("source")), []).append(e)
    out = {}
    for script, groups in by_script.items():
        pages = [shown[e["file"]] for g in groups.values() for e in g if shown.get(e["file"], (0, None))[1]]
        heading = FIRST.get(script) or (pages[0][2] if pages else f"`{script}`")
        lines = [f"## {heading}", ""]
        for (command, source), figures in groups.items():
            lines += _made_by(command, source)
            for e in figures:
                lines += _figure_lines(e, shown)
        out[script] = lines
    return out


def page_tables(page: str, block: str | None) -> tuple[str, str, list[tuple[str, list[str]]]]:
    """The page's title, the command that wrote the page or block, and its tables, each with a caption: the line
    just before it where that ends in a colon, else the headings it sits under."""
    text = (DOCS / page).read_text(encoding="utf-8")
    head, blocks = markdown_blocks.parse(text)
    lines = text.splitlines()
    if block is None:
        command, first, last = head, 1, len(lines)
    else:
        b = next(b for b in blocks if b.name == block)
        command, first, last = b.command, b.begin + 1, b.end
    headings: dict[int, str] = {}
    tables, i = [], 0
    while i < len(lines):
        line = lines[i]
        if m := re.match(r"^(#{2,4}) (.*)", line):
            level = len(m[1])
            headings = {k: v for k, v in headings.items() if k < level} | {level: m[2].strip()}
        if first <= i < last and line.startswith("|"):
            end = i
            while end < last and lines[end].startswith("|"):
                end += 1
            before = next((lines[k].strip() for k in range(i - 1, first - 1, -1) if lines[k].strip()), "")
            caption = before[:-1] if before.endswith(":") else " — ".join(headings[k] for k in sorted(headings))
            tables.append((caption, lines[i:end]))
            i = end
            continue
        i += 1
    return _title(text, page), command, tables


def table_section(sections: dict[str, list[str]]) -> list[str]:
    """The tables of :data:`TABLES`, each page's followed by the figures its script made (taken from
    ``sections``)."""
    lines = ["## The Whitted and spectral tables", ""]
    for page, block in TABLES:
        title, command, tables = page_tables(page, block)
        lines += [f"### {title}", "", f"From [{title}]({page}), which says how to read them.", "",
                  *_made_by(command, None, "Written by")]
        for caption, table in tables:
            lines += [f"**{caption}**", "", *table, ""]
        lines += sections.pop(script_words(command)[1], [])[2:]  # without its heading
    return lines


def gallery_page(images: Path = IMAGES) -> str:
    """The gallery: the demo's and the paper's figures, the tables, then every other script's figures."""
    entries = list(figure_manifest.read(images).values())
    sections = figure_sections(entries, shown_in())
    lines = ["# Gallery", "",
             "Every figure the project's scripts commit to `docs/images/`, each under the exact command that made it "
             "(run from the repository root), and the Whitted and spectral tables under the command that wrote "
             "them. The commands are read from what each script records as it writes: "
             "`docs/images/manifest.json` (`benchmarks/figure_manifest.py`) for figures, the markers of the pages "
             "for tables (`benchmarks/markdown_blocks.py`).", ""]
    for script in FIRST:
        lines += sections.pop(script, NO_DEMO if script == DEMO else [])
    lines += table_section(sections)
    for script in sorted(sections):
        lines += sections[script]
    return "\n".join(lines).rstrip("\n") + "\n"

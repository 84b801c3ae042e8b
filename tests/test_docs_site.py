"""The docs site: ``mkdocs build --strict`` passes (every page in the nav, every link and anchor resolving), and
the reference pages it writes from the code (``scripts/docs_site.py``) hold every command, option, metric,
renderer and format, and name only files and modules that exist (``tests/test_docs.py``'s checks).

Needs the ``[docs]`` extra, which ``scripts/setup.sh --tests`` installs (so this runs in CI).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("mkdocs", reason="the docs site needs the [docs] extra: pip install -e '.[docs]'")

from cornell_harness.evaluate.registry import METRICS  # noqa: E402
from cornell_harness.schemas.reader import FORMATS, check, read_toml  # noqa: E402
from scripts import docs_site  # noqa: E402
from tests.test_docs import file_paths, missing_name, page_problems  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
#: A strict build here took about 8 s; far more means the build renders something it should not (images).
BUILD_LIMIT_S = 120


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "NO_MKDOCS_2_WARNING": "1"}
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=BUILD_LIMIT_S)
    assert done.returncode == 0, done.stdout + done.stderr
    return out


@pytest.fixture(scope="module")
def pages() -> dict[str, str]:
    return docs_site.pages()


def _text(html_file: Path) -> str:
    """The page's article as plain text."""
    html = html_file.read_text(encoding="utf-8")
    return re.sub(r"<[^>]+>", "", html[html.find("<article"):html.find("</article>")])


def test_the_site_builds_strictly_with_every_page(site, pages):
    built = {p.relative_to(site).parent.as_posix() for p in site.rglob("index.html")}
    wanted = {str(Path(p).with_suffix("")) for p in pages} | {p.stem for p in (ROOT / "docs").glob("*.md")}
    assert wanted - {"index"} <= built
    assert not list(site.rglob("*.py")), "the hook or a script was copied into the site"


def test_the_api_page_reads_the_codes_own_conventions(site):
    """``#:`` comments are attributes' docstrings, and Sphinx roles show as code, not as ``:class:``."""
    text = _text(site / "api" / "index.html")
    assert "The published sources of its method" in text  # Declarations.citations' `#:` comment
    assert "Auxiliary images (AOVs) a renderer may return" in text  # AOVS's
    assert "def score_image" not in text and "score_image" in text
    assert ":class:" not in text and ":func:" not in text


@pytest.mark.parametrize("path", ["reference/cli.md", "reference/metrics.md", "reference/renderers.md",
                                  "reference/scene-format.md", "reference/gate-format.md",
                                  "reference/renderers-format.md", "gallery.md"])
def test_a_generated_page_names_only_what_exists(pages, path):
    text = pages[path]
    missing = [p for p in file_paths(text) if not (ROOT / p).exists()]
    missing += [f"{d}: {why}" for d in sorted(set(re.findall(r"(?<![\w/.])(cornell_harness(?:\.\w+)+)", text)))
                if (why := missing_name(d))]
    assert missing == [] and page_problems(path, text) == []


def _section(page: str, heading: str) -> str:
    """The text of ``page`` from ``heading`` to the next heading of any level."""
    start = page.index(heading + "\n")
    return page[start:page.find("\n#", start + len(heading))]


def test_every_command_and_option_of_cbox_help_is_on_the_cli_page(pages, capsys):
    """Each command's options as its own ``--help`` prints them, against the page's section for it."""
    from cornell_harness.cli.app import main

    page = pages["reference/cli.md"]
    commands = re.findall(r"^#+ `(cbox[^`]*)`$", page, re.M)
    assert {"cbox render", "cbox converge", "cbox gate", "cbox reference build", "cbox reference verify"} <= set(
        commands)
    for command in commands[1:]:
        if command == "cbox reference":
            continue
        with pytest.raises(SystemExit):
            main([*command.split()[1:], "--help"])
        # an option's line of rich's box starts with it (a `*` before the required ones)
        options = set(re.findall(r"^│ [ *]{0,4}(--[a-z][a-z0-9-]*)", capsys.readouterr().out, re.M)) - {"--help"}
        section = _section(page, next(h for h in re.findall(r"^#+ `.*`$", page, re.M) if h.endswith(f"`{command}`")))
        assert options and {o for o in options if f"`{o}`" not in section} == set(), command


def test_every_metric_is_on_the_metrics_page_with_its_definition(pages):
    page = pages["reference/metrics.md"]
    rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| `([\w.]+)` \|.*$", page, re.M)}
    assert set(rows) == set(METRICS)
    for key, metric in METRICS.items():
        assert metric.definition.split("(")[0].strip() in rows[key].replace("\\|", "|")
    # The published measures carry their source, in the registry itself.
    assert "Wang" in METRICS["ssim"].citation and "Sharma" in METRICS["delta_e2000_mean"].citation
    assert "Andersson" in METRICS["flip_mean"].citation and "Rousselle" in METRICS["rel_mse"].citation
    assert METRICS["ssim"].citation in rows["ssim"]


def test_every_renderer_of_ours_is_on_the_renderers_page_with_settings_and_sources(pages):
    import tomllib

    registered = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["entry-points"]["cbox.renderers"]
    renderers = docs_site.our_renderers()
    assert set(renderers) == set(registered)
    page = pages["reference/renderers.md"]
    for name, renderer in renderers.items():
        section = page[page.index(f"## `{name}`\n"):]
        section = section[:section.find("\n## ", 1)] if "\n## " in section[1:] else section
        citations = docs_site.attribute(renderer, "citations")
        assert citations, f"{name} declares no citations"
        assert all(c.replace("<", "&lt;") in section for c in citations)
        assert all(f"| `{s.name}` |" in section for s in docs_site.attribute(renderer, "settings"))


@pytest.mark.parametrize("fmt", FORMATS)
def test_each_format_page_has_its_schemas_tables_and_a_valid_example(pages, fmt):
    path, _, example, _ = docs_site.FORMAT_PAGES[fmt]
    check(read_toml(example), fmt, str(example))  # raises on an example the strict reader would refuse
    page = pages[path]
    assert docs_site.schema_tables.tables(fmt) in page
    assert example.read_text(encoding="utf-8").strip() in page

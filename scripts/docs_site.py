"""The docs site's reference pages, written from the code each time the site is built (a MkDocs hook).

``mkdocs.yml`` names this file under ``hooks:``; :func:`on_files` adds the pages of :func:`pages` to the build,
so they are never in git and cannot go stale. Each is read from the one place that defines it:

- ``reference/cli.md``: every ``cbox`` command and option, from the click command tree typer builds
  (:func:`cornell_harness.cli.common.command_tree`);
- ``reference/<format>-format.md``: the scene, gate and renderers formats, from their JSON Schemas (the tables of
  ``benchmarks/schema_tables.py``), each with an example file of this repository;
- ``reference/metrics.md``: the metric registry (:data:`cornell_harness.evaluate.registry.METRICS`);
- ``reference/renderers.md``: our registered renderers (pyproject's ``cbox.renderers`` entry points), each with its
  declarations (:func:`cornell_harness.adapters.api.attribute`) and settings;
- ``gallery.md``: the committed figures, each with the command that made it, and the Whitted and spectral tables
  (``scripts/gallery.py``; nothing is rendered).

Build the site with ``mkdocs build --strict`` (the ``[docs]`` extra); ``tests/test_docs_site.py`` does.
"""

from __future__ import annotations

import importlib.metadata
import inspect
import math
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
# The docs describe this checkout: its sources first, and the repository root for `benchmarks`.
for _path in (ROOT, ROOT / "src"):
    if str(_path) not in sys.path:
        sys.path.insert(0, str(_path))

from benchmarks import schema_tables  # noqa: E402
from cornell_harness.adapters.api import attribute  # noqa: E402
from cornell_harness.evaluate.registry import METRICS  # noqa: E402
from cornell_harness.extras import RENDERERS as RENDERER_EXTRAS, install_line  # noqa: E402
from cornell_harness.scenes.library import references_root  # noqa: E402
from scripts.gallery import PAGE as GALLERY, gallery_page  # noqa: E402

#: Each format's reference page, and the file of this repository shown as its example, with what it is.
FORMAT_PAGES = {
    "scene": ("reference/scene-format.md", "Scene files", references_root() / "cornell-box" / "scene.toml",
              "the stored scene `cornell-box`"),
    "gate": ("reference/gate-format.md", "Gate configuration (gate.toml)", ROOT / "gate.toml",
             "this repository's own gate, `gate.toml`"),
    "renderers": ("reference/renderers-format.md", "Renderers files", ROOT / "examples" / "renderers.toml",
                  "`examples/renderers.toml`"),
}


def _cell(text) -> str:
    """``text`` as one cell of a Markdown table: on one line, its pipes and angle brackets escaped."""
    return str(text).replace("|", "\\|").replace("<", "&lt;").replace("\n", " ").strip()


def _help(text: str | None) -> str:
    """A typer help text as Markdown: rich's escaped brackets (``NAME\\[...]``) as the brackets they show."""
    return (text or "").replace("\\[", "[").replace("<", "&lt;").strip()


# --- the cbox command --------------------------------------------------------------------------------------

def _commands(group, prefix: str) -> list[tuple[str, object]]:
    """Every command under ``group``, depth first, as (full name, click command), in ``--help``'s order."""
    out = []
    for name, command in group.commands.items():
        full = f"{prefix} {name}"
        out.append((full, command))
        if hasattr(command, "commands"):
            out += _commands(command, full)
    return out


def _default(param) -> str:
    value = param.default
    if value is None or value == () or value == [] or getattr(param, "is_flag", False) and value is False:
        return ""
    return f"`{value}`"


def _option_row(param) -> str:
    names = ", ".join(f"`{o}`" for o in (*param.opts, *param.secondary_opts))
    if param.param_type_name == "argument":
        names = f"`{(param.metavar or param.name).upper()}` (argument)"
    elif not getattr(param, "is_flag", False):
        names += f" `{param.metavar or param.name.upper()}`"
    notes = [n for n in ("required" if param.required else "", "repeatable" if param.multiple else "") if n]
    meaning = _help(getattr(param, "help", None)) + (f" ({', '.join(notes)})" if notes else "")
    return f"| {names} | {_cell(meaning)} | {_cell(_default(param))} |"


def _command_section(name: str, command, level: int) -> list[str]:
    lines = [f"{'#' * level} `{name}`", "", _help(command.help), ""]
    params = [p for p in command.params if not getattr(p, "hidden", False)]
    if params:
        lines += ["| option | meaning | default |", "| --- | --- | --- |", *map(_option_row, params), ""]
    return lines


def cli_page() -> str:
    """Every ``cbox`` command and option, as ``cbox --help`` and each command's ``--help`` give them."""
    import cornell_harness.cli.app  # noqa: F401  (importing it registers every command on the app)
    from cornell_harness.cli.common import command_tree

    root = command_tree()
    lines = ["# The `cbox` command", "", "Every command and option, written from the command line's own "
             "definitions (`cbox COMMAND --help` prints the same). Options of the whole program:", ""]
    lines += _command_section("cbox", root, 2)[4:]
    for name, command in _commands(root, "cbox"):
        lines += _command_section(name, command, 2 if name.count(" ") == 1 else 3)
    return "\n".join(lines)


# --- the file formats --------------------------------------------------------------------------------------

def format_page(fmt: str) -> str:
    """Format ``fmt``'s reference: its tables from the JSON Schema, then a whole example file."""
    from cornell_harness.schemas.reader import schema_file

    _, title, example, what = FORMAT_PAGES[fmt]
    schema = schema_file(fmt)
    return "\n".join([
        f"# {title}", "",
        f"Written from the format's JSON Schema, `src/cornell_harness/schemas/{schema.name}`, which the strict "
        "reader checks every file against ([file formats](../formats.md) says how, and how an editor completes "
        "keys from it). A key of a table not listed here is an error.", "",
        schema_tables.tables(fmt), "",
        "## Example", "", f"{what[0].upper()}{what[1:]}:", "", "```toml",
        example.read_text(encoding="utf-8").rstrip("\n"), "```", ""])


# --- metrics ----------------------------------------------------------------------------------------------

def _range(values: tuple[float, float]) -> str:
    lo, hi = values
    if (lo, hi) == (-math.inf, math.inf):
        return "any"
    return f"[{lo:g}, {'∞' if hi == math.inf else f'{hi:g}'}" + (")" if hi == math.inf else "]")


def metrics_page() -> str:
    """Every column a run can carry, from the metric registry: its definition, direction, range and source."""
    better = {"low": "lower", "high": "higher", None: ""}
    lines = ["# Metrics", "",
             "Every column a run can carry, written from the metric registry "
             "(`src/cornell_harness/evaluate/registry.py`), the one table the gate, the report and the command "
             "line read. *Per image*: computed from one image against the reference, so a gate may budget it. "
             "*Slope*: the log-log slope against spp an unbiased renderer shows. Each region of a scene also "
             "gets `region.<region>.<metric>` columns of the region metrics.", "",
             "| key | label | definition | better | values | per image | slope | source |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for m in METRICS.values():
        slope = "" if m.guide_slope is None else f"{m.guide_slope:g}"
        lines.append("| " + " | ".join(_cell(c) for c in (
            f"`{m.key}`", m.label, m.definition + (" (radiance images only)" if m.colour else ""),
            better[m.better], _range(m.values), "yes" if m.per_image else "", slope, m.citation or "—")) + " |")
    return "\n".join(lines) + "\n"


# --- renderers --------------------------------------------------------------------------------------------

def our_renderers() -> dict[str, object]:
    """Our registered renderers (pyproject's ``cbox.renderers`` entry points into this package), constructed
    but not probed: what each declares does not depend on what is installed."""
    eps = importlib.metadata.entry_points(group="cbox.renderers")
    return {ep.name: ep.load()() for ep in sorted(eps, key=lambda e: e.name)
            if ep.value.startswith("cornell_harness.")}


def _summary(renderer) -> str:
    """The first paragraph of the renderer's module docstring, on one line."""
    doc = inspect.getdoc(sys.modules[type(renderer).__module__]) or ""
    return " ".join(doc.split("\n\n")[0].split())


def _declarations(renderer) -> list[str]:
    rows = [("features", ", ".join(f"`{f}`" for f in sorted(renderer.features))),
            ("estimator", f"`{attribute(renderer, 'estimator')}`"),
            ("quantities", ", ".join(f"`{q}`" for q in attribute(renderer, "quantities"))),
            ("aovs", ", ".join(f"`{a}`" for a in attribute(renderer, "aovs")) or "none"),
            ("deterministic", "yes" if attribute(renderer, "deterministic") else "no")]
    if (fit := attribute(renderer, "reference_fit")) is not None:
        rows.append(("reference_fit", f"`{fit.setting} = {fit.value}`: an oracle fitted to the stored reference"))
    extras = RENDERER_EXTRAS.get(renderer.name, ())
    rows.append(("install", f"`{install_line(extras)}`" if extras else "the core install"))
    lines = ["| declaration | value |", "| --- | --- |", *(f"| {k} | {_cell(v)} |" for k, v in rows), ""]
    if approximations := attribute(renderer, "approximations"):
        lines += ["Approximations:", "", *(f"- {_help(a)}" for a in approximations), ""]
    return lines


def _settings(renderer) -> list[str]:
    settings = attribute(renderer, "settings")
    if not settings:
        return ["No settings.", ""]
    return ["| setting | default | allowed | meaning |", "| --- | --- | --- | --- |",
            *(f"| `{s.name}` | `{s.default}` | {_cell(s.allowed())} | {_cell(s.doc)} |" for s in settings), ""]


def renderers_page() -> str:
    """Every renderer the harness ships: what it is, its declarations, its settings and its sources."""
    lines = ["# Renderers", "",
             "Every renderer the harness ships, written from what each declares through the renderer API "
             "([Python API](../api.md): `Declarations`); `cbox renderers --settings` prints the same settings. "
             "A setting is given as `-r NAME[setting=value,...]`. A renderer of your own declares the same "
             "([Adding your own renderer](../our-renderers.md#adding-your-own-renderer)).", ""]
    for name, renderer in our_renderers().items():
        lines += [f"## `{name}`", "", _summary(renderer), "",
                  f"Module: `{type(renderer).__module__}`.", "", *_declarations(renderer),
                  "**Settings**", "", *_settings(renderer)]
        citations = attribute(renderer, "citations")
        lines += ["**Sources**", "", *(f"- {_help(c)}" for c in citations), ""] if citations else []
    return "\n".join(lines)


# --- the API page's docstrings ------------------------------------------------------------------------------

#: A Sphinx cross-reference role (:class:`Renderer`, :func:`~cornell_harness.adapters.api.attribute`).
_ROLE = re.compile(r":(?:class|func|data|mod|attr|meth|exc|obj):`(~?)([^`]+)`")


def _role_as_code(match: re.Match) -> str:
    target = match[2].rsplit(".", 1)[-1] if match[1] else match[2]
    return f"`{target}`"


try:
    import griffe
except ImportError:  # the hook alone needs no griffe; mkdocstrings, which loads the extension below, brings it
    griffe = None
else:
    class SphinxDocstrings(griffe.Extension):
        """The code's docstrings as Sphinx reads them, for mkdocstrings (``mkdocs.yml``'s ``extensions``):
        a ``#:`` comment above an attribute is its docstring, and a role (:class:`X`) is shown as code."""

        def on_attribute_instance(self, *, node, attr, agent, **kwargs) -> None:
            if attr.docstring is not None or not attr.lineno:
                return
            lines, above = attr.module.lines, []
            for line in reversed(lines[:attr.lineno - 1]):
                if not line.strip().startswith("#:"):
                    break
                above.insert(0, line.strip()[2:].strip())
            if above:
                attr.docstring = griffe.Docstring("\n".join(above), parent=attr)

        def on_package(self, *, pkg, **kwargs) -> None:
            todo = [pkg]
            while todo:
                obj = todo.pop()
                if obj.docstring is not None:
                    obj.docstring.value = _ROLE.sub(_role_as_code, obj.docstring.value)
                todo += [m for m in obj.members.values() if not m.is_alias]


def pages() -> dict[str, str]:
    """Every generated page, by its path under ``docs/``."""
    out = {"reference/cli.md": cli_page(), "reference/metrics.md": metrics_page(),
           "reference/renderers.md": renderers_page(), GALLERY: gallery_page()}
    out.update({page: format_page(fmt) for fmt, (page, *_) in FORMAT_PAGES.items()})
    return out


def on_files(files, config):
    """MkDocs hook: the generated pages join the build's files, as if they were in ``docs/``."""
    from mkdocs.structure.files import File

    for path, text in pages().items():
        files.append(File.generated(config, path, content=text))
    return files

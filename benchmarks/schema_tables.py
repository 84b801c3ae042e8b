"""The file formats' reference tables, written from their JSON Schemas (``src/cornell_harness/schemas/``).

One Markdown table per table of a format (its keys, type, unit, default, allowed values and meaning), so the
docs say exactly what the strict reader checks; ``tests/test_docs.py`` fails when ``docs/formats.md`` differs
from what this writes. Run::

    .venv/bin/python benchmarks/schema_tables.py --markdown docs/formats.md
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchmarks import markdown_blocks
from cornell_harness.schemas.reader import FORMATS, schema

_TYPES = {"integer": "integer", "number": "number", "string": "string", "array": "array", "object": "table",
          "boolean": "boolean"}


def _resolve(root: dict, node: dict) -> dict:
    """``node`` with its local ``$ref`` merged in (the node's own keys win)."""
    if "$ref" not in node:
        return node
    target = root["$defs"][node["$ref"].rsplit("/", 1)[-1]]
    return {**_resolve(root, target), **{k: v for k, v in node.items() if k != "$ref"}}


def _type(root: dict, node: dict) -> str:
    types = node.get("type", [])
    types = [types] if isinstance(types, str) else types
    text = " or ".join(_TYPES.get(t, t) for t in types) or "—"
    if "array" in types and "items" in node:
        item = _resolve(root, node["items"])
        n = (node.get("minItems"), node.get("maxItems"))
        size = f"{n[0]} " if n[0] == n[1] and n[0] else ""
        text = text.replace("array", f"array of {size}{_TYPES.get(item.get('type'), 'values')}")
    return text


def _allowed(node: dict) -> str:
    parts = []
    if "enum" in node:
        parts.append(", ".join(f"`{v}`" for v in node["enum"]))
    if "const" in node:
        parts.append(f"`{node['const']}`")
    for item in [node] + ([node["items"]] if isinstance(node.get("items"), dict) else []):
        if "enum" in item and item is not node:
            parts.append("each of " + ", ".join(f"`{v}`" for v in item["enum"]))
        lo = item.get("minimum", item.get("exclusiveMinimum"))
        hi = item.get("maximum", item.get("exclusiveMaximum"))
        if lo is not None or hi is not None:
            left = "−∞" if lo is None else f"{lo:g}"
            right = "∞" if hi is None else f"{hi:g}"
            parts.append(f"{'[' if 'minimum' in item else '('}{left}, {right}{']' if 'maximum' in item else ')'}")
    for branch in node.get("anyOf", []):
        parts.append(f"`{branch['const']}`" if "const" in branch else
                     f"[{branch.get('minimum', '−∞')}, {branch.get('maximum', '∞')}]")
    if node.get("x-allowInfinity"):
        parts.append("`inf`")
    if node.get("minItems") and node.get("minItems") != node.get("maxItems"):
        parts.append(f"at least {node['minItems']} items")
    return "; ".join(parts)


def _default(node: dict) -> str:
    return f"`{_toml(node['default'])}`" if "default" in node else ""


def _toml(value) -> str:
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }" if value else "{}"
    return f"{value:g}" if isinstance(value, float) else str(value)


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _table(root: dict, heading: str, node: dict, required: list[str]) -> list[str]:
    lines = [f"**{heading}**" + (f": {_cell(node['description'])}" if "description" in node else ""), "",
             "| key | type | unit | default | allowed | meaning |", "| --- | --- | --- | --- | --- | --- |"]
    for key, raw in node["properties"].items():
        p = _resolve(root, raw)
        if set(p) <= {"const"}:  # a material type's own `type`, stated by its table's heading
            continue
        name = f"`{key}`" + (" (required)" if key in required else "")
        lines.append("| " + " | ".join(_cell(c) for c in (name, _type(root, p), p.get("x-unit", ""), _default(p),
                                                           _allowed(p), p.get("description", ""))) + " |")
    return lines + [""]


def tables(fmt: str) -> str:
    """The Markdown reference of format ``fmt``: its top-level table, then each table it defines."""
    root = schema(fmt)
    out = _table(root, "top level", root, root.get("required", []))
    seen = set()
    for name, node in root["$defs"].items():
        node = _resolve(root, node)
        if "properties" in node and name not in seen and name not in ("reflectance",):
            seen.add(name)
            out += _table(root, f"[{name}]" if fmt != "scene" or name not in ("diffuse", "mirror", "dielectric")
                          else f'type = "{name}"', node, node.get("required", []))
    return "\n".join(out).rstrip("\n") + "\n"


#: The docs' block of each format's tables, named after its schema file.
BLOCKS = {"scene": "scene.schema.json", "gate": "gate.schema.json", "renderers": "renderers.schema.json"}


def blocks() -> dict[str, str]:
    """Every format's tables, by block name (:data:`BLOCKS`)."""
    return {BLOCKS[fmt]: tables(fmt) for fmt in FORMATS}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--markdown", action="append", type=Path, default=[], help="rewrite the tables in FILE")
    args = parser.parse_args(argv)
    if not args.markdown:
        print("\n".join(blocks().values()))
    markdown_blocks.write_blocks(args.markdown, blocks())


if __name__ == "__main__":
    main()

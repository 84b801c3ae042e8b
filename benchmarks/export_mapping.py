"""Each export format's mapping table, written into ``docs/export.md`` between its markers.

    .venv/bin/python -m benchmarks.export_mapping --markdown docs/export.md

The tables are :func:`cornell_harness.scenes.export.mapping_table`, the format modules' ``MAPPING`` rows: written
here so the page cannot drift from the code (``tests/scenes/test_export_docs.py`` checks that it has not).
A format whose module is missing from this tree is left as it is, with a line on stderr.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks import markdown_blocks
from cornell_harness.scenes.export import FORMATS, mapping_table

#: The block of docs/export.md that holds each format's table (benchmarks/markdown_blocks.py).
BLOCKS = {"mapping-mitsuba": "mitsuba", "mapping-luxcore": "luxcore", "mapping-pbrt-v4": "pbrt-v4",
          "mapping-json": "json", "mapping-gltf": "gltf", "mapping-usd": "usd"}


def tables() -> dict[str, str]:
    """Block name: the table, for each format whose module is present."""
    out = {}
    for block, fmt in BLOCKS.items():
        try:
            out[block] = mapping_table(fmt)
        except ModuleNotFoundError as e:
            if e.name != FORMATS[fmt]:
                raise
            print(f"export_mapping: {fmt}: {e.name} is missing; its block is left as it is", file=sys.stderr)
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", action="append", default=[], help="write the tables into this file (repeatable)")
    args = ap.parse_args(argv)
    bodies = tables()
    if not args.markdown:
        print("\n\n".join(bodies.values()))
    markdown_blocks.write_blocks([Path(p) for p in args.markdown], bodies)


if __name__ == "__main__":
    main()

"""``docs/export.md`` shows each export format's mapping table as the code has it (``mapping_table``).

The tables are written by ``benchmarks/export_mapping.py`` between the page's markers; a table edited by hand,
or a ``MAPPING`` row changed without rerunning the command, fails here.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from benchmarks import export_mapping, markdown_blocks
from cornell_harness.scenes.export import FORMATS, mapping_table

PAGE = Path(__file__).resolve().parents[2] / "docs" / "export.md"


def test_every_format_has_a_block():
    assert sorted(export_mapping.BLOCKS.values()) == sorted(FORMATS)


@pytest.mark.parametrize("block, fmt", sorted(export_mapping.BLOCKS.items()))
def test_the_page_shows_the_formats_mapping_table(block, fmt):
    if importlib.util.find_spec(FORMATS[fmt]) is None:
        pytest.skip(f"{FORMATS[fmt]} is not in this tree (another branch writes it); its table is written "
                    f"when it is: .venv/bin/python -m benchmarks.export_mapping --markdown docs/export.md")
    text = PAGE.read_text(encoding="utf-8")
    _, blocks = markdown_blocks.parse(text)
    (b,) = [b for b in blocks if b.name == block]
    body = "\n".join(text.splitlines()[b.begin + 1:b.end])
    assert body == mapping_table(fmt), f"docs/export.md's {block} is stale: rerun {b.command}"

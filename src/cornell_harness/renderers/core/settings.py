"""Settings as every renderer of ours reads them: complete and typed, validated once, by the harness.

The render path resolves a renderer's declared settings
(:class:`cornell_harness.adapters.api.Setting`) once and hands ``render`` the complete
mapping, so a renderer reads ``settings["name"]`` and never validates again.
A direct caller (a test, a benchmark) may name only the settings it changes:
:func:`with_defaults` fills in the declared defaults, and checks nothing.
"""

from __future__ import annotations

from typing import Sequence

from cornell_harness.adapters.api import Setting


def with_defaults(declared: Sequence[Setting], settings: dict | None) -> dict:
    """``settings`` over the ``declared`` defaults (a complete mapping passes through unchanged)."""
    return {**{s.name: s.default for s in declared}, **(settings or {})}

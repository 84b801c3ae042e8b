"""Durations as users write them (``10s``, ``2m``, ``500ms``): parsed once, for every time budget and time
limit, in the CLI, the gate's config and a renderers file.

Kept apart from the workflows that use them so that reading a gate config or a
renderers file imports nothing heavy (a typo must fail in a second, not after loading SciPy).
"""

from __future__ import annotations

import re


def parse_duration(text: str, what: str = "time budget") -> float:
    """``"10s"``, ``"2m"``, ``"500ms"``, ``"1.5"`` (seconds) → seconds; a ValueError names the value as ``what``."""
    m = re.fullmatch(r"\s*([0-9]*\.?[0-9]+)\s*(ms|s|m|min|h)?\s*", text)
    if not m:
        raise ValueError(f"{what} {text!r}: expected e.g. 10s, 2m, 500ms")
    scale = {"ms": 1e-3, "s": 1.0, None: 1.0, "m": 60.0, "min": 60.0, "h": 3600.0}[m.group(2)]
    value = float(m.group(1)) * scale
    if value <= 0:
        raise ValueError(f"{what} {text!r}: must be positive")
    return value

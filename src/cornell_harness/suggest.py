"""Did-you-mean: the known name closest to a misspelt one, for the one-line user errors.

Every "unknown NAME" message (renderers, their settings, stored scenes,
metrics, regions, stress variants, scene and gate-config keys, and the
``cbox`` sub-commands and options) asks :func:`closest`, so a near miss is
found the same way everywhere: by :func:`difflib.get_close_matches`, and
case-insensitively, since ``-r Mitsuba`` is as near a miss as ``-r mitsuba3``.
"""

from __future__ import annotations

import difflib
from typing import Iterable

#: difflib's similarity ratio a known name must reach to be suggested (its default).
CUTOFF = 0.6
#: Only this many characters of a given name are compared: difflib is quadratic, and a
#: 50 MB "key" from a fuzzed file must not take minutes to be refused.
MAX_CHARS = 100


def closest(word: object, known: Iterable[object]) -> str | None:
    """The name in ``known`` closest to ``word`` (ignoring case), or None when none is close."""
    by_folded: dict[str, str] = {}
    for name in map(str, known):
        by_folded.setdefault(name.casefold(), name)
    folded = str(word)[:MAX_CHARS].casefold()
    if folded in by_folded:
        return by_folded[folded]
    match = difflib.get_close_matches(folded, list(by_folded), n=1, cutoff=CUTOFF)
    return by_folded[match[0]] if match else None


def did_you_mean(word: object, known: Iterable[object], template: str = " (did you mean {!r}?)") -> str:
    """``template`` filled with the closest known name, or "" when none is close: for the end of a message."""
    hint = closest(word, known)
    return template.format(hint) if hint is not None else ""

"""Options that take one of a fixed set of words (``--input-transfer srgb|linear``, ``--format``,
``--time-basis``): matched in any case (``sRGB`` is ``srgb``), refused with did-you-mean otherwise.

The words are given as a function, so that a command module need not import
the module that owns them until the option is parsed (``cbox --help`` stays
fast). Every such option carries its words in :data:`CHOICE_OPTIONS`, where
a test finds them all.
"""

from __future__ import annotations

from typing import Any, Callable, Iterable

import typer

from cornell_harness.suggest import did_you_mean

#: The words of each choice option, by its flag (filled as the options are made; read by the tests).
CHOICE_OPTIONS: dict[str, Callable[[], Iterable[str]]] = {}


#: The refusal of a word that is none of the known ones ({value!r}, {hint}: did-you-mean, {known}: "a or b").
REFUSAL = "{value!r}: give {known}{hint}"


def canonical_choice(value: str, known: Iterable[str], refusal: str = REFUSAL) -> str:
    """``value`` spelt as in ``known``, whatever its case; :class:`typer.BadParameter` when it is none."""
    known = list(known)
    by_folded = {k.casefold(): k for k in known}
    match = by_folded.get(str(value).casefold())
    if match is None:
        raise typer.BadParameter(refusal.format(value=value, known=" or ".join(known),
                                                hint=did_you_mean(value, known), listed=", ".join(known)))
    return match


def choice_callback(flag: str, words: Callable[[], Iterable[str]], refusal: str = REFUSAL) -> Callable:
    """A typer callback turning the option's value (or each value, when repeatable) into its known spelling."""
    CHOICE_OPTIONS[flag] = words

    def callback(ctx: Any, value: Any) -> Any:
        if value is None or getattr(ctx, "resilient_parsing", False):
            return value
        if isinstance(value, (list, tuple)):
            return [canonical_choice(v, words(), refusal) for v in value]
        return canonical_choice(value, words(), refusal)

    return callback

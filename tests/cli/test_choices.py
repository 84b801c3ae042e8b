"""Enum options accept any case (issue 31): every option of every command that takes one of a fixed set of
words, found by walking the app, takes each word in upper and in mixed case, and refuses a near miss with
did-you-mean."""

from __future__ import annotations

import pytest
import typer
from typer._click.core import Context

from cornell_harness.cli.app import command_tree
from cornell_harness.cli.choices import CHOICE_OPTIONS, canonical_choice


def _options():
    """(command path, option) of every option of every command, sub-commands included."""
    def walk(group, path=()):
        for name, cmd in getattr(group, "commands", {}).items():
            yield from walk(cmd, (*path, name))
        for p in group.params:
            yield path, group, p
    return list(walk(command_tree()))


def _word_options():
    """Options whose metavar lists words (``a|b``), as the choice options show them in --help."""
    return [(path, cmd, p) for path, cmd, p in _options() if "|" in (getattr(p, "metavar", None) or "")]


def test_every_enum_option_is_a_choice_option():
    found = {o for _, _, p in _word_options() for o in p.opts if o.startswith("--")}
    # The issue's --input-transfer, and every other: none is left out, none registered is missing from the app.
    assert found == set(CHOICE_OPTIONS) >= {"--input-transfer", "--format", "--time-basis"}


@pytest.mark.parametrize("path, cmd, param", _word_options(), ids=lambda x: " ".join(x) if isinstance(x, tuple)
                         else getattr(x, "name", None))
def test_enum_options_take_any_case(path, cmd, param):
    flag = next(o for o in param.opts if o.startswith("--"))
    words = list(CHOICE_OPTIONS[flag]())
    assert param.metavar == "|".join(words)
    ctx = Context(cmd)
    for word in words:
        for given in (word.upper(), word.capitalize(), word):
            assert param.process_value(ctx, given) == word, (path, flag, given)
    with pytest.raises(typer.BadParameter, match="did you mean"):
        param.process_value(ctx, words[0][:-1] + "X")


def test_the_issue_case_srgb():
    assert canonical_choice("sRGB", ["srgb", "linear"]) == "srgb"
    with pytest.raises(typer.BadParameter, match="'rgb': give srgb or linear \\(did you mean 'srgb'\\?\\)"):
        canonical_choice("rgb", ["srgb", "linear"])

"""The generated parts of the docs: one marker convention, and one atomic way to rewrite them.

A script's tables and figures in ``docs/*.md`` and ``BENCHMARKS.md`` lie between two HTML comments (invisible
when the page is rendered); the opening one names the block and the exact command that writes it::

    <!-- gate_power.py: begin, written by .venv/bin/python benchmarks/gate_power.py --markdown docs/gate-detection.md -->
    ...
    <!-- gate_power.py: end -->

Everything outside the markers is prose and stays as it is when the script runs again. A page a script writes
whole (``docs/denoising.md``) starts with ``<!-- page, written by COMMAND -->`` instead. A block's name is unique
in its file and appears in its script as a string literal; ``tests/test_docs.py`` checks every marker of the docs
with :func:`parse`. Scripts take ``--markdown FILE`` (repeatable) and rewrite the blocks each file holds.
"""

from __future__ import annotations

import re
import shlex
import sys
from dataclasses import dataclass
from pathlib import Path

from cornell_harness.store.atomic import write_text_atomic

ROOT = Path(__file__).resolve().parents[1]
NAME = r"[\w.#/-]+"
BEGIN = re.compile(rf"<!-- (?P<name>{NAME}): begin, written by (?P<command>\S.*?) -->")
END = re.compile(rf"<!-- (?P<name>{NAME}): end -->")
PAGE = re.compile(r"<!-- page, written by (?P<command>\S.*?) -->")
#: A comment that means to be a marker (says begin, end or written by): it must match one of the three above.
MARKERISH = re.compile(r"<!--.*(\bbegin\b|\bend\b|written by).*-->")


class MarkerError(ValueError):
    """A marker that does not parse, a block without its end, or an end without its block."""


@dataclass(frozen=True)
class Block:
    name: str
    command: str
    begin: int  # line index of the opening marker
    end: int  # line index of the closing marker


def begin_marker(name: str, command: str) -> str:
    return f"<!-- {name}: begin, written by {command} -->"


def end_marker(name: str) -> str:
    return f"<!-- {name}: end -->"


def page_marker(command: str) -> str:
    return f"<!-- page, written by {command} -->"


def command_line(argv: list[str] | None = None) -> str:
    """The command that ran this script, as the markers name it: ``.venv/bin/python benchmarks/x.py ARGS``."""
    argv = list(sys.argv if argv is None else argv)
    script = Path(argv[0]).resolve()
    try:
        script = script.relative_to(ROOT)
    except ValueError:
        pass
    return " ".join([".venv/bin/python", shlex.quote(str(script))] + [shlex.quote(a) for a in argv[1:]])


def script_words(command: str) -> list[str]:
    """The command's words, ``-m benchmarks.NAME`` read as the script ``benchmarks/NAME.py`` it runs."""
    words = shlex.split(command)
    if len(words) > 2 and words[1] == "-m" and words[2].startswith("benchmarks."):
        words = [words[0], words[2].replace(".", "/") + ".py", *words[3:]]
    return words


def minus(number: str) -> str:
    """A formatted number with the docs' minus sign (U+2212) for Python's leading hyphen (an exponent's stays)."""
    return "\u2212" + number[1:] if number.startswith("-") else number


def bold(text: str, on: bool = True) -> str:
    return f"**{text}**" if on else text


def parse(text: str) -> tuple[str | None, list[Block]]:
    """The page's command (its first line's page marker, else None) and its blocks, in order.

    Raises :class:`MarkerError` for a marker-like comment that is none of the three forms, a page marker
    anywhere but the first line, a nested or unclosed block, an end without its begin, or a name used twice.
    """
    page, blocks, open_, seen = None, [], None, set()
    for i, line in enumerate(text.splitlines()):
        s = line.strip()
        if not MARKERISH.search(s):
            continue
        if m := PAGE.fullmatch(s):
            if i != 0:
                raise MarkerError(f"line {i + 1}: a page marker must be the first line")
            page = m["command"]
        elif m := BEGIN.fullmatch(s):
            if open_ is not None:
                raise MarkerError(f"line {i + 1}: block {m['name']!r} begins inside {open_[0]!r}")
            if m["name"] in seen:
                raise MarkerError(f"line {i + 1}: block {m['name']!r} appears twice")
            open_ = (m["name"], m["command"], i)
            seen.add(m["name"])
        elif m := END.fullmatch(s):
            if open_ is None or open_[0] != m["name"]:
                raise MarkerError(f"line {i + 1}: end of {m['name']!r} without its begin")
            blocks.append(Block(open_[0], open_[1], open_[2], i))
            open_ = None
        else:
            raise MarkerError(f"line {i + 1}: not a marker of the convention (markdown_blocks.py): {s}")
    if open_ is not None:
        raise MarkerError(f"line {open_[2] + 1}: block {open_[0]!r} has no end marker")
    return page, blocks


def replace_blocks(text: str, bodies: dict[str, str], command: str) -> tuple[str, set[str]]:
    """``text`` with each named block's body replaced (its opening marker naming ``command``); and the names
    it held. Blocks of other names, and everything outside the markers, are kept as they are."""
    _, blocks = parse(text)
    lines = text.splitlines()
    done = set()
    for b in reversed(blocks):  # from the end, so that earlier line indices stay valid
        if b.name in bodies:
            body = bodies[b.name].strip("\n").splitlines()
            lines[b.begin:b.end + 1] = [begin_marker(b.name, command), *body, end_marker(b.name)]
            done.add(b.name)
    return ("\n".join(lines) + "\n" if done else text), done


def write_blocks(paths: list[Path], bodies: dict[str, str], command: str | None = None) -> None:
    """Rewrite the blocks in ``paths`` (each file the blocks it holds), every file atomically.

    A block that no file holds yet is appended to the first file (created if missing), so that a first run
    leaves it where prose can be written around it.
    """
    if not paths:
        return
    command = command or command_line()
    old = {path: path.read_text(encoding="utf-8") if path.exists() else "" for path in paths}
    new, left = {}, dict(bodies)
    for path in paths:
        new[path], done = replace_blocks(old[path], left, command)
        for name in done:
            del left[name]
    first = paths[0]
    for name, body in left.items():
        new[first] = (new[first].rstrip("\n") + "\n\n" if new[first].strip() else "") + "\n".join(
            [begin_marker(name, command), body.strip("\n"), end_marker(name)]) + "\n"
    for path in paths:
        if new[path] != old[path]:
            write_text_atomic(path, new[path])


def write_page(path: Path, body: str, command: str | None = None) -> None:
    """Write a whole generated page, atomically, its first line naming the command."""
    write_text_atomic(path, page_marker(command or command_line()) + "\n" + body.lstrip("\n"))

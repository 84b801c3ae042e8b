"""The gate's CI outputs: JUnit XML for a CI's test-report view, and a Markdown step summary.

Both are written for every run, a config error included, so a CI's test
view always has something to show. In JUnit a check that ran and failed is a
``<failure>``; a crash, or a config error that stopped the gate before it
rendered, is an ``<error>`` (with the renderer's traceback as its body; a
crash's is on its ``render`` case, never a pass); a check
that was not made (a renderer that reports no variance has none to check) is
``<skipped/>``, never a pass. An inconclusive check (an interval straddles its margin: neither pass nor
fail) is a ``<failure message="inconclusive">`` with its message as the body, or, where the expectation says
``inconclusive = "pass"``, a pass whose output starts with "inconclusive". Times are honest: each expectation's
render is timed once, on a test case of its own (``render``); its checks take no time.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:  # only for annotations: writing a config error's JUnit must not load SciPy
    from cornell_harness.gate.checks import Check, Outcome


def junit_xml(outcomes: Sequence[Outcome], suite: str = "cbox gate", config_error: str | None = None) -> str:
    """JUnit XML: per expectation a ``render`` case with its time, then one case per check.

    A render that did not finish (crashed, killed at its time limit, unavailable) is not a pass: its
    ``render`` case carries the run's own check, the crash's ``<error>`` with its traceback or the time
    limit's ``<failure>``, rather than a case of its own beside a passed ``render``."""
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", name=suite)
    counts = dict.fromkeys(("tests", "failures", "errors", "skipped"), 0)
    total = 0.0
    if config_error is not None:
        case = ET.SubElement(ts, "testcase", classname="config", name="config", time="0")
        ET.SubElement(case, "error", message=config_error).text = config_error
        counts.update(tests=1, errors=1)
    for o in outcomes:
        t = float(o.record.time_s or 0.0)
        total += t
        render = ET.SubElement(ts, "testcase", classname=o.expectation.name, name="render", time=f"{t:.3f}")
        counts["tests"] += 1
        checks = list(o.checks)
        if o.record.status == "ok" or not checks:
            ET.SubElement(render, "system-out").text = f"{o.record.renderer}: {o.record.status}, {o.record.spp} spp"
        else:  # the outcome of a run that did not finish is that run's one check (checks.evaluate)
            _result(render, checks.pop(0), counts)
        for c in checks:
            case = ET.SubElement(ts, "testcase", classname=o.expectation.name, name=c.name, time="0")
            counts["tests"] += 1
            _result(case, c, counts)
    for key, n in counts.items():
        ts.set(key, str(n))
    ts.set("time", f"{total:.3f}")
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def _result(case: ET.Element, c: Check, counts: dict[str, int]) -> None:
    """``c``'s result on its test case (``<skipped/>``, ``<error>``, ``<failure>``, or a pass's message), counted."""
    if c.skipped:
        counts["skipped"] += 1
        ET.SubElement(case, "skipped", message=c.message)
    elif c.inconclusive and not c.passed:
        counts["failures"] += 1
        ET.SubElement(case, "failure", message="inconclusive").text = c.message
    elif c.inconclusive:
        ET.SubElement(case, "system-out").text = f"inconclusive (counted as a pass: inconclusive = \"pass\"): {c.message}"
    elif c.passed:
        ET.SubElement(case, "system-out").text = c.message
    elif c.error:
        counts["errors"] += 1
        ET.SubElement(case, "error", message=c.message).text = \
            c.message + (f"\n\n{c.traceback.rstrip()}" if c.traceback else "")
    else:
        counts["failures"] += 1
        ET.SubElement(case, "failure", message=c.message).text = c.message


#: The widest a Markdown table row may be: wider rows wrap into unreadable columns in a step summary.
ROW_CHARS = 120
NAME_CHARS = 44  # an expectation name longer than this is cut in the table, given in full below it
MIN_DETAIL_CHARS = 20  # a row's detail is never cut shorter (so a row may pass ROW_CHARS by a few)
_HEAD = ["| expectation | check | result | detail |", "|---|---|---|---|"]


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _cut(text: str, room: int, middle: bool = False) -> str:
    """``text`` in at most ``room`` characters: its end (or, ``middle``, its middle) replaced by "…"."""
    if len(text) <= room:
        return text
    if middle:  # a sweep's expectation name differs in its settings and its spp, at both ends
        head = (room - 1) // 2
        return text[:head] + "…" + text[len(text) - (room - 1 - head):]
    return text[:room - 1].rstrip("\\ ") + "…"


def _row(name: str, c: Check) -> tuple[str, bool]:
    """A table row of at most about :data:`ROW_CHARS` (the name and detail cut to fit) and whether it was cut."""
    cell = _cut(_cell(name), NAME_CHARS, middle=True)
    head = f"| {cell} | {_cell(c.name)} | {'**' + c.word + '**' if not c.passed else c.word} | "
    detail = _cell(c.message)
    shown = _cut(detail, max(MIN_DETAIL_CHARS, ROW_CHARS - len(head) - 2))
    return f"{head}{shown} |", shown != detail or cell != _cell(name)


def _table(rows: list[tuple[str, Check]]) -> list[str]:
    """The table of ``rows``, then in full every message the table cut and every traceback."""
    lines, notes = list(_HEAD), []
    for name, c in rows:
        row, cut = _row(name, c)
        lines.append(row)
        if cut or c.traceback:
            notes.append(f"- `{name}` **{c.name}**: {c.message}")
        if c.traceback:
            notes += ["", "  ```", *(f"  {line}" for line in c.traceback.rstrip().splitlines()), "  ```"]
    return lines + ([""] + notes if notes else [])


def markdown_summary(outcomes: Sequence[Outcome], alpha: float, config_error: str | None = None) -> str:
    """A Markdown verdict for a CI step summary: the failed checks first, in a table with each message in full
    below it; every other check folded in ``<details>``. Table rows are at most :data:`ROW_CHARS` characters."""
    if config_error is not None:
        return f"## cbox gate: ❌ **config error**\n\n`{config_error}`\n\nNothing was rendered.\n"
    rows = [(o.expectation.name, c) for o in outcomes for c in o.checks]
    failed = [(n, c) for n, c in rows if c.failed]
    open_ = [(n, c) for n, c in rows if c.inconclusive and not c.passed]
    skipped = [(n, c) for n, c in rows if c.skipped]
    rest = skipped + [(n, c) for n, c in rows if c.passed and not c.skipped]
    verdict = (f"❌ **gate failed**: {len(failed)} check(s)" if failed else
               f"⚠️ **gate inconclusive**: {len(open_)} check(s)" if open_ else "✅ **gate passed**")
    lines = [f"## cbox gate: {verdict}", "",
             f"{len(rows)} checks of {len(outcomes)} expectation(s): {len(failed)} failed, "
             + (f"{len(open_)} inconclusive, " if open_ else "")
             + f"{len(rest) - len(skipped)} passed, {len(skipped)} skipped. Agreement tests at "
             f"family-wise α = {alpha:g} (Šidák over tiles, named regions, the whole image and channels).", ""]
    if note := no_bound_note(outcomes):
        lines += [note, ""]
    if failed:
        lines += ["### Failed", "", *_table(failed), ""]
    if open_:
        lines += ["### Inconclusive", "", *_table(open_), ""]
    if rest:
        lines += [f"<details><summary>{len(rest) - len(skipped)} passed, {len(skipped)} skipped</summary>", "",
                  *_table(rest), "", "</details>"]
    return "\n".join(lines) + "\n"


def no_bound_note(outcomes: Sequence[Outcome]) -> str | None:
    """One line for a run whose unbiased expectations state no margin: their passes bound no bias."""
    bare = [o.expectation.name for o in outcomes if o.expectation.unbiased and o.expectation.margins is None]
    if not bare:
        return None
    return (f"Note: {len(bare)} unbiased expectation(s) state no margin, so their passes carry no bound: a pass "
            "says only that no bias was significant at their spp. A margin = { image = 0.01, "
            "\"region.<region>\" = 0.05 } bounds it (docs/gate-detection.md, \"Margins and three verdicts\").")

"""The gate's CI outputs: JUnit XML for a CI's test-report view, and a Markdown step summary.

Both are written for every run, a config error included, so a CI's test
view always has something to show. In JUnit a check that ran and failed is a
``<failure>``; a crash, or a config error that stopped the gate before it
rendered, is an ``<error>``. Times are honest: each expectation's render is
timed once, on a test case of its own (``render``); its checks take no time.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:  # only for annotations: writing a config error's JUnit must not load SciPy
    from harness.gate.checks import Outcome


def junit_xml(outcomes: Sequence[Outcome], suite: str = "cbox gate", config_error: str | None = None) -> str:
    """JUnit XML: per expectation a ``render`` case with its time, then one case per check."""
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", name=suite)
    tests = failures = errors = 0
    total = 0.0
    if config_error is not None:
        case = ET.SubElement(ts, "testcase", classname="config", name="config", time="0")
        ET.SubElement(case, "error", message=config_error).text = config_error
        tests, errors = 1, 1
    for o in outcomes:
        t = float(o.record.time_s or 0.0)
        total += t
        render = ET.SubElement(ts, "testcase", classname=o.expectation.name, name="render", time=f"{t:.3f}")
        ET.SubElement(render, "system-out").text = f"{o.record.renderer}: {o.record.status}, {o.record.spp} spp"
        tests += 1
        for c in o.checks:
            case = ET.SubElement(ts, "testcase", classname=o.expectation.name, name=c.name, time="0")
            tests += 1
            if c.passed:
                ET.SubElement(case, "system-out").text = c.message
            elif c.error:
                errors += 1
                ET.SubElement(case, "error", message=c.message).text = c.message
            else:
                failures += 1
                ET.SubElement(case, "failure", message=c.message).text = c.message
    ts.set("tests", str(tests))
    ts.set("failures", str(failures))
    ts.set("errors", str(errors))
    ts.set("time", f"{total:.3f}")
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def markdown_summary(outcomes: Sequence[Outcome], alpha: float, config_error: str | None = None) -> str:
    """A Markdown verdict for a CI step summary."""
    if config_error is not None:
        return f"## cbox gate: ❌ **config error**\n\n`{config_error}`\n\nNothing was rendered.\n"
    failed = [c for o in outcomes for c in o.checks if not c.passed]
    verdict = "✅ **gate passed**" if not failed else f"❌ **gate failed**: {len(failed)} check(s)"
    lines = [f"## cbox gate: {verdict}", "",
             f"Agreement tests at family-wise α = {alpha:g} (Šidák over tiles, named regions, the whole image and channels).", "",
             "| expectation | spp | seed | check | result | detail |", "|---|---|---|---|---|---|"]
    for o in outcomes:
        for c in o.checks:
            detail = c.message.replace("|", "\\|")
            result = "pass" if c.passed else "**ERROR**" if c.error else "**FAIL**"
            lines.append(f"| {o.expectation.name} | {o.record.spp} | {o.record.seed} | {c.name} | {result} | {detail} |")
    return "\n".join(lines) + "\n"

"""The gate's CI outputs: JUnit XML for a CI's test-report view, and a Markdown step summary."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from typing import Sequence

from harness.gate.checks import Outcome


def junit_xml(outcomes: Sequence[Outcome], suite: str = "cbox gate") -> str:
    """JUnit XML: one test case per check, named expectation::check."""
    checks = [c for o in outcomes for c in o.checks]
    root = ET.Element("testsuites")
    ts = ET.SubElement(root, "testsuite", name=suite, tests=str(len(checks)),
                       failures=str(sum(not c.passed for c in checks)), errors="0")
    for o in outcomes:
        t = f"{o.record.time_s:.3f}" if o.record.time_s else "0"
        for c in o.checks:
            case = ET.SubElement(ts, "testcase", classname=o.expectation.name, name=c.name, time=t)
            if not c.passed:
                ET.SubElement(case, "failure", message=c.message).text = c.message
            else:
                ET.SubElement(case, "system-out").text = c.message
    return ET.tostring(root, encoding="unicode", xml_declaration=True)


def markdown_summary(outcomes: Sequence[Outcome], alpha: float) -> str:
    """A Markdown verdict for a CI step summary."""
    failed = [c for o in outcomes for c in o.checks if not c.passed]
    verdict = "✅ **gate passed**" if not failed else f"❌ **gate failed**: {len(failed)} check(s)"
    lines = [f"## cbox gate: {verdict}", "",
             f"Agreement tests at family-wise α = {alpha:g} (Šidák over tiles and channels).", "",
             "| expectation | spp | seed | check | result | detail |", "|---|---|---|---|---|---|"]
    for o in outcomes:
        for c in o.checks:
            detail = c.message.replace("|", "\\|")
            lines.append(f"| {o.expectation.name} | {o.record.spp} | {o.record.seed} | {c.name} | "
                         f"{'pass' if c.passed else '**FAIL**'} | {detail} |")
    return "\n".join(lines) + "\n"

"""The gate's CI outputs (src/cornell_harness/reports/ci.py) on made-up outcomes: the Markdown summary's order and row width, and
JUnit's result elements. No rendering: each outcome is the few fields the writers read."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from types import SimpleNamespace

from cornell_harness.gate.checks import Check
from cornell_harness.reports.ci import ROW_CHARS, junit_xml, markdown_summary

LONG = "cornell-box-caustics/pathtracer[sampler=\"independent\",max_depth=12]@1024spp"


def _outcome(name: str, *checks: Check, status: str = "ok") -> SimpleNamespace:
    record = SimpleNamespace(time_s=1.5, renderer="pathtracer", status=status, spp=1024, seed=0)
    return SimpleNamespace(expectation=SimpleNamespace(name=name, unbiased=False, margins=None), record=record,
                           checks=list(checks))


def _outcomes() -> list[SimpleNamespace]:
    wordy = "; ".join(f"tile {i}: z = {4 + i}.25 | off by +{i}%" for i in range(30))  # ~700 characters, with pipes
    return [_outcome("cornell-box/mitsuba@256spp", Check("a", "finite", True, "no NaN or Inf pixel"),
                     Check("a", "variance", True, "skipped: the renderer reports no variance", skipped=True)),
            _outcome(LONG, Check("b", "finite", True, "no NaN or Inf pixel"),
                     Check("b", "agreement", False, wordy)),
            _outcome("furnace/crashes@1spp", Check("c", "run", False, "failed: RuntimeError: boom", error=True,
                                                   traceback="Traceback (most recent call last):\n  raise boom\n"),
                     status="failed")]


def test_markdown_failures_first_the_rest_folded_rows_at_most_120_characters():
    md = markdown_summary(_outcomes(), 0.01)
    rows = [line for line in md.splitlines() if line.startswith("|")]
    assert rows and max(len(r) for r in rows) <= ROW_CHARS, max(rows, key=len)
    # Every row has the header's four columns: a '|' inside a message is escaped, never a column.
    assert all(len(re.findall(r"(?<!\\)\|", r)) == 5 for r in rows)
    folded = md.index("<details>")
    failed_rows = [r for r in rows if "**FAIL**" in r or "**ERROR**" in r]
    assert len(failed_rows) == 2 and all(md.index(r) < folded for r in failed_rows)
    rest = md[folded:md.index("</details>")]
    assert "| finite | pass |" in rest and "| variance | skipped |" in rest and "FAIL" not in rest
    assert md.index("### Failed") < folded and "<summary>2 passed, 1 skipped</summary>" in rest
    # A message the table cut is given in full below it, and a crash's traceback with it.
    wordy = _outcomes()[1].checks[1].message
    assert f"- `{LONG}` **agreement**: {wordy}" in md[:folded]
    assert "  raise boom" in md[:folded]
    assert "3 failed" not in md and "2 failed, 2 passed, 1 skipped" in md


def test_junit_skipped_error_failure_and_pass():
    suite = ET.fromstring(junit_xml(_outcomes())).find("testsuite")
    cases = {(c.get("classname"), c.get("name")): c for c in suite.iter("testcase")}
    assert cases[("cornell-box/mitsuba@256spp", "variance")].find("skipped") is not None
    assert cases[("cornell-box/mitsuba@256spp", "finite")].find("skipped") is None
    assert cases[(LONG, "agreement")].find("failure") is not None
    # A crashed render's render case is its <error>, with the reason and traceback, not a pass beside it.
    crashed = cases[("furnace/crashes@1spp", "render")]
    error = crashed.find("error")
    assert error.get("message") == "failed: RuntimeError: boom" and crashed.find("system-out") is None
    assert error.text == "failed: RuntimeError: boom\n\nTraceback (most recent call last):\n  raise boom"
    assert ("furnace/crashes@1spp", "run") not in cases  # the one error, counted once
    assert cases[("cornell-box/mitsuba@256spp", "render")].find("system-out").text == "pathtracer: ok, 1024 spp"
    counts = (suite.get("tests"), suite.get("failures"), suite.get("errors"), suite.get("skipped"))
    assert counts == ("7", "1", "1", "1")


def test_junit_render_killed_at_its_time_limit_is_a_failure():
    killed = _outcome("cornell-box/slow@1spp", Check("d", "time_limit", False, "killed at its time limit of 5 s"),
                      status="failed")
    suite = ET.fromstring(junit_xml([killed])).find("testsuite")
    (case,) = suite.iter("testcase")
    assert case.get("name") == "render" and case.find("failure").get("message") == "killed at its time limit of 5 s"
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("1", "1", "0")


def test_markdown_of_a_passing_gate_is_all_folded():
    md = markdown_summary([_outcomes()[0]], 0.01)
    assert "gate passed" in md and "### Failed" not in md and md.count("<details>") == 1

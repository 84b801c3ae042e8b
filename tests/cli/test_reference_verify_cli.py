"""``cbox reference verify``: the table, the exit code, the recorded verdict, ``cbox scenes`` and the report page.

The stored cornell-box is copied into a temporary references folder (``CBOX_REFERENCES``), so the recorded
verdict never touches the repository's provenance.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from tests.conftest import ROOT

STORED = ROOT / "src" / "cornell_harness" / "references" / "cornell-box"


@pytest.fixture
def references(tmp_path):
    """A copy of the stored cornell-box without the verdicts its provenance carries: each test starts unverified."""
    root = tmp_path / "refs"
    shutil.copytree(STORED, root / "cornell-box")
    path = root / "cornell-box" / "provenance.json"
    prov = json.loads(path.read_text())
    prov.pop("verified", None)
    path.write_text(json.dumps(prov, indent=1) + "\n")
    return root


def _cbox(references, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "CBOX_REFERENCES": str(references)}
    return subprocess.run([sys.executable, "-m", "cornell_harness", *args], capture_output=True, text=True, timeout=600,
                          cwd=ROOT, env=env)


def test_mitsuba_at_other_seeds_agrees_and_the_verdict_is_recorded_and_listed(references, tmp_path):
    stored = (STORED / "provenance.json").read_bytes()
    assert "not verified" in _cbox(references, "scenes").stdout
    proc = _cbox(references, "reference", "verify", "--scene", "cornell-box", "--engine", "mitsuba", "--spp", "64",
                 "--batches", "4", "--report", str(tmp_path / "rep"))
    assert proc.returncode == 0, proc.stderr + proc.stdout
    for region in ("whole image", "walls", "boxes", "floor", "light", "back-edge"):
        assert f"\n  {region} " in proc.stdout, region
    assert "the engines agree" in proc.stdout and "χ²" in proc.stdout and "per-pixel z: sd" in proc.stdout
    prov = json.loads((references / "cornell-box" / "provenance.json").read_text())
    rec = prov["verified"]["mitsuba"]
    assert rec["passed"] and rec["spp"] == 64 and rec["batches"] == 4 and len(rec["regions"]) == 6
    assert rec["command"].endswith("--report " + str(tmp_path / "rep"))
    assert (STORED / "provenance.json").read_bytes() == stored  # the repository's reference untouched
    page = (tmp_path / "rep" / "reference-verify-cornell-box.html").read_text()
    assert page.count("<img ") == 3 and "back-edge" in page and "agree" in page
    listing = _cbox(references, "scenes")
    assert listing.returncode == 0, listing.stderr
    assert f"reference: verified by mitsuba: max |z| {rec['max_abs_z']:.1f} (6 regions, 64 spp)" in listing.stdout
    entry = json.loads(_cbox(references, "scenes", "--json").stdout)[0]
    assert entry["reference"]["verified"]["mitsuba"]["passed"] is True


def test_a_one_percent_darker_engine_exits_1_and_no_record_leaves_the_provenance(references):
    before = (references / "cornell-box" / "provenance.json").read_bytes()
    proc = _cbox(references, "reference", "verify", "--scene", "cornell-box", "--engine",
                 "tests.user_renderers:Biased1Percent", "--spp", "64", "--batches", "1", "--no-record")
    assert proc.returncode == 1, proc.stderr + proc.stdout
    assert "the engines DISAGREE" in proc.stdout and " * " in proc.stdout  # a failing row is starred
    assert (references / "cornell-box" / "provenance.json").read_bytes() == before
    assert "reference: not verified" in _cbox(references, "scenes").stdout


def test_bad_options_are_refused_before_rendering(references):
    proc = _cbox(references, "reference", "verify", "--scene", "cornell-box", "--engine", "mitsuba", "--spp", "10",
                 "--batches", "4")
    assert proc.returncode == 2 and "multiple of --batches" in proc.stderr
    proc = _cbox(references, "reference", "verify", "--scene", "cornell-box", "--engine",
                 "tests.user_renderers:SeededNoise", "--spp", "4", "--batches", "1")
    assert proc.returncode != 0 and "reports no variance" in proc.stderr and "Traceback" not in proc.stderr


def test_help_explains_each_option():
    proc = subprocess.run([sys.executable, "-m", "cornell_harness", "reference", "verify", "--help"], capture_output=True,
                          text=True, timeout=120, cwd=ROOT, env={**os.environ, "COLUMNS": "200"})
    assert proc.returncode == 0
    for option in ("--scene", "--engine", "--spp", "--batches", "--workers", "--record", "--report", "--set"):
        assert option in proc.stdout, option
    assert "Šidák" in proc.stdout and "Exits 1" in proc.stdout

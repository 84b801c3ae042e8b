"""``cbox reference verify``: the table, the exit code, the recorded verdict, ``cbox scenes`` and the report page.

The verdict is recorded in the test's own user store (``$CBOX_HOME``, tests/conftest.py's ``user_store``),
never in the package's stored reference, whose files each test checks are unchanged.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

from cornell_harness.store.references import VERDICTS_FILE, verdict_line
from tests.conftest import ROOT

STORED = ROOT / "src" / "cornell_harness" / "references" / "cornell-box"


def _package_files() -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in STORED.iterdir()}


def _cbox(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "cornell_harness", *args], capture_output=True, text=True, timeout=600,
                          cwd=ROOT, env=dict(os.environ))


def test_mitsuba_at_other_seeds_agrees_and_the_verdict_is_recorded_and_listed(user_store, tmp_path):
    stored = _package_files()
    before = _cbox("scenes")
    assert f"user store: {user_store} (from $CBOX_HOME)" == before.stdout.splitlines()[0]
    assert "recorded (user store)" not in before.stdout
    proc = _cbox("reference", "verify", "--scene", "cornell-box", "--engine", "mitsuba", "--spp", "64",
                 "--batches", "4", "--margin", "back-edge=0.5", "--report", str(tmp_path / "rep"))
    assert proc.returncode == 0, proc.stderr + proc.stdout
    for region in ("whole image", "walls", "boxes", "floor", "light", "back-edge"):
        assert f"\n  {region} " in proc.stdout, region
    assert "the engines agree within the margins" in proc.stdout and "χ²" in proc.stdout
    assert "per-pixel z: sd" in proc.stdout and "detectable (power 0.8)" in proc.stdout
    recorded = user_store / "references" / "cornell-box" / VERDICTS_FILE
    assert f"recorded in {recorded} under mitsuba" in proc.stdout
    rec = json.loads(recorded.read_text())["mitsuba"]
    assert rec["passed"] and rec["spp"] == 64 and rec["batches"] == 4 and len(rec["regions"]) == 6
    assert rec["command"].endswith("--report " + str(tmp_path / "rep"))
    assert rec["verdict"] == "pass" and rec["regions"]["back-edge"]["margin"] == [0.5] * 3
    assert (tmp_path / "rep" / "reference-verify-cornell-box-variance.exr").exists()
    assert rec["reference_digest"].startswith("sha256:")
    assert _package_files() == stored  # the package's reference untouched
    page = (tmp_path / "rep" / "reference-verify-cornell-box.html").read_text()
    assert page.count("<img ") == 3 and "back-edge" in page and "agree" in page
    listing = _cbox("scenes")
    assert listing.returncode == 0, listing.stderr
    line = f"recorded (user store): verified by mitsuba: max |z| {rec['max_abs_z']:.1f} (6 regions, 64 spp)"
    assert line in listing.stdout
    # The stored verdicts are shown as before, on their own line.
    shipped = json.loads(stored["provenance.json"])["verified"]
    assert f"reference: {verdict_line(shipped)}" in listing.stdout and "luxcore" in shipped
    entry = json.loads(_cbox("scenes", "--json").stdout)[0]
    assert entry["user_folder"] == str(user_store / "references" / "cornell-box")
    assert entry["reference"]["recorded"]["mitsuba"]["passed"] is True
    assert set(entry["reference"]["verified"]) == set(shipped) and not entry["reference"]["in_user_store"]


def test_a_one_percent_darker_engine_exits_1_and_no_record_writes_nothing(user_store, tmp_path):
    stored = _package_files()
    other = tmp_path / "other-home"
    proc = _cbox("reference", "verify", "--scene", "cornell-box", "--engine", "tests.user_renderers:Biased1Percent",
                 "--spp", "64", "--batches", "1", "--no-record", "--home", str(other))
    assert proc.returncode == 1, proc.stderr + proc.stdout
    assert "the engines DISAGREE" in proc.stdout and " * " in proc.stdout  # a failing row is starred
    assert _package_files() == stored and not other.exists() and not any(user_store.iterdir())
    recorded = _cbox("reference", "verify", "--scene", "cornell-box", "--engine",
                     "tests.user_renderers:Biased1Percent", "--spp", "64", "--batches", "1", "--home", str(other))
    assert recorded.returncode == 1 and (other / "references" / "cornell-box" / VERDICTS_FILE).exists()
    assert _package_files() == stored and not any(user_store.iterdir())  # --home, not $CBOX_HOME
    listing = _cbox("scenes", "--home", str(other))
    assert "recorded (user store): DISAGREES with biased-1pct" in listing.stdout, listing.stdout
    assert "recorded (user store)" not in _cbox("scenes").stdout


def test_bad_options_are_refused_before_rendering():
    proc = _cbox("reference", "verify", "--scene", "cornell-box", "--engine", "mitsuba", "--spp", "10",
                 "--batches", "4")
    assert proc.returncode == 2 and "multiple of --batches" in proc.stderr
    proc = _cbox("reference", "verify", "--scene", "cornell-box", "--engine",
                 "tests.user_renderers:SeededNoise", "--spp", "4", "--batches", "1")
    assert proc.returncode != 0 and "reports no variance" in proc.stderr and "Traceback" not in proc.stderr


def test_help_explains_each_option():
    proc = subprocess.run([sys.executable, "-m", "cornell_harness", "reference", "verify", "--help"], capture_output=True,
                          text=True, timeout=120, cwd=ROOT, env={**os.environ, "COLUMNS": "200"})
    assert proc.returncode == 0
    for option in ("--scene", "--engine", "--spp", "--batches", "--workers", "--record", "--report", "--set", "--home"):
        assert option in proc.stdout, option
    assert "Šidák" in proc.stdout and "Exits 1" in proc.stdout


def test_an_unresolved_region_is_inconclusive_exit_3_with_its_power(user_store, tmp_path):
    """The reference plus its own noise at 64 spp: no difference is significant, but the 144-pixel back edge's
    interval reaches past the default 5% margin; its image and variance are kept as EXR beside the report."""
    from cornell_harness.store.exr import read_exr

    proc = _cbox("reference", "verify", "--scene", "cornell-box", "--engine", "tests.user_renderers:ScaledMitsubaNoise",
                 "--spp", "64", "--batches", "1", "--no-record", "--report", str(tmp_path / "rep"))
    assert proc.returncode == 3, proc.stderr + proc.stdout
    rows = {line.split()[0]: line for line in proc.stdout.splitlines() if line.startswith("  ")}
    assert rows["back-edge"].rstrip().endswith("±5%     inconclusive") and rows["walls"].rstrip().endswith("pass")
    assert "INCONCLUSIVE: no significant difference" in proc.stdout and "(back-edge)" in proc.stdout
    assert "remark:" not in proc.stdout  # the noise model's own variance: z sd 1
    image = read_exr(tmp_path / "rep" / "reference-verify-cornell-box-image.exr")
    assert image.shape == (256, 256, 3)
    wide = _cbox("reference", "verify", "--scene", "cornell-box", "--engine", "tests.user_renderers:ScaledMitsubaNoise",
                 "--spp", "64", "--batches", "1", "--no-record", "--margin", "0.2")
    assert wide.returncode == 0 and "the engines agree within the margins" in wide.stdout


def test_a_bad_margin_is_exit_2():
    for bad, words in (("caustic=0.1", "has no region 'caustic'"), ("0", "(0, 1]"), ("floor=x", "(0, 1]")):
        proc = _cbox("reference", "verify", "--scene", "cornell-box", "--engine", "mitsuba", "--margin", bad)
        assert proc.returncode == 2 and words in proc.stderr, proc.stderr

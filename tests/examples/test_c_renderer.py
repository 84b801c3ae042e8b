"""examples/c-renderer: a renderer in C that reads the neutral JSON export, gated like any other.

The suite compiles ``ao.c`` with ``cc`` (``scripts/setup.sh --tests`` installs one where it is missing), and
runs it through ``cbox gate`` against the stored ``cornell-box-ao`` reference at that reference's resolution and
the project gate's 64 spp, as ``examples/renderers.toml``'s ``c-ao`` entry declares it: it passes. The same
source with one line changed, the AO distance × 0.98, fails the agreement test in the same gate run.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import tomllib
from pathlib import Path

import pytest

from tests.conftest import run_cbox

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "examples" / "c-renderer" / "ao.c"
EXAMPLES = ROOT / "examples" / "renderers.toml"
#: The planted bug: occluders counted only within 0.98 of the scene's AO distance.
LINE, BUG = "double reach = ao_distance;", "double reach = ao_distance * 0.98;"
GATE = """alpha = 0.01
[[expect]]
scene = "cornell-box-ao"
renderer = "{name}"
spp = 64
seed = 0
unbiased = true
tile = 16
"""


def compile_c(source: Path, program: Path) -> Path:
    cc = shutil.which("cc")
    if cc is None:
        pytest.fail("no C compiler (cc) on PATH: scripts/setup.sh --tests installs one")
    proc = subprocess.run([cc, "-O2", "-Wall", "-Werror", "-o", str(program), str(source), "-lm"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    return program


def declared(program: Path, name: str) -> str:
    """examples/renderers.toml's c-ao table, as TOML, with its program replaced by ``program``."""
    table = tomllib.loads(EXAMPLES.read_text(encoding="utf-8"))["renderer"]["c-ao"]
    table["command"] = [str(program), *table["command"][1:]]
    return f"[renderer.{name}]\n" + "".join(f"{k} = {json.dumps(v)}\n" for k, v in table.items())


def test_the_c_renderer_passes_the_gate_and_its_planted_bug_fails_it(tmp_path):
    text = SOURCE.read_text(encoding="utf-8")
    assert text.count(LINE) == 1
    (tmp_path / "bug.c").write_text(text.replace(LINE, BUG), encoding="utf-8")
    good, bug = compile_c(SOURCE, tmp_path / "ao"), compile_c(tmp_path / "bug.c", tmp_path / "ao-bug")
    renderers = tmp_path / "renderers.toml"
    renderers.write_text(declared(good, "c-ao") + "\n" + declared(bug, "c-ao-bug"), encoding="utf-8")
    config = tmp_path / "gate.toml"
    config.write_text(GATE.format(name="c-ao") + GATE.format(name="c-ao-bug").split("\n", 1)[1], encoding="utf-8")
    proc = run_cbox("gate", "--config", str(config), "--renderers", str(renderers), "--out", str(tmp_path / "out"),
                    "--json")
    assert proc.returncode == 1, proc.stderr
    verdicts = {e["renderer"]: e for e in json.loads(proc.stdout)["expectations"]}
    checks = {name: {c["name"]: c for c in e["checks"]} for name, e in verdicts.items()}
    assert verdicts["c-ao"]["passed"], checks["c-ao"]
    assert checks["c-ao"]["agreement"]["passed"] and not checks["c-ao"]["agreement"]["skipped"]
    assert not verdicts["c-ao-bug"]["passed"]
    assert not checks["c-ao-bug"]["agreement"]["passed"] and checks["c-ao-bug"]["finite"]["passed"]


def test_the_makefile_builds_what_the_example_file_runs():
    make = (SOURCE.parent / "Makefile").read_text(encoding="utf-8")
    command = tomllib.loads(EXAMPLES.read_text(encoding="utf-8"))["renderer"]["c-ao"]["command"]
    assert command[0] == "c-renderer/ao" and "-o $@ ao.c -lm" in make
    assert len(SOURCE.read_text(encoding="utf-8").splitlines()) <= 300

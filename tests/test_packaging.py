"""A built wheel is the product: installed into a fresh virtual environment, away from this checkout, it runs.

The wheel is built from this tree (``pip wheel --no-deps``) and installed into two fresh venvs. One holds the
core alone (``pip install`` of the wheel, its core dependencies from the package index, no extra), which
must score, export and gate, and name each missing extra's pip line. The other has the wheel installed
with ``--no-deps`` into a new venv whose only view of the dependencies is a
``.pth`` line naming this project's venv's site-packages: a path line adds
the folder but runs none of its ``.pth`` files, so the editable install of
this checkout stays invisible and every ``cornell_harness``
import comes from the wheel. Commands run from an empty folder.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from tests.conftest import ROOT


def _run(cmd, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=kw.pop("timeout", 600), **kw)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    proc = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(out), str(ROOT)])
    assert proc.returncode == 0, proc.stderr
    (path,) = out.glob("cornell_harness-*.whl")
    return path


def _pip_env() -> dict:
    """This environment without PYTHONPATH: pip would take a checkout's ``src/*.egg-info`` there for this
    distribution installed already, and install nothing."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}


@pytest.fixture(scope="module")
def venv(tmp_path_factory, wheel) -> Path:
    """A fresh venv with the wheel installed; the dependencies seen through a path line."""
    root = tmp_path_factory.mktemp("venv")
    assert _run([sys.executable, "-m", "venv", str(root)]).returncode == 0
    py = root / "bin" / "python"
    purelib = _run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip()
    (Path(purelib) / "cbox_test_deps.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    proc = _run([str(py), "-m", "pip", "install", "--no-deps", "-q", str(wheel)], env=_pip_env())
    assert proc.returncode == 0, proc.stderr
    return root


def _clean_env(tmp: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "CBOX_REFERENCES")}
    env["NUMBA_CACHE_DIR"] = str(tmp / "numba-cache")  # the installed package's folder is not ours to fill
    return env


def test_wheel_carries_the_stored_scenes_references_and_templates(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    package = ROOT / "src" / "cornell_harness"
    stored = sorted(p.relative_to(package).as_posix() for p in (package / "references").glob("*/*") if p.is_file())
    assert stored and {f"cornell_harness/{p}" for p in stored} <= names
    assert "cornell_harness/reports/templates/report.html.j2" in names
    # One top-level import package: none of the generic names other distributions on PyPI use.
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"cornell_harness"}, tops
    meta = next(n for n in names if n.endswith(".dist-info/METADATA"))
    text = zipfile.ZipFile(wheel).read(meta).decode()
    assert "License-Expression: MIT" in text  # an SPDX string (PEP 639), not a TOML table


def test_installed_wheel_lists_scenes_and_compares_from_an_empty_folder(venv, tmp_path):
    cbox, env = venv / "bin" / "cbox", _clean_env(tmp_path)
    where = _run([str(venv / "bin" / "python"), "-c", "import cornell_harness; print(cornell_harness.__file__)"], cwd=tmp_path,
                 env=env)
    assert where.stdout.startswith(str(venv)), where.stdout + where.stderr  # the wheel, not this checkout
    scenes = _run([str(cbox), "scenes"], cwd=tmp_path, env=env)
    assert scenes.returncode == 0 and "cornell-box " in scenes.stdout and "reference" in scenes.stdout, scenes.stderr
    proc = _run([str(cbox), "compare", "--scene", "cornell-box", "-r", "mitsuba", "--spp", "4", "--out", "out"],
                cwd=tmp_path, env=env)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "out" / "report.html").exists() and (tmp_path / "out" / "metrics.csv").exists()


@pytest.mark.slow
def test_installed_wheel_runs_the_demo_to_a_report(venv, tmp_path):
    """The issue's promise, in full: ``pip install`` of the wheel, then ``cbox demo`` (a few minutes)."""
    proc = _run([str(venv / "bin" / "cbox"), "demo", "--out", "out"], cwd=tmp_path, env=_clean_env(tmp_path),
                timeout=1800)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "out" / "report.html").exists()


def _tree(folder: Path) -> dict[str, tuple[str, int, int]]:
    """Every file under ``folder``: content digest, size and mtime."""
    return {p.relative_to(folder).as_posix(): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_size,
                                               p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_installed_wheel_builds_and_records_into_the_user_store_never_into_the_package(venv, tmp_path):
    """``reference build --set`` and ``reference verify`` from the wheel, its package made read-only: what they
    make lands in the user store ($CBOX_HOME). Root writes through a read-only mode, so the test also checks
    that no file of the installed package was added, removed or changed (content and mtime)."""
    cbox, env, home = venv / "bin" / "cbox", _clean_env(tmp_path), tmp_path / "home"
    env["CBOX_HOME"] = str(home)
    where = _run([str(venv / "bin" / "python"), "-c", "import cornell_harness; print(cornell_harness.__file__)"],
                 cwd=tmp_path, env=env)
    package = Path(where.stdout.strip()).parent
    assert package.is_relative_to(venv), where.stdout + where.stderr
    assert (package / "references" / "cornell-box" / "provenance.json").exists()
    before = _tree(package)
    assert _run(["chmod", "-R", "a-w", str(package)]).returncode == 0
    try:
        build = _run([str(cbox), "reference", "build", "--scene", "cornell-box", "--set", "camera.resolution=16,16",
                      "--spp", "4", "--batches", "2"], cwd=tmp_path, env=env)
        verify = _run([str(cbox), "reference", "verify", "--scene", "cornell-box", "--engine", "mitsuba", "--spp", "4",
                       "--batches", "2"], cwd=tmp_path, env=env)
        listing = _run([str(cbox), "scenes"], cwd=tmp_path, env=env)
        version = _run([str(cbox), "--version"], cwd=tmp_path, env=env)
    finally:
        _run(["chmod", "-R", "u+w", str(package)])
    assert build.returncode == 0, build.stderr
    mine = home / "references" / "cornell-box"
    (derived,) = (mine / "derived").iterdir()
    assert f"wrote {derived} " in build.stdout
    assert sorted(p.name for p in derived.iterdir()) == ["noise.exr", "provenance.json", "reference.exr",
                                                         "variance.exr"]
    # A verdict, whichever: at 4 spp a region is usually unresolved to its margin (inconclusive, exit 3).
    assert verify.returncode in (0, 1, 3) and ("the engines" in verify.stdout or "INCONCLUSIVE: " in verify.stdout), \
        verify.stdout + verify.stderr
    assert f"recorded in {mine / 'verdicts.json'} under mitsuba" in verify.stdout
    assert "mitsuba" in json.loads((mine / "verdicts.json").read_text())
    assert listing.stdout.startswith(f"user store: {home} (from $CBOX_HOME)\n"), listing.stdout
    assert "recorded (user store): " in listing.stdout and "mitsuba" in listing.stdout
    assert version.stdout.splitlines()[1] == f"user store: {home} (from $CBOX_HOME)", version.stdout
    assert _tree(package) == before


# ------------------------------------------------------------------------------------------ the core alone

#: A renderer outside the harness, run as a program (examples/renderers.toml's format): it writes the stored
#: reference it is given, or (mode=grey) a flat grey.
_PROGRAM = """
import sys
import numpy as np
import OpenImageIO as oiio
args = dict(a.split("=", 1) for a in sys.argv[1:])
img = oiio.ImageBuf(args["ref"]).get_pixels(oiio.FLOAT)[..., :3]
if args.get("mode") == "grey":
    img = np.full_like(img, 0.5)
out = oiio.ImageOutput.create(args["out"])
out.open(args["out"], oiio.ImageSpec(img.shape[1], img.shape[0], 3, oiio.FLOAT))
out.write_image(np.ascontiguousarray(img, np.float32))
out.close()
"""
_MODELS = '["triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light", "pinhole_camera", "box_filter"]'


@pytest.fixture(scope="module")
def core_venv(tmp_path_factory, wheel) -> Path:
    """A fresh venv with the wheel and its core dependencies alone, from the package index (pip's cache)."""
    root = tmp_path_factory.mktemp("core-venv")
    assert _run([sys.executable, "-m", "venv", str(root)]).returncode == 0
    proc = _run([str(root / "bin" / "python"), "-m", "pip", "install", "-q", str(wheel)], timeout=1200, env=_pip_env())
    assert proc.returncode == 0 and (root / "bin" / "cbox").exists(), proc.stdout + proc.stderr
    return root


def _stored(venv: Path, *parts: str) -> Path:
    (site_packages,) = (venv / "lib").glob("python3*/site-packages")
    return site_packages.joinpath("cornell_harness", "references", *parts)


@pytest.mark.slow  # pip installs some 50 packages into a new venv (~40 s from an empty cache), then 8 commands
def test_the_core_install_alone_scores_exports_and_gates(core_venv, tmp_path):
    py, cbox, env = core_venv / "bin" / "python", str(core_venv / "bin" / "cbox"), _clean_env(tmp_path)
    run = functools.partial(_run, cwd=tmp_path, env=env)
    assert run([str(py), "-c", "import harness"]).returncode != 0  # one import package, cornell_harness
    found = run([str(py), "-c", "import importlib.util as u; print([m for m in ('numba', 'embreex', 'mitsuba', "
                 "'pyluxcore', 'pyrender', 'pyoidn', 'dask', 'flip_evaluator') if u.find_spec(m)])"])
    assert found.stdout.strip() == "[]", found.stdout + found.stderr  # no extra came with the core

    listing = run([cbox, "renderers"])
    assert listing.returncode == 0, listing.stderr
    lines = {line.split()[0]: line for line in listing.stdout.splitlines() if line and not line[0].isspace()}
    assert "unavailable" in lines["pathtracer"] and lines["pathtracer"].endswith("pip install 'cornell-harness[ours]'")
    assert lines["luxcore"].endswith("pip install 'cornell-harness[luxcore]'")
    assert lines["mitsuba+oidn"].endswith("pip install 'cornell-harness[mitsuba,oidn]'")

    ref = _stored(core_venv, "cornell-box", "reference.exr")
    scored = run([cbox, "compare-image", str(_stored(core_venv, "cornell-box", "noise.exr")), "--reference", str(ref),
                  "--fail", "flip_mean=0.5", "--fail", "delta_e2000_mean=5", "--json"])
    assert scored.returncode == 0, scored.stderr
    metrics = json.loads(scored.stdout.splitlines()[0])["metrics"]
    assert 0.01 < metrics["flip_mean"] < 0.5 and 0.1 < metrics["delta_e2000_mean"] < 5  # HDR-FLIP without numba

    exported = run([cbox, "export", "--scene", "cornell-box", "--format", "mitsuba", "--out", "xml"])
    assert exported.returncode == 0 and (tmp_path / "xml" / "scene.xml").is_file(), exported.stderr

    (tmp_path / "program.py").write_text(_PROGRAM)
    renderers = tmp_path / "renderers.toml"
    renderers.write_text("".join(
        f'[renderer.{name}]\ncommand = ["python", "{tmp_path / "program.py"}", "ref={ref}", "out={{out}}", '
        f'"mode={name}"]\nscene_format = "mitsuba"\nmodels = {_MODELS}\n' for name in ("copy", "grey")))
    for name, code in (("copy", 0), ("grey", 1)):  # the stored reference itself passes; a flat grey fails
        (tmp_path / f"{name}.toml").write_text(f'[[expect]]\nscene = "cornell-box"\nrenderer = "{name}"\nspp = 16\n'
                                               'unbiased = true\ntile = 16\n')
        gated = run([cbox, "gate", "--renderers", str(renderers), "--config", f"{name}.toml", "--out", f"gate-{name}"])
        assert gated.returncode == code, gated.stdout + gated.stderr
        assert ("gate passed" if code == 0 else "FAIL  cornell-box/grey@16spp  agreement") in gated.stdout

    workers = run([cbox, "gate", "--renderers", str(renderers), "--config", "copy.toml", "--workers", "2",
                   "--out", "gate-workers"])
    assert workers.returncode == 2
    assert workers.stderr.strip().splitlines() == ["cbox: error: --workers needs the [dask] extra (dask, distributed "
                                                   "not installed): pip install 'cornell-harness[dask]'"]

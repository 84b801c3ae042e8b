"""Command-line renderers declared as data (src/cornell_harness/adapters/renderers_file.py) and run
(src/cornell_harness/adapters/commands.py) on fake programs.

The fake program is a Python script written into tmp_path and run with this interpreter; it writes an EXR
whose every pixel is ``spp + seed / 1000`` (so a test sees which run made which image), and fails, hangs or
writes the wrong size when told to. In this process the scene is exported in a fake format, this module
(``NAME``, ``FEATURES``, ``MAPPING``, ``write``: cornell_harness.scenes.export's interface); a sandboxed render
re-reads the renderers file in a child process, where only the real formats exist.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cornell_harness.adapters import commands, registry
from cornell_harness.adapters.commands import CommandRenderer
from cornell_harness.adapters.renderers_file import RenderersFileError, read_file, spec_of
from cornell_harness.adapters.registry import RendererError, resolve
from cornell_harness.scenes import export
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import FEATURES
from cornell_harness.workflows import runner
from tests.conftest import cbox_in_process as cbox

# --- the fake export format ------------------------------------------------------------------------------------

NAME = "fake"
FEATURES = tuple(FEATURES)
MAPPING = (("everything", "the scene", "its resolution, as text"),)


def write(scene, folder: Path) -> Path:
    main = Path(folder) / "scene.txt"
    main.write_text(f"{scene.camera.width} {scene.camera.height}\n")
    return main


@pytest.fixture
def fake_format(monkeypatch):
    monkeypatch.setitem(export.FORMATS, NAME, __name__)


# --- the fake program --------------------------------------------------------------------------------------------

PROGRAM = """\
import os, sys, time
import numpy as np
from cornell_harness.store.exr import write_exr

args = dict(a.split("=", 1) for a in sys.argv[1:])
mode = args.get("mode", "ok")
with open(args["log"], "a") as log:
    log.write(f"{args['spp']} {args['seed']} {os.getpid()}\\n")
width, height = int(args["width"]), int(args["height"])
if "copy" in args:  # the scene file it was given, kept for the test
    open(args["copy"], "w").write(open(args["scene"]).read())
if args["scene"].endswith(".txt"):  # the fake format's: the resolution (a real format's is only read there)
    assert list(map(int, open(args["scene"]).read().split())) == [width, height]
spp, seed = int(args["spp"]), int(args["seed"])
if mode == "fail":
    print("loading the scene", file=sys.stderr)
    print("fatal: no GPU here", file=sys.stderr)
    sys.exit(3)
if mode == "hang":
    time.sleep(600)
if mode == "spawn-hang":  # a child of its own, logged as a run is (its PID last), then both hang
    import subprocess
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    with open(args["log"], "a") as log:
        log.write(f"{args['spp']} {args['seed']} {child.pid}\\n")
    time.sleep(600)
if mode == "hog":  # 400 MB, touched, held
    hog = np.ones(50_000_000)
    time.sleep(600)
if mode == "small":
    width -= 1
if mode == "burn":  # 0.3 s of CPU time in all
    while time.process_time() < 0.3:
        pass
write_exr(args["out"], np.full((height, width, 3), spp + seed / 1000))
if mode != "novar" and "variance" in args:
    write_exr(args["variance"], np.full((height, width, 3), 1.0 / spp))
print(f"threads {args.get('threads')}; render took {0.25 * spp} s")
"""


def _toml(value) -> str:
    return json.dumps(value)  # a JSON string or list of strings is a TOML one


def renderers_file(tmp_path: Path, mode: str = "ok", name: str = "fake-cli", extra: str = "",
                   command_extra: tuple[str, ...] = (), scene_format: str = NAME) -> Path:
    """A renderers file declaring the fake program as ``name``, in ``mode``; ``extra`` lines join its table."""
    program = tmp_path / "program.py"
    program.write_text(PROGRAM)
    command = [sys.executable, str(program), "scene={scene}", "out={out}", "spp={spp}", "seed={seed}",
               "width={width}", "height={height}", "threads={threads}", f"mode={mode}",
               f"log={tmp_path / 'runs.log'}", *command_extra]
    path = tmp_path / f"{name}.toml"
    path.write_text(f"[renderer.{name}]\ncommand = {_toml(command)}\nscene_format = {_toml(scene_format)}\n"
                    f"models = {_toml(list(FEATURES))}\n{extra}")
    return path


def runs(tmp_path: Path) -> list[tuple[int, int]]:
    """(spp, seed) of every run of the fake program, in order."""
    log = tmp_path / "runs.log"
    return [tuple(map(int, line.split()[:2])) for line in log.read_text().splitlines()] if log.exists() else []


@pytest.fixture
def scene(write_scene):
    return resolve_scene(str(write_scene()))  # 8x6


def the_renderer(path: Path, name: str = "fake-cli") -> CommandRenderer:
    (entry,) = resolve([spec_of(path, name)])
    assert entry.available, entry.reason
    return entry.renderer


# --- renders -----------------------------------------------------------------------------------------------------


def test_each_checkpoint_is_a_run_of_its_own_at_the_same_seed(tmp_path, fake_format, scene):
    r = the_renderer(renderers_file(tmp_path))
    res = r.render(scene, 8, 5, checkpoints=[2, 4, 8])
    assert runs(tmp_path) == [(2, 5), (4, 5), (8, 5)]
    assert res.image.shape == (6, 8, 3) and np.all(res.image == np.float32(8.005))
    assert [(c.spp, float(c.image[0, 0, 0])) for c in res.checkpoints] == [(2, np.float32(2.005)),
                                                                          (4, np.float32(4.005))]
    assert res.variance is None and res.time_s > 0  # wall time of the run: its interpreter start at least
    assert res.info["scene_format"] == NAME


def test_variance_and_time_from_stdout(tmp_path, fake_format, scene):
    path = renderers_file(tmp_path, command_extra=("variance={out}.var.exr",),
                          extra='variance = "{out}.var.exr"\ntime = \'render took ([0-9.]+) s\'\n')
    res = the_renderer(path).render(scene, 16, 0)
    assert np.allclose(res.variance, 1 / 16) and res.variance.shape == (6, 8, 3)
    assert res.time_s == 4.0  # 0.25 s per spp, as the program said, not the wall time


def test_threads_placeholder_is_the_harness_thread_count(tmp_path, fake_format, scene, monkeypatch):
    monkeypatch.setenv("CBOX_THREADS", "3")
    path = renderers_file(tmp_path, extra='time = "threads ([0-9]+);"\n')
    assert the_renderer(path).render(scene, 1, 0).time_s == 3.0


@pytest.mark.parametrize("mode, extra, says", [
    ("fail", "", "exited with code 3; stderr: loading the scene | fatal: no GPU here"),
    ("small", "", "its image is 7x6, expected 8x6"),
    ("novar", 'variance = "{out}.var.exr"\n', "exited 0 but wrote no variance image"),
    ("ok", 'time = "took ([0-9.]+) hours"\n', "no match of the time regex"),
])
def test_a_failing_program_is_a_failed_run_that_quotes_its_stderr(tmp_path, fake_format, scene, mode, extra,
                                                                     says):
    (entry,) = resolve([spec_of(renderers_file(tmp_path, mode, extra=extra), "fake-cli")])
    rec = runner.run_one(entry, scene, 4, 0, None)
    assert rec.status == "failed" and says in rec.reason, rec.reason
    assert rec.reason.startswith("CommandFailed: fake-cli at 4 spp: ")


def test_a_missing_program_is_unavailable_with_the_reason(tmp_path, fake_format):
    path = tmp_path / "r.toml"
    path.write_text('[renderer.gone]\ncommand = ["no-such-renderer-here", "{scene}"]\nscene_format = "fake"\n'
                    'models = ["diffuse"]\n')
    (entry,) = resolve([spec_of(path, "gone")])
    assert not entry.available and "program 'no-such-renderer-here' not found" in entry.reason


def test_a_relative_program_path_is_the_renderers_file_folders(tmp_path, fake_format, scene):
    script = tmp_path / "bin" / "render.sh"
    script.parent.mkdir()
    script.write_text(f"#!/bin/sh\nexec {sys.executable} {renderers_file(tmp_path).parent / 'program.py'} \"$@\"\n")
    script.chmod(0o755)
    path = tmp_path / "r.toml"
    path.write_text(f'[renderer.sh]\ncommand = ["bin/render.sh", "scene={{scene}}", "out={{out}}", "spp={{spp}}", '
                    f'"seed={{seed}}", "width={{width}}", "height={{height}}", "log={tmp_path / "runs.log"}"]\n'
                    'scene_format = "fake"\nmodels = ["diffuse"]\n')
    assert np.all(the_renderer(path, "sh").render(scene, 2, 0).image == 2.0)


def test_a_renderer_of_ambient_occlusion_runs_on_the_ao_scene_through_the_json_export(tmp_path):
    """The json format carries the AO definition: a command renderer that declares the quantity is run on an AO
    scene (every other format refuses to export one), and given the scene with its distance and miss value."""
    path = renderers_file(tmp_path, scene_format="json", extra='quantity = "ambient_occlusion"\n',
                          command_extra=(f"copy={tmp_path / 'given.json'}",))
    (entry,) = resolve([spec_of(path, "fake-cli")])
    scene = resolve_scene("cornell-box-ao").with_resolution(8, 6)
    rec = runner.run_one(entry, scene, 2, 0, None)
    assert rec.status == "ok", rec.reason
    given = json.loads((tmp_path / "given.json").read_text())
    assert given["quantity"] == "ambient_occlusion" and given["ambient_occlusion"]["max_distance"] == 0.5


def test_a_quantity_the_format_cannot_carry_is_exit_2_when_the_file_is_read(tmp_path, capsys, no_files):
    path = renderers_file(tmp_path, scene_format="mitsuba", extra='quantity = "ambient_occlusion"\n')
    code, _, err = cbox(capsys, "compare", "--scene", "cornell-box-ao", "--renderers", str(path), "-r", "fake-cli", "--spp",
                        "1", "--out", str(tmp_path / "out"))
    (line,) = err.strip().splitlines()
    assert code == 2, err
    assert f"{path}: renderer.fake-cli.quantity: the scene format 'mitsuba' cannot carry ambient_occlusion" in line
    assert not runs(tmp_path)


def _sandbox_format() -> str | None:
    """A real export format (a sandboxed child knows no fake one), or None while none is written."""
    for name in export.FORMATS:
        try:
            export.format_module(name)
            return name
        except ImportError:
            continue
    return None


@pytest.mark.skipif(_sandbox_format() is None, reason="no export format module yet (cornell_harness.scenes.export.*): a "
                                                      "sandboxed child must export the scene for real")
def test_a_hanging_program_is_killed_at_the_time_limit(tmp_path, scene):
    path = renderers_file(tmp_path, "hang", scene_format=_sandbox_format())
    (entry,) = resolve([spec_of(path, "fake-cli")])
    rec = runner.run_one(entry, scene, 4, 0, None, time_limit_s=10)  # the minimal scene: every format has it
    assert rec.status == "failed" and rec.info == {"timed_out": True}, rec.reason
    assert "killed at its time limit of 10 s" in rec.reason
    (_, _, pid), = [line.split() for line in (tmp_path / "runs.log").read_text().splitlines()]
    deadline = time.monotonic() + 10
    while _running(int(pid)) and time.monotonic() < deadline:  # killed with the sandbox's process group
        time.sleep(0.05)
    assert not _running(int(pid))


@pytest.mark.skipif(_sandbox_format() is None, reason="no export format module yet (cornell_harness.scenes.export.*): a "
                                                      "sandboxed child must export the scene for real")
def test_the_programs_memory_counts_against_the_sandboxs_bound(tmp_path, scene):
    from cornell_harness.workflows.sandbox import run_sandboxed

    """The program holds 400 MB for 600 s: killed by the 300 MB bound before its sleep ends. The time bound
    (300 s, past any start-up under load, short of the sleep) is out of reach, so a slow start on a busy
    machine cannot let it fire first (as it did in the stress suite's shared-bound test)."""
    path = renderers_file(tmp_path, "hog", scene_format=_sandbox_format())
    out = run_sandboxed(spec_of(path, "fake-cli"), [(scene, 1, 0)], time_bound_s=300, rss_bound_mb=300)
    assert out.ended == "memory" and out.peak_rss_mb > 300 and out.time_s < 300, (out.ended, out.message)


@pytest.mark.skipif(_sandbox_format() is None, reason="no export format module yet (cornell_harness.scenes.export.*): a "
                                                      "sandboxed child must export the scene for real")
def test_cpu_time_is_the_programs_own(tmp_path, scene):
    """The program burns 0.3 s of CPU: a render's cpu_time_s counts it (a child's CPU time, not this process's),
    and so does the results row, in this process and through the sandbox (the child's child)."""
    path = renderers_file(tmp_path, mode="burn", scene_format=_sandbox_format())
    res = the_renderer(path).render(scene, 2, 0, checkpoints=[1, 2])
    assert 0.3 <= res.cpu_time_s < 0.3 + 5.0 and 0.3 <= res.checkpoints[0].cpu_time_s < 5.3
    (entry,) = resolve([spec_of(path, "fake-cli")])
    for limit in (None, 120.0):
        row = runner.run_one(entry, scene, 1, 0, None, time_limit_s=limit).row()
        assert row["status"] == "ok" and 0.3 <= row["cpu_time_s"] < 5.3, (limit, row)
        assert "info_cpu_time_of" not in row  # measured by the renderer, not the whole call


def _running(pid: int) -> bool:
    """Whether ``pid`` runs: not gone, nor a zombie waiting for init to reap it."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rpartition(")")[2].split()[0] != "Z"
    except FileNotFoundError:
        return False


# --- the file ----------------------------------------------------------------------------------------------------

GOOD = {"command": ["prog", "{scene}", "{out}"], "scene_format": "fake", "models": ["diffuse"]}


def _write(tmp_path: Path, table: dict, name: str = "r", top: str = "") -> Path:
    lines = [top, f"[renderer.{name}]"] + [f"{k} = {_toml(v)}" for k, v in table.items()]
    path = tmp_path / "r.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("change, field, says", [
    ({"comand": ["x"]}, "renderer.r.comand", "unknown key (did you mean 'command'?)"),
    ({"command": "prog {scene}"}, "renderer.r.command", "expected a non-empty list of strings"),
    ({"command": []}, "renderer.r.command", "expected a non-empty list of strings"),
    ({"command": ["prog", "-o", "{output}"]}, "renderer.r.command[2]",
     "unknown placeholder {output} (did you mean {out}?)"),
    ({"command": ["prog", "{spp:04d}"]}, "renderer.r.command[1]", "takes no format or conversion"),
    ({"command": ["prog", "{scene"]}, "renderer.r.command[1]", "a literal brace is written {{"),
    ({"scene_format": "mitsuba3"}, "renderer.r.scene_format", "not an export format (did you mean 'mitsuba'?)"),
    ({"models": ["difuse"]}, "renderer.r.models[0]", "unknown scene feature 'difuse'; did you mean 'diffuse'?"),
    ({"models": "diffuse"}, "renderer.r.models", "expected a list of scene features"),
    ({"quantity": "radiance2"}, "renderer.r.quantity", "unknown quantity 'radiance2'; did you mean 'radiance'?"),
    ({"quantity": "ambient_occlusion"}, "renderer.r.quantity",
     "the scene format 'fake' cannot carry ambient_occlusion; scene formats that can: json"),
    ({"estimator": "unbiassed"}, "renderer.r.estimator", "did you mean 'unbiased'?"),
    ({"variance": "{out}.{spps}.exr"}, "renderer.r.variance", "unknown placeholder {spps} (did you mean {spp}?)"),
    ({"variance": 1}, "renderer.r.variance", "expected a path"),
    ({"time": "took [0-9.]+ s"}, "renderer.r.time", "the regex has 0 groups; give exactly one"),
    ({"time": "took ([0-9.]+ s"}, "renderer.r.time", "not a regex"),
    ({"time": 3}, "renderer.r.time", "expected \"wall\" or a regex"),
])
def test_a_wrong_field_is_one_line_naming_file_and_field(tmp_path, fake_format, change, field, says):
    path = _write(tmp_path, {**GOOD, **change})
    with pytest.raises(RenderersFileError) as e:
        read_file(path)
    assert str(e.value).startswith(f"{path}: {field}: ") and says in str(e.value), str(e.value)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("text, field, says", [
    ("[renderer.r]\ncommand = [\"p\"]\nscene_format = \"fake\"\n", "renderer.r.models", "missing"),
    ("[renderers.r]\n", "renderers", "unknown key (did you mean 'renderer'?)"),
    ("x = 1\n", "x", "unknown key"),
    ("", "renderer", "declares no renderer"),
    ("[renderer]\n\"a#b\" = {}\n", "renderer.\"a#b\"", "is not a renderer name"),
    ("[renderer.r\n", "(syntax)", "invalid TOML"),
])
def test_a_wrong_file_is_one_line(tmp_path, fake_format, text, field, says):
    path = tmp_path / "r.toml"
    path.write_text(text)
    with pytest.raises(RenderersFileError) as e:
        read_file(path)
    assert str(e.value).startswith(f"{path}: {field}: ") and says in str(e.value), str(e.value)


def test_models_beyond_the_format_are_refused(tmp_path, monkeypatch):
    monkeypatch.setitem(export.FORMATS, NAME, __name__)
    monkeypatch.setattr(sys.modules[__name__], "FEATURES", ("diffuse",))
    path = _write(tmp_path, {**GOOD, "models": ["diffuse", "sphere"]})
    with pytest.raises(RenderersFileError, match=r"renderer\.r\.models: the scene format 'fake' cannot express sphere"):
        read_file(path)


# --- the registry and the command line ---------------------------------------------------------------------------


@pytest.fixture
def no_files():
    registry.use_renderer_files(())
    yield
    registry.use_renderer_files(())


def test_declared_names_resolve_through_the_option_and_the_environment(tmp_path, fake_format, monkeypatch, no_files):
    path = renderers_file(tmp_path)
    with pytest.raises(RendererError, match="unknown renderer 'fake-cli'.*--renderers FILE"):
        resolve(["fake-cli"])
    monkeypatch.setenv(registry.RENDERERS_VARIABLE, str(path))
    (entry,) = resolve(["fake-cli"])
    assert entry.name == "fake-cli" and entry.spec == f"{path.resolve()}#fake-cli"
    assert "fake-cli" in [e.name for e in resolve(None)]  # every registered and declared renderer
    monkeypatch.delenv(registry.RENDERERS_VARIABLE)
    registry.use_renderer_files([path])
    assert resolve(["fake-cli"])[0].spec == entry.spec
    # The spec alone names it in any process: what the sandbox and Dask workers are given.
    registry.use_renderer_files(())
    assert resolve([entry.spec])[0].name == "fake-cli"
    from cornell_harness.workflows.cells import entry_for

    assert entry_for(entry.spec, {}).renderer.declaration == entry.renderer.declaration


def test_a_declared_name_must_not_hide_a_registered_renderer_or_another_file(tmp_path, fake_format, no_files):
    path = _write(tmp_path, GOOD, name="mitsuba")
    with pytest.raises(RenderersFileError, match=r"renderer\.mitsuba: 'mitsuba' is a registered renderer"):
        registry.use_renderer_files([path])
    one, two = tmp_path / "one", tmp_path / "two"
    one.mkdir(), two.mkdir()
    with pytest.raises(RenderersFileError, match=r"renderer\.fake-cli: also declared in .*one"):
        registry.use_renderer_files([renderers_file(one), renderers_file(two)])


# --- the shipped examples ----------------------------------------------------------------------------------------

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples" / "renderers.toml"


def test_the_example_file_declares_the_three_programs():
    declared = read_file(EXAMPLES)
    assert list(declared) == ["mitsuba-cli", "luxcore-cli", "c-ao"]
    assert (declared["c-ao"].scene_format, declared["c-ao"].quantity) == ("json", "ambient_occlusion")
    assert declared["mitsuba-cli"].command[0] == "mitsuba" and declared["mitsuba-cli"].scene_format == "mitsuba"
    assert declared["luxcore-cli"].command[:2] == ("cbox-luxcore", "{scene}")
    assert commands.find_program("mitsuba", EXAMPLES) is not None  # the Mitsuba wheel's, beside this Python

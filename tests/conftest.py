"""Shared fixtures: a small valid scene to mutate, and the stored Cornell box."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CORNELL = ROOT / "src" / "cornell_harness" / "references" / "cornell-box" / "scene.toml"

#: One white quad lit by a small emitter, seen by a camera: every field the format has.
MINIMAL_SCENE = """\
format = 1
name = "minimal"
features = ["triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"]

[camera]
type = "pinhole"
position = [0, 0, 3]
look_at = [0, 0, 0]
up = [0, 1, 0]
fov_deg = 40
fov_axis = "smaller"
resolution = [8, 6]

[render]
max_depth = -1
pixel_filter = "box"

[materials.white]
type = "diffuse"
reflectance = [0.8, 0.8, 0.8]

[[meshes]]
name = "floor"
material = "white"
vertices = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]]
faces = [[0, 1, 2, 3]]

[[meshes]]
name = "light"
material = "white"
vertices = [[-0.1, -0.1, 1], [-0.1, 0.1, 1], [0.1, 0.1, 1], [0.1, -0.1, 1]]
faces = [[0, 1, 2, 3]]
emitter = { radiance = [10, 10, 10] }
"""


@pytest.fixture(scope="session", autouse=True)
def session_user_store(tmp_path_factory):
    """The user store (``$CBOX_HOME``) of module fixtures, which set up before :func:`user_store`: a temporary
    folder, never the user's own, whatever a test builds or records."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("CBOX_HOME", str(tmp_path_factory.mktemp("cbox-home-session")))
        yield


@pytest.fixture(autouse=True)
def user_store(tmp_path_factory, monkeypatch) -> Path:
    """Each test's own empty user store (``$CBOX_HOME``, inherited by the commands it runs): what it builds or
    records never reaches the user's store or another test's."""
    home = tmp_path_factory.mktemp("cbox-home")
    monkeypatch.setenv("CBOX_HOME", str(home))
    return home


@pytest.fixture
def write_scene(tmp_path):
    """Write a scene text to tmp_path/scene.toml and return its path."""

    def write(text: str = MINIMAL_SCENE, name: str = "scene.toml") -> Path:
        path = tmp_path / name
        path.write_text(text)
        return path

    return write


def run_cbox(*args: str, timeout: float = 600, env_path: Path | None = None,
             env_extra: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run the CLI in a fresh interpreter, as a user would; ``env_path`` joins PYTHONPATH, ``env_extra`` is
    set in its environment (the test renderers' log file, say)."""
    env = {**os.environ, **(env_extra or {})}
    if env_path is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(env_path), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "cornell_harness", *args], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, env=env)


def cbox_in_process(capsys, *args: str) -> tuple[int, str, str]:
    """``cbox ARGS`` in this process: (exit code, stdout, stderr); faster than :func:`run_cbox`, for the CLI's
    own behaviour (a fresh interpreter is for what a user's shell sees)."""
    from cornell_harness.cli.app import main

    with pytest.raises(SystemExit) as e:
        main(list(args))
    out, err = capsys.readouterr()
    return e.value.code, out, err

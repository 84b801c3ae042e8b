"""The stored scenes: ``src/cornell_harness/references/<name>/scene.toml``, found by name.

A stored scene's folder also holds its reference (:mod:`cornell_harness.store.references`). The folder is
read-only package data: what is built or recorded for its scenes goes to the user store
(:mod:`cornell_harness.store.home`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

from cornell_harness.scenes.model import Scene, SceneError
from cornell_harness.scenes.overrides import load_derived_scene
from cornell_harness.suggest import did_you_mean


def references_root() -> Path:
    """Folder of stored scenes and references, read only: ``$CBOX_REFERENCES``, else
    ``src/cornell_harness/references/``, shipped in the package."""
    env = os.environ.get("CBOX_REFERENCES")
    return Path(env) if env else Path(__file__).resolve().parents[1] / "references"


def scene_names() -> list[str]:
    root = references_root()
    return sorted(p.parent.name for p in root.glob("*/scene.toml"))


def resolve_scene(name_or_path: str, overrides: Sequence[str] | None = ()) -> Scene:
    """Load a scene by stored name (``cornell-box``) or by path to a file or folder; with ``overrides``
    (``--set KEY=VALUE``), the scene derived from it (:mod:`cornell_harness.scenes.overrides`)."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.is_dir() or os.sep in name_or_path:
        return load_derived_scene(p, overrides or ())
    stored = references_root() / name_or_path / "scene.toml"
    if not stored.exists():
        names = scene_names()
        raise SceneError(name_or_path, "--scene", f"no stored scene of that name{did_you_mean(name_or_path, names)}; "
                         f"known: {', '.join(names) or '(none)'}; or give a path")
    return load_derived_scene(stored, overrides or ())

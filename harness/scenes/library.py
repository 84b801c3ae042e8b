"""The stored scenes: ``references/<name>/scene.toml``, found by name.

A stored scene's folder also holds its reference (:mod:`harness.store.references`).
"""

from __future__ import annotations

import os
from pathlib import Path

from harness.scenes.loader import load_scene
from harness.scenes.model import Scene, SceneError


def references_root() -> Path:
    """Folder of stored references: ``$CBOX_REFERENCES`` or the project's ``references/``."""
    env = os.environ.get("CBOX_REFERENCES")
    return Path(env) if env else Path(__file__).resolve().parents[2] / "references"


def scene_names() -> list[str]:
    root = references_root()
    return sorted(p.parent.name for p in root.glob("*/scene.toml"))


def resolve_scene(name_or_path: str) -> Scene:
    """Load a scene by stored name (``cornell-box``) or by path to a file or folder."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.is_dir() or os.sep in name_or_path:
        return load_scene(p)
    stored = references_root() / name_or_path / "scene.toml"
    if not stored.exists():
        known = ", ".join(scene_names()) or "(none)"
        raise SceneError(name_or_path, "--scene", f"no stored scene of that name; known: {known}; or give a path")
    return load_scene(stored)

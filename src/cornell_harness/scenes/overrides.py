"""Scene overrides from the command line (``--set render.max_depth=3``): derived scenes.

An override names a value of the scene file by its TOML path (the names the
loader reads: ``camera.resolution``, ``render.max_depth``,
``materials.white.reflectance``) and gives it a new value, written as a TOML
value (``3``, ``0.5``, ``"box"``, ``[64,64]``), a bare word (``box``) or a
comma list (``64,64``, an array). It replaces the value in the parsed TOML
*before* validation, so every overridden value is checked by the loader's
own code (:func:`cornell_harness.scenes.loader.parse_scene`); its errors then name
the ``--set`` that caused them.

The result is a *derived scene*: it keeps its file's path, is named after its
overrides (``cornell-box[render.max_depth=3]``), records them in canonical form
(:attr:`~cornell_harness.scenes.model.Scene.overrides`, sorted by key, so order and
spelling do not matter), and has its own content hash, hence its own reference
(:func:`cornell_harness.store.references.reference_folder`). Overrides that change
nothing give the scene itself.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import re
import tomllib
from pathlib import Path
from typing import Any, Sequence

from cornell_harness.scenes.loader import keys_of, parse_scene, read_scene_document
from cornell_harness.scenes.materials import MATERIAL_TYPES, material_fields
from cornell_harness.scenes.model import Scene, SceneError, one_line
from cornell_harness.suggest import did_you_mean

OPTION = "--set"
#: A string that can be written without quotes and reads back as the same string.
_BARE_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_-]*")
#: Bare words TOML reads as something other than a string.
_TOML_WORDS = ("true", "false", "inf", "nan")


def parse_value(text: str) -> Any:
    """An override's value: a TOML value if it is one, else a comma list (an array), else the text itself."""
    text = text.strip()
    try:
        doc = tomllib.loads(f"v = {text}")
        if list(doc) == ["v"]:  # "3\nx = 4" is two keys, not a value
            return doc["v"]
    except (tomllib.TOMLDecodeError, ValueError, RecursionError):
        pass
    if "," in text:
        return [parse_value(part) for part in text.split(",")]
    return text


def format_value(value: Any) -> str:
    """The canonical text of a value, which :func:`parse_value` reads back as the same value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str) and _BARE_WORD.fullmatch(value) and value not in _TOML_WORDS:
        return value
    if isinstance(value, list):
        return "[" + ",".join(format_value(v) for v in value) + "]"
    return json.dumps(value, ensure_ascii=False)  # a JSON string is a TOML basic string


def parse_assignment(text: str) -> tuple[str, Any]:
    """``'render.max_depth=3'`` → ``('render.max_depth', 3)``; a :class:`SceneError` if it is not KEY=VALUE."""
    key, eq, value = text.partition("=")
    key = key.strip()
    if not eq or not key or not value.strip():
        raise SceneError(OPTION, repr(one_line(text, 80)), "expected KEY=VALUE, e.g. render.max_depth=3 or "
                                                           "camera.resolution=64,64")
    return key, parse_value(value)


def override_keys(doc: dict) -> tuple[str, ...]:
    """The keys a scene document can be overridden at: camera, render, its materials' fields, its AO table, its
    colour pipeline (``colour.rgb_convention``: the RGB projection an RGB renderer runs on), its animation
    (``animation.frames``, ``animation.fps``, a track as a TOML value)."""
    keys = [f"camera.{k}" for k in keys_of("camera")] + [f"render.{k}" for k in keys_of("render")]
    for name, table in (doc.get("materials") or {}).items():
        kind = table.get("type") if isinstance(table, dict) else None
        cls = MATERIAL_TYPES.get(kind) if isinstance(kind, str) else None
        if cls is not None and _BARE_WORD.fullmatch(name):
            keys += [f"materials.{name}.{f.name}" for f in material_fields(cls)]
    if isinstance(doc.get("ambient_occlusion"), dict):
        keys += [f"ambient_occlusion.{k}" for k in keys_of("ambient_occlusion")]
    if isinstance(doc.get("colour"), dict):
        keys += [f"colour.{k}" for k in keys_of("colour")]
    if isinstance(doc.get("animation"), dict):
        keys += [f"animation.{k}" for k in keys_of("animation")]
    return tuple(keys)


def apply_overrides(doc: dict, assignments: Sequence[str]) -> tuple[dict, dict[str, Any], dict[str, str]]:
    """A copy of ``doc`` with each ``KEY=VALUE`` set; also the values by key, and what each key was given as.

    Unknown keys and keys given twice are refused here; the values are
    left to the loader to check.
    """
    known = override_keys(doc)
    values: dict[str, Any] = {}
    given: dict[str, str] = {}
    for text in assignments:
        key, value = parse_assignment(text)
        if key not in known:
            raise SceneError(OPTION, one_line(key, 80), f"not a key this scene can override"
                             f"{did_you_mean(key, known)}; valid keys: {', '.join(known)}")
        if key in values:
            raise SceneError(OPTION, key, f"given twice ({given[key]!r} and {text!r}); give it once")
        values[key], given[key] = value, text
    out = copy.deepcopy(doc)
    for key, value in values.items():
        *tables, leaf = key.split(".")
        table = out
        for t in tables:
            table = table[t]  # present: the scene parsed without overrides, and only its own tables are keys
        table[leaf] = value
    return out, values, given


def _blame(error: SceneError, given: dict[str, str]) -> SceneError:
    """The loader's error, named after the ``--set`` that caused it (all of them when no one key is to blame)."""
    field = error.field
    culprits = [text for key, text in given.items() if field == key or field.startswith((f"{key}[", f"{key}."))]
    culprits = culprits or list(given.values())
    return SceneError(" ".join(f"{OPTION} {one_line(t, 80)}" for t in culprits), field, error.message)


def load_derived_scene(path: str | Path, assignments: Sequence[str] = ()) -> Scene:
    """The scene file at ``path`` with ``assignments`` (``KEY=VALUE``) applied; the file's own scene without any.

    The file is validated as it is first, so its own errors name it; any
    error after the overrides are applied is theirs.
    """
    doc, path = read_scene_document(path)
    base = parse_scene(doc, path)
    if not assignments:
        return base
    derived_doc, values, given = apply_overrides(doc, assignments)
    try:
        derived = parse_scene(derived_doc, path)
    except SceneError as e:
        raise _blame(e, given) from None
    if derived.content_hash() == base.content_hash():
        return base
    canonical = tuple(f"{key}={format_value(values[key])}" for key in sorted(values))
    return dataclasses.replace(derived, name=f"{base.name}[{','.join(canonical)}]", overrides=canonical)

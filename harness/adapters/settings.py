"""Renderer settings as data: declared by each adapter, validated, recorded, sweepable.

An adapter lists its settings in a class attribute ``settings``, a tuple of
:class:`Setting` (name, type, default, allowed range, one line of
documentation). The harness validates what a user gives against it, fills
in the defaults, hands the complete mapping to ``render(..., settings=...)``
and records it in every result row and in provenance. An adapter without a
``settings`` attribute has none, and is called without the keyword.

Users name settings on the command line as part of the renderer,
``-r 'pathtracer[rr_depth=3]'`` (comma-separated ``name=value`` pairs), in a
gate config as ``settings = { rr_depth = 3 }``, and sweep one with
``cbox converge --sweep pathtracer.rr_depth=3,5,8``.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from harness.suggest import did_you_mean


class SettingsError(ValueError):
    """A setting is unknown or out of range; ``str()`` names it and what is allowed."""


@dataclass(frozen=True)
class Setting:
    """One declared setting: ``kind`` is int, float, bool or str; bounds are inclusive."""

    name: str
    kind: type
    default: Any
    doc: str
    low: float | None = None
    high: float | None = None
    choices: tuple = ()

    def allowed(self) -> str:
        """What values are allowed, in words (for errors and ``cbox renderers --settings``)."""
        if self.choices:
            return "one of " + ", ".join(map(str, self.choices))
        kind = {int: "an integer", float: "a number", bool: "true or false", str: "a string"}[self.kind]
        if self.low is not None and self.high is not None:
            return f"{kind} in [{self.low:g}, {self.high:g}]"
        if self.low is not None:
            return f"{kind} >= {self.low:g}"
        if self.high is not None:
            return f"{kind} <= {self.high:g}"
        return kind

    def coerce(self, value: Any, renderer: str) -> Any:
        """``value`` (from TOML, or a string from the command line) as this setting's type, checked."""
        bad = SettingsError(f"renderer {renderer!r}: setting {self.name}={value!r}: expected {self.allowed()}")
        if isinstance(value, str) and self.kind is not str:
            value = _parse_word(value)
        if self.kind is bool:
            if not isinstance(value, bool):
                raise bad
        elif self.kind is int:
            # bool is an int in Python, and 3.0 from a sweep list is a fine 3; 3.5 is not.
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value != int(value):
                raise bad
            value = int(value)
        elif self.kind is float:
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise bad
            value = float(value)
        elif not isinstance(value, str):
            raise bad
        if self.choices and value not in self.choices:
            raise bad
        if (self.low is not None and value < self.low) or (self.high is not None and value > self.high):
            raise bad
        return value


def _parse_word(text: str) -> Any:
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text.strip()


def declared(renderer) -> tuple[Setting, ...]:
    """The settings a renderer declares (none for an adapter without the attribute)."""
    return tuple(getattr(renderer, "settings", ()) or ())


def resolve_settings(renderer, given: Mapping[str, Any], name: str | None = None) -> dict[str, Any]:
    """Every declared setting: ``given`` validated, defaults for the rest. Raises :class:`SettingsError`."""
    name = name or getattr(renderer, "name", "?")
    known = {s.name: s for s in declared(renderer)}
    out = {s.name: s.default for s in known.values()}
    for key, value in given.items():
        if key not in known:
            allowed = ", ".join(known) or "none"
            raise SettingsError(f"renderer {name!r}: unknown setting {key!r}" + did_you_mean(key, known)
                                + f"; its settings: {allowed}")
        out[key] = known[key].coerce(value, name)
    return out


def canonical(values: Mapping[str, Any]) -> str:
    """Settings as canonical JSON: the form recorded in results and compared between runs."""
    return json.dumps(dict(values), sort_keys=True)


_SPEC = re.compile(r"^(?P<name>[^\[\]]+?)\s*(?:\[(?P<body>[^\[\]]*)\])?\s*$")


def split_spec(spec: str) -> tuple[str, dict[str, str]]:
    """``'pathtracer[rr_depth=3, x=1]'`` → ``('pathtracer', {'rr_depth': '3', 'x': '1'})``; values stay text."""
    m = _SPEC.match(spec)
    if not m:
        raise SettingsError(f"renderer {spec!r}: expected NAME or NAME[setting=value,...]")
    given = {}
    for pair in filter(None, (p.strip() for p in (m.group("body") or "").split(","))):
        key, eq, value = pair.partition("=")
        if not eq or not key.strip():
            raise SettingsError(f"renderer {spec!r}: {pair!r} is not setting=value")
        given[key.strip()] = value.strip()
    return m.group("name").strip(), given


def label(name: str, values: Mapping[str, Any], defaults: Mapping[str, Any]) -> str:
    """The renderer's name with the settings that differ from its defaults: ``pathtracer[rr_depth=3]``."""
    changed = {k: v for k, v in values.items() if defaults.get(k) != v}
    if not changed:
        return name
    return f"{name}[{','.join(f'{k}={json.dumps(v) if isinstance(v, str) else v}' for k, v in sorted(changed.items()))}]"


def parse_sweep(text: str) -> tuple[str, str, list[str]]:
    """``'pathtracer.rr_depth=3,5,8'`` → ``('pathtracer', 'rr_depth', ['3', '5', '8'])``."""
    m = re.fullmatch(r"\s*([^=]+)\.([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.+?)\s*", text)
    if not m:
        raise SettingsError(f"--sweep {text!r}: expected RENDERER.SETTING=V1,V2,... (e.g. pathtracer.rr_depth=3,5,8)")
    values = [v.strip() for v in m.group(3).split(",") if v.strip()]
    if not values:
        raise SettingsError(f"--sweep {text!r}: no values")
    return m.group(1).strip(), m.group(2), values


def describe(settings: Sequence[Setting]) -> list[str]:
    """One line per setting: name, default, allowed values, documentation."""
    return [f"{s.name} = {s.default!r}  ({s.allowed()}): {s.doc}" for s in settings]

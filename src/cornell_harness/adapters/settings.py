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
import re
from typing import Any, Mapping, Sequence

from cornell_harness.adapters.api import Setting, SettingsError, attribute
from cornell_harness.suggest import did_you_mean

__all__ = ["Setting", "SettingsError", "canonical", "declared", "describe", "label", "match_series_labels",
           "parse_series_label", "parse_sweep", "resolve_settings", "series_key", "split_spec"]


def declared(renderer) -> tuple[Setting, ...]:
    """The settings a renderer declares (:func:`cornell_harness.adapters.api.attribute`; none when it declares none)."""
    return attribute(renderer, "settings")


def resolve_settings(renderer, given: Mapping[str, Any], name: str | None = None) -> dict[str, Any]:
    """Every declared setting: ``given`` validated, defaults for the rest. Raises :class:`SettingsError`."""
    name = name or renderer.name
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


def series_key(spec: str) -> tuple[str, tuple[tuple[str, str], ...]]:
    """What makes two specs name the same series: the renderer and its settings in any order, a value quoted
    or not (``pathtracer[sampler=independent]`` is the recorded ``pathtracer[sampler="independent"]``)."""
    name, given = split_spec(spec)
    return name, tuple(sorted((k, v[1:-1] if len(v) >= 2 and v[0] == v[-1] == '"' else v) for k, v in given.items()))


def parse_series_label(text: str) -> tuple[str, str]:
    """``'pathtracer[sampler="independent"]=PT (independent)'`` → the spec and its display text: split at the
    first ``=`` outside the brackets (a spec's settings hold ``=`` too)."""
    depth = 0
    for i, ch in enumerate(text):
        depth += (ch == "[") - (ch == "]")
        if ch == "=" and depth == 0:
            spec, shown = text[:i].strip(), text[i + 1:].strip()
            if spec and shown:
                split_spec(spec)  # a malformed spec says so here
                return spec, shown
            break
    raise SettingsError(f"{text!r}: expected SPEC=TEXT, e.g. 'pathtracer[sampler=\"independent\"]=PT (independent)'")


def match_series_labels(labels: Mapping[str, str], names: Sequence[str]) -> dict[str, str]:
    """Display text per recorded series name, from ``labels`` (spec → text, :func:`parse_series_label`); a spec
    that names none of ``names`` is a SettingsError naming the series there are: a typo must not silently
    leave a legend unlabelled."""
    keys = {series_key(n): n for n in names}
    out = {}
    for spec, shown in labels.items():
        name = keys.get(series_key(spec))
        if name is None:
            raise SettingsError(f"{spec!r} names no series here" + did_you_mean(spec, list(names))
                                + f"; the series: {', '.join(names) or '(none)'}")
        out[name] = shown
    return out

"""The registry that finds renderers: discovery, loading, and their settings as given by the user.

What a renderer is (the :class:`~cornell_harness.adapters.api.Renderer` protocol and
what it may declare, :class:`~cornell_harness.adapters.api.Declarations`) is
:mod:`cornell_harness.adapters.api`'s. Renderers are found through the entry-point
group ``cbox.renderers`` (ours are registered in ``pyproject.toml`` the same
way a third party's would be), or given directly as ``package.module:ClassName``.
Programs declared in renderers files (:mod:`cornell_harness.adapters.renderers_file`: ``--renderers
FILE`` through :func:`use_renderer_files`, and ``$CBOX_RENDERERS``) are found
by their names too; their spec, ``/abs/path/renderers.toml#NAME``, names them
in any process without either.
A declared ``estimator`` that is not one of :data:`~cornell_harness.adapters.api.ESTIMATORS`
is a :class:`RendererError` when the renderer is loaded.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

# AOVS, Checkpoint and RenderResult are re-exported for code written before the API had its own module.
from cornell_harness.adapters.api import AOVS, ESTIMATORS, Checkpoint, Renderer, RenderResult, attribute  # noqa: F401
from cornell_harness.adapters.settings import declared, label, resolve_settings, split_spec
from cornell_harness.extras import renderer_problem
from cornell_harness.scenes.model import Scene
from cornell_harness.suggest import did_you_mean

ENTRY_POINT_GROUP = "cbox.renderers"
#: Renderers files (:mod:`cornell_harness.adapters.renderers_file`) whose renderers every command knows by name, as
#: ``--renderers`` adds them: paths separated by ``os.pathsep``.
RENDERERS_VARIABLE = "CBOX_RENDERERS"
_renderer_files: list[Path] = []  # --renderers of the running command (use_renderer_files)


class RendererError(RuntimeError):
    """A renderer could not be found or loaded (bad spec, import failure)."""


@dataclass
class RendererEntry:
    """A renderer as the registry knows it: loaded, or the reason it is not, and its settings.

    ``name`` is the label results carry: the renderer's name plus the settings
    that differ from its defaults (``pathtracer[rr_depth=3]``). ``settings``
    holds every declared setting, validated (:mod:`cornell_harness.adapters.settings`).
    ``time_limit_s``: each render of it runs in a child process ended at that
    limit (:func:`cornell_harness.workflows.runner.render_timed`); None, in this one.
    """

    name: str
    spec: str
    renderer: Renderer | None
    reason: str | None  # why it is unavailable; None when available
    settings: dict = field(default_factory=dict)
    time_limit_s: float | None = None

    @property
    def available(self) -> bool:
        return self.renderer is not None and self.reason is None

    def with_settings(self, given: dict) -> "RendererEntry":
        """The same renderer with ``given`` settings (validated; SettingsError if not allowed)."""
        if self.renderer is None:
            # Cannot validate against a renderer that did not load; it will not run anyway.
            return RendererEntry(self.name, self.spec, None, self.reason, dict(given), self.time_limit_s)
        base = self.renderer.name
        values = resolve_settings(self.renderer, {**self.settings, **given}, base)
        defaults = {st.name: st.default for st in declared(self.renderer)}
        return RendererEntry(label(base, values, defaults), self.spec, self.renderer, self.reason, values,
                             self.time_limit_s)

    def with_time_limit(self, time_limit_s: float | None) -> "RendererEntry":
        """The same renderer, each render ended at ``time_limit_s`` (None: the limit it has)."""
        if time_limit_s is None:
            return self
        return RendererEntry(self.name, self.spec, self.renderer, self.reason, self.settings, time_limit_s)


def _estimator_problem(value) -> str | None:
    """What is wrong with an ``estimator`` value, or None when it is one of :data:`ESTIMATORS`."""
    if isinstance(value, str) and value in ESTIMATORS:
        return None
    return f"estimator = {value!r} is not one of {', '.join(ESTIMATORS)}" + did_you_mean(value, ESTIMATORS)


def estimator_of(renderer) -> str:
    """The renderer's declared ``estimator`` (:data:`ESTIMATORS`), "unbiased" when it declares none.

    Raises RendererError for a value that is not one of them: a typo must not
    let a biased renderer be tested as an unbiased one, or the reverse.
    """
    value = attribute(renderer, "estimator")
    if (why := _estimator_problem(value)) is not None:
        raise RendererError(f"renderer {getattr(renderer, 'name', type(renderer).__name__)!r}: {why}")
    return value


def quantities_of(renderer) -> tuple[str, ...]:
    """The quantities (:data:`cornell_harness.scenes.quantities.QUANTITIES`) a renderer computes; radiance if it says none."""
    return attribute(renderer, "quantities")


def missing_features(renderer: Renderer, scene: Scene) -> list[str]:
    """What of the scene the renderer does not model: features, and its quantity (empty: it can run)."""
    missing = sorted(scene.features - set(renderer.features))
    if scene.quantity not in quantities_of(renderer):
        missing.append(f"the quantity {scene.quantity}")
    return missing


def load_spec(spec: str) -> Renderer:
    """Instantiate ``package.module:ClassName``; raise RendererError if impossible.

    The current folder is on the import path first, as ``python -m`` puts it
    (the ``cbox`` console script alone would not), so a renderer in the
    folder a user runs ``cbox`` from is found.
    """
    module_name, _, attr = spec.partition(":")
    if not module_name or not attr:
        raise RendererError(f"renderer {spec!r}: expected a registered name or package.module:ClassName")
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:
        sys.path.insert(0, cwd)
    try:
        module = importlib.import_module(module_name)
    except ImportError as e:
        raise RendererError(f"renderer {spec!r}: cannot import {module_name}: {e}") from None
    try:
        cls = getattr(module, attr)
    except AttributeError:
        raise RendererError(f"renderer {spec!r}: {module_name} has no attribute {attr!r}") from None
    return _instantiate(cls, spec)


def _instantiate(cls, spec: str) -> Renderer:
    try:
        obj = cls()
    except Exception as e:  # a third-party constructor may raise anything
        raise RendererError(f"renderer {spec!r}: constructing it failed: {type(e).__name__}: {e}") from None
    for attr in ("name", "features", "render", "unavailable_reason", "version"):
        if not hasattr(obj, attr):
            raise RendererError(f"renderer {spec!r}: does not implement the adapter interface (no {attr!r})")
    if (why := _estimator_problem(attribute(obj, "estimator"))) is not None:
        raise RendererError(f"renderer {spec!r}: {why}")
    return obj


def _entry(name: str, spec: str, load) -> RendererEntry:
    try:
        r = load()
    except RendererError as e:
        return RendererEntry(name, spec, None, str(e))
    try:
        reason = r.unavailable_reason()
    except Exception as e:  # availability probes must never crash a run
        reason = f"availability check failed: {type(e).__name__}: {e}"
    return RendererEntry(getattr(r, "name", name), spec, r, reason, resolve_settings(r, {}, name))


def _entry_points() -> dict:
    eps = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    return {ep.name: ep for ep in sorted(eps, key=lambda e: e.name)}


def _load_entry_point(ep) -> RendererEntry:
    def load():
        try:
            cls = ep.load()
        except Exception as e:
            raise RendererError(f"renderer {ep.name!r}: cannot import {ep.value}: {type(e).__name__}: {e}") from None
        return _instantiate(cls, ep.value)

    entry = _entry(ep.name, ep.value, load)
    if (missing := renderer_problem(ep.name)) is not None:  # its extra's pip line, whatever the import said
        entry.reason = missing
    return entry


def use_renderer_files(paths: Sequence[Path | str]) -> None:
    """Make the renderers of these files (``--renderers``) known by name, besides ``$CBOX_RENDERERS``'s; each
    file is read and checked now (:class:`~cornell_harness.adapters.renderers_file.RenderersFileError`), before anything runs.
    An empty list forgets the files given before (and reads nothing)."""
    _renderer_files[:] = [Path(p).resolve() for p in paths]
    if paths:
        declared_commands()


def renderer_files() -> list[Path]:
    """The renderers files in use: ``$CBOX_RENDERERS``'s, then ``--renderers``'s; each once."""
    env = [Path(p).resolve() for p in os.environ.get(RENDERERS_VARIABLE, "").split(os.pathsep) if p.strip()]
    return list(dict.fromkeys([*env, *_renderer_files]))


def declared_commands() -> dict[str, str]:
    """The renderers the renderers files in use declare: name -> spec (``/abs/path/renderers.toml#NAME``).

    A name declared twice, or that is also a registered renderer's, is a RenderersFileError: ``-r NAME``
    must mean one renderer, and a file must not replace the reference renderer unnoticed.
    """
    from cornell_harness.adapters.renderers_file import RenderersFileError, read_file

    out: dict[str, str] = {}
    registered = _entry_points()
    for path in renderer_files():
        for name, declaration in read_file(path).items():
            if name in registered:
                raise RenderersFileError(path, f"renderer.{name}", f"{name!r} is a registered renderer "
                                         f"({registered[name].value}); give the program another name")
            if name in out:
                raise RenderersFileError(path, f"renderer.{name}", f"also declared in "
                                         f"{out[name].rpartition('#')[0]}; give one of them another name")
            out[name] = declaration.spec
    return out


def declared_series_labels() -> dict[str, str]:
    """The ``[series_labels]`` of the renderers files in use, spec → text; a later file's entry wins."""
    from cornell_harness.adapters.renderers_file import read_series_labels

    out: dict[str, str] = {}
    for path in renderer_files():
        out.update(read_series_labels(path))
    return out


def _load_command(name: str, spec: str) -> RendererEntry:
    from cornell_harness.adapters.commands import load

    return _entry(name, spec, lambda: load(spec))


def registered_names() -> list[str]:
    """Names registered under ``cbox.renderers``, without loading anything."""
    return list(_entry_points())


def discover() -> dict[str, RendererEntry]:
    """All renderers registered under ``cbox.renderers``, loaded and probed, by name."""
    return {name: _load_entry_point(ep) for name, ep in _entry_points().items()}


def resolve(specs: Sequence[str] | None) -> list[RendererEntry]:
    """Renderers named by ``specs`` (registered or declared names, module:Class, or a declared renderer's
    spec ``/abs/path/renderers.toml#NAME``), or all registered and declared (:func:`declared_commands`).

    A spec may carry settings, ``pathtracer[rr_depth=3]``; they are validated
    against the renderer's declared settings (SettingsError, a usage error).
    Only the renderers named are loaded and probed. An unknown name, or a
    ``module:Class`` that cannot be imported or found, raises RendererError (a
    usage error); a renderer that loads but cannot run here (its
    ``unavailable_reason()``) comes back unavailable, with its reason.
    """
    from cornell_harness.adapters.renderers_file import is_spec

    eps = _entry_points()
    commands = declared_commands()
    if not specs:
        return [_load_entry_point(ep) for ep in eps.values()] + [_load_command(n, s) for n, s in commands.items()]
    out = []
    for spec in specs:
        name, given = split_spec(spec)
        if name in eps:
            entry = _load_entry_point(eps[name])
        elif name in commands or is_spec(name):
            entry = _load_command(name, commands.get(name, name))
            if entry.renderer is None:
                raise RendererError(entry.reason)
        elif ":" in name:
            # Named explicitly: one that cannot be imported or found is a usage error, never "unavailable".
            entry = _entry(name, name, lambda name=name: load_spec(name))
            if entry.renderer is None:
                raise RendererError(entry.reason)
        else:
            known = ", ".join([*eps, *commands]) or "(none)"
            raise RendererError(f"unknown renderer {name!r}" + did_you_mean(name, [*eps, *commands])
                                + f"; registered: {known}; or give package.module:ClassName, or declare it in a "
                                "renderers file (--renderers FILE)")
        out.append(entry.with_settings(given) if given else entry)
    return out


def sweep(entries: Sequence[RendererEntry], renderer: str, setting: str, values: Sequence) -> list[RendererEntry]:
    """``entries`` with the one named ``renderer`` replaced by one entry per value of ``setting``.

    ``renderer`` is matched against a registered name, a ``module:Class`` spec
    or the adapter's own name; one not among ``entries`` is resolved and added.
    Each value becomes its own series (its own label) in results and reports.
    """
    def matches(e: RendererEntry) -> bool:
        return renderer in (e.spec, e.name, getattr(e.renderer, "name", None)) or e.spec.endswith(f":{renderer}")

    out, found = [], False
    for e in entries:
        if matches(e):
            found = True
            out += [e.with_settings({setting: v}) for v in values]
        else:
            out.append(e)
    if not found:
        out += sweep(resolve([renderer]), renderer, setting, values)
    return out

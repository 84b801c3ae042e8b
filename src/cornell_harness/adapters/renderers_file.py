"""Renderers files: command-line renderers declared as data (TOML), read and checked before anything runs.

A renderer written in any language is gated like ours once a renderers file says how to run it::

    [renderer.mitsuba-cli]
    command = ["mitsuba", "{scene}", "-o", "{out}", "-D", "spp={spp}", "-D", "seed={seed}"]
    scene_format = "mitsuba"            # cornell_harness.scenes.export.FORMATS: the scene is exported to it per render
    models = ["triangle_mesh", "sphere", "diffuse", "mirror", "dielectric", "area_light", "pinhole_camera",
              "box_filter"]             # the features it models (cornell_harness.scenes.model.FEATURES)
    quantity = "radiance"               # optional; cornell_harness.scenes.quantities.QUANTITIES (default radiance)
    estimator = "unbiased"              # optional; cornell_harness.adapters.api.ESTIMATORS (default unbiased)
    variance = "{out}.var.exr"          # optional: a second EXR the program writes, the variance of its mean
    time = 'render took ([0-9.]+) s'    # optional: "wall" (default) or a regex whose one group is seconds
    time_limit = "10m"                  # optional: how long one run may take (default: scaled from the samples)

The file may also name how series show in legends and tables (``--series-label`` gives the same)::

    [series_labels]
    'pathtracer[sampler="independent"]' = "PT (independent)"

``command`` is a list of arguments, run without a shell; each argument has
its placeholders replaced: ``{scene}`` (the exported scene's main file),
``{out}`` (the image the program must write: OpenEXR, or any file OpenImageIO reads, which it
recognises by its content, such as PFM), ``{spp}``, ``{seed}``,
``{width}``, ``{height}`` (the scene's resolution) and ``{threads}``
(:func:`cornell_harness.adapters.api.default_threads`, ``$CBOX_THREADS``); ``{{`` is
a literal brace. ``variance`` is a path with the same placeholders; a
relative path is taken in the run's folder. How each entry runs is
:mod:`cornell_harness.adapters.commands`.

The file is strict, as a scene file and a gate config are: its format is
``src/cornell_harness/schemas/renderers.schema.json`` (every key, in ``docs/formats.md``),
checked by :mod:`cornell_harness.schemas.reader`, then what the schema cannot say is checked
here. An unknown key, a misspelt placeholder, an unknown format, feature, quantity or estimator, a
feature or quantity the scene format cannot carry (``quantity = "ambient_occlusion"`` needs
``scene_format = "json"`` or ``"usd"``), a bad ``time_limit``, or a time regex without exactly one group is a
:class:`RenderersFileError` (one line naming the file and the field, exit 2), raised when the file is read,
before anything runs.

A declared renderer is known to the registry (:mod:`cornell_harness.adapters.registry`)
by its name, and travels to other processes (the sandbox, Dask workers) as
the self-contained spec ``/abs/path/renderers.toml#NAME`` (:func:`spec_of`),
which the registry resolves without any option or environment variable. On a
Dask cluster of other machines (``--scheduler``) the renderers file and the
program must be at the same paths there.
"""

from __future__ import annotations

import re
import string
from dataclasses import dataclass
from pathlib import Path

from cornell_harness.adapters.api import ESTIMATORS, SettingsError
from cornell_harness.durations import parse_duration
from cornell_harness.scenes.model import FEATURES
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY, QUANTITIES
from cornell_harness.schemas.reader import FormatProblem, check, read_toml
from cornell_harness.suggest import did_you_mean

#: The placeholders a command argument (and ``variance``) may hold.
PLACEHOLDERS = ("scene", "out", "spp", "seed", "width", "height", "threads")
#: What separates a renderers file from a renderer's name in a spec (:func:`spec_of`).
SPEC_SEPARATOR = "#"
#: A renderer's name: what results carry and ``-r`` takes; none of the characters a spec gives meaning to.
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")
#: A run's time limit where its entry gives none: seconds, plus seconds per sample (spp × width × height).
DEFAULT_LIMIT_START_S, DEFAULT_LIMIT_PER_SAMPLE_S = 60.0, 1e-5


class RenderersFileError(RuntimeError):
    """A renderers file is wrong; ``str()`` is one line naming the file and the field (a user error, exit 2).

    Not a ValueError: a command that turns ValueErrors into errors of one of its options must not blame
    that option for a renderers file (``$CBOX_RENDERERS``' too) that is read inside it."""

    def __init__(self, file: Path | str, field: str, message: str):
        self.file, self.field, self.message = str(file), field, message
        super().__init__(f"{file}: {field}: {message}")


@dataclass(frozen=True)
class Declaration:
    """One ``[renderer.NAME]`` of a renderers file, checked."""

    name: str
    file: Path  # absolute
    command: tuple[str, ...]
    scene_format: str
    models: frozenset[str]
    quantity: str = DEFAULT_QUANTITY
    estimator: str = ESTIMATORS[0]
    variance: str | None = None
    time: str = "wall"
    time_limit_s: float | None = None  # None: scaled from the samples (run_time_limit_s)

    def run_time_limit_s(self, spp: int, width: int, height: int) -> float:
        """How long one run at ``spp`` may take: the entry's ``time_limit``, or the default scaled from the
        samples."""
        if self.time_limit_s is not None:
            return self.time_limit_s
        return DEFAULT_LIMIT_START_S + DEFAULT_LIMIT_PER_SAMPLE_S * spp * width * height

    @property
    def spec(self) -> str:
        return spec_of(self.file, self.name)


def spec_of(file: Path | str, name: str) -> str:
    """The spec that names renderer ``name`` of ``file`` in any process: ``/abs/path/renderers.toml#NAME``."""
    return f"{Path(file).resolve()}{SPEC_SEPARATOR}{name}"


def is_spec(text: str) -> bool:
    """Whether ``text`` is a spec of :func:`spec_of` (a ``.toml`` path, ``#``, a name)."""
    path, sep, name = text.rpartition(SPEC_SEPARATOR)
    return bool(sep) and path.endswith(".toml") and bool(NAME.fullmatch(name))


# ----------------------------------------------------------------------------------------
# The file
# ----------------------------------------------------------------------------------------


def read_file(path: Path | str) -> dict[str, Declaration]:
    """Every renderer a renderers file declares, by name, checked; RenderersFileError for anything wrong.

    The format is ``src/cornell_harness/schemas/renderers.schema.json``, checked by
    :mod:`cornell_harness.schemas.reader`; what is left here is what the schema cannot say: placeholders, a
    time regex's groups, a series spec, and the features the scene format can express."""
    path = Path(path).resolve()
    doc = _document(path)
    _series_labels(path, doc)
    if "renderer" not in doc and "series_labels" not in doc:
        raise RenderersFileError(path, "renderer", "declares no renderer; add a [renderer.NAME] table")
    return {name: _declaration(path, name, t) for name, t in doc.get("renderer", {}).items()}


def _document(path: Path) -> dict:
    """The file's TOML, checked against the format's schema."""
    try:
        doc = read_toml(path)
        check(doc, "renderers")
    except FormatProblem as e:
        raise RenderersFileError(path, e.field, e.message) from None
    return doc


def read_series_labels(path: Path | str) -> dict[str, str]:
    """A renderers file's ``[series_labels]``: ``'pathtracer[sampler="independent"]' = "PT (independent)"``,
    series spec → the text legends and tables show for it (``--series-label`` gives the same)."""
    path = Path(path).resolve()
    read_file(path)  # the file's other errors first, as every reader of it reports them
    return _series_labels(path, _document(path))


def _series_labels(path: Path, doc: dict) -> dict[str, str]:
    from cornell_harness.adapters.settings import split_spec

    table = doc.get("series_labels", {})
    for spec, shown in table.items():
        if not shown.strip():
            raise RenderersFileError(path, f"series_labels.{spec}", "expected a non-empty string, the text shown "
                                     "for the series")
        try:
            split_spec(spec)
        except SettingsError as e:
            raise RenderersFileError(path, f"series_labels.{spec}", str(e)) from None
    return dict(table)


def _declaration(path: Path, name: str, t: dict) -> Declaration:
    where = f"renderer.{name}"

    def bad(field: str, message: str) -> RenderersFileError:
        return RenderersFileError(path, f"{where}.{field}" if field else where, message)

    command = t["command"]
    if not command[0].strip():
        raise bad("command", "the program (the first argument) is empty")
    for i, arg in enumerate(command):
        _check_placeholders(arg, lambda message, i=i: bad(f"command[{i}]", message))
    fmt, models, quantity = t["scene_format"], t["models"], t.get("quantity", DEFAULT_QUANTITY)
    _check_format(bad, fmt, models, quantity)
    variance = t.get("variance")
    if variance is not None:
        _check_placeholders(variance, lambda message: bad("variance", message))
    timing = t.get("time", "wall")
    if timing != "wall":
        try:
            groups = re.compile(timing).groups
        except re.error as e:
            raise bad("time", f"not a regex: {e}") from None
        if groups != 1:
            raise bad("time", f"the regex has {groups} groups; give exactly one, the seconds")
    try:
        limit = parse_duration(t["time_limit"], "duration") if "time_limit" in t else None
    except ValueError as e:
        raise bad("time_limit", str(e)) from None
    return Declaration(name, path, tuple(command), fmt, frozenset(models), quantity, t.get("estimator", ESTIMATORS[0]),
                       variance, timing, limit)


def _check_format(bad, fmt: str, models: list[str], quantity: str) -> None:
    """The scene format is known, expresses every feature the renderer models and carries its quantity."""
    from cornell_harness.scenes.export import FORMATS, format_module, quantities  # when a file is read

    def carried(f: str) -> tuple[str, ...]:
        try:
            return quantities(f)
        except ImportError:
            return ()

    if fmt not in FORMATS:
        raise bad("scene_format", f"{fmt!r} is not an export format{did_you_mean(fmt, FORMATS)}; formats: "
                                  f"{', '.join(FORMATS)}")
    try:  # a format that cannot be written here makes the renderer unavailable, not the file wrong
        expressible, carries = format_module(fmt).FEATURES, quantities(fmt)
    except ImportError:
        expressible, carries = FEATURES, QUANTITIES
    if beyond := sorted(set(models) - set(expressible)):
        raise bad("models", f"the scene format {fmt!r} cannot express {', '.join(beyond)}")
    if quantity not in carries:
        able = [f for f in FORMATS if quantity in carried(f)]
        raise bad("quantity", f"the scene format {fmt!r} cannot carry {quantity}; scene formats that can: "
                              f"{', '.join(able) or '(none)'}")


def _check_placeholders(text: str, bad) -> None:
    """Every ``{...}`` in ``text`` is a known placeholder without format spec or conversion."""
    try:
        fields = [(f, spec, conv) for _, f, spec, conv in string.Formatter().parse(text) if f is not None]
    except ValueError as e:  # an unmatched brace
        raise bad(f"{text!r}: {e} (a literal brace is written {{{{ or }}}})") from None
    for f, spec, conv in fields:
        if f not in PLACEHOLDERS:
            raise bad(f"unknown placeholder {{{f}}}" + did_you_mean(f, PLACEHOLDERS, " (did you mean {{{}}}?)")
                      + "; placeholders: " + ", ".join(f"{{{p}}}" for p in PLACEHOLDERS))
        if spec or conv:
            raise bad(f"placeholder {{{f}}} takes no format or conversion")

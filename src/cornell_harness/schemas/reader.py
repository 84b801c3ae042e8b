"""The strict reader of the harness's TOML formats: a file parsed, then checked against its format's JSON Schema.

:func:`read_toml` parses a file (bounded in size, UTF-8, TOML) and :func:`check` validates the parsed document
against ``<format>.schema.json`` with ``jsonschema`` (draft 2020-12). The first problem becomes a
:class:`FormatProblem`: the field as a dotted path (``camera.position[1]``, ``materials."my glass".type``) and one
line saying what is wrong, written from the schema (``unknown key (did you mean 'max_depth'?)``, ``missing required
field``, ``expected a number, got str``, ``out of range: must be in [0, 1], got 1.2``, ``unknown material type
'mirorr'; did you mean 'mirror'?``). Each format raises it as its own error, naming the file (exit 2 at the CLI).
What a schema cannot say (references between fields, a regex's groups, a triangle's area) stays with the format's
reader, which builds the model objects from a document this has checked.

TOML is read as the JSON data model the schemas speak of, with three rules of its own: a ``number`` is finite
(JSON has no NaN or infinity; a field whose schema says ``"x-allowInfinity": true`` also takes ``inf``) and fits
in a float64; an ``integer`` is a TOML integer (``2.0`` is a float); arrays and tables nest at most
:data:`MAX_NESTING` deep. Two annotations shape the messages: a node's ``title`` names its values in an unknown-value
message (``material type``), and its ``x-expected`` says in words what it takes (``a non-empty list of strings,
the program and its arguments``) where the words written from its keywords would say less. ``x-unit`` is
for the docs' tables only (``benchmarks/schema_tables.py``); like every ``x-`` keyword, other validators (an
editor's) ignore it.
"""

from __future__ import annotations

import functools
import json
import math
import re
import tomllib
from pathlib import Path
from typing import TYPE_CHECKING, Any, Iterable

from cornell_harness.suggest import closest

if TYPE_CHECKING:
    from jsonschema import ValidationError

#: Where the schemas are: ``<format>.schema.json`` for each of :data:`FORMATS`.
SCHEMA_DIR = Path(__file__).resolve().parent
FORMATS = ("scene", "gate", "renderers")
#: Deepest nesting of arrays and tables checked (the formats need 4); deeper is refused before validation, whose
#: messages would otherwise recurse through the value.
MAX_NESTING = 32
#: Longest text of a field or message in an error; longer user text (a 50 MB key) is cut.
MAX_ERROR_TEXT = 300
_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")
_KINDS = {"integer": "an integer", "number": "a number", "string": "a string", "array": "a list", "object": "a table",
          "boolean": "a boolean", "null": "nothing"}
_PLURALS = {"integer": "integers", "number": "numbers", "string": "strings", "array": "lists", "object": "tables",
            "boolean": "booleans"}


class FormatProblem(ValueError):
    """What is wrong with a document: ``field`` (a dotted path, or ``(file)``/``(syntax)``) and ``message``."""

    def __init__(self, field: str, message: str):
        self.field, self.message = one_line(field), one_line(message)
        super().__init__(f"{self.field}: {self.message}")


def one_line(text: str, limit: int | None = MAX_ERROR_TEXT) -> str:
    """``text`` with control characters (newlines) escaped, so an error stays one line, cut to ``limit``."""
    if limit is not None and len(text) > limit:
        text = text[: limit - 1] + "…"
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def schema_file(fmt: str) -> Path:
    """The shipped schema of format ``fmt`` (one of :data:`FORMATS`)."""
    return SCHEMA_DIR / f"{fmt}.schema.json"


@functools.cache
def schema(fmt: str) -> dict:
    """The JSON Schema of format ``fmt``, parsed (shared: do not modify)."""
    return json.loads(schema_file(fmt).read_text(encoding="utf-8"))


# ----------------------------------------------------------------------------------------
# Reading a file
# ----------------------------------------------------------------------------------------


def read_text(path: Path, limit: int) -> str:
    """The UTF-8 text of ``path``, at most ``limit`` bytes; OSError, or ValueError saying what is wrong."""
    with open(path, "rb") as f:
        data = f.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"larger than the {limit / 2**20:g} MiB limit")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"not UTF-8 text: byte 0x{data[e.start]:02x} at offset {e.start}") from None


def read_toml(path: Path, limit: int = 64 * 2**20) -> dict:
    """The parsed TOML of ``path`` (at most ``limit`` bytes); :class:`FormatProblem` at ``(file)`` or ``(syntax)``."""
    try:
        text = read_text(path, limit)
    except FileNotFoundError:
        raise FormatProblem("(file)", "no such file") from None
    except OSError as e:
        raise FormatProblem("(file)", e.strerror or str(e)) from None
    except ValueError as e:  # not UTF-8, too large, or a NUL in the path
        raise FormatProblem("(file)", str(e)) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise FormatProblem("(syntax)", f"invalid TOML: {e}") from None
    except RecursionError:
        raise FormatProblem("(syntax)", "invalid TOML: arrays or tables nested too deeply") from None
    except ValueError as e:  # e.g. an integer of more than 4300 digits
        raise FormatProblem("(syntax)", f"invalid TOML: {e}") from None


# ----------------------------------------------------------------------------------------
# Checking a document
# ----------------------------------------------------------------------------------------


def check(doc: Any, fmt: str, label: str | None = None) -> None:
    """Raise :class:`FormatProblem` for the first way ``doc`` breaks format ``fmt``'s schema.

    ``label``: a key whose string value names a table in a list, shown in its field (``meshes[2] (floor)``)."""
    path = _too_deep(doc)
    if path is not None:
        raise FormatProblem(field_text(doc, path, label), f"arrays or tables nested more than {MAX_NESTING} deep")
    error = next(iter(_validator(fmt).iter_errors(doc)), None)
    if error is not None:
        raise _problem(error, doc, label)


def key_text(key: str) -> str:
    """A table key as a field path writes it: bare if it can be, else TOML-quoted (a long one cut)."""
    key = key if len(key) <= 60 else key[:59] + "…"
    return key if _BARE_KEY.fullmatch(key) else '"' + key.replace("\\", "\\\\").replace('"', '\\"') + '"'


def field_text(doc: Any, path: Iterable, label: str | None = None) -> str:
    """The dotted path of ``path`` (keys and indices) in ``doc``, with each labelled list item's name."""
    out, node = "", doc
    for step in path:
        if isinstance(step, int):
            out += f"[{step}]"
            node = node[step] if isinstance(node, list) and step < len(node) else None
            if label is not None and isinstance(node, dict) and isinstance(node.get(label), str):
                out += f" ({one_line(node[label], 60)})"
        else:
            out += ("." if out else "") + key_text(str(step))
            node = node.get(step) if isinstance(node, dict) else None
    return out


def _too_deep(doc: Any) -> list | None:
    """The path to the first value nested deeper than :data:`MAX_NESTING`, or None (without recursion)."""
    stack = [(doc, [])]
    while stack:
        node, path = stack.pop()
        if len(path) > MAX_NESTING:
            return path
        if isinstance(node, dict):
            stack.extend((v, path + [k]) for k, v in node.items())
        elif isinstance(node, list):
            stack.extend((v, path + [i]) for i, v in enumerate(node))
    return None


def _is_number(checker, x) -> bool:
    if isinstance(x, float):
        return math.isfinite(x)
    return isinstance(x, int) and not isinstance(x, bool) and _fits_float(x)


def _fits_float(x: int) -> bool:
    try:
        float(x)
    except OverflowError:
        return False
    return True


def _is_integer(checker, x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _type(validator, types, instance, schema):
    """jsonschema's ``type``, but where ``x-allowInfinity`` lets ``inf`` through."""
    from jsonschema import Draft202012Validator

    if schema.get("x-allowInfinity") and isinstance(instance, float) and instance == math.inf:
        return
    yield from Draft202012Validator.VALIDATORS["type"](validator, types, instance, schema)


def _extras(instance: dict, schema: dict) -> list:
    """The keys of ``instance`` that neither ``properties`` nor ``patternProperties`` name, in document order."""
    known, patterns = schema.get("properties", {}), schema.get("patternProperties", {})
    return [k for k in instance if k not in known and not any(re.search(p, k) for p in patterns)]


def _additional_properties(validator, aP, instance, schema):
    """jsonschema's ``additionalProperties``, in document order (so the first problem is the same every run)."""
    from jsonschema import ValidationError

    if not validator.is_type(instance, "object"):
        return
    extras = _extras(instance, schema)
    if validator.is_type(aP, "object"):
        for extra in extras:
            yield from validator.descend(instance[extra], aP, path=extra)
    elif aP is False and extras:
        yield ValidationError(f"unknown key {extras[0]!r}")


@functools.cache
def _validator(fmt: str):
    """The validator of format ``fmt``: draft 2020-12 with the TOML rules above (jsonschema imported only when a
    file is checked: about 0.1 s that a command reading no file does not pay)."""
    from jsonschema import Draft202012Validator, validators

    checker = Draft202012Validator.TYPE_CHECKER.redefine_many({"number": _is_number, "integer": _is_integer})
    cls = validators.extend(Draft202012Validator, validators={"type": _type,
                                                              "additionalProperties": _additional_properties},
                            type_checker=checker)
    return cls(schema(fmt))


def _problem(error: ValidationError, doc: Any, label: str | None) -> FormatProblem:
    """The one-line problem of a jsonschema error: its field, and a message written from the failing node."""
    path, node, x, keyword = list(error.absolute_path), error.schema, error.instance, error.validator
    if keyword == "additionalProperties":
        extra = _extras(x, node)[0]
        known = list(node.get("properties", {}))
        close = closest(extra, known)
        hint = f"did you mean {close!r}?" if close else f"known: {', '.join(known)}"
        return FormatProblem(field_text(doc, path + [extra], label), f"unknown key ({hint})")
    if keyword == "required":
        missing = next(k for k in error.validator_value if k not in x)
        expected = node.get("properties", {}).get(missing, {}).get("x-expected")
        return FormatProblem(field_text(doc, path + [missing], label),
                             "missing required field" + (f": expected {expected}" if expected else ""))
    if "propertyNames" in error.schema_path:
        what = node.get("x-expected", f"a name matching {node.get('pattern')}")
        return FormatProblem(field_text(doc, path + [x], label), f"{one_line(str(x), 60)!r} is not {what}")
    return FormatProblem(field_text(doc, path, label), _value_message(keyword, node, x, error))


def _value_message(keyword: str, node: dict, x: Any, error: ValidationError) -> str:
    """What is wrong with value ``x`` of schema ``node``, whose ``keyword`` failed."""
    if keyword == "type":
        types = [error.validator_value] if isinstance(error.validator_value, str) else error.validator_value
        if isinstance(x, float) and not math.isfinite(x) and "number" in types:
            return f"must be finite, got {x}"
        if _is_integer(None, x) and "number" in types and not _fits_float(x):
            return f"out of range: an integer of {_digits(x)} digits"
        what = node.get("x-expected") or " or ".join(_KINDS.get(t, t) for t in types)
        return f"expected {what}, got {_type_name(x)}"
    if "x-expected" in node:
        return f"expected {node['x-expected']}, got {_shown(x)}"
    if keyword == "enum":
        close = closest(x, node["enum"]) if isinstance(x, str) else None
        hint = f"did you mean {close!r}?" if close else f"known: {', '.join(map(str, node['enum']))}"
        return f"unknown {node.get('title', 'value')} {_shown(x)}; {hint}"
    if keyword in ("minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"):
        return f"out of range: {_range(node)}, got {_shown(x)}"
    if keyword in ("anyOf", "oneOf"):
        return f"out of range: must be {' or '.join(_branch(b) for b in node[keyword])}, got {_shown(x)}"
    if keyword == "const":
        return f"must be {node['const']!r}, got {_shown(x)}"
    if keyword in ("minItems", "maxItems"):
        return f"expected {_list_kind(node)}, got a list of {len(x)}"
    if keyword == "minLength":
        return "expected a non-empty string"
    return error.message


def _range(node: dict) -> str:
    """The range a number's schema allows, in words: ``must be in (0, 10]``, ``|value| must be <= 1e+30``."""
    lo = node.get("minimum", node.get("exclusiveMinimum"))
    hi = node.get("maximum", node.get("exclusiveMaximum"))
    if lo is not None and hi is not None:
        if lo == -hi and "minimum" in node and "maximum" in node:
            return f"|value| must be <= {_number(hi)}"
        return (f"must be in {'[' if 'minimum' in node else '('}{_number(lo)}, {_number(hi)}"
                f"{']' if 'maximum' in node else ')'}")
    if lo is not None:
        return f"must be {'>=' if 'minimum' in node else '>'} {_number(lo)}"
    return f"must be {'<=' if 'maximum' in node else '<'} {_number(hi)}"


def _branch(node: dict) -> str:
    """One alternative of an ``anyOf``, in words: ``-1 (unbounded)``, ``in [1, 2147483647]``."""
    if "const" in node:
        return repr(node["const"]) + (f" ({node['description']})" if "description" in node else "")
    return _range(node).removeprefix("must be ")


def _list_kind(node: dict) -> str:
    """What a list's schema takes, in words: ``a list of 3 numbers``, ``a non-empty list of strings``."""
    items = node.get("items", {})
    noun = items.get("title", "") + "s" if "title" in items else _PLURALS.get(items.get("type"), "values")
    lo, hi = node.get("minItems", 0), node.get("maxItems")
    if lo == hi:
        return f"a list of {lo} {noun}"
    if hi is not None:
        return f"a list of {lo} to {hi} {noun}"
    return f"a non-empty list of {noun}" if lo == 1 else f"a list of at least {lo} {noun}"


def _number(v: float) -> str:
    return str(v) if isinstance(v, int) and abs(v) < 10**12 else f"{v:g}"


def _digits(x: int) -> int:
    return len(str(abs(x))) if x.bit_length() < 10000 else int(x.bit_length() * math.log10(2)) + 1


def _type_name(x: Any) -> str:
    return "a boolean" if isinstance(x, bool) else type(x).__name__


def _shown(x: Any) -> str:
    """A value for a message: a number or a short string as written; a list or table by its kind."""
    if isinstance(x, (list, dict)):
        return f"a {'list' if isinstance(x, list) else 'table'} of {len(x)}"
    if isinstance(x, int) and not isinstance(x, bool) and x.bit_length() > 64:
        return f"an integer of {_digits(x)} digits"
    if isinstance(x, str):
        return repr(one_line(x, 60))
    return repr(x) if not isinstance(x, float) else f"{x:g}" if abs(x) >= 1e16 or 0 < abs(x) < 1e-4 else repr(x)

"""The format schemas (src/cornell_harness/schemas/) are the formats' single statement: the docs' tables are
written from them, their choices and limits are the ones the code uses, and a ``#:schema`` line is ignored."""

from __future__ import annotations

import dataclasses

import pytest

from benchmarks import markdown_blocks, schema_tables
from cornell_harness.adapters.api import ESTIMATORS
from cornell_harness.adapters.renderers_file import NAME
from cornell_harness.gate.config import (DEFAULT_ALPHA, DEFAULT_REGRESSION_MARGIN, DEFAULT_REGRESSION_METRICS,
                                         DEFAULT_TIME_LIMIT_S, BiasLimit, Consistency, Expectation)
from cornell_harness.schemas.reader import FORMATS, FormatProblem, check, schema
from cornell_harness.scenes.loader import load_scene
from cornell_harness.scenes.materials import MATERIAL_TYPES, MAX_IOR, material_fields
from cornell_harness.scenes.model import FEATURES, FOV_AXES, MAX_COORDINATE, MAX_DEPTH, MAX_RADIANCE, PIXEL_FILTERS
from cornell_harness.scenes.quantities import AO_NORMALS, AO_WEIGHTINGS, QUANTITIES
from cornell_harness.scenes.spectra import EXTRAPOLATIONS, RGB_CONVENTIONS
from cornell_harness.scenes.units import LENGTH_SCALE_RANGE
from cornell_harness.durations import parse_duration
from tests.conftest import ROOT

SCENE = schema("scene")
DEFS = SCENE["$defs"]


def test_the_docs_tables_are_the_schemas():
    _, blocks = markdown_blocks.parse((ROOT / "docs" / "formats.md").read_text(encoding="utf-8"))
    lines = (ROOT / "docs" / "formats.md").read_text(encoding="utf-8").splitlines()
    found = {b.name: "\n".join(lines[b.begin + 1:b.end]) + "\n" for b in blocks}
    assert found == schema_tables.blocks(), "rerun .venv/bin/python benchmarks/schema_tables.py --markdown docs/formats.md"


def test_a_changed_schema_changes_its_table(monkeypatch):
    """The comparison above can fail: a description edited in the schema is a different table."""
    edited = {**SCENE, "properties": {**SCENE["properties"], "name": {"type": "string", "description": "edited"}}}
    monkeypatch.setattr(schema_tables, "schema", lambda fmt: edited if fmt == "scene" else schema(fmt))
    assert "edited" in schema_tables.tables("scene") and schema_tables.blocks() != {
        f"{f}.schema.json": schema_tables.tables(f) for f in FORMATS if f != "scene"}


def test_the_scene_schema_states_the_codes_choices_and_limits():
    top = SCENE["properties"]
    assert top["features"]["items"]["enum"] == list(FEATURES)
    assert top["quantity"]["enum"] == list(QUANTITIES)
    assert (top["length_scale"]["minimum"], top["length_scale"]["maximum"]) == LENGTH_SCALE_RANGE
    camera = DEFS["camera"]["properties"]
    assert camera["fov_axis"]["enum"] == list(FOV_AXES)
    assert DEFS["point"]["items"]["maximum"] == MAX_COORDINATE == -DEFS["point"]["items"]["minimum"]
    assert DEFS["render"]["properties"]["pixel_filter"]["enum"] == list(PIXEL_FILTERS)
    assert DEFS["render"]["properties"]["max_depth"]["anyOf"][1]["maximum"] == MAX_DEPTH
    assert DEFS["mesh"]["properties"]["emitter"]["properties"]["radiance"]["items"]["maximum"] == MAX_RADIANCE
    assert DEFS["ior"]["maximum"] == MAX_IOR
    assert DEFS["material"]["properties"]["type"]["enum"] == list(MATERIAL_TYPES)
    for kind, cls in MATERIAL_TYPES.items():
        fields = {f.name: f for f in material_fields(cls)}
        assert list(DEFS[kind]["properties"]) == ["type", *fields]
        assert DEFS[kind]["required"] == [n for n, f in fields.items() if f.default is dataclasses.MISSING]
        for name, f in fields.items():
            if f.default is not dataclasses.MISSING:
                assert DEFS[kind]["properties"][name]["default"] == f.default
    ao = DEFS["ambient_occlusion"]["properties"]
    assert ao["weighting"]["enum"] == list(AO_WEIGHTINGS) and ao["normal"]["enum"] == list(AO_NORMALS)
    assert DEFS["colour"]["properties"]["rgb_convention"]["enum"] == list(RGB_CONVENTIONS)
    assert DEFS["spectrum"]["properties"]["extrapolation"]["enum"] == list(EXTRAPOLATIONS)


def test_the_gate_and_renderers_schemas_state_the_codes_choices_and_defaults():
    gate = schema("gate")["properties"]
    assert gate["regression_metrics"]["default"] == list(DEFAULT_REGRESSION_METRICS)
    assert (gate["alpha"]["default"], gate["regression_margin"]["default"]) == (DEFAULT_ALPHA, DEFAULT_REGRESSION_MARGIN)
    for table, cls in (("expectation", Expectation), ("consistency", Consistency), ("bias_limit", BiasLimit)):
        fields = {f.name: f.default if f.default is not dataclasses.MISSING else f.default_factory()
                  for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING
                  or f.default_factory is not dataclasses.MISSING}
        for key, node in schema("gate")["$defs"][table]["properties"].items():
            if "default" in node and key in fields:
                value = fields[key]
                assert (list(value) if isinstance(value, tuple) else value) == node["default"], (table, key)
    assert parse_duration(gate["time_limit"]["default"]) == DEFAULT_TIME_LIMIT_S
    renderer = schema("renderers")["$defs"]["renderer"]["properties"]
    assert renderer["estimator"]["enum"] == list(ESTIMATORS)
    assert renderer["quantity"]["enum"] == list(QUANTITIES)
    assert renderer["models"]["items"]["enum"] == list(FEATURES)
    assert schema("renderers")["properties"]["renderer"]["propertyNames"]["pattern"] == f"^{NAME.pattern}$"


def test_a_schema_directive_is_a_comment_the_reader_ignores(tmp_path):
    text = (ROOT / "src" / "cornell_harness" / "references" / "furnace" / "scene.toml").read_text()
    path = tmp_path / "scene.toml"
    path.write_text("#:schema ./src/cornell_harness/schemas/scene.schema.json\n" + text)
    assert load_scene(path).content_hash() == load_scene(ROOT / "src" / "cornell_harness" / "references" / "furnace"
                                                         / "scene.toml").content_hash()


@pytest.mark.parametrize("doc, field, message", [
    ({"expect": [{"scene": "s", "renderer": "r", "spp": 4, "unbaised": True}]}, "expect[0].unbaised",
     "unknown key (did you mean 'unbiased'?)"),
    ({"alpha": float("nan"), "expect": [{}]}, "alpha", "must be finite, got nan"),
    ({"alpha": 10**400, "expect": [{}]}, "alpha", "out of range: an integer of 401 digits"),
    ({"alpha": True, "expect": [{}]}, "alpha", "expected a number, got a boolean"),
    ({"expect": [{"scene": "s", "renderer": "r", "spp": 2.0}]}, "expect[0].spp", "expected an integer, got float"),
    ({"expect": [[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[[0]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]]}, "expect" + "[0]" * 32,
     "arrays or tables nested more than 32 deep"),
])
def test_a_schema_error_is_one_line_naming_the_field(doc, field, message):
    with pytest.raises(FormatProblem) as e:
        check(doc, "gate")
    assert (e.value.field, e.value.message) == (field, message)

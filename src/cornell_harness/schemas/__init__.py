"""The harness's file formats as JSON Schemas, and the one strict reader that checks a file against its schema.

Three TOML formats, each stated once, field by field (type, unit, range, choices, default and meaning), in a
JSON Schema (draft 2020-12) shipped in this package: ``scene.schema.json`` (a scene file,
:mod:`cornell_harness.scenes.loader`), ``gate.schema.json`` (a gate config, :mod:`cornell_harness.gate.config`)
and ``renderers.schema.json`` (a renderers file, :mod:`cornell_harness.adapters.renderers_file`). The docs' format
tables are generated from them (``benchmarks/schema_tables.py``), and an editor that reads a ``#:schema``
comment (taplo, Even Better TOML) completes and checks a file against them. :mod:`.reader` is the reader.
"""

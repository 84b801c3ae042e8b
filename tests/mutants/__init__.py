"""Deliberately broken copies of our renderers, for measuring the CI gate's power.

Each :class:`Mutant` is a realistic bug in one of our renderers
(:data:`INTEGRATORS`: the path tracer, the photon mapper, SPPM, ao, ambient,
probes, the denoised path tracer ``pathtracer+oidn`` and whitted), written as
changes to named functions: each patch names a function by its qualified name
(``"_shade"``, ``"PathTracer.render"``) in the renderer's module (the
integrator, e.g. ``src/cornell_harness/renderers/pathtracer.py``), in a module
of the toolkit it is built on (``src/cornell_harness/renderers/core/``) or in
another module of ``src/cornell_harness/renderers/`` it imports (the probes'
algorithm, ``src/cornell_harness/renderers/ddgi.py``), and either edits code in
it (:class:`Edit`: an expression or statements, matched by syntax tree, so
formatting, comments and the same code elsewhere in the file do not matter),
replaces it (:class:`Replace`) or wraps it (:class:`Wrap`).
:mod:`tests.mutants.editing` applies them: only the named functions' lines
change, written out again from the patched tree. :func:`load_mutant` writes the
patched sources to real files (so numba's ``cache=True`` has a locator) as
uniquely named modules, imports them, and returns a
:class:`cornell_harness.adapters.registry.RendererEntry` named after the renderer,
which :func:`cornell_harness.gate.run.run_gate` takes as an override.

A mutant is a set of modules: the integrator is ``cbox_mutant_<name>``; a
mutant that patches any other module (``src/cornell_harness/renderers/core/<stem>.py``, or
``src/cornell_harness/renderers/<stem>.py`` such as ``ddgi``) gets a copy
``cbox_mutant_<name>__<stem>`` of it and of each core module but the scalar
helpers (:data:`SHARED_CORE`), patched or not, so no part of the renderer
still sees the unpatched code and no shared module is compiled for the
copies' types; their ``from cornell_harness.renderers.core.<stem> import`` (and
``from cornell_harness.renderers import <stem>``) lines are pointed at the copies.

Every patch must apply: if a refactor renames its function, or the code an
:class:`Edit` changes is no longer in that function exactly once,
:func:`patched_sources` raises (naming the mutant, the function and what is
missing) instead of silently testing an unmutated renderer. The sources
themselves are never modified, and no code is kept in them for the catalogue's
sake.

The gate on a mutant: :func:`gate_config` (``gate.toml`` with one renderer's
expectations), :func:`run_until_failure` (cheapest expectation first, up to
the first that fails), :func:`verdict` (what the gate said, in the terms of
the detection table) and :func:`run_isolated` (in a child process with a time
limit, for the mutants of :data:`ISOLATED` that once made a run never end).

The package: what a mutant is (:mod:`tests.mutants.model`), the bugs, one
module per renderer family (:mod:`tests.mutants.pathtracer`,
:mod:`~tests.mutants.photon_mapping`, :mod:`~tests.mutants.ambient_occlusion`,
:mod:`~tests.mutants.probes`, :mod:`~tests.mutants.denoising`, :mod:`~tests.mutants.whitted`,
:mod:`~tests.mutants.spectral`), gathered in
:mod:`tests.mutants.catalogue`, patching a function (:mod:`tests.mutants.editing`), and applying a mutant
(:mod:`tests.mutants.patching`);
the names used outside are re-exported here. Used by
``tests/gate/test_gate_power.py``, ``tests/renderers/test_ao.py`` and
``benchmarks/gate_power.py`` only.
"""

from tests.mutants.catalogue import BY_NAME, FAMILIES, ISOLATED, LOW_POWER, MUTANTS, SPECTRAL
from tests.mutants.editing import apply_patch, find_function, named_functions, span
from tests.mutants.model import (AMBIENT, AO, CORE, DDGI, HERO, INTEGRATORS, OIDN, PATHTRACER, PHOTONMAP, PROBES, ROOT,
                                 SOURCE, SPPM, WHITTED, Edit, Mutant, Patch, Replace, Wrap)
from tests.mutants.patching import (GATE_TOML, INTEGRATOR_FILES, SHARED_CORE, Verdict, cost, gate_config,
                                    imports_module, integrator, label, load_module, load_mutant, module_name,
                                    original_source, patched_file, patched_source, patched_sources, pathtracer_gate_config,
                                    run_isolated, run_until_failure, verdict)

__all__ = ["AMBIENT", "AO", "BY_NAME", "CORE", "DDGI", "FAMILIES", "GATE_TOML", "HERO", "INTEGRATORS", "INTEGRATOR_FILES",
           "ISOLATED", "LOW_POWER", "MUTANTS", "OIDN", "PATHTRACER", "PHOTONMAP", "PROBES", "ROOT", "SHARED_CORE",
           "SOURCE", "SPECTRAL", "SPPM", "WHITTED", "Edit", "Mutant", "Patch", "Replace", "Verdict", "Wrap", "apply_patch",
           "cost", "find_function", "gate_config", "imports_module", "integrator", "label", "load_module", "load_mutant",
           "module_name", "named_functions", "original_source", "patched_file", "patched_source", "patched_sources",
           "pathtracer_gate_config", "run_isolated", "run_until_failure", "span", "verdict"]

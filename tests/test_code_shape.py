"""The toolkit's shape, checked on the sources (issue 27): what a reviewer would otherwise grep for.

- every numba kernel and helper of ours takes at most :data:`MAX_KERNEL_PARAMETERS` parameters (outputs and
  inputs travel as NamedTuples of arrays, as :class:`cornell_harness.renderers.core.rays.RayBuffer` does);
- no integrator draws raw ``uniform(key, path, dim)`` numbers: every decision goes through
  :mod:`cornell_harness.renderers.core.sampler`, so the ``sampler`` setting means the same in each;
- light sampling towards a shading point (pbrt-v4's ``SampleLd``) is written once,
  :func:`cornell_harness.renderers.core.direct.sample_ld`: no other module turns an emitter sample into a shadow ray.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.conftest import ROOT

RENDERERS = ROOT / "src" / "cornell_harness" / "renderers"
MAX_KERNEL_PARAMETERS = 10
#: Where raw counter-based numbers may be drawn: the generator itself and the samplers built on it.
RAW_DRAWS_ALLOWED = {"src/cornell_harness/renderers/core/rng.py", "src/cornell_harness/renderers/core/sampler.py", "src/cornell_harness/renderers/core/sobol.py"}


def sources() -> list[Path]:
    return sorted(p for p in RENDERERS.rglob("*.py") if "__pycache__" not in p.parts)


def kernels(tree: ast.AST):
    """Functions decorated with the toolkit's ``jit`` or ``jit_inline``."""
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef) and any(isinstance(d, ast.Name) and d.id in ("jit", "jit_inline")
                                                     for d in node.decorator_list):
            yield node


def calls(tree: ast.AST, name: str) -> list[int]:
    """Lines that call ``name(...)`` (a bare name or an attribute of that name)."""
    return [n.lineno for n in ast.walk(tree) if isinstance(n, ast.Call)
            and getattr(n.func, "id", getattr(n.func, "attr", None)) == name]


@pytest.mark.parametrize("path", sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_kernel_takes_more_than_ten_parameters(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    wide = {k.name: len(k.args.args) for k in kernels(tree) if len(k.args.args) > MAX_KERNEL_PARAMETERS}
    assert wide == {}, f"bundle these kernels' arguments (NamedTuples): {wide}"


def test_no_integrator_draws_raw_numbers():
    raw = {str(p.relative_to(ROOT)): lines for p in sources()
           if str(p.relative_to(ROOT)) not in RAW_DRAWS_ALLOWED
           and (lines := calls(ast.parse(p.read_text(encoding="utf-8")), "uniform"))}
    assert raw == {}, f"draw through cornell_harness.renderers.core.sampler (path_point, sample_1d/2d), not uniform(): {raw}"


def test_light_sampling_is_written_once():
    """``towards_emitter`` (an emitter point seen from a shading point) is SampleLd's; photon emission, which
    samples emitters to leave them, is the only other caller of ``sample_emitter``."""
    towards = {str(p.relative_to(ROOT)) for p in sources()
               if calls(ast.parse(p.read_text(encoding="utf-8")), "towards_emitter")}
    emitters = {str(p.relative_to(ROOT)) for p in sources()
                if calls(ast.parse(p.read_text(encoding="utf-8")), "sample_emitter")}
    assert towards == {"src/cornell_harness/renderers/core/direct.py"}
    assert emitters == {"src/cornell_harness/renderers/core/direct.py", "src/cornell_harness/renderers/core/photons.py"}


def test_the_checks_see_what_they_check(tmp_path):
    """The parsers find a wide kernel and a raw draw when there is one (so the tests above can fail)."""
    tree = ast.parse("@jit\ndef k(a, b, c, d, e, f, g, h, i, j, k):\n    return uniform(a, b, c)\n")
    assert [len(k.args.args) for k in kernels(tree)] == [11]
    assert calls(tree, "uniform") == [3]

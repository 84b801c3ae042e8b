"""The code's shape, checked on the sources: what a reviewer would otherwise grep for.

- no module of the package names an issue of the tracker: docstrings and comments say what and why, and the
  history (issue numbers, when a figure was measured) lives in git, BENCHMARKS.md and docs/;

- every numba kernel and helper of ours takes at most :data:`MAX_KERNEL_PARAMETERS` parameters (outputs and
  inputs travel as NamedTuples of arrays, as :class:`cornell_harness.renderers.core.rays.RayBuffer` does);
- no integrator draws raw ``uniform(key, path, dim)`` numbers: every decision goes through
  :mod:`cornell_harness.renderers.core.sampler`, so the ``sampler`` setting means the same in each;
- light sampling towards a shading point (pbrt-v4's ``SampleLd``) is written once,
  :func:`cornell_harness.renderers.core.direct.sample_ld`: no other module turns an emitter sample into a shadow ray;
- every sample dimension an integrator draws is a name of the sampler's map
  (:mod:`cornell_harness.renderers.core.sampler`: a block's dimension, offset or dimension function), never a
  number or a base of its own, and the ``sampler`` setting is declared there once.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from tests.conftest import ROOT

RENDERERS = ROOT / "src" / "cornell_harness" / "renderers"
MAX_KERNEL_PARAMETERS = 10
#: Where raw counter-based numbers may be drawn: the generator itself and the samplers built on it.
RAW_DRAWS_ALLOWED = {"src/cornell_harness/renderers/core/rng.py", "src/cornell_harness/renderers/core/sampler.py", "src/cornell_harness/renderers/core/sobol.py"}
SAMPLER = "cornell_harness.renderers.core.sampler"
#: Calls whose argument at this position is a sample dimension (sample_*) or a vertex block's offset (vertex_*).
DIMENSION_ARGS = {"sample_1d": 2, "sample_2d": 2, "vertex_1d": 3, "vertex_2d": 3}


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


def own_dimensions(tree: ast.AST) -> list[int]:
    """Lines that draw a dimension (or pass a walk's ``dim_base``) not named by the sampler's map: a number,
    arithmetic, a parameter or a constant of the module's own. A name imported from the sampler, or a call of
    one, is the map's; a ``dim_base`` of 0 is no shift."""
    theirs = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module == SAMPLER
              for a in n.names}
    lines = []
    for n in ast.walk(tree):
        if not isinstance(n, ast.Call):
            continue
        name = getattr(n.func, "id", getattr(n.func, "attr", None))
        given = [n.args[DIMENSION_ARGS[name]]] if name in DIMENSION_ARGS and len(n.args) > DIMENSION_ARGS[name] else []
        given += [k.value for k in n.keywords if k.arg == "dim_base" and not (isinstance(k.value, ast.Constant)
                                                                            and k.value.value == 0)]
        for arg in given:
            named = arg.func if isinstance(arg, ast.Call) else arg
            if not (isinstance(named, ast.Name) and named.id in theirs):
                lines.append(n.lineno)
    return lines


def shifts(tree: ast.AST) -> list[int]:
    """In a module that draws from the sampler, lines with a literal ``1 << k``, 16 ≤ k ≤ 24: the bases of the
    dimension blocks (rng takes 2^24 dimensions)."""
    if not any(isinstance(n, ast.ImportFrom) and n.module == SAMPLER for n in ast.walk(tree)):
        return []
    return [n.lineno for n in ast.walk(tree) if isinstance(n, ast.BinOp) and isinstance(n.op, ast.LShift)
            and isinstance(n.left, ast.Constant) and n.left.value == 1 and isinstance(n.right, ast.Constant)
            and 16 <= n.right.value <= 24]


def sampler_settings(tree: ast.AST) -> list[int]:
    """Lines that declare a ``sampler`` setting: ``Setting("sampler", ...)``, or a replace() of the sampler's."""
    return [n.lineno for n in ast.walk(tree) if isinstance(n, ast.Call) and (
        (getattr(n.func, "id", None) == "Setting" and n.args and isinstance(n.args[0], ast.Constant)
         and n.args[0].value == "sampler")
        or (getattr(n.func, "id", getattr(n.func, "attr", None)) == "replace"
            and any(isinstance(a, ast.Name) and a.id == "SAMPLER_SETTING" for a in n.args)))]


def test_every_dimension_is_the_samplers():
    trees = {str(p.relative_to(ROOT)): ast.parse(p.read_text(encoding="utf-8")) for p in sources()}
    found = {path: lines for path, tree in trees.items()
             if path not in RAW_DRAWS_ALLOWED and (lines := own_dimensions(tree) + shifts(tree))}
    assert found == {}, f"name these dimensions in cornell_harness.renderers.core.sampler's map: {found}"


def test_the_sampler_setting_is_declared_once():
    found = {str(p.relative_to(ROOT)): lines for p in sources()
             if (lines := sampler_settings(ast.parse(p.read_text(encoding="utf-8"))))}
    assert found == {"src/cornell_harness/renderers/core/sampler.py": found.get(
        "src/cornell_harness/renderers/core/sampler.py")} and len(found[next(iter(found))]) == 1, found


def test_the_checks_see_what_they_check(tmp_path):
    """The parsers find a wide kernel, a raw draw, a dimension of a module's own and a sampler setting declared
    again when there is one (so the tests above can fail)."""
    tree = ast.parse("@jit\ndef k(a, b, c, d, e, f, g, h, i, j, k):\n    return uniform(a, b, c)\n")
    assert [len(k.args.args) for k in kernels(tree)] == [11]
    assert calls(tree, "uniform") == [3]
    tree = ast.parse(f"from {SAMPLER} import AO_U, occlusion_dim, sample_2d\nAO_DIM = 1 << 20\n"
                     "sample_2d(st, pt, AO_U)\nsample_2d(st, pt, occlusion_dim(s))\nsample_2d(st, pt, AO_DIM + 2 * s)\n"
                     "sample_1d(st, pt, 7)\nvertex_1d(st, pt, d, offset)\nwalk(rays, dim_base=AO_DIM)\n"
                     "walk(rays, dim_base=0)\n")
    assert own_dimensions(tree) == [5, 6, 7, 8] and shifts(tree) == [2]
    tree = ast.parse('Setting("sampler", str, "pmj02", "doc")\nreplace(SAMPLER_SETTING, default="x")\n'
                     'Setting("spp", int, 1, "doc")\n')
    assert sampler_settings(tree) == [1, 2]


#: An issue of our tracker named in prose ("issue 31", "Issue 30:", "issues 29 and 30"); another project's
#: ("mitsuba3 issue #372") is a citation.
ISSUE = re.compile(r"\b[Ii]ssues? [0-9]+")


def issue_mentions(text: str) -> list[int]:
    """The lines of ``text`` that name an issue."""
    return [n for n, line in enumerate(text.splitlines(), 1) if ISSUE.search(line)]


def test_no_module_names_an_issue():
    package = ROOT / "src" / "cornell_harness"
    found = {str(p.relative_to(ROOT)): lines for p in sorted(package.rglob("*"))
             if p.suffix in (".py", ".json", ".j2", ".toml") and (lines := issue_mentions(p.read_text(encoding="utf-8")))}
    assert found == {}, f"say what and why, not which issue (history belongs in git and docs/): {found}"
    assert issue_mentions("x = 1\n# measured for issue 31\n# Issue 30: why\n# an issue with it\n") == [2, 3]

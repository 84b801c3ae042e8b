"""Applying a mutant (copies of the patched modules, loaded as the renderer's entry) and running the gate on it.

See :mod:`tests.mutants` for how a mutant becomes a renderer, and why every patch must apply.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from dataclasses import dataclass
from pathlib import Path

from cornell_harness.adapters.registry import RendererEntry
from cornell_harness.adapters.settings import resolve_settings
from tests.mutants.catalogue import BY_NAME
from tests.mutants.editing import apply_patch, named_functions
from tests.mutants.model import CORE, INTEGRATORS, PATHTRACER, ROOT, Mutant

#: Core modules every mutant shares with the real renderer: scalar helpers, no types of their own.
SHARED_CORE = ("sampling", "rng")


def integrator(mutant: Mutant | str) -> str:
    """The file of the renderer module a mutant is a copy of (``src/cornell_harness/renderers/pathtracer.py``, ...)."""
    m = BY_NAME[mutant] if isinstance(mutant, str) else mutant
    return INTEGRATORS[m.renderer][0]


def original_source(renderer: str = "pathtracer") -> str:
    """The source of a renderer's integrator module (default ``src/cornell_harness/renderers/pathtracer.py``)."""
    return (ROOT / INTEGRATORS[renderer][0]).read_text(encoding="utf-8")


#: The integrators' files: a mutant's copy of one of these is its top module, ``cbox_mutant_<name>``.
INTEGRATOR_FILES = frozenset(f for f, _ in INTEGRATORS.values())


def module_name(name: str, file: str = PATHTRACER) -> str:
    """The mutant's module for ``file``: ``cbox_mutant_<name>`` for its integrator, ``..__<stem>`` for a core
    module or another module of ``src/cornell_harness/renderers/`` (``src/cornell_harness/renderers/ddgi.py``: ``cbox_mutant_<name>__ddgi``)."""
    return f"cbox_mutant_{name}" if file in INTEGRATOR_FILES else f"cbox_mutant_{name}__{Path(file).stem}"


def _core_module(file: str) -> str:
    return file[: -len(".py")].replace("/", ".")


def imports_module(text: str, module: str) -> bool:
    return re.search(rf"^\s*(from {re.escape(module)} import |import {re.escape(module)} as )", text, re.M) is not None


def _redirect(text: str, module: str, to: str) -> str:
    """``text`` with its imports of ``module`` pointed at ``to``: ``from <module> import ...`` and, for a module
    imported whole from its package (``from cornell_harness.renderers import ddgi``), ``import <to> as ddgi``."""
    text = re.sub(rf"^(\s*from ){re.escape(module)}( import )", rf"\g<1>{to}\g<2>", text, flags=re.M)
    package, _, stem = module.rpartition(".")
    text = re.sub(rf"^(\s*)from {re.escape(package)} import {stem}[ \t]*$", rf"\g<1>import {to} as {stem}", text,
                  flags=re.M)
    # Any other form would leave the copy importing the unpatched module: a mutant that tests nothing.
    left = re.search(rf"^\s*(from {re.escape(package)} import [^\n]*\b{stem}\b|import {re.escape(module)}\b)",
                     text, re.M)
    assert left is None, (f"{left.group(0).strip()!r} imports {module} in a form the mutant machinery does not "
                          f"redirect to its copy; write it 'from {package} import {stem}' or "
                          f"'from {module} import ...'")
    return text


def patched_file(mutant: Mutant | str, file: str, text: str | None = None) -> str:
    """``file``'s source (``text``, default the repository's) with the mutant's patches of it applied, its imports
    as they are: it differs from ``text`` only in the lines of the functions the patches name."""
    m = BY_NAME[mutant] if isinstance(mutant, str) else mutant
    text = (ROOT / file).read_text(encoding="utf-8") if text is None else text
    for p in m.patches:
        if p.file == file:
            text = apply_patch(text, p, m.name)
    return text


def patched_sources(mutant: Mutant | str, sources: dict[str, str] | None = None) -> dict[str, str]:
    """Every module of the mutant: {file it replaces: patched text with imports redirected to the copies}.

    ``sources`` overrides the text of some files (default: read from the
    repository). AssertionError if a patch's function is not found, or the
    code an Edit changes is not in it exactly once, or if the mutant changes
    nothing.
    """
    m = BY_NAME[mutant] if isinstance(mutant, str) else mutant
    sources = dict(sources or {})

    def read(file: str) -> str:
        if file not in sources:
            sources[file] = (ROOT / file).read_text(encoding="utf-8")
        return sources[file]

    top = integrator(m)
    texts = {top: read(top)}
    for f in named_functions(m.patches):
        texts[f] = patched_file(m, f, read(f))
    assert any(texts[f] != read(f) for f in texts), f"mutant {m.name!r} does not change the source"
    # A mutant of the toolkit gets its own copy of every core module that a kernel may call with the
    # scene tables or ray buffers: a shared module's numba cache would otherwise record a signature
    # naming the mutant's copy of a type (geometry.Tables), which a later process cannot import.
    # sampling and rng take scalars only (and sampling keys the real tree's kernel caches), so they
    # stay shared.
    core = sorted(str(f.relative_to(ROOT)) for f in (ROOT / CORE).glob("*.py"))
    copied = {f for f in texts if f != top}
    if copied:
        copied |= {f for f in core if Path(f).stem not in SHARED_CORE and Path(f).stem != "__init__"}
        texts.update({f: texts.get(f, read(f)) for f in copied})
    for f in texts:
        for c in copied:
            texts[f] = _redirect(texts[f], _core_module(c), module_name(m.name, c))
    return texts


def patched_source(mutant: Mutant | str, source: str | None = None) -> str:
    """The integrator's source for ``mutant`` (``source``: the integrator's text to patch instead of the file's)."""
    top = integrator(mutant)
    return patched_sources(mutant, None if source is None else {top: source})[top]


def load_module(name: str, tmp_dir: str | Path):
    """Write the mutant's modules to ``tmp_dir/cbox_mutant_<name>*.py``, import them, return the integrator.

    Cached per process. Either every file is rewritten or none: numba's cache
    of the integrator's kernels does not notice a change in a core module they
    inline, only in their own file.
    """
    files = {module_name(name, f): (Path(tmp_dir) / f"{module_name(name, f)}.py", text)
             for f, text in patched_sources(name).items()}
    current = all(path.exists() and path.read_text(encoding="utf-8") == text for path, text in files.values())
    top = module_name(name, integrator(name))
    loaded = sys.modules.get(top)
    if current and loaded is not None and getattr(loaded, "__file__", None) == str(files[top][0]):
        return loaded
    Path(tmp_dir).mkdir(parents=True, exist_ok=True)
    if not current:
        for path, text in files.values():
            path.write_text(text, encoding="utf-8")
    for mod in files:
        sys.modules.pop(mod, None)
    # Dependencies first: a module is executed once every copy it imports is.
    pending = dict(files)
    while pending:
        mod = next(k for k, (_, text) in pending.items()
                   if not any(imports_module(text, d) for d in pending if d != k))
        path, _ = pending.pop(mod)
        spec = importlib.util.spec_from_file_location(mod, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[mod] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            for m in files:
                sys.modules.pop(m, None)
            raise
    return sys.modules[top]


def load_mutant(name: str, tmp_dir: str | Path) -> RendererEntry:
    """A gate override: ``{m.renderer: load_mutant(name, tmp_dir)}`` runs the mutant in place of ours."""
    module = load_module(name, tmp_dir)
    renderer = BY_NAME[name].renderer
    r = getattr(module, INTEGRATORS[renderer][1])()
    # Its defaults, validated, as the registry's entries hold them: renderers read settings as handed in.
    return RendererEntry(renderer, f"mutant:{name}", r, None, resolve_settings(r, {}, renderer))


# -- running the gate on a mutant ----------------------------------------------------

GATE_TOML = ROOT.parent / "gate.toml"


def gate_config(renderer: str, path: str | Path = GATE_TOML, spectral: bool = False):
    """The project's gate config (alpha, baseline, margins) with only ``renderer``'s expectations: those of its
    ``spectral = "hero"`` mode with ``spectral``, else the others (an RGB mutant's code never runs in hero
    mode, and a hero render costs ~45 s: the RGB mutants' gate runs stay as they were)."""
    import dataclasses

    from cornell_harness.gate.config import load_config

    cfg = load_config(path)
    keep = [e for e in cfg.expectations
            if e.renderer == renderer and ((e.settings or {}).get("spectral") == "hero") == spectral]
    assert keep, f"{path}: no {renderer} expectation"
    return dataclasses.replace(cfg, expectations=keep)


def pathtracer_gate_config(path: str | Path = GATE_TOML):
    """:func:`gate_config` of the path tracer."""
    return gate_config("pathtracer", path)


def label(exp) -> str:
    """Short name of an expectation in tables: ``cornell-box@256spp``."""
    return exp.name.replace(f"/{exp.renderer}", "")


@dataclass
class Verdict:
    """What the gate said about one run (all its expectations), in the terms of the detection table."""

    passed: bool
    failing: list[str]  # failing checks, "expectation: check"
    checks: set[str]  # names of the failing checks alone ("agreement", "finite", "baseline.ssim", ...)
    p_min: float  # smallest p-value of the agreement tests (nan when a test could not say)
    level: float  # per-test level after Šidák (of the first expectation with an agreement test)
    evidence: str  # p-value and/or margins of the failing checks
    where: str  # worst location message
    time_s: float  # the renders' own time, summed


def verdict(outcomes) -> Verdict:
    """Summarise the :class:`cornell_harness.gate.checks.Outcome` list of one :func:`cornell_harness.gate.run.run_gate` call."""
    import math

    failing, checks, evidence, p_min, level, time_s = [], set(), [], math.inf, math.nan, 0.0
    worst = None  # (p, -|z|, where) of the worst rejected agreement test
    other_where = ""
    for o in outcomes:
        lab, agr = label(o.expectation), o.agreement
        time_s += o.record.time_s or 0.0
        if agr is not None:
            p_min = math.nan if math.isnan(agr.p_min) else min(p_min, agr.p_min)  # nan stays nan
            level = agr.level if math.isnan(level) else level
        for c in o.checks:
            if c.passed:
                continue
            failing.append(f"{lab}: {c.name}")
            checks.add(c.name)
            if c.name == "agreement":
                f = agr.failures[0]
                evidence.append(f"{lab}: p = {f['p']:.3g} (z = {f['z']:.1f}; level {agr.level:.2g})")
                z = abs(f["z"]) if math.isfinite(f["z"]) else math.inf
                if worst is None or (f["p"], -z) < worst[:2]:
                    worst = (f["p"], -z, f"{lab}: {f['where']}")
            elif c.name == "finite":
                evidence.append(f"{lab}: {int(c.value)} non-finite pixel(s), budget 0")
                other_where = other_where or f"{lab}: {c.message}"
            else:
                detail = c.message.split(", ", 1)[1] if ", " in c.message else c.message
                evidence.append(f"{lab}: {c.name} {detail}")
                other_where = other_where or f"{lab}: {c.message}"
    passed = all(o.passed for o in outcomes)
    p_min = math.nan if p_min == math.inf else p_min
    where = "; ".join(w for w in (other_where if "finite" in checks else "", worst[2] if worst else "") if w) \
        or other_where
    return Verdict(passed, failing, checks, p_min, level, "; ".join(evidence), where, time_s)


def cost(exp) -> int:
    """Paths an expectation traces (pixels × spp): its render time, roughly."""
    from cornell_harness.scenes.library import resolve_scene

    cam = resolve_scene(exp.scene).camera
    return cam.width * cam.height * (exp.spp or 1)


def run_until_failure(cfg, overrides=None, seed_offset: int = 0) -> list:
    """The gate's expectations one by one, cheapest first, up to the first that fails.

    The gate fails as soon as one expectation fails, so this decides the same
    verdict as :func:`cornell_harness.gate.run.run_gate` over all of them, often for the
    price of the small scenes alone. Returns the outcomes it ran.
    """
    import dataclasses

    from cornell_harness.gate.run import run_gate

    outcomes = []
    for exp in sorted(cfg.expectations, key=cost):
        outcomes += run_gate(dataclasses.replace(cfg, expectations=[exp]), overrides, seed_offset)
        if not outcomes[-1].passed:
            break
    return outcomes


_CHILD = """
import dataclasses, json, sys
sys.path.insert(0, sys.argv[1])
from tests import mutants
from cornell_harness.gate.run import run_gate
name, gate, work, until = sys.argv[2:6]
renderer = mutants.BY_NAME[name].renderer
cfg = mutants.gate_config(renderer, gate)
entry = {renderer: mutants.load_mutant(name, work)}
outcomes = mutants.run_until_failure(cfg, entry) if until == "1" else run_gate(cfg, entry)
v = mutants.verdict(outcomes)
print(json.dumps({**dataclasses.asdict(v), "checks": sorted(v.checks)}))
"""


def run_isolated(name: str, work: str | Path, timeout_s: float, gate: str | Path = GATE_TOML,
                 until_failure: bool = False) -> Verdict | None:
    """The gate on one mutant in a child process; None if it has not ended after ``timeout_s`` (killed)."""
    import json
    import subprocess

    cmd = [sys.executable, "-c", _CHILD, str(ROOT.parent), name, str(gate), str(work),
           "1" if until_failure else "0"]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, cwd=ROOT.parent)
    except subprocess.TimeoutExpired:
        return None
    if out.returncode:
        raise RuntimeError(f"the gate on mutant {name} crashed in its child process:\n{out.stderr[-3000:]}")
    d = json.loads(out.stdout.strip().splitlines()[-1])
    return Verdict(**{**d, "checks": set(d["checks"])})

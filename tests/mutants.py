"""Deliberately broken copies of our path tracer, for measuring the CI gate's power.

Each :class:`Mutant` is a realistic bug, written as a source patch of
``renderers/pathtracer.py``: an exact ``old`` snippet replaced by ``new``.
:func:`load_mutant` writes the patched source to a real file (so numba's
``cache=True`` has a locator) as a uniquely named module, imports it, and
returns a :class:`harness.adapters.registry.RendererEntry` named ``pathtracer`` that
:func:`harness.gate.run.run_gate` takes as an override.

Every patch must apply exactly once: if a refactor of the path tracer moves or
rewrites a snippet, :func:`patched_source` raises instead of silently testing
an unmutated renderer. ``renderers/pathtracer.py`` itself is never modified.

Used by ``tests/test_gate_power.py`` and ``benchmarks/gate_power.py`` only.
"""

from __future__ import annotations

import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path

from harness.adapters.registry import RendererEntry

SOURCE = Path(__file__).resolve().parent.parent / "renderers" / "pathtracer.py"


@dataclass(frozen=True)
class Mutant:
    name: str
    description: str  # the bug, as a developer would make it
    patches: tuple[tuple[str, str], ...]  # (old, new): each old occurs exactly once in the source


MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "nee_missing_cos_x",
        "NEE geometry term written cos θ_y / r² (the receiver's cos θ_x dropped)",
        (("g = cos_x * cos_y / dist2 * w / pe", "g = cos_y / dist2 * w / pe"),),
    ),
    Mutant(
        "light_pdf_2pct",
        "light pdf 2% too high where NEE reads it (pe = light_pdf_area[e] * 1.02, e.g. a stale area table)",
        (("pe = light_pdf_area[e]\n", "pe = light_pdf_area[e] * 1.02\n"),),
    ),
    Mutant(
        "rr_no_compensation",
        "Russian roulette kills paths but survivors are not divided by the survival probability",
        (("            b0, b1_, b2_ = b0 / survive, b1_ / survive, b2_ / survive\n", ""),),
    ),
    Mutant(
        "mis_emitter_double",
        "emission found by BSDF-sampled rays weighted 1 instead of its MIS weight (emitter counted twice)",
        (("w = 1.0 if depth == 1 else power_heuristic(pdf_bsdf[i], pa * ti * ti / cos_o)", "w = 1.0"),),
    ),
    Mutant(
        "camera_half_pixel",
        "pixel jitter recentred to [-0.5, 0.5) though camera_ray adds it to the pixel corner: "
        "image shifted half a pixel",
        (("j % pixels, uniform(key, j, 0), uniform(key, j, 1))",
          "j % pixels, uniform(key, j, 0) - 0.5, uniform(key, j, 1) - 0.5)"),),
    ),
    Mutant(
        "swap_rb",
        "radiance returned in BGR order (as OpenCV wants) instead of RGB: red and blue swapped",
        (("        depth += 1\n    return L\n", "        depth += 1\n    return L[:, ::-1].copy()\n"),),
    ),
    Mutant(
        "energy_loss_1pct",
        "an 'energy-conserving' fudge: the BSDF-sampled throughput multiplied by 0.99 at every bounce "
        "(indirect light only; the camera-visible direct light is untouched)",
        (("b0, b1_, b2_ = beta[i, 0] * rho[p, 0], beta[i, 1] * rho[p, 1], beta[i, 2] * rho[p, 2]",
          "b0, b1_, b2_ = (0.99 * beta[i, 0] * rho[p, 0], 0.99 * beta[i, 1] * rho[p, 1],\n"
          "                        0.99 * beta[i, 2] * rho[p, 2])"),),
    ),
    Mutant(
        "nan_one_pixel",
        "lens-distortion weight r'/r applied to each path's radiance, from the pixel's offset to the principal "
        "point: 0/0 = NaN at that one pixel",
        (("        depth += 1\n    return L\n",
          "        depth += 1\n"
          "    # Lens-distortion weight r'/r of each path's pixel, r its offset from the principal point.\n"
          "    pix = (first + np.arange(m)) % pixels\n"
          "    r = np.hypot(pix % cam.width - cam.width // 2, pix // cam.width - cam.height // 2)\n"
          "    k1 = 0.0  # no radial distortion\n"
          "    return L * (r * (1.0 + k1 * r * r) / r)[:, None]\n"),),
    ),
    Mutant(
        "nan_throughput",
        "the same lens-distortion weight r'/r folded into the camera ray's throughput: a NaN throughput at "
        "the principal-point pixel, which Russian roulette never ends (u >= NaN is false)",
        (("        for c in range(3):\n            o[i, c] = basis[0, c]\n            o32[i, c] = basis[0, c]\n"
          "            beta[i, c] = 1.0\n",
          "        px = j % pixels\n"
          "        r = math.hypot(px % width - width // 2, px // width - height // 2)\n"
          "        k1 = 0.0  # no radial distortion\n"
          "        weight = r * (1.0 + k1 * r * r) / r\n"
          "        for c in range(3):\n            o[i, c] = basis[0, c]\n            o32[i, c] = basis[0, c]\n"
          "            beta[i, c] = weight\n"),),
    ),
    Mutant(
        "shadow_tfar_past_light",
        "shadow-ray tfar lengthened (sl * (1 + 1e-3), a sign slip) so it reaches the emitter: "
        "the light occludes itself",
        (("sh_t[ns] = sl * (1.0 - 1e-6)", "sh_t[ns] = sl * (1.0 + 1e-3)"),),
    ),
    Mutant(
        "mis_pdf_area_measure",
        "MIS weight of BSDF-found emission compares the cosine pdf (solid angle) with the light pdf "
        "left in area measure (no r²/cos θ_y conversion)",
        (("power_heuristic(pdf_bsdf[i], pa * ti * ti / cos_o)", "power_heuristic(pdf_bsdf[i], pa)"),),
    ),
    Mutant(
        "offset_minus_n",
        "continuation-ray origin offset along −n instead of +n: the ray starts behind the surface "
        "and hits it from the back (self-intersection ends every path)",
        (("ox, oy, oz = x0 + eps * n0, x1 + eps * n1, x2 + eps * n2",
          "ox, oy, oz = x0 - eps * n0, x1 - eps * n1, x2 - eps * n2"),),
    ),
    Mutant(
        "cosine_pdf_mismatch",
        "continuation ray's pdf recorded as uniform-hemisphere 1/(2π) though it is sampled cosine-weighted "
        "(MIS weights no longer sum to 1)",
        (("nx_pdf[nn] = cos_w * INV_PI", "nx_pdf[nn] = 0.5 * INV_PI"),),
    ),
    Mutant(
        "two_sided_emitter",
        "the one-sided area light made two-sided: emission found on its back side counted (and |cos θ_y| in "
        "NEE)",
        (("        if cos_o <= 0.0:\n            continue  # back side",
          "        if cos_o <= 0.0:\n"
          "            if light_pdf_area[p] > 0.0:  # area lights emit on both sides; NEE never samples the back\n"
          "                for c in range(3):\n"
          "                    L[path[i], c] += beta[i, c] * le[p, c]\n"
          "            continue  # back side"),
         ("cos_y = -(nrm[e, 0] * w0 + nrm[e, 1] * w1 + nrm[e, 2] * w2)",
          "cos_y = abs(nrm[e, 0] * w0 + nrm[e, 1] * w1 + nrm[e, 2] * w2)")),
    ),
)

BY_NAME = {m.name: m for m in MUTANTS}
assert len(BY_NAME) == len(MUTANTS), "mutant names must be unique"

#: Mutants whose bias is too small for the gate at its CI budget (power < 99% over seeds), as measured by
#: ``benchmarks/gate_power.py`` (docs/gate-detection.md): name -> why, and what catches them instead.
#: Empty since gate.toml has the furnace and light-panel expectations; before them, the Cornell box alone
#: missed cosine_pdf_mismatch (0.85 sd) and had power 0.2 on mis_pdf_area_measure.
LOW_POWER: dict[str, str] = {}
assert set(LOW_POWER) <= set(BY_NAME)

#: Mutants that once made a gate run never end (a NaN throughput survived Russian roulette, so in the
#: closed furnace the path bounced forever): tests and the benchmark run them in a child process with a
#: time limit, so a regression fails instead of hanging the suite.
ISOLATED = {"nan_throughput"}
assert ISOLATED <= set(BY_NAME)


def original_source() -> str:
    return SOURCE.read_text(encoding="utf-8")


def patched_source(mutant: Mutant | str, source: str | None = None) -> str:
    """The path tracer's source with ``mutant``'s patches; AssertionError if a patch does not apply exactly once."""
    m = BY_NAME[mutant] if isinstance(mutant, str) else mutant
    original = original_source() if source is None else source
    text = original
    for old, new in m.patches:
        count = text.count(old)
        assert count == 1, (f"mutant {m.name!r}: the snippet {old!r} occurs {count} times in {SOURCE.name} "
                            f"(expected exactly once); update tests/mutants.py to the refactored source")
        text = text.replace(old, new)
    assert text != original, f"mutant {m.name!r} does not change the source"
    return text


def module_name(name: str) -> str:
    return f"cbox_mutant_{name}"


def load_module(name: str, tmp_dir: str | Path):
    """Write the mutant's source to ``tmp_dir/cbox_mutant_<name>.py`` and import it (cached per process)."""
    mod_name = module_name(name)
    text = patched_source(name)
    path = Path(tmp_dir) / f"{mod_name}.py"
    loaded = sys.modules.get(mod_name)
    if loaded is not None and getattr(loaded, "__file__", None) == str(path) and path.exists() \
            and path.read_text(encoding="utf-8") == text:
        return loaded
    path.parent.mkdir(parents=True, exist_ok=True)
    # Rewrite only when the text changed: an unchanged file keeps its stamp, so numba's cache stays valid.
    if not path.exists() or path.read_text(encoding="utf-8") != text:
        path.write_text(text, encoding="utf-8")
    spec = importlib.util.spec_from_file_location(mod_name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[mod_name]
        raise
    return module


def load_mutant(name: str, tmp_dir: str | Path) -> RendererEntry:
    """A gate override: ``{"pathtracer": load_mutant(name, tmp_dir)}`` runs the mutant in place of ours."""
    module = load_module(name, tmp_dir)
    return RendererEntry("pathtracer", f"mutant:{name}", module.PathTracer(), None)


# -- running the gate on a mutant ----------------------------------------------------

GATE_TOML = SOURCE.parent.parent / "gate.toml"


def pathtracer_gate_config(path: str | Path = GATE_TOML):
    """The project's gate config (alpha, baseline, margins) with only its ``pathtracer`` expectations."""
    import dataclasses

    from harness.gate.config import load_config

    cfg = load_config(path)
    keep = [e for e in cfg.expectations if e.renderer == "pathtracer"]
    assert keep, f"{path}: no pathtracer expectation"
    return dataclasses.replace(cfg, expectations=keep)


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
    """Summarise the :class:`harness.gate.checks.Outcome` list of one :func:`harness.gate.run.run_gate` call."""
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
    from harness.scenes.library import resolve_scene

    cam = resolve_scene(exp.scene).camera
    return cam.width * cam.height * (exp.spp or 1)


def run_until_failure(cfg, overrides=None, seed_offset: int = 0) -> list:
    """The gate's expectations one by one, cheapest first, up to the first that fails.

    The gate fails as soon as one expectation fails, so this decides the same
    verdict as :func:`harness.gate.run.run_gate` over all of them, often for the
    price of the small scenes alone. Returns the outcomes it ran.
    """
    import dataclasses

    from harness.gate.run import run_gate

    outcomes = []
    for exp in sorted(cfg.expectations, key=cost):
        outcomes += run_gate(dataclasses.replace(cfg, expectations=[exp]), overrides, seed_offset)
        if not outcomes[-1].passed:
            break
    return outcomes


_CHILD = """
import dataclasses, json, sys
sys.path.insert(0, sys.argv[1])
import mutants
from harness.gate.run import run_gate
name, gate, work, until = sys.argv[2:6]
cfg = mutants.pathtracer_gate_config(gate)
entry = {"pathtracer": mutants.load_mutant(name, work)}
outcomes = mutants.run_until_failure(cfg, entry) if until == "1" else run_gate(cfg, entry)
v = mutants.verdict(outcomes)
print(json.dumps({**dataclasses.asdict(v), "checks": sorted(v.checks)}))
"""


def run_isolated(name: str, work: str | Path, timeout_s: float, gate: str | Path = GATE_TOML,
                 until_failure: bool = False) -> Verdict | None:
    """The gate on one mutant in a child process; None if it has not ended after ``timeout_s`` (killed)."""
    import json
    import subprocess

    cmd = [sys.executable, "-c", _CHILD, str(Path(__file__).resolve().parent), name, str(gate), str(work),
           "1" if until_failure else "0"]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, cwd=SOURCE.parent.parent)
    except subprocess.TimeoutExpired:
        return None
    if out.returncode:
        raise RuntimeError(f"the gate on mutant {name} crashed in its child process:\n{out.stderr[-3000:]}")
    d = json.loads(out.stdout.strip().splitlines()[-1])
    return Verdict(**{**d, "checks": set(d["checks"])})

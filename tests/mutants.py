"""Deliberately broken copies of our renderers, for measuring the CI gate's power.

Each :class:`Mutant` is a realistic bug in one of our renderers
(:data:`INTEGRATORS`: the path tracer, the photon mapper, SPPM), written as
exact source patches: an ``old`` snippet replaced by ``new`` in the
renderer's module (the integrator, e.g. ``renderers/pathtracer.py``) or in a
module of the toolkit it is built on (``renderers/core/``), wherever the
line now lives. :func:`load_mutant` writes the patched sources to real files
(so numba's ``cache=True`` has a locator) as uniquely named modules, imports
them, and returns a :class:`harness.adapters.registry.RendererEntry` named
after the renderer, which :func:`harness.gate.checks.run_gate` takes as an override.

A mutant is a set of modules: the integrator is ``cbox_mutant_<name>``; a
mutant that patches the toolkit gets a copy ``cbox_mutant_<name>__<stem>`` of
each core module ``renderers/core/<stem>.py`` but the scalar helpers
(:data:`SHARED_CORE`), patched or not, so no part of the renderer still sees
the unpatched code and no shared module is compiled for the copies' types;
their ``from renderers.core.<stem> import`` lines are pointed at the copies.

Every patch must apply exactly once: if a refactor moves or rewrites a
snippet, :func:`patched_sources` raises instead of silently testing an
unmutated renderer. The sources themselves are never modified.

Used by ``tests/test_gate_power.py`` and ``benchmarks/gate_power.py`` only.
"""

from __future__ import annotations

import importlib.util
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from harness.adapters.registry import RendererEntry

ROOT = Path(__file__).resolve().parent.parent
PATHTRACER = "renderers/pathtracer.py"
PHOTONMAP = "renderers/photonmap.py"
SPPM = "renderers/sppm.py"
SOURCE = ROOT / PATHTRACER
CORE = "renderers/core"
#: The renderers mutants are made of: registered name -> (integrator module, adapter class).
INTEGRATORS = {"pathtracer": (PATHTRACER, "PathTracer"), "photonmap": (PHOTONMAP, "PhotonMapper"),
               "sppm": (SPPM, "SPPM")}


class Patch(NamedTuple):
    old: str  # occurs exactly once in ``file``
    new: str
    file: str = PATHTRACER  # relative to the repository root


@dataclass(frozen=True)
class Mutant:
    name: str
    description: str  # the bug, as a developer would make it
    patches: tuple[Patch, ...]  # a patch without a file patches renderers/pathtracer.py
    renderer: str = "pathtracer"  # the registered renderer it is a copy of (INTEGRATORS)

    def __post_init__(self):
        object.__setattr__(self, "patches", tuple(Patch(*p) for p in self.patches))


MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "nee_missing_cos_x",
        "NEE geometry term written cos θ_y / r² (the receiver's cos θ_x dropped)",
        (("g = cos_x * cos_y / dist2 * w / pe", "g = cos_y / dist2 * w / pe"),),
    ),
    Mutant(
        "light_pdf_2pct",
        "light pdf 2% too high where NEE reads it (pe = light_pdf_area[e] * 1.02, e.g. a stale area table)",
        (("pe = sample_emitter(vertex_1d(key, j, depth, EMITTER_PICK), u[0], u[1], geo)\n",
          "pe = sample_emitter(vertex_1d(key, j, depth, EMITTER_PICK), u[0], u[1], geo)\n"
          "            pe = pe * 1.02\n"),),
    ),
    Mutant(
        "rr_no_compensation",
        "Russian roulette kills paths but survivors are not divided by the survival probability",
        (("        b0, b1, b2 = b0 / survive, b1 / survive, b2 / survive\n", "", f"{CORE}/roulette.py"),),
    ),
    Mutant(
        "mis_emitter_double",
        "emission found by BSDF-sampled rays weighted 1 instead of its MIS weight (emitter counted twice)",
        (("return 1.0 if pdf_bsdf == 0.0 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))",
          "return 1.0"),),
    ),
    Mutant(
        "camera_half_pixel",
        "pixel jitter recentred to [-0.5, 0.5) though camera_ray adds it to the pixel corner: "
        "image shifted half a pixel",
        (("camera_ray(basis, width, height, j % pixels, u, v)",
          "camera_ray(basis, width, height, j % pixels, u - 0.5, v - 0.5)", f"{CORE}/camera.py"),),
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
        (("b0, b1, b2 = beta[0] * f[0], beta[1] * f[1], beta[2] * f[2]",
          "b0, b1, b2 = 0.99 * beta[0] * f[0], 0.99 * beta[1] * f[1], 0.99 * beta[2] * f[2]", f"{CORE}/roulette.py"),),
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
        (("        set_path(rays, i, i, (1.0, 1.0, 1.0), 0.0)\n",
          "        px = j % pixels\n"
          "        r = math.hypot(px % width - width // 2, px // width - height // 2)\n"
          "        k1 = 0.0  # no radial distortion\n"
          "        weight = r * (1.0 + k1 * r * r) / r\n"
          "        set_path(rays, i, i, (weight, weight, weight), 0.0)\n", f"{CORE}/camera.py"),),
    ),
    Mutant(
        "shadow_tfar_past_light",
        "shadow-ray tfar lengthened (sl * (1 + 1e-3), a sign slip) so it reaches the emitter: "
        "the light occludes itself",
        (("sl * SHADOW_TFAR_REL, sl", "sl * (1.0 + 1e-3), sl", f"{CORE}/rays.py"),),
    ),
    Mutant(
        "mis_pdf_area_measure",
        "MIS weight of BSDF-found emission compares the cosine pdf (solid angle) with the light pdf "
        "left in area measure (no r²/cos θ_y conversion)",
        (("power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))", "power_heuristic(pdf_bsdf, pa)"),),
    ),
    Mutant(
        "offset_minus_n",
        "continuation-ray origin offset along −n instead of +n: the ray starts behind the surface "
        "and hits it from the back (self-intersection ends every path)",
        (("set_ray(nxt, nn, offset_origin(x, side, geo.offset), wi)",
          "set_ray(nxt, nn, offset_origin(x, side, -geo.offset), wi)"),),
    ),
    Mutant(
        "cosine_pdf_mismatch",
        "continuation ray's pdf recorded as uniform-hemisphere 1/(2π) though it is sampled cosine-weighted "
        "(MIS weights no longer sum to 1)",
        (("return True, (b0, b1, b2), bsdf_pdf(mat, cos_w)", "return True, (b0, b1, b2), 0.5 / 3.141592653589793",
          f"{CORE}/roulette.py"),),
    ),
    Mutant(
        "two_sided_emitter",
        "the one-sided area light made two-sided: emission found on its back side counted (and |cos θ_y| in "
        "NEE)",
        (("        if not (cos_o > 0.0 or (cos_o < 0.0 and two_sided(mat))):\n            continue  # back side",
          "        if not (cos_o > 0.0 or (cos_o < 0.0 and two_sided(mat))):\n"
          "            if geo.light_pdf_area[p] > 0.0:  # area lights emit on both sides; NEE never samples the back\n"
          "                for c in range(3):\n"
          "                    L[rays.path[i], c] += rays.beta[i, c] * geo.radiance[p, c]\n"
          "            continue  # back side"),
         ("return -(ny[0] * w[0] + ny[1] * w[1] + ny[2] * w[2])",
          "return abs(ny[0] * w[0] + ny[1] * w[1] + ny[2] * w[2])", f"{CORE}/lights.py")),
    ),
    # -- specular materials (mirror, glass) ------------------------------------------
    Mutant(
        "fresnel_schlick",
        "Schlick's approximation R0 + (1 - R0)(1 - cos θi)^5 in place of the exact Fresnel equations, with "
        "cos θi taken on whichever side the ray arrives (exact inside the glass needs cos θt)",
        (("        a_s = (eta_it * ct - ci) / (eta_it * ct + ci)\n"
          "        a_p = (eta_it * ci - ct) / (eta_it * ci + ct)\n"
          "        r = 0.5 * (a_s * a_s + a_p * a_p)\n",
          "        r0 = ((eta - 1.0) / (eta + 1.0)) ** 2\n"
          "        r = r0 + (1.0 - r0) * (1.0 - ci) ** 5 if cos_t_sqr > 0.0 else 1.0\n", f"{CORE}/bsdf.py"),),
    ),
    Mutant(
        "ior2_missing",
        "refracted radiance not scaled by (η_i/η_t)² (the weight of a transmission left at 1, as in "
        "importance transport)",
        (("return refract(wo, n, cos_o, cos_t, eta_ti), cos_t, eta_ti * eta_ti, True",
          "return refract(wo, n, cos_o, cos_t, eta_ti), cos_t, 1.0, True", f"{CORE}/bsdf.py"),),
    ),
    Mutant(
        "tir_absorbed",
        "total internal reflection treated as absorption: no refracted direction exists, so the sample is "
        "declared invalid and the path ends",
        (("    r, cos_t, eta_it, eta_ti = fresnel_dielectric(cos_o, eta)\n",
          "    r, cos_t, eta_it, eta_ti = fresnel_dielectric(cos_o, eta)\n"
          "    if cos_t == 0.0:\n"
          "        return (0.0, 0.0, 1.0), 0.0, 0.0, False  # no refracted ray\n", f"{CORE}/bsdf.py"),),
    ),
    Mutant(
        "nee_at_delta_vertex",
        "next-event estimation at every vertex, mirrors and glass included, with the BSDF evaluated as "
        "Lambertian whatever the material (delta lobes get direct light twice over)",
        (("if geo.emitter_ids.size > 0 and not is_delta(mat):", "if geo.emitter_ids.size > 0:"),
         ("    if material == LAMBERT:\n        return lambert_eval(rho, cos)\n    return 0.0\n",
          "    return lambert_eval(rho, cos)\n", f"{CORE}/bsdf.py"),
         ("    if material == LAMBERT:\n        return lambert_pdf(cos)\n    return 0.0\n",
          "    return lambert_pdf(cos)\n", f"{CORE}/bsdf.py")),
    ),
    Mutant(
        "mirror_reflectance_ignored",
        "the mirror's specular reflectance ignored: a perfect reflector (weight 1) whatever the scene says",
        (("return reflect(wo, n, cos_o), cos_o, rho, cos_o > 0.0",
          "return reflect(wo, n, cos_o), cos_o, (1.0, 1.0, 1.0), cos_o > 0.0", f"{CORE}/bsdf.py"),),
    ),
    Mutant(
        "delta_emission_mis_weighted",
        "emission found after a mirror or glass bounce MIS-weighted against light sampling that was never "
        "done there (the weight is 1 only for camera rays): caustics and mirrored lights vanish",
        (("return 1.0 if pdf_bsdf == 0.0 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))",
          "return 1.0 if depth == 1 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))"),
         ("def _emission_weight(pdf_bsdf, pa, t, cos_o) -> float:",
          "def _emission_weight(pdf_bsdf, pa, t, cos_o, depth) -> float:"),
         ("w = _emission_weight(rays.pdf[i], pa, t, cos_o)", "w = _emission_weight(rays.pdf[i], pa, t, cos_o, depth)")),
    ),
    # -- photon mapping (photonmap, sppm) ------------------------------------------------
    Mutant(
        "photon_power_not_divided",
        "photon flux not divided by the number of photons emitted (each photon carries the light's whole "
        "power)",
        (("    photons.power[:] /= max(emitted, 1)\n", "", f"{CORE}/photons.py"),),
        "photonmap",
    ),
    Mutant(
        "double_cosine",
        "density estimate weighted by the cosine of each photon's incidence, which its flux already counts",
        (("            w = kernel_weight(kernel, dist[i, a], r)\n",
          "            w = kernel_weight(kernel, dist[i, a], r) * cos_in\n", f"{CORE}/photon_map.py"),),
        "photonmap",
    ),
    Mutant(
        "caustic_photon_on_specular_surface",
        "caustic photons stored where they leave the last specular surface (the ray's origin) instead of "
        "where they land",
        (("                _store(out, ns, x, power, d, n, depth, caustic)\n",
          "                _store(out, ns, o if mode == STORE_CAUSTIC else x, power, d, n, depth, caustic)\n",
          f"{CORE}/photons.py"),),
        "photonmap",
    ),
    Mutant(
        "no_normal_test",
        "no normal test in the density estimate: photons on a wall count on the floor at their corner",
        (("            if cos_n < NORMAL_COS_MIN:\n                continue\n", "", f"{CORE}/photon_map.py"),),
        "photonmap",
    ),
    Mutant(
        "no_radius_shrinking",
        "SPPM's α left out of the photon-count update (N' = N + M): the radius never shrinks, and the image "
        "converges to a blurred one",
        (("        n_new = self.n[hit] + alpha * m[hit]\n", "        n_new = self.n[hit] + m[hit]\n", SPPM),),
        "sppm",
    ),
    Mutant(
        "sppm_power_not_divided",
        "SPPM's gathered flux not divided by the iteration's photon count",
        (("            phi /= photons\n", "", SPPM),),
        "sppm",
    ),
)

BY_NAME = {m.name: m for m in MUTANTS}
assert len(BY_NAME) == len(MUTANTS), "mutant names must be unique"

#: Mutants whose bias is too small for the gate at its CI budget (power < 99% over seeds), as measured by
#: ``benchmarks/gate_power.py`` (docs/gate-detection.md): name -> why, and what catches them instead.
#: None of the path tracer's since gate.toml has the furnace and light-panel expectations; before them, the
#: Cornell box alone missed cosine_pdf_mismatch (0.85 sd) and had power 0.2 on mis_pdf_area_measure.
LOW_POWER: dict[str, str] = {
    "no_normal_test": "the density estimate's incoming-side test rejects most of what the normal test does (a "
                      "wall photon that came from the floor arrived from below the floor's plane); what is left, "
                      "wall photons that came from above both surfaces, reaches pixels only through final "
                      "gathering (diluted) or the caustic map (sparse on walls): in every region of the stored scenes the two differ by less than the "
                      "seed-to-seed spread, and in a corner made for it (a low panel lighting a wall head-on) "
                      "by 0 with gather_rays = 0 and 0.6% of the corner's radiance with 1; caught by "
                      "tests/test_photons.py::test_normal_test_keeps_wall_photons_off_the_floor",
}
assert set(LOW_POWER) <= set(BY_NAME)

#: Mutants that once made a gate run never end (a NaN throughput survived Russian roulette, so in the
#: closed furnace the path bounced forever): tests and the benchmark run them in a child process with a
#: time limit, so a regression fails instead of hanging the suite.
ISOLATED = {"nan_throughput"}
assert ISOLATED <= set(BY_NAME)


#: Core modules every mutant shares with the real renderer: scalar helpers, no types of their own.
SHARED_CORE = ("sampling", "rng")


def integrator(mutant: Mutant | str) -> str:
    """The file of the renderer module a mutant is a copy of (``renderers/pathtracer.py``, ...)."""
    m = BY_NAME[mutant] if isinstance(mutant, str) else mutant
    return INTEGRATORS[m.renderer][0]


def original_source(renderer: str = "pathtracer") -> str:
    """The source of a renderer's integrator module (default ``renderers/pathtracer.py``)."""
    return (ROOT / INTEGRATORS[renderer][0]).read_text(encoding="utf-8")


def module_name(name: str, file: str = PATHTRACER) -> str:
    """The mutant's module for ``file``: ``cbox_mutant_<name>`` for its integrator, ``..__<stem>`` for core."""
    return f"cbox_mutant_{name}__{Path(file).stem}" if file.startswith(f"{CORE}/") else f"cbox_mutant_{name}"


def _core_module(file: str) -> str:
    return file[: -len(".py")].replace("/", ".")


def _imports(text: str, module: str) -> bool:
    return re.search(rf"^\s*from {re.escape(module)} import ", text, re.M) is not None


def _redirect(text: str, module: str, to: str) -> str:
    return re.sub(rf"^(\s*from ){re.escape(module)}( import )", rf"\g<1>{to}\g<2>", text, flags=re.M)


def patched_sources(mutant: Mutant | str, sources: dict[str, str] | None = None) -> dict[str, str]:
    """Every module of the mutant: {file it replaces: patched text with imports redirected to the copies}.

    ``sources`` overrides the text of some files (default: read from the
    repository). AssertionError if a patch does not apply exactly once, or
    if the mutant changes nothing.
    """
    m = BY_NAME[mutant] if isinstance(mutant, str) else mutant
    sources = dict(sources or {})

    def read(file: str) -> str:
        if file not in sources:
            sources[file] = (ROOT / file).read_text(encoding="utf-8")
        return sources[file]

    top = integrator(m)
    texts = {top: read(top)}
    for p in m.patches:
        text = texts.get(p.file, read(p.file))
        count = text.count(p.old)
        assert count == 1, (f"mutant {m.name!r}: the snippet {p.old!r} occurs {count} times in {p.file} "
                            f"(expected exactly once); update tests/mutants.py to the refactored source")
        texts[p.file] = text.replace(p.old, p.new)
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
                   if not any(_imports(text, d) for d in pending if d != k))
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
    return RendererEntry(renderer, f"mutant:{name}", getattr(module, INTEGRATORS[renderer][1])(), None)


# -- running the gate on a mutant ----------------------------------------------------

GATE_TOML = SOURCE.parent.parent / "gate.toml"


def gate_config(renderer: str, path: str | Path = GATE_TOML):
    """The project's gate config (alpha, baseline, margins) with only ``renderer``'s expectations."""
    import dataclasses

    from harness.gate.config import load_config

    cfg = load_config(path)
    keep = [e for e in cfg.expectations if e.renderer == renderer]
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

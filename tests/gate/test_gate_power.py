"""The CI gate neither flakes on our path tracer nor misses real bugs in it.

Both run the gate's own ``pathtracer`` expectations of ``gate.toml`` (their
scenes, spp, seeds, tiles, α and baseline; the other renderers'
expectations are left out) through :func:`cornell_harness.gate.run.run_gate`.

- **Power**: each mutant of ``tests/mutants/`` (a realistic bug patched
  into a copy of ``src/cornell_harness/renderers/pathtracer.py``) must fail the gate at the CI
  budget, on an agreement test or a finite check (the baseline checks alone
  do not count: a baseline re-recorded from a buggy renderer would hide the
  bug). The gate fails as soon as one expectation fails, so the
  expectations run cheapest first and stop at the first failure
  (:func:`mutants.run_until_failure`). A mutant that once hung the gate
  (``mutants.ISOLATED``) runs in a child process with a time limit;
  mutants the gate cannot fail (``mutants.LOW_POWER``: ``no_normal_test``)
  are listed as expected failures with the reason, not run.
- **False alarms**: the unmutated path tracer passes the whole gate at the
  CI seeds, and its statistical checks at :data:`SEEDS` seed offsets, at
  most one false alarm; baseline checks run only at the baseline's seeds.

Every render is a pure function of its seed (bit-identical on any thread
count), so each verdict here is reproducible; the rates in the docstrings
say how often a correct gate would fail such a test over fresh seeds.
``benchmarks/gate_power.py`` makes the full measurement (every mutant on
every expectation, 20 seeds, effect sizes): see ``docs/gate-detection.md``.
"""

from __future__ import annotations

import ast
import dataclasses

import numpy as np
import pytest
from scipy.stats import binom, norm

from tests import mutants
from cornell_harness.gate.run import run_gate

pytest.importorskip("embreex")

#: Seed offsets for the false-alarm tests: 0 (the CI seeds themselves) .. 4.
SEEDS = 5
#: Time limit of a mutants.ISOLATED mutant's gate run, only a guard against the hang it once caused: the run
#: takes ~10-20 s on a quiet machine (a numba compile of the copied toolkit, then the small scenes catch it),
#: several times that on a busy one (two CPU burners, a shared CI runner), never near this.
ISOLATED_TIMEOUT_S = 300


@pytest.fixture(scope="module")
def cfg():
    return mutants.pathtracer_gate_config()


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("mutants")


# -- the catalogue --------------------------------------------------------------------

def _outside(text: str, spans: list[tuple[int, int]]) -> list[str]:
    """The text of ``text`` around the given line spans (1-based, inclusive, in order): one piece more than spans."""
    lines, pieces, at = text.splitlines(keepends=True), [], 0
    for first, last in spans:
        pieces.append("".join(lines[at:first - 1]))
        at = last
    return pieces + ["".join(lines[at:])]


def test_catalogue_applies_and_changes_only_the_named_functions():
    """Every mutant applies to today's sources, and each file it patches differs from the original only inside the
    functions its patches name: every other line is kept byte for byte, in order, and each named function's syntax
    tree changes (the patched copy is still Python)."""
    assert len(mutants.MUTANTS) >= 8
    for m in mutants.MUTANTS:
        assert m.description
        for file, names in mutants.named_functions(m.patches).items():
            original = (mutants.ROOT / file).read_text(encoding="utf-8")
            patched = mutants.patched_file(m, file)
            before, after = ast.parse(original), ast.parse(patched, f"{m.name}:{file}")
            pieces = _outside(original, sorted(mutants.span(mutants.find_function(before, f)) for f in names))
            assert patched.startswith(pieces[0]) and patched.endswith(pieces[-1]), f"{m.name}: {file}"
            rest = patched[len(pieces[0]):len(patched) - len(pieces[-1])]
            for piece in pieces[1:-1]:  # the text between two named functions
                assert piece in rest, f"{m.name}: {file} changed between {sorted(names)}"
                rest = rest[rest.index(piece) + len(piece):]
            for f in names:
                assert ast.dump(mutants.find_function(after, f)) != ast.dump(mutants.find_function(before, f)), \
                    f"{m.name}: {f} in {file} unchanged"


DEMO = '''import math


def other(a, b):
    x = a + b  # the same code as in kernel: left alone
    return x


@decorate
def kernel(a, b):
    """Docstring,
    on two lines."""
    x = (a +
         b)  # written over two lines
    return math.sqrt(x) * x


class Box:
    def area(self, w, h):
        return w * h
'''


def _demo(patch) -> str:
    return mutants.apply_patch(DEMO, patch, "demo")


def test_catalogue_edit_matches_syntax_inside_its_function_only():
    """An Edit matches the code's syntax tree (formatting and comments do not matter), only inside the function it
    names; the function is written out again over its own lines, decorators and docstring kept, the rest of the
    file byte for byte; an Edit of statements replaces, inserts or deletes them."""
    out = _demo(mutants.Edit("kernel", "a + b", "a - b", "demo.py"))
    assert "    x = a - b\n" in out and "    x = a + b  # the same code as in kernel: left alone\n" in out
    assert '@decorate\ndef kernel(a, b):\n    """Docstring,\n    on two lines."""\n' in out
    head, tail = DEMO.split("@decorate")[0], DEMO.split("return math.sqrt(x) * x\n")[1]
    assert out.startswith(head) and out.endswith(tail)
    out = _demo(mutants.Edit("Box.area", "return w * h", "w = w + 1\nreturn w * h", "demo.py"))
    assert "    def area(self, w, h):\n        w = w + 1\n        return w * h\n" in out
    out = _demo(mutants.Edit("other", "x = a + b", "", "demo.py"))
    assert "def other(a, b):\n    return x\n" in out


def test_catalogue_replace_and_wrap_a_named_function():
    """A Replace keeps the original's decorators; a Wrap decorates the function with the wrapper, outermost, and
    leaves no name behind."""
    out = _demo(mutants.Replace("kernel", "def kernel(a, b):\n    return 0.0", "demo.py"))
    assert "@decorate\ndef kernel(a, b):\n    return 0.0\n" in out
    out = _demo(mutants.Wrap("Box.area", "def wrap(f):\n    return lambda self, w, h: 2 * f(self, w, h)", "demo.py"))
    namespace = {"decorate": lambda f: f}
    exec(compile(out, "demo", "exec"), namespace)
    box = namespace["Box"]
    assert box().area(2, 3) == 12 and not [k for k in vars(box) if "wrap" in k] and "_mutant_wrap_area" not in namespace


@pytest.mark.parametrize("patch, error", [
    (mutants.Edit("kernel", "a * b", "a - b", "demo.py"), r"'a \* b' occur\(s\) 0 times in the function"),
    (mutants.Edit("kernel", "x", "y", "demo.py"), r"'x' occur\(s\) 2 times in the function"),
    (mutants.Edit("gone", "a + b", "a - b", "demo.py"), "0 definitions of 'gone'"),
    (mutants.Edit("Box.volume", "w * h", "w", "demo.py"), r"0 definitions of 'volume' \(of 'Box.volume'\)"),
    (mutants.Replace("kernel", "def other(a, b):\n    return 0", "demo.py"), "one def named 'kernel'"),
    (mutants.Edit("kernel", "a + b", "(a + b)  # the same", "demo.py"), "the patch does not change the function"),
    (mutants.Edit("kernel", "a +", "a - b", "demo.py"), "'a \\+' is not Python"),
], ids=["absent", "twice", "no-function", "no-method", "replace-renames", "no-change", "not-python"])
def test_catalogue_patch_that_does_not_apply_once_fails_loudly(patch, error):
    """A patch whose function is gone, or whose code is not in it exactly once, raises, naming the mutant and the
    function: a refactor breaks the catalogue loudly instead of testing an unmutated renderer. So does a patch that
    changes nothing, or is not Python."""
    with pytest.raises(AssertionError, match=f"mutant 'demo', {patch.function} in demo.py: .*{error}"):
        _demo(patch)


def test_load_mutant_imports_a_renderer_from_a_real_file(work):
    entry = mutants.load_mutant("swap_rb", work)
    module = type(entry.renderer).__module__
    assert (entry.name, entry.spec, entry.available) == ("pathtracer", "mutant:swap_rb", True)
    assert module == "cbox_mutant_swap_rb" and (work / f"{module}.py").read_text() == \
        mutants.patched_source("swap_rb")


def test_probes_mutants_patch_a_copy_of_ddgi_that_the_integrator_imports():
    """A patch in src/cornell_harness/renderers/ddgi.py (neither an integrator nor core) gets its own copy, with the toolkit's, and
    probes.py's ``from cornell_harness.renderers import ddgi`` is pointed at it; an import form the machinery cannot redirect
    fails loudly instead of leaving the copy on the unpatched module."""
    name = "chebyshev_inverted"
    texts = mutants.patched_sources(name)
    top, helper = texts[mutants.PROBES], texts[mutants.DDGI]
    assert mutants.module_name(name, mutants.DDGI) == f"cbox_mutant_{name}__ddgi"
    assert f"import cbox_mutant_{name}__ddgi as ddgi\n" in top and "from cornell_harness.renderers import ddgi" not in top
    assert "if r < mean:" in helper and f"from cbox_mutant_{name}__octahedral import " in helper
    assert f"from cbox_mutant_{name}__visible_points import " in top  # the toolkit copied too (but SHARED_CORE)
    assert mutants.imports_module(top, f"cbox_mutant_{name}__ddgi")
    source = mutants.original_source("probes").replace("from cornell_harness.renderers import ddgi\n",
                                                       "from cornell_harness.renderers import ddgi, core\n")
    with pytest.raises(AssertionError, match="does not redirect"):
        mutants.patched_sources(name, {mutants.PROBES: source})


# -- power -----------------------------------------------------------------------------

#: Mutants that only the caustics expectation shows: the gate detects them after rendering every cheaper
#: expectation (~80 s each in the suite), so their gate test is slow; by default the unit tests that pin the
#: same code catch them (tests/renderers/core/test_bsdf.py: Fresnel against the closed form; tests/renderers/test_specular.py: a
#: coloured mirror).
SLOW_MUTANTS = {"fresnel_schlick": "tests/renderers/core/test_bsdf.py", "mirror_reflectance_ignored": "tests/renderers/test_specular.py",
                # Photon mutants: 23-44 s each in the gate (a numba compile of the copied toolkit, then a
                # photon expectation; measured), so slow; tests/renderers/test_photons.py catches each by default (flux
                # conservation, the furnaces, the caustic map's contents, SPPM's radius).
                **{m.name: "tests/renderers/test_photons.py" for m in mutants.MUTANTS if m.renderer in ("photonmap", "sppm")},
                # AO mutants: a compile of the copied toolkit each; tests/renderers/test_ao.py catches each by default.
                **{m.name: "tests/renderers/test_ao.py" for m in mutants.MUTANTS if m.renderer == "ao"},
                "ambient_not_occluded": "tests/renderers/test_ambient.py",
                # Probe mutants: a compile of the copied toolkit and ddgi each (25-40 s in the gate, measured
                # 2026-12-02); each fails tests/renderers/test_probes.py when patched in (checked): chebyshev_inverted its
                # two-rooms leak test (dark/lit 0.18, budget 0.002), irradiance_not_cosine_weighted its half-space
                # sky blend, probe_index_off_by_one its lookup at a probe and between two.
                **{m.name: "tests/renderers/test_probes.py" for m in mutants.MUTANTS if m.renderer == "probes"},
                # The six costliest path tracer ones in the suite (21-23 s each, measured 2026-12-01), slow to
                # keep the suite within its time: each was checked to fail these unit tests when patched in.
                "two_sided_emitter": "tests/renderers/test_pathtracer.py", "camera_half_pixel": "tests/renderers/test_pathtracer.py",
                "swap_rb": "tests/renderers/test_pathtracer.py", "nee_at_delta_vertex": "tests/renderers/test_specular.py",
                "ior2_missing": "tests/renderers/test_specular.py", "tir_absorbed": "tests/renderers/test_specular.py",
                # Two more (15-16 s each, measured 2026-12-02) when the AO tests joined the suite; both fail
                # tests/renderers/test_pathtracer.py::test_white_furnace when patched in (checked).
                "energy_loss_1pct": "tests/renderers/test_pathtracer.py", "shadow_tfar_past_light": "tests/renderers/test_pathtracer.py",
                # Three more (13-17 s each, measured 2026-12-02) when the probes joined the suite; each fails
                # tests/renderers/test_pathtracer.py::test_white_furnace when patched in (checked: NaN, and the albedo 0.5
                # furnace off by 7% and 5%).
                "nan_throughput": "tests/renderers/test_pathtracer.py", "cosine_pdf_mismatch": "tests/renderers/test_pathtracer.py",
                "rr_no_compensation": "tests/renderers/test_pathtracer.py",
                # Denoiser mutants: 12-20 s each in the gate (measured 2026-12-02); oidn_aux_not_prefiltered runs
                # by default; each of these fails tests/renderers/test_oidn.py when patched in (checked): the flat HDR image
                # and every checkpoint denoised.
                "oidn_ldr": "tests/renderers/test_oidn.py", "oidn_checkpoints_not_denoised": "tests/renderers/test_oidn.py",
                # 13 s in the gate (furnace-glass catches it; measured 2026-12-03 beside a benchmark); it fails
                # tests/renderers/test_specular.py::test_specular_furnace[0.5] when patched in (checked: the glass
                # sphere's pixels z = -12.7, the glass cube's -13.0, against 4.10).
                "caustic_95": "tests/renderers/test_specular.py",
                # The hero path tracer's (issue 33): a toolkit copy's hero kernels compile, then a 256-spp hero render
                # of cornell-box-measured (~45 s each); each fails the spectral furnace (test_mutant_is_caught).
                **{name: "tests/renderers/test_hero_wavelength.py" for name in mutants.SPECTRAL}}


def _params() -> list:
    out = []
    for m in mutants.MUTANTS:
        marks = [pytest.mark.slow] if m.name in SLOW_MUTANTS else []
        if m.name in mutants.LOW_POWER:
            marks += [pytest.mark.xfail(reason=f"the gate cannot fail it: {mutants.LOW_POWER[m.name]}",
                                       run=False)]
        out.append(pytest.param(m.name, marks=marks, id=m.name))
    return out


#: Mutants that misreport the variance of a correct image, and what the variance check's message says of them.
VARIANCE_MUTANTS = {"variance_understated_4x": "× too little over the whole image",
                    "variance_overstated_4x": "× too much over the whole image"}


#: Photon-mapper mutants whose bias only the bias limit sees (issue 29): within every budget of gate.toml (photon_flux_98
#: moves the caustic -2.2% against 5%, the image -0.6% against 1%; sppm_flux_added_after_shrink the image +0.93% against
#: 1%, measured at the gate's seeds), so the bias_limit check must be among the failing ones.
BIAS_LIMIT_MUTANTS = {"photon_flux_98", "sppm_flux_98", "sppm_flux_added_after_shrink"}


@pytest.mark.parametrize("name", _params())
def test_gate_detects_mutant(work, name):
    """The gate fails the mutant at the CI budget: for an unbiased renderer on an agreement test or a
    finite check; for a biased one (photon mapping) on a budget or consistency check.

    Not a false-alarm question: every mutant run here has a bias of at least
    30 standard deviations on its most affected test of the gate (a NaN: a
    certainty), so the gate's power on it is > 0.999 for any seed
    (docs/gate-detection.md), except ``caustic_95`` (slow): 7.9 sd on the
    caustics scene's whole image, power 1.000 to three places; the verdict at
    the gate's fixed seeds is reproducible. The exceptions are BIAS_LIMIT_MUTANTS,
    caught only by the bias limit's t-test over 8 seeds, whose power over seed
    sets benchmarks/biased_gate.py measures (docs/gate-detection.md, "Biased
    renderers"); at the gate's seeds they fail it.
    """
    if name in mutants.ISOLATED:  # it once hung the gate: a child process, killed after the time limit
        v = mutants.run_isolated(name, work, ISOLATED_TIMEOUT_S, until_failure=True)
        assert v is not None, f"the gate run on {name} did not end in {ISOLATED_TIMEOUT_S} s"
    else:
        renderer = mutants.BY_NAME[name].renderer
        config = mutants.gate_config(renderer, spectral=name in mutants.SPECTRAL)
        outcomes = mutants.run_until_failure(config, {renderer: mutants.load_mutant(name, work)})
        assert all(o.record.status == "ok" for o in outcomes), [o.record.reason for o in outcomes]
        v = mutants.verdict(outcomes)
    assert not v.passed, f"the gate missed {name}: {mutants.BY_NAME[name].description}; smallest p = {v.p_min:.3g}"
    if name in VARIANCE_MUTANTS:  # the image is the clean one: only the variance check can see it
        assert "variance" in v.checks and VARIANCE_MUTANTS[name] in v.evidence, f"{name}: {v.failing}: {v.evidence}"
    elif name in BIAS_LIMIT_MUTANTS:
        assert any(c.startswith("bias_limit.") for c in v.checks), f"{name} fails only {v.failing}: {v.evidence}"
    elif mutants.BY_NAME[name].renderer == "pathtracer":
        assert {"agreement", "finite"} & v.checks, f"{name} fails only {v.failing}: {v.evidence}"
    else:  # a re-recorded baseline would hide a bug: a budget or consistency check must fail
        assert {c for c in v.checks if not c.startswith("baseline.")}, f"{name} fails only {v.failing}"


# -- false alarms ------------------------------------------------------------------------

#: The checks with a stated false-alarm rate: agreement, variance and outliers share the expectation's alpha.
STATISTICAL = {"agreement", "variance", "outliers", "finite"}


@pytest.fixture(scope="module")
def clean_run(cfg):
    """The unmutated path tracer through the gate at its own seeds (offset 0): its outcomes."""
    # In this process (no time limit): the same images as the sandboxed CLI gate (test_gate.py checks so).
    return run_gate(cfg, sandbox=False)


@pytest.fixture(scope="module")
def clean_runs(cfg, clean_run):
    """The unmutated path tracer through the gate at seed offsets 0 .. SEEDS-1: {offset: outcomes}."""
    return {0: clean_run} | {off: run_gate(cfg, seed_offset=off, sandbox=False) for off in range(1, SEEDS)}


def _failing(outcomes, which) -> list[str]:
    return [f"{o.expectation.name}: {c.message}" for o in outcomes for c in o.checks if not c.passed and which(c.name)]


def test_unmutated_path_tracer_passes_the_gate_at_its_seeds(clean_run):
    """At the CI seeds (offset 0) every check passes, the baseline checks included (what CI runs)."""
    assert not _failing(clean_run, lambda name: True)


@pytest.mark.slow
def test_unmutated_path_tracer_few_false_alarms_over_seeds(cfg, clean_runs):
    """At most one of SEEDS = 5 seed offsets fails a statistical check (agreement or finite).

    Each expectation's statistical checks share a family-wise false-alarm
    rate α = 0.01, so a gate run of E = 5 expectations fails with
    probability at most 1 - 0.99^5 = 0.049, and a correct gate fails this
    test with probability P(Binomial(5, 0.049) ≥ 2) = 0.022. With these
    fixed seeds it passes (see docs/gate-detection.md for 20 seeds).
    """
    alarms = {off: f for off, outcomes in clean_runs.items() if (f := _failing(outcomes, STATISTICAL.__contains__))}
    per_run = 1.0 - (1.0 - cfg.alpha) ** len(cfg.expectations)
    assert binom.sf(1, SEEDS, per_run) < 0.025, "gate.toml changed: update the rate this docstring states"
    assert len(alarms) <= 1, alarms


@pytest.mark.slow
def test_unmutated_path_tracer_no_baseline_alarms_at_other_seeds(clean_runs):
    """Baselines compare like with like: at seeds other than the baseline's, no baseline check runs.

    (At other seeds a metric's spread can exceed the 5% margin: the small
    scenes' trimmed relMSE moves by ~10% between seeds.)
    """
    for off, outcomes in clean_runs.items():
        names = [c.name for o in outcomes for c in o.checks if c.name.startswith("baseline.")]
        assert (off == 0) == bool(names), (off, names)


def test_unmutated_path_tracer_region_means_within_noise_on_caustics(clean_run):
    """On cornell-box-caustics at the gate's budget and seed, every named region's mean agrees with the reference.

    Per region (caustic, glass-shadow, mirror, glass, walls), ``mean_z`` is the
    z-score of the region's mean difference from the reference given both
    variances (cornell_harness.evaluate.regions). Two-sided, α = 1e-3 family-wise
    over the regions (Šidák), so a correct path tracer fails this with
    probability 1e-3. Region means average 147 to 34406 pixels × 256
    samples, so the central limit theorem holds for them even where single
    pixels are skewed (the caustic).
    """
    rows = {0: next(o for o in clean_run if o.expectation.scene == "cornell-box-caustics").record.regions}
    n = sum(len(r) for r in rows.values())
    crit = norm.isf((1.0 - (1.0 - 1e-3) ** (1.0 / n)) / 2.0)
    assert {"caustic", "glass-shadow", "mirror", "glass", "walls"} <= set(rows[0])
    worst = max(((abs(m["mean_z"]), off, name) for off, r in rows.items() for name, m in r.items()))
    assert worst[0] < crit, (worst, crit)


def test_a_caustic_five_percent_dark_fails_the_gate_on_its_region(cfg, clean_run):
    """Issue 29's case: the clean path tracer's caustic written ×0.95 (its variance ×0.95²) fails the agreement test.

    The gate's own render (cornell-box-caustics, 512 spp, seed 0) re-checked, so no rendering here. Before region
    tests the 147 caustic pixels fell across two 16×16 tiles and the smallest p was 5.7e-6 against the level
    4.35e-6 (a pass); as a region of the agreement test it is z = −5.3 (measured 2026-12-03), beyond the level's
    4.6. Over fresh seeds the test has power 0.98 on this error (docs/gate-detection.md, Results); at this seed
    the verdict is reproducible.
    """
    from cornell_harness.evaluate.regions import region_masks
    from cornell_harness.gate.checks import evaluate
    from cornell_harness.scenes.library import resolve_scene
    from cornell_harness.store.references import load_reference

    outcome = next(o for o in clean_run if o.expectation.scene == "cornell-box-caustics")
    scene = resolve_scene("cornell-box-caustics")
    masks = region_masks(scene)
    rec = outcome.record
    factor = np.where(masks["caustic"][..., None], 0.95, 1.0)
    dark = dataclasses.replace(rec, image=rec.image * factor,
                               variance=None if rec.variance is None else rec.variance * factor ** 2)
    checks = {c.name: c for c in evaluate(outcome.expectation, dark, load_reference(scene), cfg, None, None,
                                          masks).checks}
    assert outcome.passed and not checks["agreement"].passed, checks["agreement"].message
    assert "region caustic" in checks["agreement"].message, checks["agreement"].message

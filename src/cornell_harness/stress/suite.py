"""``cbox stress``: numerical stability at the extremes.

A suite of scene variants, each pushing one thing to an extreme
(:mod:`cornell_harness.stress.variants`: the table of variants, their spp and bounds,
and what the first full run found). Every renderer that is available and
models the variant's features (:func:`cornell_harness.adapters.registry.missing_features`)
renders it once, seed :data:`~cornell_harness.stress.variants.SEED`, **in a process
of its own** (:mod:`cornell_harness.workflows.sandbox`), so that the run can be timed,
its memory measured, and the process killed at either bound. One row per
(variant, renderer); a row passes when every check passes
(:mod:`cornell_harness.stress.judge`): finite, non-negative pixels; wall time and
peak memory within the variant's bounds; mean radiance within the tolerance
of the expected value (:mod:`cornell_harness.stress.expectations`: the analytic
furnace value, the stored reference, or a variant reference the suite renders
itself, each with its noise model); linearity in the emitted radiance for
radiance-1e6.

This module runs the suite: it plans which (variant, renderer) pairs run and
which are skipped, renders a variant reference only when a row needs it,
judges every run, and writes ``stress.csv``. The HTML report
(``cornell_harness.reports.stress``) is written by the CLI from the table and provenance
this module returns.

The suite for our path tracer and Mitsuba takes 1.5-2 minutes on a 2-core
machine. Entry points: :func:`run_stress` (the table), :func:`run_suite`
(``cbox stress``: ``stress.csv``, provenance) and
:func:`print_summary` (the table as text, the exit code).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from cornell_harness.adapters.api import attribute
from cornell_harness.scenes.model import Scene
from cornell_harness.stress.expectations import Z_CRIT, Expectation, expectation_for
from cornell_harness.stress.judge import COLUMNS, STATUSES, fmt_value, judge_run, new_row
from cornell_harness.workflows.sandbox import SandboxOutcome, run_sandboxed
from cornell_harness.stress.variants import REFERENCE_BATCHES, REFERENCE_SEED, SEED, Variant, cornell_scene, select_variants

Progress = Callable[[int, int, str], None]


@dataclass
class _Counter:
    """Runs done out of ``total``, reported to ``progress`` as the suite starts (0 done) and after each process
    ends."""

    total: int
    progress: Progress | None
    done: int = 0

    def __post_init__(self) -> None:
        if self.progress:
            self.progress(0, self.total, "")

    def tick(self, label: str) -> None:
        self.done += 1
        if self.progress:
            self.progress(self.done, self.total, label)


def run_stress(renderer_specs: list[str] | None, variants: list[str] | None = None,
               progress: Progress | None = None, reference_renderer: str | None = None,
               time_limit_s: float | None = None):
    """Run the stress variants on the renderers; a pandas DataFrame, one row per (variant, renderer).

    ``renderer_specs``: registered names or ``module:Class`` (None: every
    registered renderer); ``variants``: names from
    :data:`~cornell_harness.stress.variants.VARIANTS` (None: all; an unknown name
    raises ValueError). ``progress(done, total, label)`` is called as the runs
    start (``done`` 0) and after each process ends. ``reference_renderer`` (a registered name or ``module:Class``;
    the CLI's is Mitsuba) renders the variant references; None: they are not
    rendered and those rows say so. ``time_limit_s`` replaces every variant's time bound (the time a render
    is ended at and judged by). Columns: :data:`~cornell_harness.stress.judge.COLUMNS`; ``status``
    is pass, fail, skipped (unavailable, or does not model a feature) or
    error (the renderer raised, or gave an image of the wrong shape).
    """
    import pandas as pd

    from cornell_harness.adapters.registry import resolve

    chosen = [v if time_limit_s is None else dataclasses.replace(v, time_bound_s=time_limit_s)
              for v in select_variants(variants)]
    entries = resolve(renderer_specs)
    plan = _plan(chosen, entries)
    needs_ref = {v.name for v, _, cells in plan if v.expected == "variant-reference"
                 and any(why is None and _checks_mean(e) for e, why in cells)}
    ref_entry, ref_why = _reference_entry(entries, reference_renderer) if needs_ref else (None, None)
    total = sum(why is None for _, _, cells in plan for _, why in cells)
    counter = _Counter(total + (len(needs_ref) if ref_entry is not None else 0), progress)
    stored: list = []  # the stored reference, loaded when a variant first needs it
    rows = []
    for v, scene, cells in plan:
        exp = _expectation(v, scene, stored, ref_entry if v.name in needs_ref else None, ref_why, counter,
                           reference_renderer)
        rows += _run_cells(v, scene, cells, exp, counter)
    return pd.DataFrame(rows, columns=list(COLUMNS))


def _plan(chosen: Sequence[Variant], entries) -> list[tuple[Variant, Scene, list]]:
    """Each variant's scene and its (renderer entry, why it is skipped or None) cells."""
    from cornell_harness.adapters.registry import missing_features

    plan = []
    for v in chosen:
        scene = v.build()
        cells = []
        for e in entries:
            if not e.available:
                cells.append((e, f"unavailable: {e.reason}"))
            elif missing := missing_features(e.renderer, scene):
                cells.append((e, f"does not model {', '.join(missing)}"))
            else:
                cells.append((e, None))
        plan.append((v, scene, cells))
    return plan


def _checks_mean(entry) -> bool:
    return not attribute(entry.renderer, "approximations")


def _reference_entry(entries, name: str | None) -> tuple[object | None, str | None]:
    """(the reference renderer ``name``'s entry, None), or (None, why it cannot render variant references)."""
    from cornell_harness.adapters.registry import RendererError, resolve

    if name is None:
        return None, "no reference renderer was given"
    ref_entry = next((e for e in entries if name in (e.name, e.spec)), None)
    if ref_entry is None:
        try:
            (ref_entry,) = resolve([name])
        except RendererError as e:
            return None, str(e)
    if not ref_entry.available:
        return None, f"{name} is unavailable: {ref_entry.reason}"
    return ref_entry, None


def _expectation(v: Variant, scene: Scene, stored: list, ref_entry, ref_why: str | None,
                 counter: _Counter, reference_renderer: str | None) -> Expectation:
    """The variant's expectation, loading the stored reference or rendering the variant reference if needed."""
    if v.expected == "reference" and not stored:
        from cornell_harness.store.references import load_reference

        stored.append(load_reference(cornell_scene()))
    outcome: SandboxOutcome | None = None
    if v.expected == "variant-reference" and ref_entry is not None:
        seeds = [REFERENCE_SEED + b for b in range(REFERENCE_BATCHES)]
        outcome = run_sandboxed(ref_entry.spec, [(scene, v.reference_spp, s) for s in seeds],
                                2.0 * v.time_bound_s, v.rss_bound_mb)
        counter.tick(f"{v.name}: {ref_entry.name} reference")
    return expectation_for(v, scene, stored[0] if stored else None, outcome, ref_why or "not needed",
                           reference_renderer or "the reference renderer")


def _run_cells(v: Variant, scene: Scene, cells: list, exp: Expectation, counter: _Counter) -> list[dict]:
    """The rows of one variant: each renderer run in the sandbox and judged, or skipped."""
    rows = []
    for e, why in cells:
        if why is not None:
            rows.append(new_row(v, e.name, scene, "skipped", why))
            continue
        renders = [(scene, v.spp, SEED)]
        if v.linearity:  # the same seed's unscaled render, for the linearity check
            renders.append((cornell_scene().with_resolution(scene.camera.width, scene.camera.height),
                            v.spp, SEED))
        outcome = run_sandboxed(e.spec, renders, v.time_bound_s, v.rss_bound_mb)
        rows.append(judge_run(v, e.renderer, e.name, scene, outcome, exp))
        counter.tick(f"{v.name}: {e.name} {rows[-1]['status']}")
    return rows


# ----------------------------------------------------------------------------------------
# The table as text
# ----------------------------------------------------------------------------------------


def format_table(table) -> str:
    """The stress table as fixed-width text, one line per row, then the failures' messages."""
    head = ("variant", "renderer", "status", "spp", "res", "time s", "bound", "RSS MB", "bound", "NaN/Inf/neg",
            "mean", "expected", "±tol", "rel err", "z")
    records = table.to_dict("records")
    lines = [_table_line(r) for r in records]
    widths = [max(len(h), *(len(x[i]) for x in lines)) if lines else len(h) for i, h in enumerate(head)]
    out = ["  ".join(h.ljust(w) for h, w in zip(head, widths))]
    out += ["  ".join(c.ljust(w) for c, w in zip(x, widths)) for x in lines]
    notes = [f"  {r['variant']} / {r['renderer']} ({r['status']}): {r['message']}"
             for r in records if r["status"] != "pass" and r["message"]]
    notes += [f"  {r['variant']} / {r['renderer']}: mean {r['mean_check']}" for r in records
              if r["status"] == "pass" and str(r["mean_check"]).startswith("n/a")]
    if notes:
        out += ["", "notes:", *notes]
    return "\n".join(out)


def _table_line(r: dict) -> tuple[str, ...]:
    counts = "-" if r["nan_count"] is None or _isnan(r["nan_count"]) else \
        f"{int(r['nan_count'])}/{int(r['inf_count'])}/{int(r['negative_count'])}"
    return (r["variant"], r["renderer"], r["status"], str(r["spp"]), r["resolution"],
            fmt_value(r["time_s"], 3), f"{r['time_bound_s']:g}", fmt_value(r["peak_rss_mb"], 4),
            f"{r['rss_bound_mb']:.0f}", counts, fmt_value(r["mean"], 6), fmt_value(r["expected"], 6),
            fmt_value(r["tolerance"], 2),
            "-" if _isnan(r["rel_error"]) else f"{r['rel_error']:+.3%}",
            "-" if _isnan(r["z"]) else f"{r['z']:+.2f}")


def _isnan(x) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))


# ----------------------------------------------------------------------------------------
# The entry for the CLI
# ----------------------------------------------------------------------------------------


@dataclass
class StressRun:
    """A finished suite: its table, its provenance (for the report), its wall time and ``stress.csv``."""

    table: object  # pandas DataFrame, columns COLUMNS
    provenance: dict
    wall_s: float
    csv_path: Path

    @property
    def exit_code(self) -> int:
        """0 if every row passed or was skipped, 1 if any failed or had an error."""
        return 1 if self.table["status"].isin(["fail", "error"]).any() else 0


def run_suite(renderer_specs: list[str] | None, variants: list[str] | None, out_dir: Path,
              progress: Progress | None = None, reference_renderer: str | None = None,
              time_limit_s: float | None = None) -> StressRun:
    """``cbox stress``: run the suite (``progress``, ``reference_renderer`` and ``time_limit_s`` as in
    :func:`run_stress`) and
    write ``out_dir/stress.csv`` atomically.

    Unknown variant names raise ValueError before anything runs or is
    written, unknown renderers RendererError, a stale reference
    ReferenceError (usage errors: the CLI exits 2). The caller writes the
    report from the returned table and provenance, then calls
    :func:`print_summary`.
    """
    import datetime as _dt

    from cornell_harness.store.atomic import atomic_path
    from cornell_harness.store.provenance import provenance

    select_variants(variants)  # fail on a bad name before anything runs
    out_dir = Path(out_dir)
    date = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    table = run_stress(renderer_specs, variants, progress, reference_renderer, time_limit_s)
    wall = time.perf_counter() - t0
    out_dir.mkdir(parents=True, exist_ok=True)
    with atomic_path(out_dir / "stress.csv") as tmp:
        table.to_csv(tmp, index=False)
    prov = provenance({"date": date, "kind": "stress"}, table)
    prov.update(seed=SEED, z_crit=Z_CRIT, suite_wall_time_s=round(wall, 1))
    return StressRun(table, prov, wall, out_dir / "stress.csv")


def print_summary(run: StressRun, *also_written: Path) -> int:
    """Print the table, the count of each status and the files written; return the exit code."""
    print(format_table(run.table))
    counts = run.table["status"].value_counts()
    summary = ", ".join(f"{int(counts.get(s, 0))} {s}" for s in STATUSES if counts.get(s, 0))
    written = " and ".join(str(p) for p in (run.csv_path, *also_written))
    print(f"\n{summary or 'nothing run'} in {run.wall_s:.0f} s; wrote {written}")
    return run.exit_code

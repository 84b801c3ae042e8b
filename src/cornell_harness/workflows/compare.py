"""``cbox compare``: renderers on one scene scored against its reference (:func:`run_comparison`), at equal spp,
equal time (the spp a time budget buys) or equal quality (the time a target error costs), their renders timed
again (``--time-repeats``) in rounds interleaved over the renderers; and the comparison's folder."""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from cornell_harness.adapters.api import attribute, machine_cores
from cornell_harness.adapters.registry import RendererEntry, missing_features
from cornell_harness.evaluate import timing_stats
from cornell_harness.evaluate.timing_quality import auto_basis
from cornell_harness.scenes.model import Scene
from cornell_harness.store.atomic import atomic_path, json_safe, write_json_atomic
from cornell_harness.store.experiments import (CONFIG_FILE, RESULTS_FILE, ExperimentError, cell_name, experiment_lock,
                                       write_parquet_atomic)
from cornell_harness.store.exr import write_exr
from cornell_harness.store.references import Reference
from cornell_harness.workflows import runner


#: The spp of a time budget's first calibration renders: the line through their times is a first estimate of
#: what the budget buys, which sizes the probe render (:data:`PROBE_FRACTION`).
CALIBRATION_SPP = (1, 4)
#: The probe render has this fraction of the first estimate's spp, and the spp the budget buys is the line
#: through its time and the 4-spp render's. Renders of 1 and 4 spp take tens of ms, where a renderer's cost is
#: not yet linear in spp (Mitsuba's per-pass cost) and a busy machine's noise is a large part of the time, so a
#: line through them alone, extrapolated 100x, misses the budget (docs/timing.md, "How close the budget
#: lands"); the probe takes about 1/8 of the budget, which keeps the extrapolation within 8x at 1/8 of the
#: budget's cost per round.
PROBE_FRACTION = 8


def spp_for_calibration(t_low: float, t_high: float, budget_s: float, spp_low: int = 1, spp_high: int = 4) -> float:
    """The spp (not yet whole) that should take ``budget_s`` seconds, from the times of two renders, at ``spp_low``
    and ``spp_high`` samples per pixel: the line time = overhead + cost·spp through them.

    Per-render overhead (photon tracing, set-up inside the clock) and per-sample cost are separated by
    the two timings. Where the smaller render reads as long as the larger
    (stalled by a busy machine: load only adds time), the difference says nothing
    about the per-sample cost (floored at 1e-9 s it gives ~10⁹ spp, a
    render without end); ``t_high / spp_high`` is then used, an upper bound on
    the per-sample cost (the overhead is ≥ 0): fewer samples than the budget
    buys, never more.
    """
    per_spp = (t_high - t_low) / (spp_high - spp_low) if t_high > t_low else t_high / spp_high
    per_spp = max(per_spp, 1e-9)  # a renderer that reports no time at all
    overhead = max(t_high - spp_high * per_spp, 0.0)  # 0 in the fallback
    return max(1.0, (budget_s - overhead) / per_spp)


def probe_spp(first_estimate: int) -> int | None:
    """The probe render's spp (:data:`PROBE_FRACTION` of the first estimate), or None where the 4-spp render is
    already within that fraction of the estimate, a short extrapolation that a probe would not shorten."""
    spp = first_estimate // PROBE_FRACTION
    return spp if spp > CALIBRATION_SPP[1] else None


@dataclass
class BudgetChoice:
    """The spp a time budget buys one renderer, from K rounds of calibration renders.

    ``spp`` is :func:`spp_for_calibration` of the median times at the two
    spp of ``fit_spp``: 4 spp and the probe's (:data:`PROBE_FRACTION`), or 1
    and 4 spp where no probe was needed. ``spp_low`` / ``spp_high`` is the 95% interval
    (:func:`cornell_harness.evaluate.timing_stats.median_interval`) of what each
    round's own pair of renders would buy, the spread of the per-sample
    cost (and overhead) carried to spp, widened to hold ``spp``; None with
    one round. ``basis`` is the clock the budget was spent in (wall or cpu).
    """

    spp: int
    spp_low: int | None
    spp_high: int | None
    samples: list[float]  # per round, the spp its two renders buy
    basis: str
    fit_spp: tuple[int, int] = CALIBRATION_SPP

    def record_in(self, info: dict, budget_s: float) -> None:
        """The choice as a run's ``info`` (columns ``info_time_budget_s``, ``info_spp_low``, ...)."""
        info.update(time_budget_s=budget_s, time_budget_basis=self.basis, spp_low=self.spp_low,
                    spp_high=self.spp_high, time_budget_spp_samples=[round(s, 2) for s in self.samples],
                    time_budget_fit_spp=list(self.fit_spp))


def budget_choice(t_lows: Sequence[float], t_highs: Sequence[float], budget_s: float, basis: str = "wall",
                  fit_spp: tuple[int, int] = CALIBRATION_SPP) -> BudgetChoice:
    """The spp ``budget_s`` buys, from K rounds' timings at the two spp of ``fit_spp`` (:class:`BudgetChoice`)."""
    spp = int(spp_for_calibration(float(np.median(t_lows)), float(np.median(t_highs)), budget_s, *fit_spp))
    samples = [spp_for_calibration(a, b, budget_s, *fit_spp) for a, b in zip(t_lows, t_highs)]
    _, low, high = timing_stats.median_interval(samples)
    if math.isnan(low):
        return BudgetChoice(spp, None, None, samples, basis, fit_spp)
    return BudgetChoice(spp, max(1, math.floor(min(low, spp))), math.ceil(max(high, spp)), samples, basis,
                        fit_spp)


def calibrate_time_budget(entries: Sequence[RendererEntry], scene: Scene, budget_s: float, seed: int,
                          repeats: int = 1, basis: str = "wall",
                          on_render: Callable[[str], None] | None = None) -> list[BudgetChoice | Exception]:
    """Per entry, the spp ``budget_s`` buys (or the exception its calibration raised): ``repeats`` rounds of
    two short timed renders (1 and 4 spp), then ``repeats`` rounds of one probe render at about 1/8 of the
    budget (:data:`PROBE_FRACTION`, sized by the first renders), each round interleaved over the renderers
    (A1 A4 B1 B4, A1 A4 B1 B4, ..., Ap Bp, Ap Bp, ...), so that a change of load during calibration hits every
    renderer alike. The spp is the line through the median 4-spp and probe times (:func:`budget_choice`).

    ``basis`` "cpu" spends the budget in process CPU seconds (:func:`cornell_harness.workflows.runner.cpu_time`: the
    render proper's, or the whole call's for a renderer that measures none); "auto" spends it in CPU seconds
    where any calibration render was contended (:func:`cornell_harness.evaluate.timing_quality.auto_basis`:
    other processes took cores the render's threads needed), else in wall seconds, every renderer alike; each
    choice's ``basis`` says which. The calibration renders are not
    counted in the budget; the final render's own time is what is reported. ``on_render(label)`` follows each
    calibration render, and each round's probe that was not needed (progress: three per round and renderer).
    """
    timings: list[dict[int, list[tuple[float, float]]] | Exception] = [{} for _ in entries]
    machine: list[dict] = []  # each calibration render's figures, for the auto basis

    def rounds(spp_of: Callable[[int], Sequence[int]], skipped: str = "") -> None:
        for round_ in range(repeats):
            for i, entry in enumerate(entries):
                if isinstance(timings[i], Exception):
                    continue
                if skipped and not spp_of(i) and on_render:
                    on_render(f"{entry.name} calibration {skipped}, round {round_ + 1}/{repeats}")
                try:
                    for spp in spp_of(i):
                        result, timing = runner.render_timed(entry, scene, spp, seed)
                        timings[i].setdefault(spp, []).append((float(result.time_s), runner.cpu_time(result, timing)))
                        machine.append({**timing.as_dict(), "threads": runner.threads_of(result.info)})
                        if on_render:
                            on_render(f"{entry.name} calibration {spp} spp, round {round_ + 1}/{repeats}")
                except Exception as e:  # recorded as the renderer's failure by the caller; the others go on
                    timings[i] = e

    def clock() -> str:
        return (auto_basis(pd.DataFrame(machine), machine_cores()) if machine else "wall") if basis == "auto" else basis

    def choice(t: dict, spp: tuple[int, int], clock_: str) -> BudgetChoice:
        low, high = ([c if clock_ == "cpu" else w for w, c in t[s]] for s in spp)
        return budget_choice(low, high, budget_s, clock_, spp)

    rounds(lambda i: CALIBRATION_SPP)
    first = clock()
    probes = [None if isinstance(t, Exception) else probe_spp(choice(t, CALIBRATION_SPP, first).spp)
              for t in timings]
    rounds(lambda i: (probes[i],) if probes[i] else (), skipped="probe not needed (4 spp is near the budget's)")
    final = clock()
    return [t if isinstance(t, Exception) else choice(t, (CALIBRATION_SPP[1], p) if p else CALIBRATION_SPP, final)
            for t, p in zip(timings, probes)]


def spp_for_time_budget(entry: RendererEntry, scene: Scene, budget_s: float, seed: int) -> int:
    """The spp that should take ``budget_s`` seconds, from one round of calibration (:func:`calibrate_time_budget`)."""
    (choice,) = calibrate_time_budget([entry], scene, budget_s, seed)
    if isinstance(choice, Exception):
        raise choice
    return choice.spp


def retime(entries: Sequence[RendererEntry], records: Sequence[runner.RunRecord], scene: Scene, repeats: int,
           on_render: Callable[[str], None] | None = None) -> None:
    """Time each record's render ``repeats`` times in all (its first render counts as the first), in rounds
    interleaved over the renderers (A B A B ...): ``time_s`` becomes the median, ``time_samples`` the timings.

    ``entries[i]`` rendered ``records[i]``. A repeat renders the same renderer, scene, spp and seed, so a
    renderer deterministic per seed gives the same image bit for bit; the first render's image and scores
    are kept, and a repeat whose image differs is counted in ``info["repeat_images_differ"]`` (a
    renderer that is not repeatable, said, not refused). A repeat that raises ends that record's repeats
    (``info["time_repeat_error"]``); its timings so far stand.
    """
    timed = [(e, r) for e, r in zip(entries, records) if r.status == "ok" and r.time_s is not None]
    for _, r in timed:
        r.time_samples = [(float(r.time_s), r.cpu_time_s)]
    for round_ in range(1, repeats):
        for entry, rec in timed:
            if "time_repeat_error" in rec.info:
                continue
            try:
                result, timing = runner.render_timed(entry, scene, rec.spp, rec.seed)
            except Exception as e:  # the first render's record stands
                rec.info["time_repeat_error"] = f"{type(e).__name__}: {e}"
                continue
            rec.time_samples.append((float(result.time_s), runner.cpu_time(result, timing)))
            if rec.image is not None and not np.array_equal(result.image, rec.image, equal_nan=True):
                rec.info["repeat_images_differ"] = rec.info.get("repeat_images_differ", 0) + 1
            if on_render:
                on_render(f"{entry.name} repeat {round_ + 1}/{repeats}")
    for _, rec in timed:
        wall, cpu = timing_stats.medians([w for w, _ in rec.time_samples], [c for _, c in rec.time_samples])
        rec.time_s = wall
        if cpu is not None:
            rec.cpu_time_s = cpu


def render_to_target(entry: RendererEntry, scene: Scene, reference: Reference, metric: str, target: float,
                     seed: int, max_spp: int) -> runner.RunRecord:
    """Renders at 1, 2, 4, ... spp until ``metric`` ≤ ``target`` (or ``max_spp``); the record says which.

    The reported time is that of the render that reached the target (a
    renderer that resumed its last render would need at most that). A
    deterministic renderer stops early once two doublings of spp leave its error unchanged.
    """
    spp, previous, stalls = 1, None, 0
    deterministic = attribute(entry.renderer, "deterministic")
    while True:
        rec = runner.run_one(entry, scene, spp, seed, reference)
        if rec.status != "ok":
            return rec
        value = rec.metrics.get(metric)
        if value is None:
            raise ExperimentError(f"--target-error: unknown metric {metric!r}")
        rec.info["target"] = f"{metric}<={target:g}"
        rec.info["target_reached"] = bool(value <= target)
        # A deterministic renderer whose error stopped changing for two doublings will not reach it
        # with more samples (1e-6: GL rasterisers are repeatable only to float rounding).
        same = deterministic and previous is not None and abs(value - previous) <= 1e-6 * abs(previous)
        stalls = stalls + 1 if same else 0
        if value <= target or spp >= max_spp or stalls >= 2:
            return rec
        spp, previous = min(2 * spp, max_spp), value


def default_time_repeats(time_budget: float | None, target: tuple[str, float] | None) -> int:
    """The timings of each final render when none is asked for: 3 for an equal-time or equal-quality
    comparison (the time is the result), 1 for a plain one at a given spp."""
    return 3 if time_budget or target else 1


@dataclass
class Comparison:
    """What one ``cbox compare`` runs: ``entries`` on ``scene`` against ``reference``, each at ``spp``, or at the
    spp ``budget_s`` seconds buy it (equal time), or at the least of 1, 2, 4, ... ``max_spp`` that brings
    ``target`` = (metric, value) within its value (equal quality); each final render timed ``repeats`` times."""

    scene: Scene
    reference: Reference
    entries: Sequence[RendererEntry]
    spp: int
    seed: int = 0
    budget_s: float | None = None
    target: tuple[str, float] | None = None
    max_spp: int = 4096
    repeats: int = 1
    time_basis: str = "wall"  # or cpu, or auto: resolved to one of them by run_comparison

    @property
    def runnable(self) -> list[bool]:
        """Per entry: whether it renders here (available, and it models every feature the scene uses)."""
        return [e.available and not missing_features(e.renderer, self.scene) for e in self.entries]

    @property
    def mode(self) -> str:
        """``10 s each``, ``to rel_mse<=0.001`` or ``64 spp``."""
        if self.budget_s:
            return f"{self.budget_s:g} s each"
        return f"to {self.target[0]}<={self.target[1]:g}" if self.target else f"{self.spp} spp"

    @property
    def renders(self) -> int:
        """The renders it makes (a progress bar's length): the calibrations (1 spp, 4 spp and a probe per round:
        :func:`calibrate_time_budget`), one per renderer, the repeats."""
        runnable = sum(self.runnable)
        calibrations = 3 * self.repeats * runnable if self.budget_s else 0
        return calibrations + len(self.entries) + (self.repeats - 1) * runnable


def run_comparison(c: Comparison, on_start: Callable[[str], None] | None = None,
                   on_render: Callable[[str], None] | None = None,
                   on_record: Callable[[runner.RunRecord], None] | None = None) -> list[runner.RunRecord]:
    """Render, score and time every entry of ``c``; one record per entry, in order (a renderer's failure is
    its record's, never raised). An unbiased renderer's run gets the agreement test (:func:`judge_agreement`).

    With a time budget each renderer's spp comes from calibration renders, ``c.repeats`` rounds of them
    interleaved over the renderers; every final render is then timed ``c.repeats`` times in all, in rounds
    interleaved over the renderers too (:func:`retime`). ``on_start(label)`` comes before each renderer's
    renders, ``on_render(label)`` after each render (progress), ``on_record(record)`` as each record is
    scored, before the repeats retime it.

    A ``c.time_basis`` of "auto" is resolved in ``c``: with a budget, as its calibration chose; without one,
    from the final renders' timing quality (:func:`cornell_harness.evaluate.timing_quality.auto_basis`).
    """
    runnable = c.runnable
    if c.budget_s and on_start:
        on_start("the time budget's calibration renders")
    chosen = calibrate_time_budget([e for e, ok in zip(c.entries, runnable) if ok], c.scene, c.budget_s,
                                   c.seed, c.repeats, c.time_basis, on_render=on_render) if c.budget_s else []
    c.time_basis = next((ch.basis for ch in chosen if isinstance(ch, BudgetChoice)), c.time_basis)
    choices = iter(chosen)
    records = []
    for entry, ok in zip(c.entries, runnable):
        if on_start:
            on_start(entry.name)
        rec = _run_entry(c, entry, next(choices) if c.budget_s and ok else None, ok)
        judge_agreement(rec, c.scene, c.reference)
        records.append(rec)
        if on_render:
            on_render(f"{rec.renderer} {rec.status}")
        if on_record:
            on_record(rec)
    retime(c.entries, records, c.scene, c.repeats, on_render=on_render)
    if c.time_basis == "auto":
        c.time_basis = auto_basis(runner.rows_frame(records), machine_cores())
    return records


def _run_entry(c: Comparison, entry: RendererEntry, choice: BudgetChoice | Exception | None,
               runnable: bool) -> runner.RunRecord:
    """One entry's scored run: at its time budget's ``choice``, to the target error, or at ``c.spp``."""
    if isinstance(choice, Exception):
        rec = runner.RunRecord.new(c.scene, entry, 1, c.seed)
        rec.status, rec.reason = "failed", f"time budget calibration: {type(choice).__name__}: {choice}"
        return rec
    if choice is not None:
        rec = runner.run_one(entry, c.scene, choice.spp, c.seed, c.reference)
        choice.record_in(rec.info, c.budget_s)
        return rec
    if c.target and runnable:
        return render_to_target(entry, c.scene, c.reference, c.target[0], c.target[1], c.seed, c.max_spp)
    return runner.run_one(entry, c.scene, c.spp, c.seed, c.reference)


#: Family-wise false-alarm rate of the agreement test :func:`judge_agreement` gives a run (its ``agreement``
#: column): a correct renderer reads "fail" in 1% of runs.
AGREEMENT_ALPHA = 0.01


def judge_agreement(rec: runner.RunRecord, scene: Scene, reference: Reference) -> None:
    """An ok run of an unbiased renderer gets the gate's agreement test against the reference
    (:func:`cornell_harness.evaluate.agreement.render_agreement`: tiles of 16, the scene's regions, family-wise
    :data:`AGREEMENT_ALPHA`) as ``rec.agreement`` ("pass" or "fail") and ``rec.agreement_p_min``; other runs are
    left as they are. Here, not in :func:`runner.run_one`: the gate runs its own test at its own level, and
    SciPy's statistics stay out of every command that renders."""
    from cornell_harness.evaluate import agreement  # imports scipy.stats (~1 s)
    from cornell_harness.evaluate import regions as named_regions

    if rec.status != "ok" or rec.estimator != "unbiased" or rec.image is None:
        return
    agr = agreement.render_agreement(rec.image, rec.variance, rec.spp, reference.image, reference.variance,
                                     reference.spp, alpha=AGREEMENT_ALPHA, regions=named_regions.region_masks(scene))
    rec.agreement, rec.agreement_p_min = ("pass" if agr.passed else "fail"), agr.p_min


def store_comparison(out: Path, scene: Scene, records: Sequence[runner.RunRecord], command: str,
                     time_basis: str = "wall", time_repeats: int = 1) -> None:
    """A comparison as an experiment folder: images, results table, CSV and JSON (a report can then be built).

    ``time_basis`` (recorded in experiment.json) is the clock its time-derived figures read, so that
    ``cbox report`` redraws them alike; ``time_repeats`` the K each final render was timed."""
    with experiment_lock(out, command):
        _store(out, scene, records, command, {"time_basis": time_basis, "time_repeats": time_repeats})


def _store(out: Path, scene: Scene, records: Sequence[runner.RunRecord], command: str, timing: dict) -> None:
    for r in records:
        if r.image is not None:
            write_exr(out / "images" / f"{cell_name(r.renderer, r.seed)}.exr", r.image)
    rows = [r.row() for r in records]
    frame = pd.DataFrame(rows)
    write_json_atomic(out / CONFIG_FILE, {
        "kind": "compare", "scene": str(scene.path), "scene_name": scene.name, "scene_hash": scene.content_hash(),
        "renderers": [r.renderer for r in records], "spp": sorted({r.spp for r in records}),
        "seeds": sorted({r.seed for r in records}), "command": command, **timing,
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")})
    write_parquet_atomic(frame, out / RESULTS_FILE)
    with atomic_path(out / "metrics.csv") as tmp:
        frame.to_csv(tmp, index=False)
    write_json_atomic(out / "metrics.json", [json_safe(r) for r in rows])

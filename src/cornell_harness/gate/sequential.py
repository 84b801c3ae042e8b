"""A sequential expectation: looks at spp doubling up to ``max_spp``, stopped at the first verdict.

::

    [[expect]]
    scene = "cornell-box"
    renderer = "pathtracer"
    max_spp = 1024          # looks at 64, 128, 256, 512, 1024 spp (first_spp, default max_spp // 16)
    unbiased = true
    margin = { image = 0.005, "region.walls" = 0.01 }

One render to ``max_spp`` gives every look as a checkpoint; a renderer that declares ``stops_early``
(:class:`cornell_harness.adapters.api.Declarations`: ours and Mitsuba) ends at the first look with a
verdict (:class:`StopRule`, run where it renders), so a gross bias or a clean render with a generous margin
costs a fraction of the budget. One that cannot (LuxCore, Cycles, a command renderer) renders the whole
budget, and the same looks, taken from its checkpoints afterwards, give the same verdict without the saving;
a look it has no checkpoint for is skipped, its share of the error rates unspent.

At look k, at n_k spp (information fraction t_k = n_k / max_spp):

- **fail** when the agreement test (tiles, regions and the whole image, Šidák,
  :func:`cornell_harness.evaluate.agreement.render_agreement`) rejects at its increment of the agreement's
  share of ``alpha``, spent over the looks (:func:`cornell_harness.evaluate.sequential.look_levels`;
  Lan & DeMets 1983): a correct renderer fails at some look with probability at most that share;
- **pass** when every region × channel interval of the relative bias
  (:func:`cornell_harness.gate.margins.bias_table`), at two-sided level 2·Δβ_k, lies inside its margin. Each
  side then errs with probability Δβ_k, so a bias at a margin passes look k with probability at most Δβ_k,
  and some look at most ``beta`` (the config's); a pass needs every interval inside (an intersection-union
  test, Berger 1982), so no correction over regions is needed;
- otherwise the next look, and **inconclusive** after the last.

The variance and outlier tests are made once, at the look the gate stops at; which look that is depends on
the data, so each runs at its share of ``alpha`` divided by the number of looks (Bonferroni over the looks
it could have been). The variance test reads the stopping look's variance, which the stop rule relied on,
and also the variance of the result the renderer returned where that is another (rendered past the look, or
numbers its checkpoints did not show): what users read must be honest too. Every look takes the render's own
variance at its spp where the checkpoint carries one (:class:`cornell_harness.adapters.api.Checkpoint`),
floored at the reference's noise model as the fixed gate's is, else the model alone; the rule in the renderer's
process and the gate's reading of the looks afterwards see the same checkpoints, so the same numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from cornell_harness.evaluate import agreement, metrics
from cornell_harness.evaluate.equivalence import FAIL, INCONCLUSIVE, PASS
from cornell_harness.evaluate.sequential import fractions, look_levels
from cornell_harness.gate.checks import (Check, Outcome, evaluate, outlier_check, statistical_alpha, three_way,
                                        variance_of_render_check)
from cornell_harness.gate.config import Expectation, GateConfig
from cornell_harness.gate.margins import BiasTable, Margins, bias_table, equivalence_message
from cornell_harness.store.references import Reference
from cornell_harness.workflows import runner

#: A look with neither verdict: the render goes on to the next.
CONTINUE = "continue"


@dataclass(frozen=True)
class Design:
    """The looks of a sequential expectation and the levels each is tested at."""

    spps: tuple[int, ...]
    fail_levels: tuple[float, ...]  # the agreement test's family-wise level at each look
    pass_levels: tuple[float, ...]  # each bias interval's two-sided level at each look: 2·Δβ_k
    other_level: float  # the variance and outlier tests' level, at the look the gate stops at
    alpha: float
    beta: float
    spending: str

    def note(self, k: int, stopped: bool) -> str:
        """``sequential: stopped at look 3 of 5 (256 of 1024 spp; obrien-fleming spending ...: agreement at
        level 4.4e-09, each bias interval at level 0.0011)``."""
        how = "stopped at" if stopped else "verdict at"
        return (f"sequential: {how} look {k + 1} of {len(self.spps)} ({self.spps[k]} of {self.spps[-1]} spp; "
                f"{self.spending} spending of α = {self.alpha:g} and β = {self.beta:g}: agreement at level "
                f"{self.fail_levels[k]:.3g}, each bias interval at level {self.pass_levels[k]:.3g})")


def design(exp: Expectation, cfg: GateConfig) -> Design:
    """The looks of ``exp`` (``max_spp``) and their levels under ``cfg``'s alpha, beta and spending."""
    spps = exp.looks()
    t = fractions(spps)
    share = statistical_alpha(cfg.alpha)
    fail = look_levels(t, share, cfg.spending)
    passes = np.minimum(2.0 * look_levels(t, cfg.beta, cfg.spending), 1.0 - 1e-12)
    return Design(tuple(spps), tuple(map(float, fail)), tuple(map(float, passes)), share / len(spps), cfg.alpha,
                  cfg.beta, cfg.spending)


@dataclass
class Look:
    """One look's verdict (:data:`PASS`, :data:`FAIL`, :data:`CONTINUE`, or :data:`INCONCLUSIVE` at the last)."""

    k: int
    spp: int
    verdict: str
    agreement: agreement.Agreement
    table: BiasTable
    image: np.ndarray  # what it looked at: the render after ``spp`` and its variance (None: none given)
    variance: np.ndarray | None


def look(image: np.ndarray, variance: np.ndarray | None, k: int, d: Design, ref: Reference,
         masks: Mapping[str, np.ndarray] | None, tile: int, margins: Margins) -> Look:
    """Look ``k`` of design ``d`` at ``image`` (the render after d.spps[k] spp) and its ``variance`` (None: the
    renderer gives none; it is floored at the reference's noise model either way, as the fixed gate's)."""
    spp = d.spps[k]
    agr = agreement.render_agreement(image, variance, spp, ref.image, ref.variance, ref.spp, tile,
                                     d.fail_levels[k], masks)
    table = bias_table(image, variance, spp, ref, masks, d.alpha, margins, level=d.pass_levels[k])
    verdict = FAIL if not agr.passed else PASS if not table.unresolved else CONTINUE
    if verdict == CONTINUE and k == len(d.spps) - 1:
        verdict = INCONCLUSIVE
    return Look(k, spp, verdict, agr, table, image, variance)


@dataclass
class StopRule:
    """The ``stop`` a renderer that ``stops_early`` calls at each checkpoint: True at the first look with a
    verdict. Plain data, so it travels to a sandbox's child process with the render."""

    design: Design
    reference: Reference
    masks: Mapping[str, np.ndarray] | None
    tile: int
    margins: Margins

    def __call__(self, checkpoint) -> bool:
        if checkpoint.spp not in self.design.spps:
            return False
        k = self.design.spps.index(checkpoint.spp)
        result = look(checkpoint.image, checkpoint.variance, k, self.design, self.reference, self.masks, self.tile,
                      self.margins)
        return result.verdict in (PASS, FAIL)


def looks(exp: Expectation, rec: runner.RunRecord, ref: Reference, cfg: GateConfig,
          masks: Mapping[str, np.ndarray] | None) -> tuple[Design, list[Look], list[int]]:
    """The looks of a sequential run, in order up to the first with a verdict (the last: inconclusive), and
    the spps of looks the render has no image of (skipped)."""
    d = design(exp, cfg)
    shots = {c.spp: (c.image, c.variance) for c in rec.checkpoints}  # what the stop rule saw
    shots.setdefault(rec.spp, (rec.image, rec.variance))
    out, skipped = [], []
    for k, n in enumerate(d.spps):
        if n not in shots:
            skipped.append(n)
            continue
        out.append(look(*shots[n], k, d, ref, masks, exp.tile, exp.margins))
        if out[-1].verdict != CONTINUE:
            break
    return d, out, skipped


def evaluate_sequential(exp: Expectation, rec: runner.RunRecord, ref: Reference, cfg: GateConfig,
                        masks: Mapping[str, np.ndarray] | None = None) -> Outcome:
    """The checks of a sequential expectation on its run: finite, agreement, variance and outliers at the look
    it stopped at, and the equivalence check of that look; a failed run is checked as the fixed gate's."""
    if rec.status != "ok":
        return evaluate(exp, rec, ref, cfg)
    d, seen, skipped = looks(exp, rec, ref, cfg, masks)
    last = seen[-1]
    note = d.note(last.k, stopped=rec.spp == last.spp and last.spp < d.spps[-1])
    if last.verdict != CONTINUE and rec.spp > last.spp:
        note += f"; the renderer cannot stop early and rendered all {rec.spp} spp"
    if skipped:
        note += f"; no image at {', '.join(map(str, skipped))} spp: those looks skipped"
    rec.info["sequential"] = {"looks": [x.spp for x in seen], "verdict": last.verdict, "stop_spp": last.spp,
                              **_cost(rec, last.spp)}
    bad = int(np.count_nonzero(~np.isfinite(last.image)))
    checks = [Check(exp.name, "finite", bad == 0, "no NaN or Inf pixel" if bad == 0 else
                    f"{bad} NaN or Inf values at {last.spp} spp", bad, 0)]
    checks.append(Check(exp.name, "agreement", last.agreement.passed, f"{last.agreement.message()} [{note}]",
                        last.agreement.p_min, last.agreement.level))
    # Each at its share of α over the looks, on the stopping look's image and variance (as the stop rule saw
    # them); the variance check reads the result's variance too (_variance_checks).
    clean = metrics.zero_broken_pixels(last.image)
    share = (f" [at {last.spp} spp, level {d.other_level:.3g}: the test's share of α over {len(d.spps)} "
             "looks]")
    checks.append(_variance_checks(exp, rec, last, clean, ref, d))
    checks.append(outlier_check(exp, last.variance, last.spp, clean, ref, d.other_level, share))
    checks.append(three_way(exp, "equivalence", not last.table.unresolved,
                             f"{equivalence_message(last.table)} [{note}]", len(last.table.unresolved), 0))
    return Outcome(exp, rec, checks, last.agreement, last.table)


def _variance_checks(exp: Expectation, rec: runner.RunRecord, last: Look, clean: np.ndarray, ref: Reference,
                     d: Design) -> Check:
    """The variance check of the stopping look's variance (what the stop rule relied on) and, where the result
    the renderer returned carries another (a later spp, or numbers its checkpoints did not show), of the
    result's too: that is the variance users read. Two tests then share the variance test's level (Bonferroni);
    the check fails when either does, with the failing test's message."""
    shown = rec.variance is not None and not (
        rec.spp == last.spp and last.variance is not None and np.array_equal(rec.variance, last.variance))
    level = d.other_level / (2 if shown else 1)
    share = (f" [at {{spp}} spp, level {level:.3g}: the test's share of α over {len(d.spps)} looks"
             f"{' and the result' if shown else ''}]")
    check = variance_of_render_check(exp, last.variance, last.spp, clean, ref, level,
                                     share.format(spp=last.spp))
    if not shown or not check.passed:
        return check
    result = variance_of_render_check(exp, rec.variance, rec.spp, metrics.zero_broken_pixels(rec.image), ref,
                                      level, f" (the result's variance){share.format(spp=rec.spp)}")
    return check if last.variance is not None and result.passed else result


def _cost(rec: runner.RunRecord, spp: int) -> dict:
    """The render's time and CPU time to the look at ``spp`` (its checkpoint's, or the whole render's)."""
    shot = next((c for c in rec.checkpoints if c.spp == spp), None)
    if shot is None:
        return {"time_to_verdict_s": rec.time_s, "cpu_to_verdict_s": rec.cpu_time_s}
    return {"time_to_verdict_s": float(shot.time_s), "cpu_to_verdict_s": shot.cpu_time_s}

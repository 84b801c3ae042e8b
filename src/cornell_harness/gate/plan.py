"""``cbox gate --plan``: the spp each unbiased expectation needs for its margins to resolve, from a short pilot.

Each unbiased expectation renders once at a pilot budget (its spp / 16 by default, one seed; the gate's own
render path, :func:`cornell_harness.workflows.runner.run_one`). The pilot's relative-bias table
(:func:`cornell_harness.gate.margins.bias_table`: the render's variance floored at the reference's noise model,
and the reference's own, Šidák-simultaneous at the config's ``alpha``) gives each region's and channel's standard
error and the share of it that falls with spp. The plan asks for the spp at which an *unbiased* render passes
the equivalence check with probability 1 − β per region and channel: its estimate lies within
±z_{1−β/2}·se with that probability, and it passes when that plus the interval's half-width z·se fits in the
margin, m = (z + z_{1−β/2})·se, which is :func:`~cornell_harness.evaluate.relative_bias.detectable_bias` at
β/2 (Chow, Shao & Wang 2008, §3.2, equivalence at a true difference of 0). The half-width to reach is then
z·m / (z + z_{1−β/2}), and :func:`~cornell_harness.evaluate.relative_bias.spp_for_half_width` turns it into spp;
where the reference's variance alone is wider than that, no spp reaches it. β = 0.2, as ``reference verify``'s
detectable bias uses. The power is per region and channel: the expectation passes when every interval does, so
with several regions near their planned spp its chance is lower; the largest region's spp leaves the others
with more. The standard errors are taken at the pilot's estimate, as the gate's intervals are. An expectation
without a ``margin`` table is planned with the default margins (:mod:`cornell_harness.gate.margins`). The time
is the pilot's, scaled by the spp ratio (set-up included, so an over-estimate for a renderer with a long
set-up).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from cornell_harness.evaluate.agreement import CHANNELS
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.evaluate.relative_bias import critical_z, detectable_bias, spp_for_half_width
from cornell_harness.gate.config import Expectation, GateConfig
from cornell_harness.gate.margins import BiasTable, Margins, bias_table
from cornell_harness.gate.run import resolve_all
from cornell_harness.workflows import runner
from cornell_harness.workflows.compare import spp_for_time_budget

#: The chance the plan leaves an unbiased render of not passing (inconclusive), per region and channel.
BETA = 0.2
#: The pilot's spp is the configured spp over this (at least 1).
PILOT_FRACTION = 16


def target_half_width(margin, level: float, beta: float = BETA) -> np.ndarray:
    """The interval half-width at which an unbiased render's interval lies inside ±``margin`` with probability
    1 − ``beta`` (module docstring): z·m / (z + z_{1−β/2})."""
    return critical_z(level) * np.asarray(margin, np.float64) / detectable_bias(1.0, level, beta / 2.0)


@dataclass(frozen=True)
class RegionPlan:
    """One region's plan: its worst channel (the one needing the most spp), its margin there, the half-width to
    reach, the spp that reaches it (∞: the reference's variance forbids it) and about the time."""

    region: str  # "image" or the region's name
    channel: str
    margin: float
    half_width: float
    spp: float
    time_s: float | None

    @property
    def reference_bound(self) -> bool:
        return not np.isfinite(self.spp)


def region_plans(table: BiasTable, pilot_time_s: float | None, beta: float = BETA) -> list[RegionPlan]:
    """Per region of the pilot's ``table`` (with margins), what resolves it: the largest spp over its channels."""
    b, level = table.intervals, table.intervals.level
    hw = target_half_width(table.margins, level, beta)
    need = spp_for_half_width(b.se, b.render_share, table.spp, hw, level)
    plans = []
    for i in range(len(table.regions)):
        c = int(np.argmax(need[i]))
        n = float(need[i, c])
        time = None if pilot_time_s is None or not np.isfinite(n) else pilot_time_s * n / table.spp
        plans.append(RegionPlan(table.label(i), CHANNELS[c], float(table.margins[i, c]), float(hw[i, c]), n, time))
    return plans


@dataclass(frozen=True)
class ExpectationPlan:
    """An expectation's pilot and what each region needs; ``problem`` says why there is no plan."""

    name: str
    budget_spp: int | None  # the configured spp (None for a time budget)
    budget_s: float | None  # the configured time budget
    pilot_spp: int
    pilot_time_s: float | None
    default_margins: bool
    regions: list[RegionPlan]
    problem: str | None = None

    @property
    def needed_spp(self) -> float:
        return max((r.spp for r in self.regions), default=0.0)

    @property
    def reference_bound(self) -> list[RegionPlan]:
        return [r for r in self.regions if r.reference_bound]

    @property
    def affordable(self) -> bool:
        """Whether the configured budget reaches every region's spp (a time budget: about its time)."""
        if self.problem is not None or self.reference_bound:
            return False
        if self.budget_spp is not None:
            return self.needed_spp <= self.budget_spp
        return all(r.time_s is not None and r.time_s <= self.budget_s for r in self.regions)


def pilot_spp(budget_spp: int, fraction: int = PILOT_FRACTION) -> int:
    return max(1, budget_spp // fraction)


def plan_expectation(exp: Expectation, scene, ref, entry, alpha: float, pilot: int | None = None,
                     time_limit_s: float | None = None, beta: float = BETA) -> ExpectationPlan:
    """Render ``exp``'s pilot (``pilot`` spp, default :func:`pilot_spp` of its budget) and plan it."""
    budget = exp.spp if exp.spp is not None else exp.max_spp  # a sequential expectation: its last look
    if pilot is None:
        full = budget if budget is not None else spp_for_time_budget(entry, scene, exp.time_s, exp.seed)
        pilot = pilot_spp(full)
    margins = exp.margins if exp.margins is not None else Margins()
    rec = runner.run_one(entry, scene, pilot, exp.seed, ref, time_limit_s=time_limit_s)
    head = dict(name=exp.name, budget_spp=budget, budget_s=exp.time_s, pilot_spp=pilot, pilot_time_s=rec.time_s,
                default_margins=exp.margins is None)
    if rec.status != "ok":
        return ExpectationPlan(**head, regions=[], problem=f"the pilot did not render: {rec.reason}")
    table = bias_table(rec.image, rec.variance, rec.spp, ref, region_masks(scene), alpha, margins)
    return ExpectationPlan(**head, regions=region_plans(table, rec.time_s, beta))


def plan_gate(cfg: GateConfig, overrides: dict | None = None, pilot: int | None = None, beta: float = BETA,
              sandbox: bool = True, scene_overrides: Sequence[str] = ()) -> list[ExpectationPlan]:
    """Plans of the config's unbiased expectations, everything resolved first as the gate does
    (:func:`cornell_harness.gate.run.resolve_all`: a config error before anything renders). ``overrides``
    replaces renderers by name (objects of this process: no time limit) and ``scene_overrides`` derives the
    scenes, as for the gate."""
    resolved = resolve_all(cfg, overrides, scene_overrides)
    return [plan_expectation(exp, scene, ref, entry, cfg.alpha, pilot,
                             exp.time_limit_s if sandbox and exp.renderer not in (overrides or {}) else None, beta)
            for exp, (scene, ref, entry, _) in zip(cfg.expectations, resolved) if exp.unbiased]


def _spp_text(n: float) -> str:
    return "∞" if not np.isfinite(n) else f"{int(np.ceil(n))}"


def plan_lines(plans: Sequence[ExpectationPlan], beta: float = BETA) -> list[str]:
    """One line per expectation and region, then the expectations whose budget cannot resolve their margins."""
    lines = []
    for p in plans:
        budget = f"{p.budget_spp} spp" if p.budget_spp is not None else f"{p.budget_s:g} s"
        time = f" in {p.pilot_time_s:.3g} s" if p.pilot_time_s is not None else ""
        note = ", default margins" if p.default_margins else ""
        lines.append(f"{p.name}: budget {budget}; pilot {p.pilot_spp} spp{time}{note}")
        if p.problem:
            lines.append(f"  {p.problem}")
        for r in p.regions:
            if r.reference_bound:
                what = "unresolvable at any spp, the reference's own variance is wider (rebuild it with more spp)"
            else:
                what = f"about {_spp_text(r.spp)} spp" + (f", {r.time_s:.2g} s" if r.time_s is not None else "")
            lines.append(f"  {r.region}: margin ±{100 * r.margin:g}% ({r.channel}), half-width "
                         f"{100 * r.half_width:.3g}%: {what}")
    short = [p for p in plans if not p.affordable]
    lines.append(f"power {1 - beta:g} per region and channel; " + (
        f"{len(short)} expectation(s) cannot resolve their margins at their budget:" if short
        else "every budget resolves its margins"))
    for p in short:
        if p.problem:
            why = p.problem
        elif p.reference_bound:
            why = "the reference's variance alone forbids " + ", ".join(r.region for r in p.reference_bound)
        else:
            why = f"needs about {_spp_text(p.needed_spp)} spp"
        lines.append(f"  {p.name}: {why}")
    return lines

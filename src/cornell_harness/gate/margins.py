"""An unbiased expectation's margins: the smallest relative bias that matters, and its three-way verdict.

::

    margin = { image = 0.005, "region.glass-shadow" = 0.05, "region.caustic" = [0.05, 0.05, 0.08] }
    inconclusive = "fail"        # default; "pass" counts an inconclusive verdict as a pass

With a ``margin`` table (an empty one too) the expectation gets an ``equivalence`` check: for the whole image
and each of the scene's named regions, per channel, the relative bias render mean / reference mean − 1 with its
Fieller interval from both variances (:mod:`cornell_harness.evaluate.relative_bias`), simultaneous at the
config's ``alpha`` by Šidák's correction over regions × channels. It passes when every interval lies inside its
±margin (:mod:`cornell_harness.evaluate.equivalence`), and is *inconclusive* otherwise; a bias that is
significant fails the agreement test as before. A margin is a number or one per channel [R, G, B]; a region
the table does not name has its kind's default (:data:`~cornell_harness.evaluate.equivalence.DEFAULT_IMAGE_MARGIN`,
1%; :data:`~cornell_harness.evaluate.equivalence.DEFAULT_REGION_MARGIN`, 5%).

``inconclusive = "pass"`` turns an inconclusive verdict into a pass (exit 0, JUnit a pass): the pass then again
means only "no significant bias", and bounds nothing. It is for a gate that must stay green while its budgets
are raised, never for good.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from cornell_harness.evaluate import metrics, noise
from cornell_harness.evaluate.agreement import CHANNELS, sidak_level
from cornell_harness.evaluate.equivalence import (DEFAULT_IMAGE_MARGIN, DEFAULT_REGION_MARGIN, INCONCLUSIVE, PASS,
                                                  inside, resolving_half_width)
from cornell_harness.evaluate.registry import REGION_PREFIX
from cornell_harness.evaluate.relative_bias import (BiasIntervals, critical_z, interval_text, region_sums,
                                                    relative_bias, spp_for_half_width)
from cornell_harness.suggest import closest

#: The whole image's key in a ``margin`` table.
IMAGE_KEY = "image"
#: How an inconclusive verdict counts: ``fail`` (exit 3, a JUnit failure "inconclusive") or ``pass``.
INCONCLUSIVE_AS = ("fail", "pass")


class MarginProblem(ValueError):
    """A bad ``margin`` entry: ``field`` (relative to the expectation) and what is wrong."""

    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field, self.message = field, message


@dataclass(frozen=True)
class Margins:
    """Margins per region key (``image`` or a region's name), each (3,) for R, G, B; others take the defaults."""

    values: dict = field(default_factory=dict)

    def of(self, region: str) -> np.ndarray:
        """The (3,) margin of ``region`` ("" or :data:`IMAGE_KEY`: the whole image)."""
        key = IMAGE_KEY if region in ("", IMAGE_KEY) else region
        if key in self.values:
            return np.asarray(self.values[key], np.float64)
        return np.full(3, DEFAULT_IMAGE_MARGIN if key == IMAGE_KEY else DEFAULT_REGION_MARGIN)

    def regions(self) -> list[str]:
        """The named regions the table sets (the gate checks them against the scene's)."""
        return [k for k in self.values if k != IMAGE_KEY]


def parse_margins(t: dict, bias_margin: bool = False) -> Margins | None:
    """The ``margin`` table of an expectation (None without one), and its ``inconclusive`` key checked: it needs
    a margin here or in its bias limit (``bias_margin``). MarginProblem for a bad one; the schema has checked
    the types and ranges."""
    if "inconclusive" in t and "margin" not in t and not bias_margin:
        raise MarginProblem("inconclusive", "goes with a margin (margin = { ... }, or bias_limit.margin): "
                            "without one there is no inconclusive verdict")
    if "margin" not in t:
        return None
    if not t.get("unbiased", False):
        raise MarginProblem("margin", "bounds an unbiased renderer's bias interval; give unbiased = true (a "
                            "biased renderer's bias limit takes bias_limit.margin)")
    values = {}
    for key, value in t["margin"].items():
        if key == IMAGE_KEY:
            name = IMAGE_KEY
        elif key.startswith(REGION_PREFIX) and len(key) > len(REGION_PREFIX):
            name = key[len(REGION_PREFIX):]
        else:
            hint = " (did you mean 'image'?)" if closest(key, [IMAGE_KEY]) else ""
            raise MarginProblem(f"margin.{key}", f"expected {IMAGE_KEY!r} or \"region.<region>\"{hint}")
        values[name] = tuple(float(v) for v in (value if isinstance(value, list) else [value] * 3))
    return Margins(values)


@dataclass(frozen=True)
class BiasTable:
    """An unbiased expectation's relative-bias intervals, per region (the whole image first, named ``""``) and
    channel, with their margins and verdicts where it states margins."""

    regions: list[str]
    pixels: list[int]
    intervals: BiasIntervals  # arrays (regions, 3)
    alpha: float  # family-wise: the intervals cover together with probability ≥ 1 − alpha
    spp: int
    margins: np.ndarray | None = None  # (regions, 3); None: the expectation states none
    verdicts: np.ndarray | None = None  # (regions, 3) pass / inconclusive (a significant bias is the agreement's)
    spp_needed: np.ndarray | None = None  # (regions,) about the spp that would resolve an unresolved region
    reference_bound: np.ndarray | None = None  # (regions,) the reference's variance alone keeps it unresolved

    @property
    def unresolved(self) -> list[int]:
        """Indices of the regions with a channel whose interval is not inside its margin."""
        if self.verdicts is None:
            return []
        return [i for i in range(len(self.regions)) if (self.verdicts[i] != PASS).any()]

    def label(self, i: int) -> str:
        return self.regions[i] or IMAGE_KEY

    def worst_channel(self, i: int) -> int:
        """The channel whose interval reaches furthest, relative to its margin (or to 1 without margins)."""
        b = self.intervals
        reach = np.maximum(np.abs(b.low[i]), np.abs(b.high[i]))
        return int(np.argmax(reach / (self.margins[i] if self.margins is not None else 1.0)))

    def text(self, i: int) -> str:
        """``glass-shadow: bias −0.4% [−6.1%, +5.3%] (B, margin ±5%)``: the region's worst channel."""
        c, b = self.worst_channel(i), self.intervals
        out = interval_text(self.label(i), float(b.estimate[i, c]), float(b.low[i, c]), float(b.high[i, c]))
        margin = "" if self.margins is None else f", margin ±{100 * self.margins[i, c]:g}%"
        return f"{out} ({CHANNELS[c]}{margin})"

    def resolution(self, i: int) -> str:
        """What would resolve unresolved region ``i``: about how many spp, or that none would."""
        if self.reference_bound[i]:
            return ("the reference's own variance keeps it unresolvable at any spp: build the reference with more "
                    "spp, or widen the margin")
        n = self.spp_needed[i]
        if not np.isfinite(n):
            return "its estimate sits on the margin: no spp resolves it"
        return f"about {_power_of_two(n)} spp would resolve it"


def _power_of_two(n: float) -> int:
    """The doubling (as the gate's checkpoints go) at or above ``n``."""
    return int(2 ** math.ceil(math.log2(max(n, 1.0))))


def bias_table(image, variance, spp: int, ref, masks, alpha: float, margins: Margins | None,
               level: float | None = None) -> BiasTable:
    """The relative bias of the render against the reference ``ref`` (a Reference) over the whole image and
    each of ``masks``, per channel, with Fieller intervals simultaneous at ``alpha`` (Šidák over regions ×
    channels), from the render's ``variance`` floored at the reference's noise model (as the agreement test's,
    :func:`cornell_harness.evaluate.agreement.render_agreement`) and the reference's; with ``margins``, each
    one's verdict and what would resolve it. ``level`` sets each interval's two-sided level instead (a
    sequential look's share of β, :mod:`cornell_harness.gate.sequential`); ``alpha`` then is what they cover
    together, by Šidák."""
    model = noise.render_variance(ref.variance, ref.spp, spp)
    var = model if variance is None else np.maximum(variance, model)
    names, x, vx = region_sums(metrics.zero_broken_pixels(image), var, masks or {})
    _, y, vy = region_sums(ref.image, ref.variance, masks or {})
    pixels = [int(np.prod(ref.image.shape[:2]))] + [int(np.count_nonzero(masks[n])) for n in names[1:]]
    if level is None:
        level = sidak_level(alpha, x.size)
    else:
        alpha = 1.0 - (1.0 - level) ** x.size
    b = relative_bias(x, vx, y, vy, level)
    if margins is None:
        return BiasTable(names, pixels, b, alpha, spp)
    m = np.array([margins.of(n) for n in names])
    verdicts = np.where(inside(b.low, b.high, m), PASS, INCONCLUSIVE)
    hw = resolving_half_width(b.estimate, m)
    need = spp_for_half_width(b.se, b.render_share, spp, hw, level)
    open_ = verdicts != PASS
    fixed = critical_z(level) * b.se * np.sqrt(1.0 - b.render_share)  # the reference's share of the half-width
    bound = (open_ & (hw > 0) & (fixed >= hw)).any(axis=1)
    spp_needed = np.where(open_, need, 0.0).max(axis=1)
    return BiasTable(names, pixels, b, alpha, spp, m, verdicts, spp_needed, bound)


def equivalence_message(t: BiasTable) -> str:
    """The ``equivalence`` check's message: every region's interval, the unresolved ones first with what would
    resolve them."""
    level = t.intervals.level
    head = (f"{len(t.regions)} region(s) × 3 channels, Fieller intervals simultaneous at {1 - t.alpha:.6g} (Šidák: "
            f"each at level {level:.3g})")
    bad = t.unresolved
    if not bad:
        return f"every bias interval inside its margin at {t.spp} spp ({head}): " + "; ".join(
            t.text(i) for i in range(len(t.regions)))
    rest = [i for i in range(len(t.regions)) if i not in bad]
    return (f"inconclusive: {len(bad)} of {len(t.regions)} region(s) unresolved at {t.spp} spp: "
            + "; ".join(f"{t.text(i)}: {t.resolution(i)}" for i in bad)
            + (f". Resolved: {'; '.join(t.text(i) for i in rest)}" if rest else "") + f" ({head})")

"""Do two engines agree on a scene? The stored reference against an independent render, region by region.

A reference made by one engine cannot show that engine's own mistakes (its
dielectric, its emitters, our conversion of the scene into it). ``cbox
reference verify`` renders the scene with a second engine
(:mod:`cornell_harness.workflows.reference_verify`) and this module judges the two
images, each with its per-pixel variance of the mean:

- **Per region and channel** (the scene's named regions,
  :func:`cornell_harness.evaluate.regions.region_masks`, and always the whole image,
  :data:`WHOLE_IMAGE`): the mean of each image over the region's pixels,
  their difference, and z = difference / √(V_ref + V_other), where a region
  mean's variance is V = Σ var / n² over its n pixels (pixels are
  independent). Each z is a two-sided test; p = 2 Φ(−|z|).
- **Verdict**: the engines disagree when any region-channel p is below the
  Šidák-corrected level ``1 − (1 − α)^(1/m)`` for the m tests
  (:func:`cornell_harness.evaluate.agreement.sidak_level`) at the family-wise
  false-alarm rate α = :data:`FAMILY_ALPHA` = 0.01: two engines that agree
  are called disagreeing at most once in a hundred verifications. The three
  channels of a region come from the same paths and the whole image overlaps
  every region, so the tests are correlated; Šidák's bound still holds, since
  for jointly normal z with any correlation P(all |z_i| ≤ c_i) ≥ Π P(|z_i| ≤
  c_i) (Šidák 1967, J. Am. Stat. Assoc. 62, 626-633): correlation makes the
  test conservative, never liberal.
- **χ²** = Σ z² over the same tests, with m degrees of freedom and its
  upper-tail p-value: one number for "is the whole set of differences larger
  than noise", which sees many small disagreements no single test does. Its
  p-value is exact only for independent tests; with the correlations above it
  is for reading, not the verdict.
- **Per-pixel z spread**: z per pixel and channel from the two per-pixel
  variances, its standard deviation, its robust spread ŝ = median|z| / Φ⁻¹(3/4)
  (:mod:`cornell_harness.evaluate.variance_check`'s) and the fractions below −3
  and above +3 (0.13% each for standard normal z). Reported, not judged. With
  normal batch means and a variance from B batches z is Student-t, sd
  √((B − 1)/(B − 3)) (:func:`expected_pixel_z_sd`). A pixel whose light comes
  partly by rare bright paths (light through glass, a small light seen in a
  mirror) is not normal at a few hundred spp: the image with fewer samples has
  not drawn those paths in most such pixels, so it is low there and its batch
  variance misses what it did not draw; z then has a one-sided tail far beyond
  t's, with no bias on average, and more spp, not more batches, make it normal
  (docs/references.md measures it). A region's z sums many pixels' samples and
  is not skewed this way. :meth:`ReferenceAgreement.spread_remark` says which
  of the two a spread far from t looks like.
- **Power and margins**: per region and channel, the relative bias with its
  Fieller interval at the tests' level (:meth:`ReferenceAgreement.bias`,
  :mod:`cornell_harness.evaluate.relative_bias`), the smallest bias the test
  detects with power 1 − β, β = :data:`DETECTION_BETA`
  (:meth:`ReferenceAgreement.detectable`), and three verdicts against margins
  (:meth:`ReferenceAgreement.verdicts`, :mod:`cornell_harness.evaluate.equivalence`):
  "the engines agree" is then said only where every interval lies inside its margin.

A pixel-channel with no variance on either side and no difference (black
background, a dark room) is 0/0 and says nothing: z = 0; a difference with no
variance is |z| = ∞ and fails; a NaN fails (p = 0), never a silent pass, as in
:mod:`cornell_harness.evaluate.agreement`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.stats import chi2 as chi2_dist
from scipy.stats import norm

from cornell_harness.evaluate.agreement import CHANNELS, sidak_level
from cornell_harness.evaluate.equivalence import (DEFAULT_IMAGE_MARGIN, DEFAULT_REGION_MARGIN, FAIL, INCONCLUSIVE,
                                                  PASS, combine, interval_verdicts)
from cornell_harness.evaluate.relative_bias import BiasIntervals, detectable_bias, interval_text, relative_bias
from cornell_harness.evaluate.variance_check import Q3

#: Family-wise false-alarm rate of a verification: two agreeing engines fail it at most this often.
FAMILY_ALPHA = 0.01
#: Name of the region that is the whole image, tested beside the scene's own regions.
WHOLE_IMAGE = "whole image"
#: |z| beyond which a pixel counts in the reported tail fraction (0.27% for a standard normal).
PIXEL_Z_TAIL = 3.0
#: A tail is one-sided when its smaller side holds less than this share of it (about half for symmetric z).
ONE_SIDED_SHARE = 0.1
#: The miss rate at which the detectable bias is stated: a bias that large is detected with power 1 − β = 0.8.
DETECTION_BETA = 0.2
#: A per-pixel z sd more than this factor from its expectation is remarked on.
PIXEL_Z_SD_FACTOR = 1.25


def expected_pixel_z_sd(batches: int) -> float:
    """The sd of the per-pixel z when the other image's variance is estimated from ``batches`` independent renders
    and dominates, and the batch means are normal: z is then Student-t with batches − 1 degrees of freedom, sd
    √(ν / (ν − 2)) (1.07 for 16 batches); 1 for the engine's own variance (``batches`` = 1) or many batches; ∞
    below 4 batches. Rare bright paths make the batch means far from normal
    (:meth:`ReferenceAgreement.spread_remark`)."""
    if batches <= 1:
        return 1.0
    nu = batches - 1
    return math.sqrt(nu / (nu - 2)) if nu > 2 else math.inf


@dataclass
class RegionAgreement:
    """One region's comparison: per channel (R, G, B) means, difference, z and p."""

    name: str
    pixels: int
    mean_reference: np.ndarray  # (3,)
    mean_other: np.ndarray  # (3,)
    z: np.ndarray  # (3,) (other − reference) / √(V_ref + V_other)
    p: np.ndarray  # (3,) two-sided
    pixel_z_sd: float  # standard deviation of the per-pixel z inside the region (nan if none usable)
    variance_reference: np.ndarray | None = None  # (3,) the variance of the reference's region mean
    variance_other: np.ndarray | None = None  # (3,) and of the other's

    @property
    def difference(self) -> np.ndarray:
        return self.mean_other - self.mean_reference

    @property
    def relative_difference(self) -> np.ndarray:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.mean_reference != 0, self.difference / np.abs(self.mean_reference),
                            np.where(self.difference == 0, 0.0, np.inf))

    @property
    def max_abs_z(self) -> float:
        return float(np.nanmax(np.abs(self.z))) if np.isfinite(self.z).all() else math.inf


@dataclass
class ReferenceAgreement:
    """Outcome of :func:`reference_agreement`: the regions' tests, χ², the per-pixel z spread and the verdict."""

    regions: list[RegionAgreement]
    alpha: float
    tests: int
    level: float  # per-test level after Šidák
    chi2: float
    dof: int
    chi2_p: float
    pixel_z_sd: float  # over the whole image's usable pixel-channels
    pixel_z_spread: float  # robust: median|z| / Φ⁻¹(3/4)
    pixel_z_tail: float  # fraction of usable pixel-channels with |z| > PIXEL_Z_TAIL (a NaN z counts)
    pixel_z_below: float  # fraction with z < −PIXEL_Z_TAIL: the engine lower
    pixel_z_above: float  # fraction with z > PIXEL_Z_TAIL: the engine higher
    pixel_count: int  # usable pixel-channels

    @property
    def failures(self) -> list[tuple[str, str, float, float]]:
        """(region, channel, z, p) of every test below the level, worst first."""
        out = [(r.name, CHANNELS[c], float(r.z[c]), float(r.p[c]))
               for r in self.regions for c in range(3) if r.p[c] < self.level]
        return sorted(out, key=lambda f: (f[3], -abs(f[2]) if math.isfinite(f[2]) else -math.inf))

    @property
    def passed(self) -> bool:
        return not self.failures

    @property
    def p_min(self) -> float:
        return float(min((float(r.p.min()) for r in self.regions), default=1.0))

    @property
    def max_abs_z(self) -> float:
        return max((r.max_abs_z for r in self.regions), default=0.0)

    def bias(self) -> BiasIntervals:
        """Per region and channel (regions, 3): the relative bias other / reference − 1 with its Fieller interval
        at the tests' Šidák level (simultaneous at 1 − α). An interval excludes 0 exactly where the region's
        z-test rejects: both ask whether (other − reference)² > z² (V_other + V_ref)."""
        x, vx, y, vy = (np.array([getattr(r, a) for r in self.regions]) for a in
                        ("mean_other", "variance_other", "mean_reference", "variance_reference"))
        return relative_bias(x, vx, y, vy, self.level)

    def detectable(self, beta: float = DETECTION_BETA) -> np.ndarray:
        """Per region and channel, the smallest relative bias its test detects with power 1 − ``beta``
        (:func:`~cornell_harness.evaluate.relative_bias.detectable_bias`, at the standard error of no bias)."""
        vx, y, vy = (np.array([getattr(r, a) for r in self.regions]) for a in
                     ("variance_other", "mean_reference", "variance_reference"))
        with np.errstate(divide="ignore", invalid="ignore"):
            se = np.where(vx + vy > 0, np.sqrt(vx + vy) / np.abs(y), 0.0)
        return detectable_bias(se, self.level, beta)

    def verdicts(self, margins: np.ndarray) -> np.ndarray:
        """Per region and channel against ``margins`` (regions, 3): fail (the z-test rejects), pass (the interval
        inside ±margin) or inconclusive (:func:`~cornell_harness.evaluate.equivalence.interval_verdicts`)."""
        b = self.bias()
        out = interval_verdicts(b.low, b.high, margins)
        failed = np.array([[r.p[c] < self.level for c in range(3)] for r in self.regions])
        return np.where(failed, FAIL, np.where(out == FAIL, INCONCLUSIVE, out))

    def margins(self, given: Mapping[str, float] | None = None) -> np.ndarray:
        """(regions, 3) margins: ``given`` by region name (:data:`WHOLE_IMAGE` or ``image`` for the whole image),
        else the default of the region's kind (:mod:`cornell_harness.evaluate.equivalence`)."""
        given = dict(given or {})
        if "image" in given:
            given.setdefault(WHOLE_IMAGE, given.pop("image"))
        return np.array([[given.get(r.name, DEFAULT_IMAGE_MARGIN if r.name == WHOLE_IMAGE else DEFAULT_REGION_MARGIN)]
                         * 3 for r in self.regions], np.float64)

    def power_table(self, margins: np.ndarray, beta: float = DETECTION_BETA) -> list[str]:
        """Per region as text lines: its bias interval (the channel reaching furthest past its margin), the bias
        its test detects with power 1 − ``beta`` (the largest over channels), the margin and the verdict."""
        b, det, verdicts = self.bias(), self.detectable(beta), self.verdicts(margins)
        rows = [("region", f"bias [{1 - self.alpha:g} simultaneous interval]", f"detectable (power {1 - beta:g})",
                 "margin", "verdict")]
        for i, r in enumerate(self.regions):
            c = int(np.argmax(np.maximum(np.abs(b.low[i]), np.abs(b.high[i])) / margins[i]))
            rows.append((r.name, interval_text("", float(b.estimate[i, c]), float(b.low[i, c]),
                                               float(b.high[i, c])) + f" ({CHANNELS[c]})",
                         f"{100 * float(det[i].max()):.2g}%", f"±{100 * float(margins[i, c]):g}%",
                         combine(verdicts[i])))
        widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
        return ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]

    def verdict(self, margins: np.ndarray) -> str:
        """pass, fail or inconclusive over every region and channel against ``margins``."""
        return combine(self.verdicts(margins))

    def verdict_message(self, margins: np.ndarray) -> str:
        """The verdict in words: agree within the margins, DISAGREE, or INCONCLUSIVE naming the open regions."""
        verdict = self.verdict(margins)
        if verdict == FAIL:
            return self.message()
        if verdict == PASS:
            return f"the engines agree within the margins (every interval inside): {self.message()}"
        open_ = [r.name for r, v in zip(self.regions, self.verdicts(margins)) if combine(v) != PASS]
        return (f"INCONCLUSIVE: {self.message()}; but {len(open_)} region(s) are not resolved to their margins "
                f"({', '.join(open_)}): their intervals reach past them; more spp (or batches), or wider margins, "
                "resolve them")

    def spread_remark(self, batches: int) -> str | None:
        """A remark when the per-pixel z sd is more than :data:`PIXEL_Z_SD_FACTOR` from the t expectation of
        ``batches`` (:func:`expected_pixel_z_sd`), saying whether its tail is one-sided (rare paths one image did
        not draw, or light one lacks) or two-sided (variances that understate or overstate); None when near."""
        sd, expected = self.pixel_z_sd, expected_pixel_z_sd(batches)
        if not (math.isfinite(sd) and math.isfinite(expected)):
            return None
        if 1 / PIXEL_Z_SD_FACTOR <= sd / expected <= PIXEL_Z_SD_FACTOR:
            return None
        low, high = self.pixel_z_below, self.pixel_z_above
        head = (f"remark: the per-pixel z sd {sd:.2f} is far from the {expected:.2f} expected for {batches} "
                f"batch(es) of normal batch means; {low:.1%} of pixel-channels lie below −{PIXEL_Z_TAIL:g}, "
                f"{high:.1%} above +{PIXEL_Z_TAIL:g}")
        if sd > expected and min(low, high) < ONE_SIDED_SHARE * (low + high):
            lower, other = ("engine", "reference") if low > high else ("reference", "engine")
            return (f"{head}: one-sided, the {lower} is the lower image there. Rare bright paths (light through "
                    f"glass, a small light seen in a mirror) do this where the {lower}'s samples drew them in few "
                    f"pixels and the {other}'s in many: such a pixel is low, and its batch variance misses what "
                    "it did not draw (no bias on average; more spp, not more batches, make it normal). So does "
                    f"light the {lower} lacks. The regions' z sum many pixels' samples and tell the two apart; "
                    f"their χ² p {self.chi2_p:.2g} says whether they are calibrated (docs/references.md)")
        return (f"{head}: the variances {'understate' if sd > expected else 'overstate'} the pixels' spread; "
                "the regions' z use the same variances, so weigh their verdicts with that")

    def message(self) -> str:
        head = (f"{len(self.regions)} region{'s' if len(self.regions) != 1 else ''} × 3 channels = {self.tests} tests at family-wise α = {self.alpha:g} "
                f"(Šidák per-test level {self.level:.3g}); max |z| {self.max_abs_z:.2f}, "
                f"χ² {self.chi2:.1f} on {self.dof} dof (p {self.chi2_p:.3g})")
        if self.passed:
            return f"no significant difference: smallest p = {self.p_min:.3g} ≥ {self.level:.3g}; {head}"
        worst = "; ".join(f"{name} {ch}: z = {z:.2f}, p = {p:.2g}" for name, ch, z, p in self.failures[:3])
        return f"the engines DISAGREE in {len(self.failures)} of {self.tests} tests ({worst}); {head}"

    def table(self) -> list[str]:
        """The per-region table as text lines (one row per region; R G B in each cell)."""
        rows = [("region", "pixels", "reference mean (R G B)", "difference % (R G B)", "z (R G B)", "min p",
                 "pixel z sd")]
        for r in self.regions:
            rows.append((r.name, str(r.pixels), " ".join(f"{m:.4g}" for m in r.mean_reference),
                         " ".join(f"{100 * d:+.3f}" for d in r.relative_difference),
                         " ".join(f"{z:+.2f}" for z in r.z), f"{float(r.p.min()):.3g}"
                         + (" *" if (r.p < self.level).any() else ""),
                         "-" if math.isnan(r.pixel_z_sd) else f"{r.pixel_z_sd:.3f}"))
        widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
        return ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]

    def summary(self, margins: np.ndarray | None = None) -> dict:
        """Plain, JSON-safe data of the verdict (what a reference's provenance records); with ``margins``, the
        three-way verdict and per region its bias interval, detectable bias and margin too."""
        def num(x: float, digits: int = 4) -> float | None:
            return float(f"{x:.{digits}g}") if math.isfinite(x) else None
        out = self._summary(num)
        if margins is not None:
            b, det = self.bias(), self.detectable()
            out["verdict"] = self.verdict(margins)
            out["detection_beta"] = DETECTION_BETA
            for i, r in enumerate(self.regions):
                out["regions"][r.name].update(
                    bias=[num(v, 3) for v in b.estimate[i]], bias_low=[num(v, 3) for v in b.low[i]],
                    bias_high=[num(v, 3) for v in b.high[i]], detectable=[num(v, 3) for v in det[i]],
                    margin=[num(v, 3) for v in margins[i]])
        return out

    def _summary(self, num) -> dict:
        return {
            "passed": self.passed, "alpha": self.alpha, "tests": self.tests, "level": num(self.level),
            "max_abs_z": num(self.max_abs_z), "p_min": num(self.p_min), "chi2": num(self.chi2), "dof": self.dof,
            "chi2_p": num(self.chi2_p),
            "pixel_z": {"sd": num(self.pixel_z_sd), "robust_spread": num(self.pixel_z_spread),
                        f"fraction_beyond_{PIXEL_Z_TAIL:g}": num(self.pixel_z_tail),
                        f"fraction_below_-{PIXEL_Z_TAIL:g}": num(self.pixel_z_below),
                        f"fraction_above_{PIXEL_Z_TAIL:g}": num(self.pixel_z_above), "count": self.pixel_count},
            "regions": {r.name: {"pixels": r.pixels, "mean_reference": [num(m, 6) for m in r.mean_reference],
                                 "mean_other": [num(m, 6) for m in r.mean_other],
                                 "z": [num(z, 3) for z in r.z], "p": [num(p, 3) for p in r.p]}
                        for r in self.regions},
        }


def region_mean(image: np.ndarray, variance: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per channel: the mean of ``image`` over ``mask``'s n pixels and that mean's variance Σ var / n²."""
    x, v = np.asarray(image, np.float64)[mask], np.asarray(variance, np.float64)[mask]
    n = x.shape[0]
    return x.mean(axis=0), v.sum(axis=0) / n**2


def z_scores(diff: np.ndarray, var: np.ndarray) -> np.ndarray:
    """diff/√var; 0 where both are 0 (no information), ±inf where only the variance is 0, NaN kept."""
    diff, var = np.asarray(diff, np.float64), np.asarray(var, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = diff / np.sqrt(var)
    return np.where((var == 0) & (diff == 0), 0.0, z)


def two_sided_p(z: np.ndarray) -> np.ndarray:
    """2 Φ(−|z|); a NaN z gives p = 0 (a test that cannot be evaluated rejects)."""
    return np.nan_to_num(2.0 * norm.sf(np.abs(z)), nan=0.0)


def pixel_z_stats(z: np.ndarray, usable: np.ndarray) -> tuple[float, float, float, float, float, int]:
    """(sd, robust spread median|z|/Φ⁻¹(3/4), fraction |z| > PIXEL_Z_TAIL, fraction z < −PIXEL_Z_TAIL, fraction
    z > PIXEL_Z_TAIL, count) of the usable z.

    The sd is over the finite z only (an infinite one would make it meaningless; it counts in the tail, and on
    its side); a NaN z counts in the tail, on neither side."""
    zs = np.asarray(z, np.float64)[usable]
    if zs.size == 0:
        return math.nan, math.nan, 0.0, 0.0, 0.0, 0
    absz = np.where(np.isnan(zs), np.inf, np.abs(zs))
    finite = zs[np.isfinite(zs)]
    sd = float(np.sqrt(np.mean(finite**2))) if finite.size else math.nan  # about the known centre 0
    return (sd, float(np.median(absz)) / Q3, float(np.mean(absz > PIXEL_Z_TAIL)),
            float(np.mean(zs < -PIXEL_Z_TAIL)), float(np.mean(zs > PIXEL_Z_TAIL)), int(zs.size))


def reference_agreement(reference: np.ndarray, reference_variance: np.ndarray, other: np.ndarray,
                        other_variance: np.ndarray, masks: Mapping[str, np.ndarray],
                        alpha: float = FAMILY_ALPHA) -> ReferenceAgreement:
    """Compare ``other`` (a second engine's image, with its variance of the mean) with the reference.

    ``masks`` are the scene's named regions (name -> (H, W) bool); the whole
    image is tested too, as :data:`WHOLE_IMAGE`. Regions without pixels are
    left out. See the module docstring for the statistics.
    """
    ref, other = np.asarray(reference, np.float64), np.asarray(other, np.float64)
    if ref.shape != other.shape:
        raise ValueError(f"the two images differ in shape: reference {ref.shape}, other {other.shape}")
    var_ref, var_other = np.asarray(reference_variance, np.float64), np.asarray(other_variance, np.float64)
    pixel_diff, pixel_var = other - ref, var_ref + var_other
    z_pix = z_scores(pixel_diff, pixel_var)
    usable = ~((pixel_var == 0) & (pixel_diff == 0))
    regions = []
    whole = np.ones(ref.shape[:2], dtype=bool)
    if WHOLE_IMAGE in masks:
        raise ValueError(f"a region may not be named {WHOLE_IMAGE!r}: that name is the whole image's")
    for name, mask in [(WHOLE_IMAGE, whole), *masks.items()]:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != ref.shape[:2]:
            raise ValueError(f"region {name!r}: mask shape {mask.shape} does not match image shape {ref.shape[:2]}")
        n = int(np.count_nonzero(mask))
        if n == 0:
            continue
        m_ref, v_ref = region_mean(ref, var_ref, mask)
        m_other, v_other = region_mean(other, var_other, mask)
        z = z_scores(m_other - m_ref, v_ref + v_other)
        sd = pixel_z_stats(z_pix[mask], usable[mask])[0]
        regions.append(RegionAgreement(name, n, m_ref, m_other, z, two_sided_p(z), sd, v_ref, v_other))
    tests = 3 * len(regions)
    zs = np.concatenate([r.z for r in regions]) if regions else np.zeros(0)
    chi2 = float(np.sum(np.where(np.isnan(zs), np.inf, zs) ** 2))  # a NaN test counts as infinitely far
    chi2_p = float(chi2_dist.sf(chi2, tests)) if tests else 1.0
    return ReferenceAgreement(regions, alpha, tests, sidak_level(alpha, tests), chi2, tests, chi2_p,
                              *pixel_z_stats(z_pix, usable))

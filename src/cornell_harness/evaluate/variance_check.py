"""Does a renderer overstate its variance? A sign test on the spread of its z-scores.

The agreement test (:mod:`cornell_harness.evaluate.agreement`) measures distance in
units of the variance the renderer reports, so a renderer that overstates
its variance hides its bias: 1% too dark and reporting 100× its true
variance, it passes at every seed. This check tests the reported variance
against the renderer's own residuals.

**Statistic.** Per pixel and channel, z = (img − ref) / √(var_img + var_ref).
If ``var_img`` is right, z has unit spread, and a renderer that reports F
times its true variance gives a spread of about 1/√F. The spread is
estimated robustly, as the median absolute deviation of z about its known
centre 0 scaled to the normal, ŝ = median|z| / Φ⁻¹(3/4) (Hampel 1974,
J. Am. Stat. Assoc. 69, 383-393): Monte Carlo residuals are heavy-tailed
at low spp, and a few fireflies, which dominate any mean of z², cannot
move a median.

**Tolerance.** A correct renderer does not give ŝ = 1 exactly. With the
renderer's own estimate of its variance from n samples, z is a
Student-type ratio, wider than normal because that estimate is noisy
(relative sd √((κ−1)/n) for samples of kurtosis κ; Monte Carlo samples
have large κ) and correlated with the mean where the samples are skewed.
The estimate's noise widens z on average (1/√v̂ is convex: Jensen), so
the tolerance is asymmetric: ŝ must lie in [1/(1+δ), 1 + δ + 1/√n] with
δ = :data:`TOLERANCE` = 0.1. The 1/√n term is calibrated on our path
tracer, whose ŝ is 1.24, 1.15, 1.09, 1.06 and 1.03 at 8, 16, 32, 64 and
256 spp on the Cornell box (about 1 + 0.75 n^−0.6), and 0.93-1.06 on the
furnace and the light panel at 256 spp, whose 1024 and 4096 pixels make
ŝ vary more between seeds (see ``docs/gate-detection.md``):
1/√n is 0.35, 0.25, 0.18, 0.125 and 0.06 there. A reported variance
more than (1+δ)² ≈ 1.21 times too large fails at any spp, given enough
pixels.

**Understatement: a ratio of sums, not the median.** ŝ above
1 + δ + 1/√n (the residuals larger than the reported variance allows) is
*not* a reliable sign of understatement: a correct renderer gives it where
its per-pixel samples are strongly skewed. Where rare paths carry much of
the radiance (caustics, light through glass), most pixels of a 256-spp
render have not yet drawn one, so they lie below the mean with a small
estimated variance: our path tracer on ``cornell-box-caustics`` at 256
spp, unbiased, has median z = −1.76 and ŝ = 2.6. Sums are immune to that
skew: an unbiased variance estimate v̂ (the sample variance over n, or the
spread of independent batch means) has E v̂ = Var(img) however skewed the
samples, so for an unbiased renderer E d² = E v with d = img − ref and v =
var_img + var_ref, pixel by pixel. A renderer that reports 1/F of its
variance has E d² ≈ F·E v. The statistic is the ratio R = Σd²/Σv over the
usable pixel-channels (≈ F), and the test is one-sided on the pixel units
u_i = Σ_c d² − c·Σ_c v (channels of a pixel summed: they share paths):
H₀: E u ≤ 0, i.e. the variance is understated by less than
c = :data:`UNDERSTATEMENT` = √2, the midpoint on the log scale between
right (1) and 2× too small. It rejects when the t statistic
t = ū/(s_u/√N) exceeds the Student quantile at α/2 (the pixels are
independent; N ≥ 1024 in every gate scene, so the CLT holds for the mean
of u). A correct renderer has E u = (1 − c)·E v < 0, a margin of 0.41
Σv; one that reports half its variance has E u = (2 − c)·E v, and t grows
as √N: over 20 seeds (``docs/gate-detection.md``) the furnace, light panel,
glass furnace and AO expectations fail ÷2 at every seed; the Cornell box
rendered at 64×64 (4096 pixels, its fireflies in Σd²) fails ÷4 at 17 of 20
and ÷2 at none, so the gate's power there comes from the other scenes. Fireflies, which dominate sums
of squares, raise v̂ of their pixel about as much as d², so they push u
down, not up; the measured false-alarm rate over 20 seeds of every
unbiased renderer that reports a variance is in ``docs/gate-detection.md``.
A bias also raises Σd² (by the squared bias): a bias of RMS above
≈ 0.64 of the noise fails here as well as in the agreement test, and
the message says so. Pixel-channels with a non-finite value or variance
are the ``finite`` check's and are left out of the sums.

**Test of overstatement.** One-sided sign tests of a quantile. ŝ ≥ s_lo = 1/(1+δ)
means that at most half the |z| lie below c_lo = Φ⁻¹(3/4)·s_lo (the
test); ŝ ≤ s_hi, that at most half lie above c_hi = Φ⁻¹(3/4)·s_hi (a
note only, for the skew above). The three channels of a pixel come from the same
paths, so the units are pixels (independent): each contributes the
fraction of its channels beyond the cut, a number in [0, 1], and f is the
mean over the N pixels (E f ≤ 1/2 when ŝ is within the tolerance). Hoeffding's inequality
(Hoeffding 1963, J. Am. Stat. Assoc. 58, 13-30) bounds
P(f − E f ≥ ε) ≤ exp(−2Nε²) for any distribution of those fractions and
any dependence between a pixel's channels; with
ε = √(ln(2/α) / (2N)) the test rejects a renderer whose spread is within
the tolerance with probability at most α/2. No assumption on the tails of z enters. With the
understatement test at α/2, a correct renderer fails the check with probability at most α.

A pixel-channel that agrees with the reference exactly (d = 0: a black
background, AO exactly 1 beyond its maximum distance, where both renderers
are exact) says nothing of the variance, whatever variance it reports, and
is left out of both tests; one with no variance but a difference
(|z| = ∞) or a NaN counts as a large |z|.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import norm
from scipy.stats import t as student

CHANNELS = "RGB"
#: Tolerance δ on the spread of z: ŝ within [1/(1+δ), 1 + δ + 1/√spp] passes (see the module docstring).
TOLERANCE = 0.1
#: c: a reported variance more than this many times too small is the understatement test's alternative (module
#: docstring); √2 puts right (1) and 2× too small equally far from it on the log scale.
UNDERSTATEMENT = math.sqrt(2.0)
#: Φ⁻¹(3/4): median |z| of a standard normal z.
Q3 = float(norm.ppf(0.75))


@dataclass
class VarianceCheck:
    """Outcome of :func:`variance_check`."""

    passed: bool
    alpha: float
    tolerance: float
    spp: int
    scale: float  # ŝ = median|z| / Φ⁻¹(3/4) over all pixel-channels used
    scale_channels: tuple[float, float, float]  # the same per channel (nan where a channel has no data)
    frac_low: float  # f_lo: mean over pixels of the fraction of channels with |z| < c_lo (at most 1/2 + eps)
    frac_high: float  # f_hi: the same with |z| > c_hi (reported, not failed: see the module docstring)
    eps: float  # Hoeffding margin
    pixels: int  # N, pixels with at least one usable channel
    ratio: float = math.nan  # R = Σd² / Σ(reported + reference variance): about F for a variance F× too small
    t_under: float = math.nan  # t statistic of u = Σ_c d² − c·Σ_c v against 0 (understatement test)
    t_limit: float = math.inf  # its critical value, Student's at α/2
    understatement: float = UNDERSTATEMENT  # c

    @property
    def overstated(self) -> bool:
        return self.frac_low > 0.5 + self.eps

    @property
    def understated(self) -> bool:
        return self.t_under > self.t_limit

    @property
    def bounds(self) -> tuple[float, float]:
        return spread_bounds(self.tolerance, self.spp)

    @property
    def variance_factor(self) -> float:
        """How many times the true variance the renderer reports, about 1/ŝ² (inf when ŝ = 0)."""
        return 1.0 / self.scale**2 if self.scale > 0 else math.inf

    def message(self) -> str:
        lo, hi = self.bounds
        by_channel = ", ".join(f"{c} {s:.3f}" for c, s in zip(CHANNELS, self.scale_channels))
        head = (f"robust spread of z = (render − reference)/√(reported variance + reference variance): "
                f"ŝ = median|z|/{Q3:.4f} = {self.scale:.3f} over {self.pixels} pixels (by channel: {by_channel})")
        rule = (f"tolerance [{lo:.3f}, {hi:.3f}] (1/(1+δ), 1 + δ + 1/√spp; δ = {self.tolerance:g}, "
                f"{self.spp} spp), "
                f"sign tests at α = {self.alpha:.3g} "
                f"(Hoeffding margin ±{self.eps:.4f} on the fractions)")
        if self.pixels == 0:
            return "no pixel with a variance or a difference: nothing to test"
        under = (f"Σd²/Σv = {self.ratio:.3g} (d = render − reference, v = reported + reference variance), "
                 f"t = {self.t_under:.2f} against {self.t_limit:.2f} for H₀: understated less than "
                 f"{self.understatement:.3g}× (one-sided at α/2 = {self.alpha / 2:.3g})")
        if self.understated:
            return (f"the renderer reports less variance than its residuals show, about {self.ratio:.3g}× too little "
                    f"over the whole image (or it is biased: a bias adds its square to the residuals): {under}; "
                    f"{head}; {rule}")
        if self.overstated:
            return (f"the renderer reports more variance than its residuals show, about {self.variance_factor:.3g}× "
                    f"too much over the whole image: {head}; {self.frac_low:.1%} of |z| < {Q3 * lo:.3f} where at most "
                    f"{0.5 + self.eps:.1%} may be; {rule}")
        if self.frac_high > 0.5 + self.eps:
            return (f"reported variance neither overstated nor understated ({under}); the median |z| is larger than "
                    f"it allows, ŝ about {1 / self.scale:.3g}× too wide, as where per-pixel samples are skewed by "
                    f"rare bright paths (caustics at low spp): {head}; {self.frac_high:.1%} of |z| > "
                    f"{Q3 * hi:.3f}; {rule}")
        return f"reported variance consistent with the residuals: {under}; {head}; {rule}"


def spread_bounds(tolerance: float, spp: int) -> tuple[float, float]:
    """The interval [1/(1+δ), 1 + δ + 1/√spp] that the spread of z may lie in."""
    return 1.0 / (1.0 + tolerance), 1.0 + tolerance + 1.0 / math.sqrt(max(spp, 1))


def variance_check(img: np.ndarray, var_img: np.ndarray, ref: np.ndarray, var_ref: np.ndarray, spp: int,
                   alpha: float = 0.01, tolerance: float = TOLERANCE) -> VarianceCheck:
    """Test that ``var_img``, the renderer's own variance of ``img`` (``spp`` samples), matches its residuals."""
    img, ref = np.asarray(img, np.float64), np.asarray(ref, np.float64)
    var = np.asarray(var_img, np.float64) + np.asarray(var_ref, np.float64)
    diff = img - ref
    with np.errstate(divide="ignore", invalid="ignore"):
        absz = np.abs(diff) / np.sqrt(var)
    usable = diff != 0  # exact agreement: no information (module docstring); NaN stays usable, as a large |z|
    absz = np.where(np.isnan(absz), np.inf, absz)  # a NaN counts as a large |z|
    s_lo, s_hi = spread_bounds(tolerance, spp)
    c_lo, c_hi = Q3 * s_lo, Q3 * s_hi
    n_ch = usable.sum(axis=-1)
    pix = n_ch > 0
    n = int(pix.sum())
    if n == 0:
        return VarianceCheck(True, alpha, tolerance, spp, math.nan, (math.nan,) * 3, 0.0, 0.0, math.inf, 0)
    low = ((absz < c_lo) & usable).sum(axis=-1)[pix] / n_ch[pix]
    high = ((absz > c_hi) & usable).sum(axis=-1)[pix] / n_ch[pix]
    f_lo, f_hi = float(low.mean()), float(high.mean())
    eps = math.sqrt(math.log(2.0 / alpha) / (2.0 * n))
    scale = float(np.median(absz[usable])) / Q3
    per = tuple(float(np.median(absz[..., c][usable[..., c]])) / Q3 if usable[..., c].any() else math.nan
                for c in range(3))
    ratio, t_under, t_limit = understatement_test(diff, var, alpha / 2.0)
    v = VarianceCheck(True, alpha, tolerance, spp, scale, per, f_lo, f_hi, eps, n, ratio, t_under, t_limit)
    v.passed = not (v.overstated or v.understated)
    return v


def understatement_test(diff: np.ndarray, var: np.ndarray, level: float,
                        c: float = UNDERSTATEMENT) -> tuple[float, float, float]:
    """(R = Σd²/Σv, t of u = Σ_c d² − c·Σ_c v per pixel, Student's critical value at ``level``): module docstring.

    Pixel-channels with a non-finite difference or variance, and exact ones (d = 0), are left out; t is 0 where u is
    constant and not positive, inf where it is constant and positive (v = 0 everywhere and d not).
    """
    ok = np.isfinite(diff) & np.isfinite(var) & (diff != 0)
    a = np.where(ok, diff * diff, 0.0).sum(axis=-1)
    b = np.where(ok, var, 0.0).sum(axis=-1)
    pix = ok.any(axis=-1)
    a, b = a[pix], b[pix]
    n = a.size
    if n < 2:
        return math.nan, math.nan, math.inf
    ratio = float(a.sum() / b.sum()) if b.sum() > 0 else math.inf
    u = a - c * b
    mean, sd = float(u.mean()), float(u.std(ddof=1))
    t = mean / (sd / math.sqrt(n)) if sd > 0 else (math.inf if mean > 0 else 0.0)
    return ratio, t, float(student.isf(level, n - 1))

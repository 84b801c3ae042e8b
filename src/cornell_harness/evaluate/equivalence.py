"""Three verdicts from confidence intervals and margins: pass (equivalence), fail, inconclusive.

A test of "no bias" alone can only fail: its pass says that no bias was
seen at this budget, not that none larger than some bound is there. A
*margin* m states the smallest bias that matters, and turns the question
round (equivalence testing):

- **pass**: the (1 − α) confidence interval of the bias lies inside
  [−m, +m]. This is the interval-inclusion form of the two one-sided tests
  (TOST; Schuirmann 1987, "A comparison of the two one-sided tests procedure
  and the power approach for assessing the equivalence of average
  bioavailability", J. Pharmacokinet. Biopharm. 15, 657-680): a two-sided
  (1 − α) interval inside ±m is TOST at level α/2 on each side, so a bias of
  at least m passes with probability at most α/2. Over several regions and
  channels a pass needs every interval inside its margin: an
  intersection-union test (Berger 1982, "Multiparameter hypothesis testing
  and acceptance sampling", Technometrics 24, 295-300), whose false-pass rate
  is at most the largest of its parts', so it needs no multiplicity
  correction; the callers still use Šidák-corrected, simultaneous intervals,
  so that every interval they print covers at the stated level together.
- **fail**: the bias is significant (the interval lies wholly beyond a
  tolerance, 0 for an unbiased renderer; or the caller's own test says so).
- **inconclusive**: neither. More samples resolve it: the interval's
  half-width must fall to max(m − |b̂|, |b̂| − tolerance) at the estimate b̂
  (:func:`resolving_half_width`), which
  :func:`cornell_harness.evaluate.relative_bias.spp_for_half_width` turns
  into spp.

Pure functions on arrays of any one shape (regions × channels).
"""

from __future__ import annotations

import numpy as np

PASS, FAIL, INCONCLUSIVE = "pass", "fail", "inconclusive"
VERDICTS = (PASS, FAIL, INCONCLUSIVE)
#: The whole image's default margin of relative bias: an energy error of 1% across the image is one to see.
DEFAULT_IMAGE_MARGIN = 0.01
#: A named region's default margin: regions are small (a caustic, a shadow), their means noisier.
DEFAULT_REGION_MARGIN = 0.05


def inside(low, high, margin) -> np.ndarray:
    """Where the interval [low, high] lies inside [−margin, +margin] (equivalence shown)."""
    low, high, margin = (np.asarray(a, np.float64) for a in (low, high, margin))
    return (low >= -margin) & (high <= margin)


def beyond(low, high, tolerance=0.0) -> np.ndarray:
    """Where the interval lies wholly outside [−tolerance, +tolerance] (a bias beyond it is significant)."""
    low, high, tol = (np.asarray(a, np.float64) for a in (low, high, tolerance))
    return (low > tol) | (high < -tol)


def interval_verdicts(low, high, margin, tolerance=0.0) -> np.ndarray:
    """Per interval: :data:`FAIL` wholly beyond ±tolerance, :data:`PASS` inside ±margin, else
    :data:`INCONCLUSIVE` (an array of those strings)."""
    out = np.where(inside(low, high, margin), PASS, INCONCLUSIVE)
    return np.where(beyond(low, high, tolerance), FAIL, out)


def combine(verdicts) -> str:
    """One verdict of several: fail if any fails, else inconclusive if any is, else pass (none: pass)."""
    v = set(np.asarray(verdicts, dtype=object).ravel().tolist())
    return FAIL if FAIL in v else INCONCLUSIVE if INCONCLUSIVE in v else PASS


def resolving_half_width(estimate, margin, tolerance=0.0) -> np.ndarray:
    """The half-width at which an interval centred on ``estimate`` stops straddling: max(margin − |b̂|,
    |b̂| − tolerance). At most 0 (never resolved by a narrower interval) only where |b̂| is exactly the margin
    and the tolerance is the margin."""
    b, m, tol = (np.abs(np.asarray(a, np.float64)) for a in (estimate, margin, tolerance))
    return np.maximum(m - b, b - tol)

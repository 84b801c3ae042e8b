"""Sampled spectra and their projection to linear sRGB: what a spectral scene's colours mean for RGB renderers.

This module owns the sampled spectrum (:class:`Spectrum`), its interpolation,
and the colour pipeline a spectral scene declares: the observer, the output
space, the two named conventions that turn a reflectance spectrum into an RGB
reflectance, and the rule that turns an emission spectrum into an RGB
radiance. Scenes bind spectra to materials and emitters in
:mod:`cornell_harness.scenes.spectral_scene`.

Sampled spectrum
----------------
Wavelengths in nm, strictly increasing, with one finite value each. Between
samples the spectrum is the linear interpolation; outside ``[first, last]``
it is zero (``extrapolation = "zero"``, the default) or the nearest end value
(``"constant"``).

Colour pipeline (:data:`OBSERVER`, :data:`OUTPUT`)
-------------------------------------------------
- Observer: the CIE 1931 2° standard colorimetric observer (CIE 015:2018,
  §7.1), colour-science's ``CIE 1931 2 Degree Standard Observer`` table,
  360–830 nm at 1 nm. Tristimulus values are the sums
  X = Σ S(λ) x̄(λ) Δλ (and Y, Z alike) over that grid, Δλ = 1 nm, with the
  spectrum interpolated onto it (CIE 015:2018, eq. 7.1–7.3, as sums).
- Output: linear sRGB, IEC 61966-2-1:1999 (ITU-R BT.709 primaries, D65
  white), XYZ → RGB by the standard's matrix (§5.2, colour-science's
  ``RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB``), no transfer function and
  no chromatic adaptation.

RGB conventions (for reflectances; :data:`RGB_CONVENTIONS`)
------------------------------------------------------------
- :data:`ILLUMINANT_E` (``"illuminant_E"``): XYZ of ρ(λ) under the
  equal-energy illuminant E, normalised so that a perfect white has Y = 1,
  i.e. XYZ = Σ ρ x̄ / Σ ȳ, then the matrix. These are Mitsuba 3's
  ``mi.cornell_box()`` reflectances and the values
  ``derived_reference_values_colour_science_cie1931_2deg.illuminant_E_to_linear_sRGB_no_adaptation``
  of Cornell's data (``src/cornell_harness/scenes/data/cornell-pcg.json``). A perfect
  white maps to M·(1, 1, 1) ≈ (1.205, 0.948, 0.909), not to (1, 1, 1).
- :data:`SCENE_LIGHT` (``"scene_light"``): ρ under the scene's own light
  spectrum L, white-balanced to it per channel:
  ρ_c = RGB_c(ρ·L) / RGB_c(L), with RGB(S) = M · Σ S x̄ / Σ ȳ. So an RGB
  renderer's product ρ_c · L_c (L_c by the emitter rule below) equals the
  RGB of the spectral product ρ·L: light reflected once off the surface is
  exact, and a perfect white maps to exactly (1, 1, 1). Normalising by the
  light's Y alone would give a perfect white the light's own colour, which an
  RGB renderer then multiplies by the light's RGB again. Under D65 the two
  normalisations agree to ~1e-3 (RGB(D65)/Y ≈ (1, 1, 1)); the data's
  ``D65_to_linear_sRGB`` values check this rule with L = D65.

Emitters (:func:`emission_rgb`)
-------------------------------
An emission spectrum L(λ) maps to RGB radiance M · Σ L x̄ / Σ ȳ, in both
conventions: the ȳ-normalised tristimulus values, so a flat spectrum of value
c has Y = c, in the same units as L's values. Mitsuba 3's spectral film divides
by the same integral (its ``CIE_Y_integral``), so a spectral reference's
XYZ → linear sRGB and an RGB renderer's radiance are on one scale.

Data
----
:data:`CORNELL_PCG` (``src/cornell_harness/scenes/data/cornell-pcg.json``) is a copy, shipped
in the package, of the project's shared ``shared/data/cornell-pcg.json``: the
Cornell Program of Computer Graphics' "Cornell Box Data" page (its ``source``
field), geometry in mm, reflectance and emission spectra, and derived RGB
values the tests check these projections against.

colour-science is imported lazily (``import colour`` takes ~1.5 s), only when
a projection is first computed, and every projection is cached.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: The observer a spectral scene declares (``[colour] observer``): CIE 1931 2°.
OBSERVER = "CIE1931_2"
#: The output space (``[colour] output``): linear sRGB, D65 white (IEC 61966-2-1).
OUTPUT = "linear_srgb_d65"
#: Reflectance under the equal-energy illuminant E, no adaptation (mi.cornell_box()'s values).
ILLUMINANT_E = "illuminant_E"
#: Reflectance under the scene's own light, white-balanced to it per channel.
SCENE_LIGHT = "scene_light"
#: The conventions by which a reflectance spectrum becomes an RGB reflectance (module docstring).
RGB_CONVENTIONS: dict[str, str] = {
    ILLUMINANT_E: "XYZ of reflectance x E, perfect white Y = 1, to linear sRGB without adaptation",
    SCENE_LIGHT: "RGB of reflectance x scene light divided per channel by the light's RGB (white -> 1, 1, 1)",
}
#: How a spectrum continues outside its sampled range.
EXTRAPOLATIONS: dict[str, str] = {
    "zero": "zero outside [first, last] wavelength",
    "constant": "the nearest end value outside [first, last] wavelength",
}
#: Cornell's measured box data (module docstring, Data).
CORNELL_PCG = Path(__file__).resolve().parent / "data" / "cornell-pcg.json"
#: colour-science's name of the observer's table.
_COLOUR_OBSERVER = "CIE 1931 2 Degree Standard Observer"
#: Fewest samples of a spectrum (a line needs two).
MIN_SAMPLES = 2
#: Largest |value| of a spectrum: the same bound as an RGB radiance (cornell_harness.scenes.model.MAX_RADIANCE).
MAX_SPECTRUM_VALUE = 1e30


@dataclass(frozen=True)
class Spectrum:
    """A sampled spectrum: ``wavelengths_nm`` strictly increasing, one value each (module docstring).

    Tuples, so a spectrum is hashable and its projections cache.
    """

    wavelengths_nm: tuple[float, ...]
    values: tuple[float, ...]
    extrapolation: str = "zero"

    def at(self, wavelengths_nm) -> np.ndarray:
        """The spectrum at ``wavelengths_nm`` (any shape), float64: linear between samples, extrapolated outside."""
        return interpolate(np.asarray(self.wavelengths_nm), np.asarray(self.values), wavelengths_nm,
                           self.extrapolation)

    def hash_payload(self) -> dict:
        return {"wavelengths_nm": list(self.wavelengths_nm), "values": list(self.values),
                "extrapolation": self.extrapolation}


def interpolate(wavelengths: np.ndarray, values: np.ndarray, at, extrapolation: str = "zero") -> np.ndarray:
    """Linear interpolation of samples (``wavelengths`` strictly increasing) at ``at``; outside the range zero
    (``"zero"``) or the end value (``"constant"``)."""
    outside = 0.0 if extrapolation == "zero" else None
    return np.interp(np.asarray(at, dtype=np.float64), np.asarray(wavelengths, dtype=np.float64),
                     np.asarray(values, dtype=np.float64), left=outside, right=outside)


def written_samples(spectrum: Spectrum, lo: float, hi: float, zero_step: float | None = None
                    ) -> tuple[list[float], list[float]]:
    """The samples of ``spectrum`` as written for a renderer whose sampled spectra are zero outside their samples
    and linear between them (Mitsuba's ``irregular`` plugin, pbrt-v4's inline ``"spectrum"``): the extrapolation
    written out over its wavelength range [``lo``, ``hi``] nm.

    ``"constant"``: the end values repeated at ``lo`` and ``hi``. ``"zero"``: as the samples are, or, with
    ``zero_step``, with a zero sample ``zero_step`` nm beyond each end whose value is not zero, so that a reader
    which extends a spectrum's end values instead (pbrt-v4 does for its spectrum files) still reads zero there.
    That ramp over ``zero_step`` nm is the only change: of the order ``zero_step`` / (the range's width).
    """
    w, v = [float(x) for x in spectrum.wavelengths_nm], [float(x) for x in spectrum.values]
    if spectrum.extrapolation == "constant":
        if w[0] > lo:
            w, v = [lo] + w, [v[0]] + v
        if w[-1] < hi:
            w, v = w + [hi], v + [v[-1]]
    elif zero_step is not None:
        if v[0] != 0.0:
            w, v = [w[0] - zero_step] + w, [0.0] + v
        if v[-1] != 0.0:
            w, v = w + [w[-1] + zero_step], v + [0.0]
    return w, v


def spectrum_problem(wavelengths: list, values: list, extrapolation: str) -> tuple[str, str] | None:
    """What is wrong with a spectrum's samples, as (field, message), the field relative to the spectrum's table
    (``values[3]``); None if nothing is."""
    for key, raw in (("wavelengths_nm", wavelengths), ("values", values)):
        if not isinstance(raw, list):
            return key, f"expected a list of numbers, got {type(raw).__name__}"
        for i, x in enumerate(raw):
            if isinstance(x, bool) or not isinstance(x, (int, float)):
                return f"{key}[{i}]", f"expected a number, got {type(x).__name__}"
            try:
                x = float(x)
            except OverflowError:
                return f"{key}[{i}]", "out of range: an integer beyond float64"
            if not math.isfinite(x) or abs(x) > MAX_SPECTRUM_VALUE:
                return f"{key}[{i}]", f"must be finite and |value| <= {MAX_SPECTRUM_VALUE:g}, got {x:g}"
    if len(wavelengths) < MIN_SAMPLES:
        return "wavelengths_nm", f"needs at least {MIN_SAMPLES} samples, got {len(wavelengths)}"
    if len(values) != len(wavelengths):
        return "values", f"needs one value per wavelength: {len(wavelengths)} wavelengths, {len(values)} values"
    for i in range(1, len(wavelengths)):
        if not float(wavelengths[i]) > float(wavelengths[i - 1]):
            return f"wavelengths_nm[{i}]", (f"wavelengths must be strictly increasing, got {wavelengths[i - 1]} "
                                            f"then {wavelengths[i]}")
    if float(wavelengths[0]) <= 0.0:
        return "wavelengths_nm[0]", f"wavelengths are in nm and must be positive, got {wavelengths[0]}"
    if extrapolation not in EXTRAPOLATIONS:
        return "extrapolation", f"unknown extrapolation {extrapolation!r}; known: {', '.join(EXTRAPOLATIONS)}"
    return None


def _colour():
    """colour-science, imported lazily (~1.5 s, only when a spectrum is projected), without the warning it prints
    on import when matplotlib is absent (its plotting, which the harness does not use)."""
    import warnings

    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message='"Matplotlib" related API features are not available')
        import colour
    return colour


@functools.cache
def observer() -> tuple[np.ndarray, np.ndarray]:
    """The CIE 1931 2° colour-matching functions: wavelengths (n,) in nm at 1 nm, and x̄ȳz̄ (n, 3); read-only."""
    colour = _colour()

    cmfs = colour.MSDS_CMFS[_COLOUR_OBSERVER]
    wavelengths, xyz_bar = np.array(cmfs.wavelengths, dtype=np.float64), np.array(cmfs.values, dtype=np.float64)
    assert np.all(np.diff(wavelengths) == 1.0), "the sums below take Δλ = 1 nm"
    wavelengths.setflags(write=False)
    xyz_bar.setflags(write=False)
    return wavelengths, xyz_bar


@functools.cache
def xyz_to_linear_srgb() -> np.ndarray:
    """The XYZ → linear sRGB matrix of IEC 61966-2-1 (D65 white, no adaptation), (3, 3), read-only."""
    colour = _colour()

    m = np.array(colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB, dtype=np.float64)
    m.setflags(write=False)
    return m


def tristimulus(values: np.ndarray, xyz_bar: np.ndarray) -> np.ndarray:
    """XYZ = Σ S(λ) (x̄, ȳ, z̄)(λ) Δλ over a 1 nm grid, for ``values`` S already on that grid (CIE 015:2018 eq. 7.1-7.3)."""
    return np.asarray(values, dtype=np.float64) @ xyz_bar


def _rgb(spectrum_on_grid: np.ndarray) -> np.ndarray:
    """M · Σ S x̄ / Σ ȳ: the ȳ-normalised tristimulus values of S, to linear sRGB."""
    _, xyz_bar = observer()
    return xyz_to_linear_srgb() @ (tristimulus(spectrum_on_grid, xyz_bar) / xyz_bar[:, 1].sum())


def _rounded(rgb: np.ndarray) -> tuple[float, float, float]:
    # 12 decimals: the projection enters the scene's content hash, which must not depend on the last bits
    # of a BLAS sum.
    return tuple(float(round(float(x), 12)) for x in rgb)


def luminance(emission: Spectrum) -> float:
    """The luminance Y = Σ L ȳ / Σ ȳ of an emission spectrum, in L's units: the Y of :func:`emission_rgb`'s XYZ."""
    grid, xyz_bar = observer()
    return float(tristimulus(emission.at(grid), xyz_bar)[1] / xyz_bar[:, 1].sum())


@functools.cache
def emission_rgb(emission: Spectrum) -> tuple[float, float, float]:
    """An emission spectrum's RGB radiance: M · Σ L x̄ / Σ ȳ (module docstring, Emitters)."""
    grid, _ = observer()
    return _rounded(_rgb(emission.at(grid)))


@functools.cache
def reflectance_rgb(reflectance: Spectrum, convention: str, light: Spectrum | None = None) -> tuple[float, float, float]:
    """A reflectance spectrum's RGB reflectance under ``convention`` (:data:`RGB_CONVENTIONS`; module docstring).

    :data:`SCENE_LIGHT` needs the scene's ``light`` spectrum, whose RGB must be positive in every channel
    (a ValueError otherwise: the per-channel white balance divides by it).
    """
    grid, _ = observer()
    rho = reflectance.at(grid)
    if convention == ILLUMINANT_E:
        return _rounded(_rgb(rho))
    if convention == SCENE_LIGHT:
        if light is None:
            raise ValueError("the scene_light convention needs the scene's light spectrum")
        le = light.at(grid)
        white = _rgb(le)
        if not np.all(white > 0.0):
            raise ValueError(f"the light's linear-sRGB colour {np.round(white, 6).tolist()} is not positive in every "
                             "channel, so reflectances cannot be white-balanced to it")
        return _rounded(_rgb(rho * le) / white)
    raise ValueError(f"unknown RGB convention {convention!r}; known: {', '.join(RGB_CONVENTIONS)}")

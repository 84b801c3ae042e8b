"""CIEDE2000 colour difference of linear-sRGB images, and the sRGB transfer functions, in numpy.

- sRGB: IEC 61966-2-1:1999, the piecewise EOTF and its inverse, on values in
  [0, 1];
- linear sRGB (BT.709 primaries, D65) → CIE XYZ: the normalised primary
  matrix, SMPTE RP 177-1993, derived from the primaries and the same D65 xy
  used as the CIELAB white (not the 4-decimal IEC matrix: that maps RGB
  (1, 1, 1) slightly off D65, so greys would not be exactly neutral);
- XYZ → CIELAB: CIE 15:2004 §8.2.1;
- CIEDE2000: Sharma, Wu and Dalal, "The CIEDE2000 color-difference formula:
  implementation notes, supplementary test data, and mathematical
  observations", Color Res. Appl. 30(1), 2005, eqs. (1)-(22), k_L = k_C = k_H = 1.

The arithmetic of colour-science's
``eotf_sRGB``/``eotf_inverse_sRGB``, ``XYZ_to_Lab`` and ``delta_E_CIE2000``
(tests/evaluate/test_ciede2000.py compares them, and compares this version with
that arithmetic written array-wise as colour-science writes it): ``import colour`` costs ~1.5 s (it imports
its plotting package and SciPy's interpolation), which ``cbox compare-image``
cannot afford (it is held within 3× idiff's time: BENCHMARKS.md).

Written for speed (``cbox compare-image`` computes two 256² maps per image):
one pass over flat channel arrays, no ``np.select``/``np.where``/
``np.hypot``/``%`` (each costs 0.6-1.3 ms per 256² here, against ~0.02 ms for
an addition), the hue's cases as arithmetic on masks, eq. (15)'s four cosines
from one cos and sin of the mean hue, ``x**7`` as products, ``cbrt`` for the
cube root. numpy's ``cbrt``, ``arctan2``, ``exp`` and ``sqrt`` are SIMD
(AVX-512) here, 10-25× faster than libm's scalar calls: a numba kernel of
the same formulas measured no faster than the old numpy (17 ms a map, all
in libm), so there is none. The arithmetic differs from colour-science's
only by an ulp per step (tests/evaluate/test_ciede2000.py: 1e-12 relative
against the array-wise original, kept there as the oracle; near-grey pixels,
whose hue angle is rounding noise, to 1e-6).
"""

from __future__ import annotations

import numpy as np

#: The CIE 1931 2° chromaticity of D65 (CIE 15:2004 table T.3), the white of sRGB and of our CIELAB.
D65_XY = np.array([0.3127, 0.3290])
#: The chromaticities of the sRGB (BT.709) primaries R, G, B.
SRGB_PRIMARIES_XY = np.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]])


def _spow(a, p):
    """Sign-preserving power (colour-science's ``spow``): negative values stay negative instead of NaN."""
    return np.sign(a) * np.abs(a) ** p


def xy_to_XYZ(xy) -> np.ndarray:
    """XYZ of chromaticity ``xy`` at Y = 1."""
    x, y = np.asarray(xy, dtype=np.float64)
    return np.array([x * (1 / y), 1.0, (1 - (x + y)) * (1 / y)])


def normalised_primary_matrix(primaries_xy, white_xy) -> np.ndarray:
    """The RGB → XYZ matrix of primaries ``primaries_xy`` (3×2) and white ``white_xy`` (SMPTE RP 177)."""
    primaries = np.asarray(primaries_xy, dtype=np.float64).reshape(3, 2)
    z = (1 - primaries[:, 0] - primaries[:, 1])[:, None]
    primaries = np.transpose(np.hstack([primaries, z]))
    coefficients = np.diagflat(np.dot(np.linalg.inv(primaries), xy_to_XYZ(white_xy)))
    return np.dot(primaries, coefficients)


RGB_TO_XYZ = normalised_primary_matrix(SRGB_PRIMARIES_XY, D65_XY)
_WHITE = xy_to_XYZ(D65_XY)


def srgb_eotf(code) -> np.ndarray:
    """Linear values of sRGB-encoded ones (IEC 61966-2-1)."""
    v = np.asarray(code, dtype=np.float64)
    return np.where(srgb_eotf_inverse(0.0031308) >= v, v / 12.92, _spow((v + 0.055) / 1.055, 2.4))


def srgb_eotf_inverse(linear) -> np.ndarray:
    """sRGB-encoded values of linear ones (IEC 61966-2-1): the display encoding."""
    v = np.asarray(linear, dtype=np.float64)
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * _spow(v, 1 / 2.4) - 0.055)


#: Where CIELAB's f(t) turns from the cube root to its linear segment, (6/29)^3 (CIE 15:2004 §8.2.1).
_LAB_EPSILON = (24 / 116) ** 3
_25_POW_7 = 25.0**7
_TO_DEG = 180 / np.pi  # np.degrees and np.deg2rad multiply by these: the same bits
_TO_RAD = np.pi / 180
#: cos and sin of the phase shifts of eq. (15)'s terms: 30°, 6° and 63°.
_C30, _S30 = np.cos(30 * _TO_RAD), np.sin(30 * _TO_RAD)
_C6, _S6 = np.cos(6 * _TO_RAD), np.sin(6 * _TO_RAD)
_C63, _S63 = np.cos(63 * _TO_RAD), np.sin(63 * _TO_RAD)


def _lab_f(t: np.ndarray) -> np.ndarray:
    """CIELAB's f(t), in place of ``t``: the cube root above epsilon (colour-science's spow(t, 1/3), which is
    t ** (1/3) there; cbrt is that to an ulp at a fifth of pow's cost), the linear segment at or below it."""
    low = t <= _LAB_EPSILON
    linear = (841 / 108) * t[low] + 16 / 116
    np.cbrt(t, out=t)
    t[low] = linear
    return t


def _lab_channels(rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """L*, a*, b* (flat arrays) of linear-sRGB rows ``rgb`` (n, 3): XYZ by :data:`RGB_TO_XYZ`, relative to D65."""
    r, g, b = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    # Written out: numpy's matmul of an (n, 3) by a 3×3 takes ~3 ms per 256², these nine products ~0.3 ms.
    fx, fy, fz = (_lab_f((m[0] * r + m[1] * g + m[2] * b) / w) for m, w in zip(RGB_TO_XYZ, _WHITE))
    return 116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz)


def _pow7(x: np.ndarray) -> np.ndarray:
    x2 = x * x
    return x2 * x2 * x2 * x  # pow(x, 7) to an ulp or two, at a fifth of np.power's cost


def _hue(b: np.ndarray, a_p: np.ndarray) -> np.ndarray:
    """Hue angle h' in degrees in [0, 360) (eq. 7), 0 where a' = b = 0."""
    h = np.arctan2(b, a_p)
    h *= _TO_DEG
    h += 360.0 * (h < 0)  # ``% 360`` on [-180, 180] (and -0 becomes +0, as there)
    h[(b == 0) & (a_p == 0)] = 0.0
    return h


def _hue_weight(h_bar_p: np.ndarray) -> np.ndarray:
    """T of eq. (15) at the mean hue (degrees): cos(h - 30°), cos 2h, cos(3h + 6°), cos(4h - 63°) from one cos and
    sin of h by the multiple-angle formulas (four cosines cost more than the rest of the formula)."""
    h = h_bar_p * _TO_RAD
    c, s = np.cos(h), np.sin(h)
    c2, s2 = c * c - s * s, 2 * s * c
    c3, s3 = c2 * c - s2 * s, s2 * c + c2 * s
    c4, s4 = c2 * c2 - s2 * s2, 2 * s2 * c2
    return 1 - 0.17 * (c * _C30 + s * _S30) + 0.24 * c2 + 0.32 * (c3 * _C6 - s3 * _S6) - 0.20 * (c4 * _C63 + s4 * _S63)


def _delta_e2000(L_1, a_1, b_1, L_2, a_2, b_2) -> np.ndarray:
    """CIEDE2000 of flat CIELAB channel arrays (Sharma et al. 2005, eqs. 1-22, k_L = k_C = k_H = 1)."""
    C_bar_ab = (np.sqrt(a_1 * a_1 + b_1 * b_1) + np.sqrt(a_2 * a_2 + b_2 * b_2)) / 2
    C_bar_ab_7 = _pow7(C_bar_ab)
    G = 0.5 * (1 - np.sqrt(C_bar_ab_7 / (C_bar_ab_7 + _25_POW_7)))  # eq. (4): a* rescaled near the neutral axis
    a_p_1, a_p_2 = (1 + G) * a_1, (1 + G) * a_2
    C_p_1, C_p_2 = np.sqrt(a_p_1 * a_p_1 + b_1 * b_1), np.sqrt(a_p_2 * a_p_2 + b_2 * b_2)
    h_p_1, h_p_2 = _hue(b_1, a_p_1), _hue(b_2, a_p_2)
    delta_L_p = L_2 - L_1
    delta_C_p = C_p_2 - C_p_1
    h_diff = h_p_2 - h_p_1
    C_p_product = C_p_1 * C_p_2
    achromatic = C_p_product == 0
    # eq. (10): the hue difference the short way round the circle; 0 where a colour is achromatic.
    delta_h_p = h_diff - 360.0 * (h_diff > 180) + 360.0 * (h_diff < -180)
    delta_h_p[achromatic] = 0.0
    delta_H_p = 2 * np.sqrt(C_p_product) * np.sin((delta_h_p / 2) * _TO_RAD)
    L_bar_p = (L_1 + L_2) / 2
    C_bar_p = (C_p_1 + C_p_2) / 2
    h_sum = h_p_1 + h_p_2
    # eq. (14): the mean hue, also the short way round; the sum itself where a colour is achromatic.
    wrap = np.fabs(h_p_1 - h_p_2) > 180
    h_bar_p = (h_sum + 360.0 * (wrap & (h_sum < 360)) - 360.0 * (wrap & (h_sum >= 360))) / 2
    h_bar_p[achromatic] = h_sum[achromatic]
    T = _hue_weight(h_bar_p)
    q = (h_bar_p - 275) / 25
    delta_theta = 30 * np.exp(-(q * q))
    C_bar_p_7 = _pow7(C_bar_p)
    R_C = 2 * np.sqrt(C_bar_p_7 / (C_bar_p_7 + _25_POW_7))
    L_bar_p_2 = (L_bar_p - 50) * (L_bar_p - 50)
    S_L = 1 + ((0.015 * L_bar_p_2) / np.sqrt(20 + L_bar_p_2))
    S_C = 1 + 0.045 * C_bar_p
    S_H = 1 + 0.015 * C_bar_p * T
    R_T = -np.sin((2 * delta_theta) * _TO_RAD) * R_C  # eq. (22): the blue region's hue-chroma interaction
    dL, dC, dH = delta_L_p / S_L, delta_C_p / S_C, delta_H_p / S_H
    return np.sqrt(dL * dL + dC * dC + dH * dH + R_T * dC * dH)


def _rows(a) -> np.ndarray:
    """``a`` (..., 3) as a float64 (n, 3) array."""
    return np.asarray(a, dtype=np.float64).reshape(-1, 3)


def linear_srgb_to_lab(img) -> np.ndarray:
    """CIELAB (D65, 2° observer) of linear-sRGB values of shape (..., 3), unclipped."""
    img = np.asarray(img, dtype=np.float64)
    return np.stack(_lab_channels(_rows(img)), axis=-1).reshape(img.shape)


def delta_e2000(lab_1, lab_2) -> np.ndarray:
    """CIEDE2000 between CIELAB arrays of shape (..., 3) (Sharma et al. 2005, k_L = k_C = k_H = 1)."""
    lab_1, lab_2 = np.broadcast_arrays(np.asarray(lab_1, dtype=np.float64), np.asarray(lab_2, dtype=np.float64))
    l_1, l_2 = _rows(lab_1).T, _rows(lab_2).T
    return _delta_e2000(*l_1, *l_2).reshape(lab_1.shape[:-1])


#: Pixels per pass of :func:`delta_e2000_linear`: each of the formula's ~60 temporaries is then 128 KiB and they
#: stay in this machine's caches (1 MiB of L2 a core), also while other processes share them. Whole-image
#: temporaries (8 MiB each at 1024²) made it memory-bound; measured on this 2-core machine under load, CPU time
#: at 1024²: 2^13-2^15 pixels 134-150 ms, 2^16 300-340 ms, one pass 500-700 ms; at 256², 2^14 10 ms, one pass
#: 17-21 ms. Each pixel's value is the same either way.
CHUNK_PIXELS = 1 << 14


def delta_e2000_linear(img, ref, exposure: float) -> np.ndarray:
    """CIEDE2000 of linear-sRGB ``img`` against ``ref`` (shape (..., 3)), both scaled by ``exposure``, per pixel.

    The pixels of ``img`` with a NaN or Inf are black first (the harness's rule,
    :func:`cornell_harness.evaluate.pixels.zero_broken_pixels`); ``ref``'s are taken as they are.
    """
    img, ref = np.asarray(img, dtype=np.float64), np.asarray(ref, dtype=np.float64)
    if img.shape != ref.shape or img.shape[-1:] != (3,):
        raise ValueError(f"expected two (..., 3) arrays of one shape, got {img.shape} and {ref.shape}")
    rgb = _rows(img)
    with np.errstate(invalid="ignore", over="ignore"):
        clean = np.isfinite(rgb.sum())  # one sum settles the common case, an image without NaN or Inf
    if not clean:
        rgb = np.where(np.isfinite(rgb).all(axis=-1, keepdims=True), rgb, 0.0)
    ref_rgb = _rows(ref)
    out = np.empty(rgb.shape[0])
    for start in range(0, rgb.shape[0], CHUNK_PIXELS):
        part = slice(start, start + CHUNK_PIXELS)
        out[part] = _delta_e2000(*_lab_channels(rgb[part] * exposure), *_lab_channels(ref_rgb[part] * exposure))
    return out.reshape(img.shape[:-1])

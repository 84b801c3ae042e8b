"""CIEDE2000 colour difference of linear-sRGB images (a numba kernel), and the sRGB transfer functions (numpy).

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

The same arithmetic, in the same order, as colour-science's
``eotf_sRGB``/``eotf_inverse_sRGB``, ``XYZ_to_Lab`` and ``delta_E_CIE2000``
(tests/evaluate/test_ciede2000.py compares them, and compares the kernel with
that arithmetic written in numpy): ``import colour`` costs ~1.5 s (it imports
its plotting package and SciPy's interpolation), which ``cbox compare-image``
cannot afford (issue 31: within 3× idiff's time).

Linear sRGB → XYZ → CIELAB → ΔE00 runs per pixel in one compiled pass
(:func:`delta_e2000_linear`): in numpy the same formulas made ~50 temporary
images and cost 40-85 ms per 256² map, twice per ``compare-image`` (the
image's map and the noise yardstick's), most of its warm cost. float64
throughout, no fastmath: it agrees with the numpy arithmetic to ~1e-15
relative (``x**7`` is ``pow`` in both; ``x**2`` a product in both). The
kernels are compiled with ``cache=True``: a fresh process loads them from
numba's cache in milliseconds instead of compiling them (~2 s).
"""

from __future__ import annotations

import math

import numba
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
_M = RGB_TO_XYZ
_WX, _WY, _WZ = (float(w) for w in _WHITE)
_25_POW_7 = 25.0**7
_TO_DEG = 180.0 / math.pi
_TO_RAD = math.pi / 180.0

_jit = numba.njit(cache=True, nogil=True)


@_jit
def _lab_f(t):
    # colour-science's spow(t, 1/3) is taken only for t > epsilon > 0, where it is t ** (1/3); cbrt is that
    # within an ulp, at half pow's cost.
    return np.cbrt(t) if t > _LAB_EPSILON else (841 / 108) * t + 16 / 116


@_jit
def _lab(r, g, b):
    """CIELAB of one linear-sRGB colour: XYZ by :data:`RGB_TO_XYZ`, relative to D65."""
    fx = _lab_f((_M[0, 0] * r + _M[0, 1] * g + _M[0, 2] * b) / _WX)
    fy = _lab_f((_M[1, 0] * r + _M[1, 1] * g + _M[1, 2] * b) / _WY)
    fz = _lab_f((_M[2, 0] * r + _M[2, 1] * g + _M[2, 2] * b) / _WZ)
    return 116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz)


@_jit
def _hue(b, a_p):
    """Hue angle h' in degrees in [0, 360) (eq. 7), 0 for an achromatic colour."""
    if b == 0 and a_p == 0:
        return 0.0
    return (math.atan2(b, a_p) * _TO_DEG) % 360.0


@_jit
def _pow7(x):
    x2 = x * x
    return x2 * x2 * x2 * x  # pow(x, 7) to an ulp or two, without a pow call


#: cos and sin of the phase shifts of eq. (15)'s terms: 30°, 6° and 63°.
_C30, _S30 = math.cos(30 * _TO_RAD), math.sin(30 * _TO_RAD)
_C6, _S6 = math.cos(6 * _TO_RAD), math.sin(6 * _TO_RAD)
_C63, _S63 = math.cos(63 * _TO_RAD), math.sin(63 * _TO_RAD)


@_jit
def _hue_weight(h):
    """T of eq. (15) at the mean hue ``h`` (radians): cos(h - 30°), cos 2h, cos(3h + 6°), cos(4h - 63°) from one
    cos and sin of h by the multiple-angle formulas (four cosines cost as much as the rest of the pixel)."""
    c, s = math.cos(h), math.sin(h)
    c2, s2 = c * c - s * s, 2 * s * c
    c3, s3 = c2 * c - s2 * s, s2 * c + c2 * s
    c4, s4 = c2 * c2 - s2 * s2, 2 * s2 * c2
    return (1 - 0.17 * (c * _C30 + s * _S30) + 0.24 * c2 + 0.32 * (c3 * _C6 - s3 * _S6)
            - 0.20 * (c4 * _C63 + s4 * _S63))


@_jit
def _delta_e2000(L_1, a_1, b_1, L_2, a_2, b_2):
    """CIEDE2000 of one pair of CIELAB colours (Sharma et al. 2005, eqs. 1-22, k_L = k_C = k_H = 1)."""
    C_bar_ab = (math.hypot(a_1, b_1) + math.hypot(a_2, b_2)) / 2
    C_bar_ab_7 = _pow7(C_bar_ab)
    G = 0.5 * (1 - math.sqrt(C_bar_ab_7 / (C_bar_ab_7 + _25_POW_7)))  # eq. (4): a* rescaled near the neutral axis
    a_p_1, a_p_2 = (1 + G) * a_1, (1 + G) * a_2
    C_p_1, C_p_2 = math.hypot(a_p_1, b_1), math.hypot(a_p_2, b_2)
    h_p_1, h_p_2 = _hue(b_1, a_p_1), _hue(b_2, a_p_2)
    delta_L_p = L_2 - L_1
    delta_C_p = C_p_2 - C_p_1
    h_diff = h_p_2 - h_p_1
    C_p_product = C_p_1 * C_p_2
    # eq. (10): the hue difference the short way round the circle; 0 where a colour is achromatic
    # (and, as numpy's select defaults, 0 where no case holds: a NaN hue).
    if C_p_product == 0:
        delta_h_p = 0.0
    elif math.fabs(h_diff) <= 180:
        delta_h_p = h_diff
    elif h_diff > 180:
        delta_h_p = h_diff - 360
    elif h_diff < -180:
        delta_h_p = h_diff + 360
    else:
        delta_h_p = 0.0
    delta_H_p = 2 * math.sqrt(C_p_product) * math.sin((delta_h_p / 2) * _TO_RAD)
    L_bar_p = (L_1 + L_2) / 2
    C_bar_p = (C_p_1 + C_p_2) / 2
    h_abs_diff = math.fabs(h_p_1 - h_p_2)
    h_sum = h_p_1 + h_p_2
    # eq. (14): the mean hue, also the short way round.
    if C_p_product == 0:
        h_bar_p = h_sum
    elif h_abs_diff <= 180:
        h_bar_p = h_sum / 2
    elif h_abs_diff > 180 and h_sum < 360:
        h_bar_p = (h_sum + 360) / 2
    elif h_abs_diff > 180 and h_sum >= 360:
        h_bar_p = (h_sum - 360) / 2
    else:
        h_bar_p = 0.0
    T = _hue_weight(h_bar_p * _TO_RAD)
    q = (h_bar_p - 275) / 25
    delta_theta = 30 * math.exp(-(q * q))
    C_bar_p_7 = _pow7(C_bar_p)
    R_C = 2 * math.sqrt(C_bar_p_7 / (C_bar_p_7 + _25_POW_7))
    L_bar_p_2 = (L_bar_p - 50) * (L_bar_p - 50)
    S_L = 1 + ((0.015 * L_bar_p_2) / math.sqrt(20 + L_bar_p_2))
    S_C = 1 + 0.045 * C_bar_p
    S_H = 1 + 0.015 * C_bar_p * T
    R_T = -math.sin((2 * delta_theta) * _TO_RAD) * R_C  # eq. (22): the blue region's hue-chroma interaction
    dL, dC, dH = delta_L_p / S_L, delta_C_p / S_C, delta_H_p / S_H
    return math.sqrt(dL * dL + dC * dC + dH * dH + R_T * dC * dH)


@_jit
def _lab_rows(rgb, out):
    for i in range(rgb.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = _lab(rgb[i, 0], rgb[i, 1], rgb[i, 2])


@_jit
def _delta_e2000_rows(lab_1, lab_2, out):
    for i in range(lab_1.shape[0]):
        out[i] = _delta_e2000(lab_1[i, 0], lab_1[i, 1], lab_1[i, 2], lab_2[i, 0], lab_2[i, 1], lab_2[i, 2])


@_jit
def _delta_e2000_linear_rows(img, ref, exposure, out):
    for i in range(img.shape[0]):
        r, g, b = img[i, 0], img[i, 1], img[i, 2]
        if not (math.isfinite(r) and math.isfinite(g) and math.isfinite(b)):
            r = g = b = 0.0  # the harness's one rule for broken pixels (harness.evaluate.pixels.zero_broken_pixels)
        L_1, a_1, b_1 = _lab(r * exposure, g * exposure, b * exposure)
        L_2, a_2, b_2 = _lab(ref[i, 0] * exposure, ref[i, 1] * exposure, ref[i, 2] * exposure)
        out[i] = _delta_e2000(L_1, a_1, b_1, L_2, a_2, b_2)


def _rows(a) -> np.ndarray:
    """``a`` (..., 3) as a C-contiguous float64 (n, 3) array."""
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1, 3))


def linear_srgb_to_lab(img) -> np.ndarray:
    """CIELAB (D65, 2° observer) of linear-sRGB values of shape (..., 3), unclipped."""
    img = np.asarray(img, dtype=np.float64)
    out = np.empty((img.size // 3, 3))
    _lab_rows(_rows(img), out)
    return out.reshape(img.shape)


def delta_e2000(lab_1, lab_2) -> np.ndarray:
    """CIEDE2000 between CIELAB arrays of shape (..., 3) (Sharma et al. 2005, k_L = k_C = k_H = 1)."""
    lab_1, lab_2 = np.broadcast_arrays(np.asarray(lab_1, dtype=np.float64), np.asarray(lab_2, dtype=np.float64))
    out = np.empty(lab_1.size // 3)
    _delta_e2000_rows(_rows(lab_1), _rows(lab_2), out)
    return out.reshape(lab_1.shape[:-1])


def delta_e2000_linear(img, ref, exposure: float) -> np.ndarray:
    """CIEDE2000 of linear-sRGB ``img`` against ``ref`` (shape (..., 3)), both scaled by ``exposure``, per pixel.

    The pixels of ``img`` with a NaN or Inf are black first (the harness's rule,
    :func:`harness.evaluate.pixels.zero_broken_pixels`); ``ref``'s are taken as they are.
    One pass: no CIELAB image is made.
    """
    img, ref = np.asarray(img, dtype=np.float64), np.asarray(ref, dtype=np.float64)
    if img.shape != ref.shape or img.shape[-1:] != (3,):
        raise ValueError(f"expected two (..., 3) arrays of one shape, got {img.shape} and {ref.shape}")
    out = np.empty(img.size // 3)
    _delta_e2000_linear_rows(_rows(img), _rows(ref), float(exposure), out)
    return out.reshape(img.shape[:-1])

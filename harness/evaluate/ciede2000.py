"""CIEDE2000 colour difference of linear-sRGB images, and the sRGB transfer functions, in plain numpy.

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
(tests/evaluate/test_ciede2000.py compares them): ``import colour`` costs
~1.5 s (it imports its plotting package and SciPy's interpolation), which
``cbox compare-image`` cannot afford (issue 31: within 3× idiff's time).
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


def xyz_to_lab(xyz, white=_WHITE) -> np.ndarray:
    """CIELAB (L in [0, 100]) of XYZ values of shape (..., 3), relative to ``white``."""
    xyz = np.asarray(xyz, dtype=np.float64)

    def f(t):
        return np.where(t > (24 / 116) ** 3, _spow(t, 1 / 3), (841 / 108) * t + 16 / 116)

    fx, fy, fz = (f(xyz[..., i] / white[i]) for i in range(3))
    return np.stack([116 * fy - 16, 500 * (fx - fy), 200 * (fy - fz)], axis=-1)


def linear_srgb_to_lab(img) -> np.ndarray:
    """CIELAB (D65, 2° observer) of linear-sRGB values of shape (..., 3), unclipped."""
    return xyz_to_lab(np.asarray(img) @ RGB_TO_XYZ.T)


def delta_e2000(lab_1, lab_2) -> np.ndarray:
    """CIEDE2000 between CIELAB arrays of shape (..., 3) (Sharma et al. 2005, k_L = k_C = k_H = 1)."""
    lab_1, lab_2 = np.asarray(lab_1, dtype=np.float64), np.asarray(lab_2, dtype=np.float64)
    L_1, a_1, b_1 = (lab_1[..., i] for i in range(3))
    L_2, a_2, b_2 = (lab_2[..., i] for i in range(3))
    C_bar_ab = (np.hypot(a_1, b_1) + np.hypot(a_2, b_2)) / 2
    C_bar_ab_7 = C_bar_ab**7
    G = 0.5 * (1 - np.sqrt(C_bar_ab_7 / (C_bar_ab_7 + 25**7)))  # eq. (4): a* rescaled near the neutral axis
    a_p_1, a_p_2 = (1 + G) * a_1, (1 + G) * a_2
    C_p_1, C_p_2 = np.hypot(a_p_1, b_1), np.hypot(a_p_2, b_2)
    h_p_1 = np.where((b_1 == 0) & (a_p_1 == 0), 0, np.degrees(np.arctan2(b_1, a_p_1)) % 360)
    h_p_2 = np.where((b_2 == 0) & (a_p_2 == 0), 0, np.degrees(np.arctan2(b_2, a_p_2)) % 360)
    delta_L_p = L_2 - L_1
    delta_C_p = C_p_2 - C_p_1
    h_diff = h_p_2 - h_p_1
    C_p_product = C_p_1 * C_p_2
    # eq. (10): the hue difference the short way round the circle; 0 where a colour is achromatic.
    delta_h_p = np.select([C_p_product == 0, np.fabs(h_diff) <= 180, h_diff > 180, h_diff < -180],
                          [0, h_diff, h_diff - 360, h_diff + 360])
    delta_H_p = 2 * np.sqrt(C_p_product) * np.sin(np.deg2rad(delta_h_p / 2))
    L_bar_p = (L_1 + L_2) / 2
    C_bar_p = (C_p_1 + C_p_2) / 2
    h_abs_diff = np.fabs(h_p_1 - h_p_2)
    h_sum = h_p_1 + h_p_2
    # eq. (14): the mean hue, also the short way round.
    h_bar_p = np.select([C_p_product == 0, h_abs_diff <= 180, (h_abs_diff > 180) & (h_sum < 360),
                         (h_abs_diff > 180) & (h_sum >= 360)],
                        [h_sum, h_sum / 2, (h_sum + 360) / 2, (h_sum - 360) / 2])
    T = (1 - 0.17 * np.cos(np.deg2rad(h_bar_p - 30)) + 0.24 * np.cos(np.deg2rad(2 * h_bar_p))
         + 0.32 * np.cos(np.deg2rad(3 * h_bar_p + 6)) - 0.20 * np.cos(np.deg2rad(4 * h_bar_p - 63)))
    delta_theta = 30 * np.exp(-(((h_bar_p - 275) / 25) ** 2))
    C_bar_p_7 = C_bar_p**7
    R_C = 2 * np.sqrt(C_bar_p_7 / (C_bar_p_7 + 25**7))
    L_bar_p_2 = (L_bar_p - 50) ** 2
    S_L = 1 + ((0.015 * L_bar_p_2) / np.sqrt(20 + L_bar_p_2))
    S_C = 1 + 0.045 * C_bar_p
    S_H = 1 + 0.015 * C_bar_p * T
    R_T = -np.sin(np.deg2rad(2 * delta_theta)) * R_C  # eq. (22): the blue region's hue-chroma interaction
    return np.sqrt((delta_L_p / S_L) ** 2 + (delta_C_p / S_C) ** 2 + (delta_H_p / S_H) ** 2
                   + R_T * (delta_C_p / S_C) * (delta_H_p / S_H))

"""The array-wise CIEDE2000 that :mod:`cornell_harness.evaluate.ciede2000` was sped up from, kept as its oracle: the
formulas as colour-science writes them (``XYZ_to_Lab``, ``delta_E_CIE2000``: ``np.select``, ``np.hypot``,
``% 360``, four cosines, ``pow``), which the fast version rearranges."""

from __future__ import annotations

import numpy as np

from cornell_harness.evaluate.ciede2000 import _WHITE, RGB_TO_XYZ, _spow


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

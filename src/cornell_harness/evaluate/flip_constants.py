"""HDR-FLIP's constants as the authors' C++ library (``flip-evaluator`` 1.7, ``FLIP.h``) states them, in float32.

Shared by :mod:`cornell_harness.evaluate.hdr_flip` (numba kernels) and
:mod:`cornell_harness.evaluate.hdr_flip_numpy` (their numpy stand-ins), so both compute with the same numbers.
"""

from __future__ import annotations

import math

import numpy as np

F = np.float32
#: The library's π (``FLIP::PI``) and its square, as it computes them in float32.
PI = F(3.14159265358979)
PI_SQ = F(PI * PI)
#: LDR-FLIP's constants (§3-4): q_c, p_c, p_t, w (degrees), q_f.
GQC, GPC, GPT, GW, GQF = F(0.7), F(0.4), F(0.95), F(0.082), F(0.5)
#: Contrast-sensitivity filters of Y, Cx, Cz (§3.1): a₁, b₁, a₂, b₂ of each channel's sum of Gaussians.
CSF_A1, CSF_B1 = (F(1.0), F(1.0), F(34.1)), (F(0.0047), F(0.0053), F(0.04))
CSF_A2, CSF_B2 = (F(0.0), F(0.0), F(13.5)), (F(1.0e-5), F(1.0e-5), F(0.025))
#: D65 in XYZ and its reciprocal, as the library states them.
_ILL = (F(0.950428545), F(1.0), F(1.088900371))
_INV_ILL = (F(1.052156925), F(1.0), F(0.918357670))
#: Linear sRGB → XYZ (the library's rational entries) and back.
_RGB_XYZ = tuple(F(n) / F(d) for n, d in (
    (10135552.0, 24577794.0), (8788810.0, 24577794.0), (4435075.0, 24577794.0),
    (2613072.0, 12288897.0), (8788810.0, 12288897.0), (887015.0, 12288897.0),
    (1425312.0, 73733382.0), (8788810.0, 73733382.0), (70074185.0, 73733382.0)))
_XYZ_RGB = tuple(F(v) for v in (3.241003275, -1.537398934, -0.498615861, -0.969224334, 1.875930071,
                                0.041554224, 0.055639423, -0.204011202, 1.057148933))
_DELTA = F(6.0) / F(29.0)
_DELTA_CUBE = _DELTA * (_DELTA * _DELTA)
_LAB_FACTOR = F(1.0) / (F(3.0) * (_DELTA * _DELTA))
_LAB_TERM = F(4.0) / F(29.0)
_ZERO, _ONE, _16, _116, _200, _500 = F(0.0), F(1.0), F(16.0), F(116.0), F(200.0), F(500.0)
_THIRD, _HUNT = F(1.0) / F(3.0), F(0.01)
_ONE_OVER_116, _SIXTEEN_OVER_116 = F(1.0) / F(116.0), F(16.0) / F(116.0)
_SQRT_HALF = F(1.0) / F(math.sqrt(2.0))  # the library's 1.0f / std::sqrt(2.0f): sqrt(2) is exact in float32

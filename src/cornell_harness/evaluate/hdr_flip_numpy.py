"""HDR-FLIP's per-pixel kernels in numpy, for an install without numba (the core, without ``[ours]``).

Each function here computes what its namesake in :mod:`cornell_harness.evaluate.hdr_flip` computes, on whole
planes instead of pixel by pixel, with the same float32 operations in the same order: a convolution still adds
its taps from the left/top, one plane-wide multiply-add per tap, so every sum is the numba kernel's. What numpy
does not compute as numba does is the C library's ``powf`` and ``expf``, which numba's float32 ``**`` and
``np.exp`` call (numpy's own SIMD ``power`` and ``exp`` differ from them by an ulp on a large share of values):

- :func:`powf` takes the power in float64 and rounds it to float32, which is ``powf``'s answer except where the
  float64 result lies within a few thousandths of an ulp of halfway between two float32 values (there ``powf``'s
  own float64 arithmetic may round the other way); those few (under 1 %) are computed by ``powf`` itself;
- :func:`expf` (the filters' weights, a few dozen per pixels-per-degree) is ``expf`` itself.

The result is the numba path's map bit for bit on the images tests/evaluate/test_hdr_flip_numpy.py checks,
computed more slowly (BENCHMARKS.md, "A core install and ``[all]``", measures how much).
"""

from __future__ import annotations

import ctypes

import numpy as np

from cornell_harness.evaluate.flip_constants import (_116, _200, _500, _DELTA_CUBE, _HUNT, _ILL, _INV_ILL, _LAB_FACTOR,
                                                     _LAB_TERM, _ONE, _ONE_OVER_116, _RGB_XYZ, _SIXTEEN_OVER_116,
                                                     _SQRT_HALF, _THIRD, _XYZ_RGB, _ZERO, GPC, GPT, GQC, GQF, _16, F)

assert GQF == 0.5  # keep_largest_error's square root

#: The C library the process runs on (numba's JIT code calls its ``powf`` and ``expf``); None where
#: ``ctypes`` cannot name it (then :func:`powf` is the float64 power rounded, an ulp off now and then).
try:
    _LIBC = ctypes.CDLL(None)
    _POWF, _EXPF = _LIBC.powf, _LIBC.expf
    _POWF.restype, _POWF.argtypes = ctypes.c_float, [ctypes.c_float, ctypes.c_float]
    _EXPF.restype, _EXPF.argtypes = ctypes.c_float, [ctypes.c_float]
except (OSError, AttributeError, TypeError):
    _POWF = _EXPF = None

#: Distance from halfway between two float32 values, in float32 ulps, within which a float64 power is handed to
#: ``powf``: its float64 arithmetic was measured off by at most 0.0015 ulp of the float32 result (2 million
#: random bases and five exponents), and this is 2.6 times that.
_HALFWAY_MARGIN = 2.0**-8


def expf(x) -> np.float32:
    """The C library's ``expf`` of a float32 scalar (numpy's where the library cannot be reached)."""
    return F(_EXPF(float(x))) if _EXPF is not None else np.exp(F(x))


def powf(base, exponent) -> np.ndarray:
    """``base ** exponent`` in float32 as the C library's ``powf`` gives it, element-wise (arrays or scalars)."""
    b64, e64 = np.asarray(base, np.float64), np.asarray(exponent, np.float64)
    exact = np.power(b64, e64)
    out = exact.astype(np.float32)
    if _POWF is None:
        return out
    ulp = np.spacing(np.abs(out)).astype(np.float64)
    with np.errstate(invalid="ignore"):
        near_halfway = 0.5 - np.abs(exact - out) / ulp < _HALFWAY_MARGIN
    if out.ndim == 0:
        return F(_POWF(float(b64), float(e64))) if near_halfway else F(out)
    idx = np.flatnonzero(near_halfway)
    if idx.size:
        bases, exps = np.broadcast_to(b64, out.shape).ravel()[idx], np.broadcast_to(e64, out.shape).ravel()[idx]
        out.ravel()[idx] = [_POWF(b, e) for b, e in zip(bases.tolist(), exps.tolist())]
    return out


def _clamp01(v):
    return np.minimum(np.maximum(v, _ZERO), _ONE)


def exposed_ycxcz(rgb, scale, tc, out):
    """:func:`cornell_harness.evaluate.hdr_flip._exposed_ycxcz` on whole planes."""
    v = rgb * scale
    v = _clamp01((v * v * tc[0] + v * tc[1] + tc[2]) / (v * v * tc[3] + v * tc[4] + tc[5]))
    c0, c1, c2 = v[..., 0], v[..., 1], v[..., 2]
    xx = (_RGB_XYZ[0] * c0 + _RGB_XYZ[1] * c1 + _RGB_XYZ[2] * c2) * _INV_ILL[0]
    yy = (_RGB_XYZ[3] * c0 + _RGB_XYZ[4] * c1 + _RGB_XYZ[5] * c2) * _INV_ILL[1]
    zz = (_RGB_XYZ[6] * c0 + _RGB_XYZ[7] * c1 + _RGB_XYZ[8] * c2) * _INV_ILL[2]
    lum = _116 * yy - _16
    out[0] = lum
    out[1] = _500 * (xx - yy)
    out[2] = _200 * (yy - zz)
    out[3] = lum * _ONE_OVER_116 + _SIXTEEN_OVER_116


def filter_rows(src, sources, weights, out):
    """:func:`cornell_harness.evaluate.hdr_flip._filter_rows`: one multiply-add of the row-padded plane per tap."""
    w, width = out.shape[2], weights.shape[1]
    r = width // 2
    for j in range(out.shape[0]):
        pad = np.pad(src[sources[j]], ((0, 0), (r, r)), mode="edge")
        o = out[j]
        o[:] = _ZERO
        for k in range(width):
            o += weights[j, k] * pad[:, k:k + w]


def filter_columns(src, sources, weights, out):
    """:func:`cornell_harness.evaluate.hdr_flip._filter_columns`: one multiply-add of the column-padded plane per tap."""
    h, width = out.shape[1], weights.shape[1]
    r = width // 2
    for j in range(out.shape[0]):
        pad = np.pad(src[sources[j]], ((r, r), (0, 0)), mode="edge")
        o = out[j]
        o[:] = _ZERO
        for k in range(width):
            o += weights[j, k] * pad[k:k + h]


def _lab_f(t):
    return np.where(t > _DELTA_CUBE, powf(np.maximum(t, _DELTA_CUBE), _THIRD), _LAB_FACTOR * t + _LAB_TERM)


def perceived(colour, features, out):
    """:func:`cornell_harness.evaluate.hdr_flip._perceived` on whole planes."""
    fy = (colour[0] + _16) / _116
    cx = colour[1] / _500
    cz = (colour[2] + colour[3]) / _200
    xx, yy, zz = (fy + cx) * _ILL[0], fy * _ILL[1], (fy - cz) * _ILL[2]
    r = _clamp01(_XYZ_RGB[0] * xx + _XYZ_RGB[1] * yy + _XYZ_RGB[2] * zz)
    g = _clamp01(_XYZ_RGB[3] * xx + _XYZ_RGB[4] * yy + _XYZ_RGB[5] * zz)
    b = _clamp01(_XYZ_RGB[6] * xx + _XYZ_RGB[7] * yy + _XYZ_RGB[8] * zz)
    xx = (_RGB_XYZ[0] * r + _RGB_XYZ[1] * g + _RGB_XYZ[2] * b) * _INV_ILL[0]
    yy = (_RGB_XYZ[3] * r + _RGB_XYZ[4] * g + _RGB_XYZ[5] * b) * _INV_ILL[1]
    zz = (_RGB_XYZ[6] * r + _RGB_XYZ[7] * g + _RGB_XYZ[8] * b) * _INV_ILL[2]
    fx, fy, fz = _lab_f(xx), _lab_f(yy), _lab_f(zz)
    lum = _116 * fy - _16
    out[0] = lum
    out[1] = _HUNT * lum * (_500 * (fx - fy))
    out[2] = _HUNT * lum * (_200 * (fy - fz))
    dx, ddx, dy, ddy = features[0], features[1], features[2], features[3]
    out[3] = np.sqrt(dx * dx + dy * dy)
    out[4] = np.sqrt(ddx * ddx + ddy * ddy)


def keep_largest_error(ref, test, error, cmax):
    """:func:`cornell_harness.evaluate.hdr_flip._keep_largest_error` on whole planes; ``cmax`` its c_max."""
    pccmax = GPC * cmax
    low_slope = GPT / pccmax
    da, db = ref[1] - test[1], ref[2] - test[2]
    c = powf(np.abs(ref[0] - test[0]) + np.sqrt(da * da + db * db), GQC)
    c = np.where(c < pccmax, c * low_slope, GPT + ((c - pccmax) / (cmax - pccmax)) * (_ONE - GPT))
    # x ** q_f with q_f = 0.5 a constant: LLVM compiles numba's to sqrt (not powf), and so must this.
    f = np.sqrt(_SQRT_HALF * np.maximum(np.abs(ref[3] - test[3]), np.abs(ref[4] - test[4])))
    np.maximum(error, powf(c, _ONE - f), out=error)

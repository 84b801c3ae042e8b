"""HDR-FLIP's per-pixel map in numba (numpy without it), with each reference's side done once per exposure, cached.

HDR-FLIP (Andersson, Nilsson, Shirley & Akenine-Möller 2021, "Visualizing Errors in Rendered High Dynamic
Range Images", Eurographics short papers) exposes both images by ``2^c`` at each exposure ``c``, tone-maps and
clamps them, scores them with LDR-FLIP (Andersson et al. 2020, "FLIP: A Difference Evaluator for Alternating
Images", HPG, §3-4) and keeps each pixel's largest error. LDR-FLIP has two pipelines, each of which filters the
two images independently before they meet:

- colour (§3.1-3.2): linear RGB → YCxCz, each channel convolved with its contrast-sensitivity filter (a
  Gaussian for Y and Cx, a sum of two for Cz: separated as the authors do, "separatedConvolutions.pdf" in
  their repository), back to linear RGB clamped to [0, 1], CIELAB with the Hunt adjustment; the two images'
  HyAB distance, raised to q_c = 0.7 and remapped to [0, 1] (p_c = 0.4, p_t = 0.95);
- features (§3.3): the normalised Y convolved with a Gaussian's first and second derivatives (σ = w/2 degrees,
  w = 0.082), the edge and point magnitudes; their larger difference (÷√2), raised to q_f = 0.5;

and the error is colour^(1 − features). Everything up to the two magnitudes and the Hunt-adjusted CIELAB
depends on one image and the exposure only: :func:`reference_side` computes the reference's once per
(reference content, exposure, pixels per degree) and keeps it in a small cache (:class:`SideCache`), so that
scoring many images against one reference costs only their own side and the comparison.

The arithmetic is the authors' C++ library's (``flip-evaluator`` 1.7, ``FLIP.h``) step for step in float32:
the same constants, the same order of every sum (a convolution adds its taps from the left/top, borders
clamped), the same separable filters and their normalisation, powf and sqrtf where it takes them. Its map
agrees to a few 1e-6 per pixel, often bit for bit (tests/evaluate/test_hdr_flip.py states the tolerance it
checks). float32 on purpose, against the harness's float64 rule: it is the metric's definition as published
and computed, and half the memory traffic of the convolutions.

Without numba (a core install, no ``[ours]`` extra) the per-pixel kernels are
:mod:`cornell_harness.evaluate.hdr_flip_numpy`'s, the same arithmetic on whole planes, and the scalar helpers
below run as Python: the same map, slower.

Inputs: (H, W, 3) float32 linear-sRGB images, non-negative and finite (:func:`cornell_harness.evaluate.flip.flip_input`
makes them so); the exposure range and the pixels per degree come from :mod:`cornell_harness.evaluate.flip`.
"""

from __future__ import annotations

import functools
import hashlib
import math
import threading
from collections import OrderedDict

import numpy as np

# By name: numba reads module globals as compile-time constants (float32 here).
from cornell_harness.evaluate.flip_constants import (_116, _200, _500, _DELTA_CUBE, _HUNT, _ILL, _INV_ILL,
                                                     _LAB_FACTOR, _LAB_TERM, _ONE, _ONE_OVER_116, _RGB_XYZ,
                                                     _SIXTEEN_OVER_116, _SQRT_HALF, _THIRD, _XYZ_RGB, _ZERO, CSF_A1,
                                                     CSF_A2, CSF_B1, CSF_B2, GPC, GPT, GQC, GQF, GW, PI, PI_SQ, _16, F)

try:
    from numba import njit
except ImportError:  # the core install, without [ours]: the kernels of hdr_flip_numpy
    njit = None


def _jit(fn):
    """``fn`` compiled by numba (cached on disk) where numba is installed; else ``fn`` itself, for the scalar
    helpers, while :mod:`cornell_harness.evaluate.hdr_flip_numpy` replaces the per-pixel kernels."""
    return njit(cache=True)(fn) if njit is not None else fn


if njit is not None:
    @_jit
    def _expf(x):
        return np.exp(x)

    @_jit
    def _powf(x, y):
        return x ** y
else:
    from cornell_harness.evaluate.hdr_flip_numpy import expf as _expf, powf as _powf


# ---------------------------------------------------------------------------------------------- filters


@_jit
def _gaussian(x2, a, b):
    return a * np.sqrt(PI / b) * _expf(-PI_SQ * x2 / b)


@_jit
def _gaussian_sqrt(x2, a, b):
    return np.sqrt(a * np.sqrt(PI / b)) * _expf(-PI_SQ * x2 / b)


@_jit
def _spatial_filters(ppd, radius):
    """Rows Y, Cx, Cz₁, Cz₂ of the separated contrast-sensitivity filters (the library's setSpatialFilters)."""
    width = 2 * radius + 1
    out = np.empty((4, width), np.float32)
    delta_x = _ONE / ppd
    sums = np.zeros(4, np.float32)
    for i in range(width):
        ix = F(i - radius) * delta_x
        ix2 = ix * ix
        out[0, i] = _gaussian(ix2, CSF_A1[0], CSF_B1[0])
        out[1, i] = _gaussian(ix2, CSF_A1[1], CSF_B1[1])
        out[2, i] = _gaussian_sqrt(ix2, CSF_A1[2], CSF_B1[2])
        out[3, i] = _gaussian_sqrt(ix2, CSF_A2[2], CSF_B2[2])
        for c in range(4):
            sums[c] += out[c, i]
    norm_y, norm_cx = _ONE / sums[0], _ONE / sums[1]
    norm_cz = _ONE / np.sqrt(sums[2] * sums[2] + sums[3] * sums[3])
    for i in range(width):
        out[0, i] *= norm_y
        out[1, i] *= norm_cx
        out[2, i] *= norm_cz
        out[3, i] *= norm_cz
    return out


@_jit
def _feature_filters(std_dev, radius):
    """Rows Gaussian, its first and its second derivative (the library's setFeatureFilter): the Gaussian sums
    to 1, each derivative's positive and negative weights to ±1."""
    width = 2 * radius + 1
    out = np.empty((3, width), np.float32)
    g_sum, d_neg, d_pos, dd_neg, dd_pos = _ZERO, _ZERO, _ZERO, _ZERO, _ZERO
    for i in range(width):
        x = F(i - radius)
        g = _expf(-(x * x) / (F(2.0) * std_dev * std_dev))
        g_sum += g
        dg = -x * g
        if dg > _ZERO:
            d_pos += dg
        else:
            d_neg -= dg
        ddg = (x * x / (std_dev * std_dev) - _ONE) * g
        if ddg > _ZERO:
            dd_pos += ddg
        else:
            dd_neg -= ddg
        out[0, i], out[1, i], out[2, i] = g, dg, ddg
    for i in range(width):
        out[0, i] = out[0, i] / g_sum
        out[1, i] = out[1, i] / (d_pos if out[1, i] > _ZERO else d_neg)
        out[2, i] = out[2, i] / (dd_pos if out[2, i] > _ZERO else dd_neg)
    return out


@functools.lru_cache(maxsize=8)
def filters(ppd: float) -> tuple[np.ndarray, np.ndarray]:
    """The spatial (4, 2r+1) and feature (3, 2r'+1) filters at ``ppd`` pixels per degree, the library's radii."""
    ppd = F(ppd)
    max_b = max(*CSF_B1, *CSF_B2)
    radius = int(math.ceil(F(3.0) * np.sqrt(max_b / (F(2.0) * PI_SQ)) * ppd))
    std_dev = F(0.5) * GW * ppd
    return _spatial_filters(ppd, radius), _feature_filters(std_dev, int(math.ceil(F(3.0) * std_dev)))


# ------------------------------------------------------------------------------------------ one image's side


@_jit
def _tone(v, scale, tc):
    v = v * scale
    v = (v * v * tc[0] + v * tc[1] + tc[2]) / (v * v * tc[3] + v * tc[4] + tc[5])
    return min(max(v, _ZERO), _ONE)


@_jit
def _exposed_ycxcz(rgb, scale, tc, out):
    """``rgb`` × ``scale``, tone-mapped by t(x) = (t₀x² + t₁x + t₂)/(t₃x² + t₄x + t₅), clamped to [0, 1],
    in YCxCz: ``out`` (4, H, W) as Y, Cx, Cz and the feature pipeline's normalised Y, (Y + 16)/116."""
    h, w = rgb.shape[0], rgb.shape[1]
    for y in range(h):
        for x in range(w):
            c0, c1, c2 = (_tone(rgb[y, x, 0], scale, tc), _tone(rgb[y, x, 1], scale, tc),
                          _tone(rgb[y, x, 2], scale, tc))
            xx = _RGB_XYZ[0] * c0 + _RGB_XYZ[1] * c1 + _RGB_XYZ[2] * c2
            yy = _RGB_XYZ[3] * c0 + _RGB_XYZ[4] * c1 + _RGB_XYZ[5] * c2
            zz = _RGB_XYZ[6] * c0 + _RGB_XYZ[7] * c1 + _RGB_XYZ[8] * c2
            xx, yy, zz = xx * _INV_ILL[0], yy * _INV_ILL[1], zz * _INV_ILL[2]
            lum = _116 * yy - _16
            out[0, y, x] = lum
            out[1, y, x] = _500 * (xx - yy)
            out[2, y, x] = _200 * (yy - zz)
            out[3, y, x] = lum * _ONE_OVER_116 + _SIXTEEN_OVER_116


@_jit
def _filter_rows(src, sources, weights, out):
    """out[j, y, x] = Σₖ weights[j, k] · src[sources[j], y, x + k − r], x + k − r clamped to the row."""
    n, h, w = out.shape
    width = weights.shape[1]
    r = width // 2
    pad = np.empty(w + 2 * r, np.float32)
    for j in range(n):
        s = sources[j]
        for y in range(h):
            row = src[s, y]
            for i in range(r):
                pad[i] = row[0]
                pad[r + w + i] = row[w - 1]
            for x in range(w):
                pad[r + x] = row[x]
            o = out[j, y]
            o[:] = _ZERO
            for k in range(width):
                wk = weights[j, k]
                for x in range(w):
                    o[x] += wk * pad[x + k]


@_jit
def _filter_columns(src, sources, weights, out):
    """out[j, y, x] = Σₖ weights[j, k] · src[sources[j], y + k − r, x], y + k − r clamped to the column."""
    n, h, w = out.shape
    width = weights.shape[1]
    r = width // 2
    for j in range(n):
        s = sources[j]
        for y in range(h):
            o = out[j, y]
            o[:] = _ZERO
            for k in range(width):
                wk = weights[j, k]
                row = src[s, min(max(y + k - r, 0), h - 1)]
                for x in range(w):
                    o[x] += wk * row[x]


@_jit
def _lab_f(t):
    return _powf(t, _THIRD) if t > _DELTA_CUBE else _LAB_FACTOR * t + _LAB_TERM


@_jit
def _perceived(colour, features, out):
    """``out`` (5, H, W): per pixel, Hunt-adjusted CIELAB (L, 0.01·L·a, 0.01·L·b) of the filtered colour,
    clamped in linear RGB, and the edge and point magnitudes of the filtered luminance. One loop body, no
    helper returning the five: that call measured 2.8× the cost of the loop (LLVM does not inline it)."""
    for y in range(out.shape[1]):
        for x in range(out.shape[2]):
            fy = (colour[0, y, x] + _16) / _116
            cx = colour[1, y, x] / _500
            cz = (colour[2, y, x] + colour[3, y, x]) / _200
            xx, yy, zz = (fy + cx) * _ILL[0], fy * _ILL[1], (fy - cz) * _ILL[2]
            r = min(max(_XYZ_RGB[0] * xx + _XYZ_RGB[1] * yy + _XYZ_RGB[2] * zz, _ZERO), _ONE)
            g = min(max(_XYZ_RGB[3] * xx + _XYZ_RGB[4] * yy + _XYZ_RGB[5] * zz, _ZERO), _ONE)
            b = min(max(_XYZ_RGB[6] * xx + _XYZ_RGB[7] * yy + _XYZ_RGB[8] * zz, _ZERO), _ONE)
            xx = (_RGB_XYZ[0] * r + _RGB_XYZ[1] * g + _RGB_XYZ[2] * b) * _INV_ILL[0]
            yy = (_RGB_XYZ[3] * r + _RGB_XYZ[4] * g + _RGB_XYZ[5] * b) * _INV_ILL[1]
            zz = (_RGB_XYZ[6] * r + _RGB_XYZ[7] * g + _RGB_XYZ[8] * b) * _INV_ILL[2]
            fx, fy, fz = _lab_f(xx), _lab_f(yy), _lab_f(zz)
            lum = _116 * fy - _16
            out[0, y, x] = lum
            out[1, y, x] = _HUNT * lum * (_500 * (fx - fy))
            out[2, y, x] = _HUNT * lum * (_200 * (fy - fz))
            dx, ddx, dy, ddy = features[0, y, x], features[1, y, x], features[2, y, x], features[3, y, x]
            out[3, y, x] = np.sqrt(dx * dx + dy * dy)
            out[4, y, x] = np.sqrt(ddx * ddx + ddy * ddy)


#: The colour pipeline's channels: horizontal pass Y, Cx, Cz (twice, for Cz's two Gaussians); the vertical
#: pass filters each of those four with the same row of weights.
_COLOUR_ROWS, _COLOUR_COLUMNS = np.array([0, 1, 2, 2]), np.array([0, 1, 2, 3])
#: The feature pipeline's: horizontal first and second derivative and Gaussian of the normalised Y (plane 3);
#: vertical, the derivatives smoothed by the Gaussian and the Gaussian differentiated once and twice.
_FEATURE_ROWS, _FEATURE_ROW_WEIGHTS = np.array([3, 3, 3]), np.array([1, 2, 0])
_FEATURE_COLUMNS, _FEATURE_COLUMN_WEIGHTS = np.array([0, 1, 2, 2]), np.array([0, 0, 1, 2])


class Workspace:
    """Scratch planes for one image size: the filtering's, and the test image's side, reused across the
    exposures of one map."""

    def __init__(self, h: int, w: int):
        self.ycxcz, self.rows, self.colour = (np.empty((4, h, w), np.float32) for _ in range(3))
        self.side = np.empty((5, h, w), np.float32)


def _filtered(rgb, scale, tone_mapper, ppd, ws: Workspace) -> tuple[np.ndarray, np.ndarray]:
    """One image's filtered colour channels (Y, Cx, Cz₁, Cz₂) and luminance derivatives (dx, ddx, dy, ddy) at
    one exposure, in ``ws``'s planes (valid until its next use)."""
    spatial, feature = filters(ppd)
    _exposed_ycxcz(rgb, F(scale), np.asarray(tone_mapper, np.float32), ws.ycxcz)
    _filter_rows(ws.ycxcz, _COLOUR_ROWS, spatial, ws.rows)
    _filter_columns(ws.rows, _COLOUR_COLUMNS, spatial, ws.colour)
    _filter_rows(ws.ycxcz, _FEATURE_ROWS, feature[_FEATURE_ROW_WEIGHTS], ws.rows[:3])
    _filter_columns(ws.rows, _FEATURE_COLUMNS, feature[_FEATURE_COLUMN_WEIGHTS], ws.ycxcz)  # Y is no longer needed
    return ws.colour, ws.ycxcz


def image_side(rgb: np.ndarray, scale: float, tone_mapper, ppd: float, ws: Workspace | None = None) -> np.ndarray:
    """One image's side of LDR-FLIP at one exposure: (5, H, W) float32, Hunt-adjusted CIELAB of its filtered
    colour and the edge and point magnitudes of its luminance (:func:`_perceived`); with a workspace ``ws``,
    its plane ``side`` (valid until its next use), else a new array.

    ``rgb`` (H, W, 3) float32 linear, ``scale`` the exposure's factor 2^c (float32), ``tone_mapper`` its six
    coefficients.
    """
    h, w = rgb.shape[:2]
    colour, features = _filtered(rgb, scale, tone_mapper, ppd, ws or Workspace(h, w))
    out = np.empty((5, h, w), np.float32) if ws is None else ws.side
    _perceived(colour, features, out)
    return out


# -------------------------------------------------------------------------------------- the comparison


@_jit
def _max_distance():
    """c_max: the HyAB distance of Hunt-adjusted green and blue, raised to q_c (the library's computeMaxDistance)."""
    labs = np.empty((2, 3), np.float32)
    for i in range(2):
        r, g, b = _ZERO, _ONE if i == 0 else _ZERO, _ONE if i == 1 else _ZERO
        xx = (_RGB_XYZ[0] * r + _RGB_XYZ[1] * g + _RGB_XYZ[2] * b) * _INV_ILL[0]
        yy = (_RGB_XYZ[3] * r + _RGB_XYZ[4] * g + _RGB_XYZ[5] * b) * _INV_ILL[1]
        zz = (_RGB_XYZ[6] * r + _RGB_XYZ[7] * g + _RGB_XYZ[8] * b) * _INV_ILL[2]
        fx, fy, fz = _lab_f(xx), _lab_f(yy), _lab_f(zz)
        lum = _116 * fy - _16
        labs[i, 0], labs[i, 1], labs[i, 2] = lum, _HUNT * lum * (_500 * (fx - fy)), _HUNT * lum * (_200 * (fy - fz))
    da, db = labs[0, 1] - labs[1, 1], labs[0, 2] - labs[1, 2]
    return _powf(abs(labs[0, 0] - labs[1, 0]) + np.sqrt(da * da + db * db), GQC)


@_jit
def _keep_largest_error(ref, test, error):
    """``error`` = max(``error``, LDR-FLIP of ``test`` against ``ref``), both sides (5, H, W) of one exposure.

    Apart from :func:`_perceived`, not fused with it: the fused loop measured 4× slower than the two."""
    cmax = _max_distance()
    pccmax = GPC * cmax
    low_slope = GPT / pccmax
    h, w = error.shape
    for y in range(h):
        for x in range(w):
            da, db = ref[1, y, x] - test[1, y, x], ref[2, y, x] - test[2, y, x]
            c = (abs(ref[0, y, x] - test[0, y, x]) + np.sqrt(da * da + db * db)) ** GQC
            if c < pccmax:
                c *= low_slope
            else:
                c = GPT + ((c - pccmax) / (cmax - pccmax)) * (_ONE - GPT)
            f = (_SQRT_HALF * max(abs(ref[3, y, x] - test[3, y, x]), abs(ref[4, y, x] - test[4, y, x]))) ** GQF
            e = c ** (_ONE - f)
            if e > error[y, x]:
                error[y, x] = e


if njit is None:  # numpy's whole-plane kernels, the same arithmetic (hdr_flip_numpy)
    from cornell_harness.evaluate import hdr_flip_numpy as _planes

    _exposed_ycxcz, _perceived = _planes.exposed_ycxcz, _planes.perceived
    _filter_rows, _filter_columns = _planes.filter_rows, _planes.filter_columns

    def _keep_largest_error(ref, test, error):
        _planes.keep_largest_error(ref, test, error, _max_distance())


def exposure_scales(start: float, stop: float, count: int) -> list[np.float32]:
    """The factors 2^c of ``count`` exposures c evenly spaced over [start, stop], in the library's float32."""
    start, stop = F(start), F(stop)
    step = (stop - start) / F(count - 1)
    return [np.power(F(2.0), start + F(i) * step) for i in range(count)]


class SideCache:
    """A reference's sides (:func:`image_side`) by (content digest, shape, exposure factor, pixels per degree,
    tone mapper), least recently used dropped beyond ``max_bytes``.

    Keyed by the reference's content (a SHA-256 digest of its float32 pixels, ~0.5 ms at 256²), not by the array
    object: a reference changed in place, or a new array with other pixels, is a new key, and never gets an
    entry made for other pixels.
    """

    def __init__(self, max_bytes: int = 256 << 20):
        self.max_bytes = max_bytes
        self.entries: OrderedDict[tuple, np.ndarray] = OrderedDict()
        self.hits = self.misses = 0
        self._lock = threading.Lock()  # a Dask worker may score in threads; an entry is computed outside it

    @staticmethod
    def digest(ref: np.ndarray) -> str:
        return hashlib.sha256(np.ascontiguousarray(ref, np.float32).data).hexdigest()

    def side(self, ref: np.ndarray, digest: str, scale, tone_mapper, ppd: float) -> np.ndarray:
        key = (digest, ref.shape, float(scale), float(F(ppd)), tuple(float(F(t)) for t in tone_mapper))
        with self._lock:
            found = self.entries.get(key)
            if found is not None:
                self.hits += 1
                self.entries.move_to_end(key)
                return found
            self.misses += 1
        found = image_side(ref, scale, tone_mapper, ppd)
        found.setflags(write=False)
        with self._lock:
            self.entries[key] = found
            while sum(a.nbytes for a in self.entries.values()) > self.max_bytes and len(self.entries) > 1:
                self.entries.popitem(last=False)
        return found

    def clear(self) -> None:
        with self._lock:
            self.entries.clear()


#: The process's cache of reference sides (8 exposures of a 256² reference: 10 MiB).
REFERENCE_SIDES = SideCache()


def hdr_flip_map(test: np.ndarray, ref: np.ndarray, scales, tone_mapper, ppd: float,
                 cache: SideCache | None = REFERENCE_SIDES, digest: str | None = None) -> np.ndarray:
    """Per-pixel HDR-FLIP (H, W) float32 of ``test`` against ``ref`` ((H, W, 3) float32, non-negative, finite)
    over the exposure factors ``scales`` (:func:`exposure_scales`): each pixel's largest LDR-FLIP error.

    The reference's side of each exposure comes from ``cache`` (None: computed afresh); ``digest`` is
    :meth:`SideCache.digest` of ``ref``, where the caller has it already.
    """
    if cache is not None and digest is None:
        digest = SideCache.digest(ref)
    ws = Workspace(*ref.shape[:2])
    error = np.zeros(ref.shape[:2], np.float32)
    for scale in scales:
        ref_side = (cache.side(ref, digest, scale, tone_mapper, ppd) if cache is not None
                    else image_side(ref, scale, tone_mapper, ppd))
        _keep_largest_error(ref_side, image_side(test, scale, tone_mapper, ppd, ws), error)
    return error

"""Spatiotemporal variance-guided filtering (SVGF): temporal accumulation, a variance estimate, and an à-trous filter.

Schied, Kaplanyan, Wyman, Patney, Chaitanya, Burgess, Liu, Dachsbacher, Lefohn
and Salvi 2017, "Spatiotemporal Variance-Guided Filtering: Real-Time
Reconstruction for Path-Traced Global Illumination" (HPG), as the stage
``<renderer>+svgf`` (``pathtracer+svgf``) around any renderer that gives the
albedo AOV (:data:`cornell_harness.adapters.api.AOVS`); the toolkit gives the G-buffer
(depth, normal, object) and the motion vectors (:mod:`cornell_harness.renderers.core.frames`).
Per frame:

1. **Demodulation** (§4): the illumination is the colour divided by the
   albedo where it is not black, so texture is not blurred; the filtered
   illumination is multiplied by it again at the end.
2. **Temporal accumulation** (§4.1): the illumination and the first two
   moments μ₁, μ₂ of its luminance l are blended into the reprojected history
   (:func:`cornell_harness.renderers.core.motion.reproject`, with its disocclusion
   rejection) by exponential moving averages, weights max(α, 1/n) with n the
   history length in frames (a young history is an exact mean); the colour
   history is the output of the first à-trous iteration, as the paper does.
3. **Variance** (§4.2): σ² = μ₂ − μ₁² where the history has at least
   :data:`MIN_HISTORY` frames; elsewhere the moments of a 7 × 7 neighbourhood,
   weighted by the depth and normal edge-stopping functions below.
4. **À-trous wavelet filter** (§4.3, Dammertz et al. 2010): ``iterations``
   passes of the 5 × 5 B3-spline kernel h with holes 2^k,

       ĉ_{k+1}(p) = Σ_q h(q) w(p, q) ĉ_k(q) / Σ_q h(q) w(p, q)        (Eq. 1)
       Var_{k+1}(p) = Σ_q h(q)² w(p, q)² Var_k(q) / (Σ_q h(q) w(p, q))²

   with w = w_z · w_n · w_l, the edge-stopping functions of §4.4:

       w_z = exp(−|z(p) − z(q)| / (σ_z |∇z(p) · (p − q)| + ε))     (depth)
       w_n = max(0, n(p) · n(q))^σ_n                              (normal)
       w_l = exp(−|l(p) − l(q)| / (σ_l √(g₃ₓ₃(Var(l(p)))) + ε))    (luminance)

   (σ_z = 1, σ_n = 128, σ_l = 4, g₃ₓ₃ a 3 × 3 Gaussian: the paper's values),
   and 0 between different objects. Emitters are not filtered: the paper
   filters the illumination without emission, which is added back after.

Not modelled: the paper's separate filtering of direct and indirect light (our
renderers give one image), its 3 × 3 fallback of reprojection, and its final
TAA pass.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from cornell_harness.adapters.api import Setting
from cornell_harness.renderers.core.motion import reproject
from cornell_harness.renderers.core.frames import Frame, TemporalStage

#: Rec. 709 luminance of linear sRGB (the scene model's colour space).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
#: Frames of history from which the variance is the temporal moments' (§4.2).
MIN_HISTORY = 4
#: The B3-spline's weights (1, 4, 6, 4, 1)/16 of the à-trous kernel, and the 3 × 3 Gaussian's (1, 2, 1)/4.
B3 = np.array([1.0, 4.0, 6.0, 4.0, 1.0]) / 16.0
GAUSS3 = np.array([1.0, 2.0, 1.0]) / 4.0
EPSILON = 1e-10
#: Albedo below which a pixel is not demodulated (its colour is filtered as it is).
BLACK = 1e-3


def luminance(rgb: np.ndarray) -> np.ndarray:
    return rgb @ LUMINANCE


def demodulate(colour: np.ndarray, albedo: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(illumination, the albedo to multiply back): colour / albedo per channel, 1 where the albedo is black."""
    factor = np.where(albedo > BLACK, albedo, 1.0)
    return colour / factor, factor


def accumulate_moments(illum: np.ndarray, old_illum: np.ndarray, old_moments: np.ndarray, old_length: np.ndarray,
                       valid: np.ndarray, alpha: float, alpha_moments: float):
    """Step 2: (illumination, moments (H, W, 2) of luminance, history length) after this frame.

    Where ``valid`` the new values are blended into the reprojected history with weights max(α, 1/n)
    (n the new history length); elsewhere the history restarts at this frame (n = 1)."""
    lum = luminance(illum)
    current = np.stack([lum, lum * lum], axis=-1)
    length = np.where(valid, old_length + 1.0, 1.0)
    a = np.maximum(alpha, 1.0 / length)[..., None]
    am = np.maximum(alpha_moments, 1.0 / length)[..., None]
    out = np.where(valid[..., None], a * illum + (1.0 - a) * old_illum, illum)
    moments = np.where(valid[..., None], am * current + (1.0 - am) * old_moments, current)
    return out, moments, length


def _shifted(a: np.ndarray, dy: int, dx: int, fill=0.0) -> tuple[np.ndarray, np.ndarray]:
    """(a[y + dy, x + dx] for every pixel, whether that is inside the image); ``fill`` outside."""
    h, w = a.shape[:2]
    out = np.full_like(a, fill)
    inside = np.zeros((h, w), bool)
    ys, yd = slice(max(dy, 0), h + min(dy, 0)), slice(max(-dy, 0), h + min(-dy, 0))
    xs, xd = slice(max(dx, 0), w + min(dx, 0)), slice(max(-dx, 0), w + min(-dx, 0))
    out[yd, xd] = a[ys, xs]
    inside[yd, xd] = True
    return out, inside


def _depth_gradient(depth: np.ndarray) -> np.ndarray:
    """(H, W, 2) screen-space gradient (∂z/∂x, ∂z/∂y) per pixel; 0 where the depth is not finite."""
    z = np.where(np.isfinite(depth), depth, np.nan)
    with np.errstate(invalid="ignore"):
        gy, gx = np.gradient(z) if min(z.shape) > 1 else (np.zeros_like(z), np.zeros_like(z))
    return np.nan_to_num(np.stack([gx, gy], axis=-1))


def _geometry_weight(g, grad, dy: int, dx: int, sigma_z: float, sigma_n: float) -> np.ndarray:
    """w_z · w_n between each pixel p and q = p + (dx, dy); 0 where q is outside, sees nothing or another object."""
    zq, inside = _shifted(np.nan_to_num(g.depth, posinf=0.0), dy, dx)
    nq, _ = _shifted(np.nan_to_num(g.normal), dy, dx)
    oq, _ = _shifted(g.object, dy, dx, -1)
    z = np.nan_to_num(g.depth, posinf=0.0)
    step = np.abs(grad[..., 0] * dx + grad[..., 1] * dy)
    wz = np.exp(-np.abs(z - zq) / (sigma_z * step + EPSILON))
    wn = np.maximum(0.0, np.sum(np.nan_to_num(g.normal) * nq, axis=-1)) ** sigma_n
    return np.where(inside & (g.object >= 0) & (oq == g.object), wz * wn, 0.0)


def variance_estimate(moments: np.ndarray, length: np.ndarray, g, sigma_z: float, sigma_n: float) -> np.ndarray:
    """Step 3: σ² of luminance per pixel: μ₂ − μ₁² with enough history, a 7 × 7 bilateral estimate elsewhere."""
    temporal = np.maximum(moments[..., 1] - moments[..., 0] ** 2, 0.0)
    if np.all(length >= MIN_HISTORY):
        return temporal
    grad = _depth_gradient(g.depth)
    total, m = np.zeros(length.shape), np.zeros(moments.shape)
    for dy in range(-3, 4):
        for dx in range(-3, 4):
            w = 1.0 if dx == dy == 0 else _geometry_weight(g, grad, dy, dx, sigma_z, sigma_n)
            mq, _ = _shifted(moments, dy, dx)
            m += w[..., None] * mq if np.ndim(w) else w * mq
            total += w
    m /= total[..., None]
    spatial = np.maximum(m[..., 1] - m[..., 0] ** 2, 0.0)
    return np.where(length >= MIN_HISTORY, temporal, spatial)


def _blur3(a: np.ndarray) -> np.ndarray:
    """g₃ₓ₃: the 3 × 3 Gaussian of ``a`` (H, W), renormalised at the border."""
    total, out = np.zeros(a.shape), np.zeros(a.shape)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            v, inside = _shifted(a, dy, dx)
            k = GAUSS3[dy + 1] * GAUSS3[dx + 1] * inside
            out += k * v
            total += k
    return out / total


def atrous(illum: np.ndarray, variance: np.ndarray, g, iterations: int, sigma_z: float = 1.0,
           sigma_n: float = 128.0, sigma_l: float = 4.0, emitting: np.ndarray | None = None):
    """Step 4 (Eq. 1 and the variance's propagation, with w_z, w_n, w_l): (the filtered illumination, the output
    of the first iteration, the next frame's colour history). Pixels that see nothing or an emitter
    (``emitting``, (H, W) bool) are left as they are."""
    emitting = np.zeros(g.object.shape, bool) if emitting is None else emitting
    grad = _depth_gradient(g.depth)
    c, var, first = illum, variance, illum
    for k in range(iterations):
        hole = 1 << k
        lum = luminance(c)
        scale = sigma_l * np.sqrt(_blur3(var)) + EPSILON
        num, total, vnum = np.zeros(c.shape), np.zeros(lum.shape), np.zeros(lum.shape)
        for i, dy in enumerate(range(-2, 3)):
            for j, dx in enumerate(range(-2, 3)):
                h = B3[i] * B3[j]
                if dx == dy == 0:
                    w = np.ones(lum.shape)
                else:
                    lq, _ = _shifted(lum, dy * hole, dx * hole)
                    w = _geometry_weight(g, grad, dy * hole, dx * hole, sigma_z, sigma_n) \
                        * np.exp(-np.abs(lum - lq) / scale)
                cq, _ = _shifted(c, dy * hole, dx * hole)
                vq, _ = _shifted(var, dy * hole, dx * hole)
                num += (h * w)[..., None] * cq
                total += h * w
                vnum += (h * w) ** 2 * vq
        seen = (g.object >= 0)[..., None] & ~emitting[..., None]
        c = np.where(seen, num / total[..., None], c)
        var = np.where(seen[..., 0], vnum / total ** 2, var)
        if k == 0:
            first = c
    return c, first


def emitters(scene) -> np.ndarray:
    """(objects,) bool: which of the scene's objects (:meth:`~cornell_harness.scenes.model.Scene.object_names`) emit."""
    return np.array([m.is_emitter for m in scene.meshes] + [False] * len(scene.spheres), bool)


class SVGF(TemporalStage):
    """``<renderer>+svgf`` (module docstring) around ``base``, which must give the albedo AOV."""

    suffix = "svgf"
    aovs_needed = ("albedo", "normal")  # asked for together: a renderer of ours writes both in one pass
    OWN_SETTINGS = (
        Setting("alpha", float, 0.2, "weight of the new frame in the colour's moving average (SVGF 0.2)",
                low=0.001, high=1.0),
        Setting("alpha_moments", float, 0.2, "weight of the new frame in the moments' moving average (SVGF 0.2)",
                low=0.001, high=1.0),
        Setting("iterations", int, 5, "à-trous iterations (SVGF 5: a 61-pixel footprint)", low=0, high=10),
        Setting("sigma_l", float, 4.0, "luminance edge-stopping σ_l (SVGF 4)", low=0.01, high=1000.0),
    )
    citations = ('Schied et al. 2017, "Spatiotemporal Variance-Guided Filtering: Real-Time Reconstruction for '
                 'Path-Traced Global Illumination" (HPG)',
                 'Dammertz, Sewtz, Hanika and Lensch 2010, "Edge-Avoiding À-Trous Wavelet Transform for fast Global '
                 'Illumination Filtering" (HPG)')
    approximation = ("denoised by SVGF: moving averages of reprojected history and an edge-stopping à-trous "
                     "filter; lags, blurs, ghosts; biased")

    def step(self, history: dict, frame: Frame, prev: Frame | None, settings: Mapping[str, Any]):
        g = frame.gbuffer
        illum, factor = demodulate(np.asarray(frame.result.image, np.float64),
                                   np.asarray(frame.result.aovs["albedo"], np.float64))
        shape = illum.shape[:2]
        if prev is None:
            old = np.zeros(shape + (6,))
            valid = np.zeros(shape, bool)
        else:
            stacked = np.concatenate([history["illum"], history["moments"], history["length"][..., None]], -1)
            old, valid = reproject(stacked, frame.motion, prev.gbuffer, g, prev.offsets, frame.offsets)
        illum, moments, length = accumulate_moments(illum, old[..., :3], old[..., 3:5], old[..., 5], valid,
                                                    settings["alpha"], settings["alpha_moments"])
        variance = variance_estimate(moments, length, g, 1.0, 128.0)
        filtered, first = atrous(illum, variance, g, settings["iterations"], sigma_l=settings["sigma_l"],
                                 emitting=emitters(frame.scene)[np.maximum(g.object, 0)] & (g.object >= 0))
        history.update(illum=first, moments=moments, length=length)
        return filtered * factor, {"history_fraction": round(float(valid.mean()), 4),
                                   "mean_variance": float(variance.mean())}


class PathTracerSVGF(SVGF):
    """``pathtracer+svgf``: our path tracer (:mod:`cornell_harness.renderers.pathtracer`), filtered by SVGF."""

    def __init__(self, threads: int | None = None):
        from cornell_harness.renderers.pathtracer import PathTracer

        super().__init__(PathTracer(threads), threads)

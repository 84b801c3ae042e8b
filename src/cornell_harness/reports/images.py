"""Pixels of the report: colour maps applied, PNG and float16 embedding, per-pixel error maps.

The report's images are embedded as HDR data (little-endian float16, base64,
:func:`f16_base64`) and its colour bars and the gate's maps as PNG
(:func:`png_data_uri`). The viewer's false-colour maps
(:func:`error_maps`) are

- per-pixel CIEDE2000 (:func:`cornell_harness.evaluate.metrics.delta_e2000`), viridis, fixed
  0..10;
- per-pixel relMSE ``mean_c (x − r)² / (r² + ε)``, ε =
  :data:`cornell_harness.evaluate.metrics.REL_MSE_EPS`, inferno on a fixed log scale
  10⁻⁶..1 (embedded as log10 so float16 keeps its precision);
- FLIP (Andersson et al. 2020; computed by :mod:`cornell_harness.evaluate.hdr_flip`) in its **HDR
  mode on the linear images** (non-finite pixels set to 0, negatives
  clipped to 0), magma, 0..1: :func:`cornell_harness.evaluate.flip.flip_map`, whose
  mean is the ``flip_mean`` metric. Its exposure range comes from the
  reference (:func:`cornell_harness.evaluate.flip.flip_parameters`), so it does not
  depend on the harness exposure.

Maps are computed from the float32 images in Python and embedded as
float16, not recomputed from the float16 images in the browser. Colour
tables come from :mod:`cornell_harness.reports.colormaps`.
"""

from __future__ import annotations

import base64
import io

import numpy as np
from PIL import Image

from cornell_harness.evaluate import flip, metrics
from cornell_harness.reports.colormaps import TABLES

#: Fixed ΔE00 range of every heatmap; values outside are clipped.
DELTA_E_RANGE = (0.0, 10.0)
#: Fixed log10 range of the per-pixel relMSE map.
REL_MSE_LOG_RANGE = (-6.0, 0.0)
#: FLIP's own range.
FLIP_RANGE = (0.0, 1.0)
#: Just-noticeable difference in ΔE00 (same value the metrics use).
JND = getattr(metrics, "JND_DELTA_E2000", 2.3)
#: Largest finite float16; finite radiance above it is clipped to it when embedded.
F16_MAX = 65504.0
#: Colour map of each false-colour mode.
MAP_COLORMAPS = {"de": "viridis", "relmse": "inferno", "flip": "magma"}


def apply_colormap(values, vmin: float = DELTA_E_RANGE[0], vmax: float = DELTA_E_RANGE[1],
                   cmap: str = "viridis") -> np.ndarray:
    """Colours of ``values`` on [vmin, vmax] (clipped), uint8 of shape ``values.shape + (3,)``.

    NaN maps to the top of the scale: an undefined difference is shown as the
    worst one, never hidden as a good one. The report's script uses the same
    256-entry tables and the same rule.
    """
    v = np.asarray(values, dtype=np.float64)
    t = np.clip((v - vmin) / (vmax - vmin), 0.0, 1.0)
    t = np.where(np.isnan(t), 1.0, t)
    return TABLES[cmap][np.round(t * 255).astype(np.int64)]


def to_uint8(encoded) -> np.ndarray:
    """A display-encoded float image in [0, 1] as uint8 (rounded, clipped)."""
    x = np.nan_to_num(np.asarray(encoded, dtype=np.float64), nan=0.0)
    return np.round(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)


def png_data_uri(pixels: np.ndarray) -> str:
    """``data:image/png;base64,...`` of a uint8 (H, W) or (H, W, 3) array."""
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels)).save(buf, format="PNG", optimize=True)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def colorbar_data_uri(cmap: str = "viridis", width: int = 256, height: int = 1) -> str:
    """The colour bar of ``cmap`` as a (height, width) PNG, low values on the left."""
    ramp = apply_colormap(np.linspace(0.0, 1.0, width), 0.0, 1.0, cmap)
    return png_data_uri(np.repeat(ramp[None, :, :], height, axis=0))


def f16_base64(values) -> str:
    """Little-endian float16 bytes of ``values`` (row-major), base64.

    NaN and ±Inf stay as they are; finite values beyond the float16 range are
    clipped to ±65504 so that a bright but finite pixel does not turn into Inf.
    """
    a = np.asarray(values, dtype=np.float64)
    a = np.where(np.isfinite(a), np.clip(a, -F16_MAX, F16_MAX), a)
    return base64.b64encode(np.ascontiguousarray(a.astype("<f2")).tobytes()).decode("ascii")


def f16_decode(text: str, shape) -> np.ndarray:
    """Inverse of :func:`f16_base64` (float32), for tests and tools."""
    return np.frombuffer(base64.b64decode(text, validate=True), dtype="<f2").astype(np.float32).reshape(shape)


def rel_mse_map(img, ref, eps: float = metrics.REL_MSE_EPS) -> np.ndarray:
    """Per-pixel relMSE, ``mean_c (x − r)² / (r² + ε)``, shape (H, W); its mean is :func:`metrics.rel_mse`.

    A pixel with a non-finite channel is taken as black, as the metrics do.
    """
    img = np.asarray(img, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    clean = np.where(np.all(np.isfinite(img), axis=-1)[..., None], img, 0.0)
    return np.mean((clean - ref) ** 2 / (ref**2 + eps), axis=-1)


def error_maps(img, ref, exposure: float) -> dict[str, np.ndarray | None]:
    """The viewer's three false-colour maps: ``de`` (ΔE00), ``relmse`` and ``flip`` (HDR-FLIP, the metric's map)."""
    _, de = metrics.delta_e2000(img, ref, exposure=exposure, full=True)
    return {"de": np.asarray(de, dtype=np.float64), "relmse": rel_mse_map(img, ref), "flip": flip.flip_map(img, ref)}

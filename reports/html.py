"""The HTML report: one self-contained file comparing every renderer to the reference.

The file works offline: no scripts, fonts or styles are fetched, and every
image is inlined as a base64 PNG ``data:`` URI. It shows

- the scene, the reference's provenance, the command line and the runs' spp/seed;
- the reference and each renderer's image, all display-encoded with the
  harness's one encoding (:func:`harness.metrics.display_encode`) at the one
  exposure derived from the reference (:func:`harness.metrics.exposure_scale`);
- per renderer, its CIEDE2000 map on a fixed 0..10 viridis scale, so maps of
  different renderers can be compared by eye, with a labelled colour bar;
- the metrics table (one row per record) and why any renderer did not run.

Entry point: :func:`write_report`.
"""

from __future__ import annotations

import base64
import datetime as _dt
import io
import math
from pathlib import Path
from typing import Any, Iterable, Sequence

import jinja2
import numpy as np
from PIL import Image

from harness import metrics
from harness.atomic import write_text_atomic

#: Fixed ΔE00 range of every heatmap; values outside are clipped.
DELTA_E_RANGE = (0.0, 10.0)
#: Just-noticeable difference in ΔE00 (same value the metrics use).
JND = getattr(metrics, "JND_DELTA_E2000", 2.3)
#: On-screen magnification of every image (CSS pixels per image pixel).
DISPLAY_SCALE = 2

# Matplotlib's viridis (van der Walt & Smith, CC0), entries 0, 16, ..., 240, 255
# of its 256-entry table; :func:`apply_colormap` interpolates linearly between
# them. The lightness of viridis increases monotonically, so the heatmap reads
# correctly in greyscale too.
_VIRIDIS_POS = np.array([i / 255 for i in (*range(0, 256, 16), 255)])
_VIRIDIS_RGB = np.array(
    [
        (0.267004, 0.004874, 0.329415),
        (0.282327, 0.094955, 0.417331),
        (0.278826, 0.175490, 0.483397),
        (0.258965, 0.251537, 0.524736),
        (0.229739, 0.322361, 0.545706),
        (0.199430, 0.387607, 0.554642),
        (0.172719, 0.448791, 0.557885),
        (0.149039, 0.508051, 0.557250),
        (0.127568, 0.566949, 0.550556),
        (0.120638, 0.625828, 0.533488),
        (0.157851, 0.683765, 0.501686),
        (0.246070, 0.738910, 0.452024),
        (0.369214, 0.788888, 0.382914),
        (0.515992, 0.831158, 0.294279),
        (0.678489, 0.863742, 0.189503),
        (0.845561, 0.887322, 0.099702),
        (0.993248, 0.906157, 0.143936),
    ]
)

# Metrics table: (record key, column header, tooltip). Keys starting with
# "noise_" are appended after these.
METRIC_COLUMNS: tuple[tuple[str, str, str], ...] = (
    ("renderer", "renderer", "renderer name"),
    ("status", "status", "ok, skipped, unavailable or failed"),
    ("version", "version", "renderer version"),
    ("spp", "spp", "samples per pixel"),
    ("time_s", "time (s)", "wall time of the render proper"),
    ("rmse", "RMSE", "root-mean-square error on linear radiance"),
    ("rel_mse", "relMSE", "mean of (img-ref)²/(ref²+0.01) on linear radiance"),
    ("psnr", "PSNR (dB)", "PSNR of the display-encoded images"),
    ("ssim", "SSIM", "mean SSIM of the display-encoded images"),
    ("delta_e2000_mean", "ΔE mean", "mean CIEDE2000"),
    ("delta_e2000_p95", "ΔE p95", "95th percentile of CIEDE2000"),
    ("delta_e2000_max", "ΔE max", "maximum CIEDE2000"),
    ("delta_e2000_frac_gt_2_3", "ΔE > 2.3", "fraction of pixels above the just-noticeable difference"),
    ("nan_count", "NaN px", "pixels with a NaN channel"),
    ("inf_count", "Inf px", "pixels with an infinite channel"),
    ("negative_count", "neg px", "pixels with a negative channel"),
    ("mean_radiance_rel_error", "mean rad. err", "relative error of the image's mean radiance"),
)

#: Headers of the noise yardsticks we know; any other "noise_*" key gets a generic one.
NOISE_COLUMNS: dict[str, tuple[str, str]] = {
    "noise_rmse": ("RMSE (noise)", "expected RMSE from sampling noise alone at this spp"),
    "noise_delta_e2000_mean": ("ΔE mean (noise)", "ΔE mean of a simulated noise-only image at this spp"),
    "noise_mean_radiance_z": (
        "mean rad. z", "z-score of the mean-radiance difference given the noise; |z| > 3 points at bias"),
}

_NOT_RUN = ("skipped", "unavailable", "failed")


# --------------------------------------------------------------------------
# Images
# --------------------------------------------------------------------------


def apply_colormap(values, vmin: float = DELTA_E_RANGE[0], vmax: float = DELTA_E_RANGE[1]) -> np.ndarray:
    """Viridis colours of ``values`` on [vmin, vmax] (clipped), uint8 of shape ``values.shape + (3,)``.

    NaN maps to the top of the scale: an undefined difference is shown as the
    worst one, never hidden as a good one.
    """
    v = np.asarray(values, dtype=np.float64)
    t = np.clip((v - vmin) / (vmax - vmin), 0.0, 1.0)
    t = np.where(np.isnan(t), 1.0, t)
    rgb = np.stack([np.interp(t, _VIRIDIS_POS, _VIRIDIS_RGB[:, c]) for c in range(3)], axis=-1)
    return np.round(rgb * 255.0).astype(np.uint8)


def to_uint8(encoded) -> np.ndarray:
    """A display-encoded float image in [0, 1] as uint8 (rounded, clipped)."""
    x = np.nan_to_num(np.asarray(encoded, dtype=np.float64), nan=0.0)
    return np.round(np.clip(x, 0.0, 1.0) * 255.0).astype(np.uint8)


def png_data_uri(pixels: np.ndarray) -> str:
    """``data:image/png;base64,...`` of a uint8 (H, W) or (H, W, 3) array."""
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(pixels)).save(buf, format="PNG", optimize=True)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def colorbar_data_uri(width: int = 256, height: int = 1) -> str:
    """The colour bar as a (height, width) PNG, low values on the left."""
    lo, hi = DELTA_E_RANGE
    ramp = apply_colormap(np.linspace(lo, hi, width))
    return png_data_uri(np.repeat(ramp[None, :, :], height, axis=0))


# --------------------------------------------------------------------------
# Numbers
# --------------------------------------------------------------------------


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _generic(v: float) -> str:
    if v == 0:
        return "0"
    a = abs(v)
    if a >= 1e5 or a < 1e-3:
        return f"{v:.3e}"
    return f"{v:.4g}"


def format_value(key: str, v: Any) -> str:
    """A table cell: sensible precision per metric, "—" for missing values."""
    if v is None:
        return "—"
    if not _is_number(v):
        return str(v)
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    v = float(v)
    if math.isnan(v):
        return "NaN"
    if math.isinf(v):
        return "∞" if v > 0 else "−∞"
    if key.endswith("_count") or key == "spp":
        return str(int(v)) if v.is_integer() else _generic(v)
    if key == "time_s":
        return f"{v:.3f}" if v < 100 else f"{v:.1f}"
    if key == "psnr":
        return f"{v:.2f}"
    if key == "ssim":
        return f"{v:.4f}"
    if "frac" in key:
        return f"{100 * v:.1f} %"
    if key == "mean_radiance_rel_error":
        return f"{100 * v:+.2f} %"
    if key.endswith("_z"):
        return f"{v:+.2f}"
    if key.startswith("delta_e2000") or key.startswith("noise_delta_e2000"):
        return f"{v:.2f}"
    return _generic(v)


# --------------------------------------------------------------------------
# The report
# --------------------------------------------------------------------------


def _record_value(rec, key: str) -> Any:
    if key in ("renderer", "status", "version", "spp", "time_s", "seed", "reason"):
        return getattr(rec, key, None)
    return (rec.metrics or {}).get(key)


def _noise_keys(records: Iterable) -> list[str]:
    keys: list[str] = []
    for rec in records:
        for k in (rec.metrics or {}):
            if k.startswith("noise_") and k not in keys:
                keys.append(k)
    return keys


def _noise_column(key: str) -> tuple[str, str, str]:
    label, tip = NOISE_COLUMNS.get(
        key, (key.removeprefix("noise_").replace("_", " ") + " (noise)", "noise yardstick at this spp"))
    return key, label, tip


def _runs_summary(records: Sequence) -> str:
    pairs = sorted({(r.spp, r.seed) for r in records})
    if not pairs:
        return "no runs"
    if len(pairs) == 1:
        spp, seed = pairs[0]
        return f"{spp} spp, seed {seed}"
    return "; ".join(f"{spp} spp / seed {seed}" for spp, seed in pairs)


def _max_depth_text(max_depth: int) -> str:
    if max_depth < 0:
        return "unbounded (Russian roulette)"
    return f"{max_depth} segments"


def _provenance_rows(prov: dict, scene_hash: str) -> list[tuple[str, str]]:
    renderer = " ".join(
        str(x) for x in (prov.get("renderer"), prov.get("renderer_version")) if x not in (None, "")
    ) or "—"
    if prov.get("variant") and str(prov["variant"]) not in renderer:
        renderer += f", variant {prov['variant']}"
    spp = str(prov.get("spp", "—"))
    if prov.get("batches") and prov.get("batch_spp"):
        spp += f" ({prov['batches']} batches × {prov['batch_spp']} spp)"
    rows = [("renderer", renderer), ("spp", spp), ("date", str(prov.get("date", "—")))]
    for key, label in (("wall_time_s", "wall time (s)"), ("machine", "machine"), ("command", "built with")):
        if prov.get(key) not in (None, ""):
            rows.append((label, str(prov[key])))
    ref_hash = prov.get("scene_hash")
    if ref_hash and ref_hash != scene_hash:
        rows.append(("warning", f"reference built for scene hash {ref_hash}, not this scene's"))
    return rows


def _renderer_card(rec, reference: np.ndarray, exposure: float) -> dict:
    card = {
        "renderer": rec.renderer,
        "version": rec.version,
        "spp": rec.spp,
        "seed": rec.seed,
        "time": None if rec.time_s is None else format_value("time_s", rec.time_s),
        "approximations": [str(a) for a in (rec.approximations or ())],
        "render_uri": None,
        "heatmap_uri": None,
        "note": None,
        "stats": [],
    }
    image = rec.image
    if image is None:
        card["note"] = "no image was recorded for this run"
        return card
    image = np.asarray(image)
    if image.shape != reference.shape:
        card["note"] = f"image shape {image.shape} does not match the reference's {reference.shape}"
        return card
    card["render_uri"] = png_data_uri(to_uint8(metrics.display_encode(image, exposure)))
    mean_de, de_map = metrics.delta_e2000(image, reference, exposure=exposure, full=True)
    de_map = np.asarray(de_map, dtype=np.float64)
    card["heatmap_uri"] = png_data_uri(apply_colormap(de_map))
    m = rec.metrics or {}
    finite = de_map[np.isfinite(de_map)]
    p95 = float(np.percentile(finite, 95)) if finite.size else float("nan")
    frac = float(np.mean(de_map > JND))
    card["stats"] = [
        ("ΔE mean", format_value("delta_e2000_mean", mean_de)),
        ("ΔE p95", format_value("delta_e2000_p95", p95)),
        (f"ΔE > {JND:g}", format_value("delta_e2000_frac", frac)),
    ]
    if "noise_delta_e2000_mean" in m:
        card["stats"].append(("noise ΔE", format_value("noise_delta_e2000_mean", m["noise_delta_e2000_mean"])))
    for key, label in (("psnr", "PSNR"), ("ssim", "SSIM"), ("mean_radiance_rel_error", "mean rad.")):
        if key in m:
            card["stats"].append((label, format_value(key, m[key])))
    return card


def _environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.PackageLoader("reports", "templates"),
        autoescape=True,
        trim_blocks=True,
        lstrip_blocks=True,
        undefined=jinja2.StrictUndefined,
    )


def _harness_version() -> str:
    try:
        from importlib.metadata import version

        return version("cornell-harness")
    except Exception:
        return "unknown"


def render_html(
    *,
    scene,
    reference_image,
    reference_provenance: dict,
    records: Sequence,
    command: str = "",
    title: str | None = None,
) -> str:
    """The report's HTML text (see :func:`write_report`)."""
    reference = np.asarray(reference_image, dtype=np.float32)
    exposure = metrics.exposure_scale(reference)
    h, w = reference.shape[:2]
    scene_hash = scene.content_hash()
    records = list(records)
    prov = dict(reference_provenance or {})

    noise_keys = _noise_keys(records)
    columns = [*METRIC_COLUMNS, *(_noise_column(k) for k in noise_keys)]
    rows = []
    for rec in records:
        cells = []
        for key, _, _ in columns:
            v = _record_value(rec, key)
            cells.append({"key": key, "text": format_value(key, v), "numeric": _is_number(v)})
        rows.append({"status": rec.status, "cells": cells})

    ctx = {
        "title": title or f"Renderer comparison — {scene.name}",
        "scene": {
            "name": scene.name,
            "hash": scene_hash,
            "description": getattr(scene, "description", "") or "",
            "resolution": f"{scene.camera.width} × {scene.camera.height}",
            "max_depth": _max_depth_text(scene.max_depth),
            "pixel_filter": scene.pixel_filter,
        },
        "provenance": _provenance_rows(prov, scene_hash),
        "command": command,
        "runs": _runs_summary(records),
        "generated": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "harness_version": _harness_version(),
        "exposure": f"{exposure:.4g}",
        "reference_uri": png_data_uri(to_uint8(metrics.display_encode(reference, exposure))),
        "img_w": w * DISPLAY_SCALE,
        "img_h": h * DISPLAY_SCALE,
        "scale": DISPLAY_SCALE,
        "de_lo": DELTA_E_RANGE[0],
        "de_hi": DELTA_E_RANGE[1],
        "jnd": JND,
        "jnd_pct": 100 * (JND - DELTA_E_RANGE[0]) / (DELTA_E_RANGE[1] - DELTA_E_RANGE[0]),
        "ticks": [
            (f"{t:g}", 100 * (t - DELTA_E_RANGE[0]) / (DELTA_E_RANGE[1] - DELTA_E_RANGE[0]))
            for t in np.linspace(*DELTA_E_RANGE, 6)
        ],
        "colorbar_uri": colorbar_data_uri(),
        "cards": [_renderer_card(r, reference, exposure) for r in records if r.status == "ok"],
        "not_run": [
            {
                "renderer": r.renderer,
                "status": r.status,
                "reason": r.reason or "(no reason given)",
                "traceback": (r.info or {}).get("traceback"),
            }
            for r in records
            if r.status in _NOT_RUN
        ],
        "columns": columns,
        "rows": rows,
        "counts": {s: sum(r.status == s for r in records) for s in ("ok", *_NOT_RUN)},
    }
    return _environment().get_template("report.html.j2").render(**ctx)


def write_report(
    path,
    *,
    scene,
    reference_image,
    reference_provenance: dict,
    records,
    command: str = "",
    title: str | None = None,
) -> Path:
    """Write the self-contained HTML report to ``path`` atomically; return the path.

    ``scene`` is a :class:`harness.scene.Scene`, ``reference_image`` the
    (H, W, 3) linear-sRGB reference, ``records`` the
    :class:`harness.runner.RunRecord` list of a comparison, ``command`` the
    command line that produced it.
    """
    path = Path(path)
    html = render_html(
        scene=scene,
        reference_image=reference_image,
        reference_provenance=reference_provenance,
        records=records,
        command=command,
        title=title,
    )
    write_text_atomic(path, html)
    return path

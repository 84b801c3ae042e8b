"""Synthetic inputs for the HTML report tests: a small scene, a fake reference, tidy runs and a summary.

Nothing here renders: the "renderers" are the reference plus Gaussian noise
that shrinks as 1/√spp, and optionally a bias, so the numbers behave like
real convergence data (RMSE slope ≈ −½, a biased renderer flattens).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from cornell_harness.evaluate import metrics
from cornell_harness.store.references import Reference
from cornell_harness.scenes.loader import load_scene

ROOT = Path(__file__).resolve().parent.parent
EVIL = '<script>alert("x")</script> & more'

#: name -> (noise per sample (relative), bias (relative), seconds per spp, approximations)
RENDERERS = {
    "alpha-tracer": (0.6, 0.0, 0.010, ["no caustics", "light leaks at corners"]),
    "beta-photons": (0.25, 0.04, 0.004, ["density estimation blurs the lighting"]),
    "gamma-raster": (0.0, 0.12, 0.0005, []),
    "delta-fast": (1.2, 0.0, 0.002, []),
    "epsilon-probes": (0.1, 0.08, 0.003, ["probe grid of 8³"]),
}


def scene(width: int = 32, height: int = 32):
    return load_scene(ROOT / "src" / "cornell_harness" / "references" / "cornell-box").with_resolution(width, height)


def _stored_reference(h: int, w: int) -> np.ndarray | None:
    """The stored Cornell-box reference, box-filtered down to (h, w) when 256 is a multiple of both."""
    from cornell_harness.store.exr import read_exr

    path = ROOT / "src" / "cornell_harness" / "references" / "cornell-box" / "reference.exr"
    try:
        full = np.asarray(read_exr(path), dtype=np.float64)
    except Exception:
        return None
    fh, fw = full.shape[:2]
    if fh % h or fw % w:
        return None
    return full.reshape(h, fh // h, w, fw // w, 3).mean(axis=(1, 3)).astype(np.float32)


def reference(sc, spp: int = 4096) -> Reference:
    h, w = sc.camera.height, sc.camera.width
    rng = np.random.default_rng(0)
    img = _stored_reference(h, w)
    if img is None:  # a smooth synthetic image with a bright "light"
        yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
        base = 0.2 + 0.6 * np.stack([xx, 1 - yy, 0.5 + 0.3 * np.sin(6 * xx)], axis=-1)
        img = (base * rng.uniform(0.9, 1.1, (h, w, 3))).astype(np.float32)
        img[: max(1, h // 16), w // 3: 2 * w // 3] = 20.0
    variance = np.full_like(img, 1e-6)
    noise = img + rng.normal(0, 0.01, img.shape).astype(np.float32)
    prov = {"renderer": "mitsuba", "renderer_version": "3.9.1 (llvm_ad_rgb)", "variant": "llvm_ad_rgb",
            "spp": spp, "batches": 64, "batch_spp": spp // 64, "date": "2025-01-02T03:04:05+00:00",
            "scene_hash": sc.content_hash(), "seeds": list(range(1_000_000_000, 1_000_000_064)),
            "noise_spp": 64, "machine": "x86_64, 2 CPUs"}
    return Reference(img, variance, noise, prov, ROOT / "src" / "cornell_harness" / "references" / "cornell-box")


def render(ref: np.ndarray, name: str, spp: int, seed: int) -> np.ndarray:
    sigma, bias, _, _ = RENDERERS[name]
    rng = np.random.default_rng([seed, spp, sum(map(ord, name))])
    noisy = ref * (1 + bias) + ref * sigma / math.sqrt(spp) * rng.standard_normal(ref.shape)
    return np.maximum(noisy, 0).astype(np.float32)


def make_case(
    width: int = 32,
    height: int = 32,
    names=("alpha-tracer", "beta-photons", "gamma-raster"),
    spps=(4, 16, 64),
    seeds=(0, 1, 2),
    not_run: bool = True,
    with_summary: bool = True,
) -> dict:
    """Everything :func:`cornell_harness.reports.html.write_report` takes, plus the raw images by (name, seed, spp)."""
    sc = scene(width, height)
    ref = reference(sc)
    exposure = metrics.exposure_scale(ref.image)
    rows, raw = [], {}
    for name in names:
        sigma, bias, cost, approx = RENDERERS[name]
        for seed in seeds:
            for spp in spps:
                img = render(ref.image, name, spp, seed)
                raw[name, seed, spp] = img
                m = metrics.image_metrics(img, ref.image, exposure=exposure)
                m["mse"] = m["rmse"] ** 2
                m["rel_mse_trimmed"] = m["rel_mse"] * 0.9
                t = cost * spp * (1 + 0.05 * seed)
                rows.append({
                    "scene": sc.name, "scene_hash": sc.content_hash(), "renderer": name, "status": "ok",
                    "reason": None, "version": f"{name} 1.0", "settings": json.dumps({"max_depth": -1, "rr": 5}),
                    "approximations": json.dumps(approx), "seed": seed, "spp": spp, "time_s": t, **m,
                    "efficiency": 1.0 / (m["mse"] * t), "noise_rmse": m["rmse"] * 0.8,
                })
    if not_run:
        for name, status, reason in (
            ("zeta-skip", "skipped", "does not model area_light"),
            ("eta-missing", "unavailable", "eta is not installed; pip install eta"),
            ("theta-crash", "failed", f"RuntimeError: {EVIL}"),
        ):
            rows.append({"scene": sc.name, "scene_hash": sc.content_hash(), "renderer": name, "status": status,
                         "reason": reason, "version": None, "settings": "{}", "approximations": "[]",
                         "seed": math.nan, "spp": math.nan, "time_s": math.nan})
    runs = pd.DataFrame(rows)
    top = max(spps)
    images = {name: raw[name, seeds[0], top] for name in names}
    summary = None
    if with_summary:
        srows = []
        for name in names:
            g = runs[runs["renderer"] == name]
            slopes = [np.polyfit(np.log(s["spp"]), np.log(s["rmse"]), 1)[0] for _, s in g.groupby("seed")] \
                if len(spps) > 1 else [math.nan]
            finals = np.stack([raw[name, s, top] for s in seeds]).astype(np.float64)
            s2 = finals.var(axis=0, ddof=1) if len(seeds) > 1 else np.full(finals.shape[1:], np.nan)
            bias2 = float(np.mean((finals.mean(axis=0) - ref.image) ** 2 - s2 / len(seeds)))
            var = float(np.mean(s2))
            srows.append({
                "renderer": name, "seeds": len(seeds), "max_spp": top,
                "slope_rmse_spp": float(np.mean(slopes)), "slope_rmse_spp_ci": float(np.std(slopes) + 0.01),
                "slope_rmse_time": float(np.mean(slopes)), "slope_rmse_time_ci": float(np.std(slopes) + 0.01),
                "time_to_delta_e2000_mean_le_1": 0.05 if name == "alpha-tracer" else math.nan,
                "time_to_rel_mse_le_0.001": 0.2 if name != "gamma-raster" else math.nan,
                "efficiency": float(g[g["spp"] == top]["efficiency"].median()),
                "bias2": bias2, "variance": var,
                "bias2_fraction": max(bias2, 0) / (max(bias2, 0) + var) if var > 0 else math.nan,
            })
        summary = pd.DataFrame(srows)
    provenance = {"versions": {name: f"{name} 1.0" for name in names} | {"numpy": np.__version__, "harness": "0.1.0"},
                  "machine": "test machine, 2 CPUs", "seeds": list(seeds), "date": "2025-02-03T04:05:06+00:00",
                  "threads": 2}
    return {
        "scene": sc, "reference": ref, "runs": runs, "images": images, "summary": summary,
        "thresholds": {"delta_e2000_mean": ("<=", 3.0), "ssim": (">=", 0.9)},
        "provenance": provenance, "command": "cbox converge --scene cornell-box --spp 4,16,64 --seeds 0,1,2",
        "raw": raw,
    }


def write_case(path, case: dict, **overrides) -> Path:
    """:func:`cornell_harness.reports.html.write_report` on the case; without the figure files unless ``figures=True`` (the
    tests of figures ask for them; converting them to PDF and PNG takes seconds)."""
    from cornell_harness.reports.html import write_report

    kwargs = {k: case[k] for k in ("scene", "reference", "runs", "images", "summary", "thresholds",
                                   "provenance", "command")}
    kwargs["figures"] = False
    kwargs.update(overrides)
    return write_report(path, **kwargs)

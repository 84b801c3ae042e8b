"""Ambient occlusion: screen-space AO against ray-traced AO, and the ambient term against full GI (issue 12).

Five measurements, each printed as a markdown table (docs/ambient-occlusion.md
explains them):

1. **SSAO variants on ``cornell-box-ao``** (256²): ``ssao`` at several settings
   of each variant (crytek and hemisphere at 8/16/32 samples; gtao at
   slices × steps 2×4, 4×8 (default), 8×12, 16×16; gtao, crytek and
   hemisphere with a ``thickness``): milliseconds per frame (median of
   ``--frames`` timed frames of the screen-space pass after one warm-up
   frame, the pass the adapter times, G-buffer excluded), and RMSE, relMSE,
   SSIM image-wide and RMSE per region, from the harness's own scoring
   (:func:`cornell_harness.workflows.runner.run_one`). AO images have no ΔE.
2. **``ao`` against spp and time**: :func:`cornell_harness.workflows.converge.run_experiment`
   (what ``cbox converge`` runs; resumable in ``OUT/ao``) at spp 1, 2, 4, ...,
   ``--max-spp`` for ``--seeds`` seeds: RMSE and SSIM (medians over seeds) per
   spp and time, and the log-log slope of RMSE (mean over seeds, 95% CI).
3. **The crossover**: the spp and time at which ``ao`` becomes more accurate
   than the best SSAO setting of part 1, by RMSE and by SSIM, interpolated
   log-log between checkpoints (per seed, median over seeds:
   :func:`cornell_harness.evaluate.convergence.time_to_target`).
4. **``ambient`` against full GI on ``cornell-box``**: ΔE mean image-wide and
   per region for ``ambient`` (radiosity ambient), ``ambient[ambient=oracle]``,
   ``ambient[ambient=none]``, ``pyrender`` (all at ``--ambient-spp``), and the
   path tracer at equal time: its spp chosen, as ``cbox compare --time-budget``
   does (:func:`cornell_harness.workflows.compare.spp_for_time_budget`), for the wall
   time ``ambient`` (radiosity) took.
5. **SSAO's artefacts**, each with a figure written to ``--images``:
   screen borders (the same pixels rendered as a centred crop, whose frame
   cuts the walls), haloes at depth discontinuities (SSAO with and without
   the boxes: beyond the radius from a box its true effect is 0), thin
   geometry (the light quad 0.01 below the ceiling) and crytek's flat 1/2.

Results are cached in ``--out`` (JSON per measured setting, parquet cells for
the ``ao`` experiment): running the command again recomputes only what is
missing; delete the folder (or a file in it) to measure again.

``--markdown FILE`` (repeatable) writes the tables into the file's blocks (``benchmarks/markdown_blocks.py``):
docs/ambient-occlusion.md holds ``ambient_occlusion.py#ssao``, ``#ao``, ``#crossover``, ``#ambient`` and
``#haloes``; BENCHMARKS.md the summaries ``#summary-ssao`` and ``#summary-ambient``.

Run: ``.venv/bin/python benchmarks/ambient_occlusion.py --markdown docs/ambient-occlusion.md --markdown
BENCHMARKS.md`` (about 2 minutes on 2 cores from an empty ``--out``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import statistics
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont
from scipy.ndimage import binary_dilation
from scipy.spatial import cKDTree

import figure_manifest
import markdown_blocks
from markdown_blocks import bold, minus
from cornell_harness.adapters.registry import resolve
from cornell_harness.adapters.settings import resolve_settings
from cornell_harness.evaluate.convergence import slope_over_seeds, time_to_target
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Region
from cornell_harness.store.atomic import write_json_atomic
from cornell_harness.store.references import load_reference
from cornell_harness.workflows import runner
from cornell_harness.workflows.compare import spp_for_time_budget
from cornell_harness.workflows.converge import run_experiment
from cornell_harness.workflows.spp_list import parse_spp_list
from cornell_harness.renderers.core.gbuffer import gbuffer, view_space
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.adapters.api import default_threads
from cornell_harness.renderers.ssao import SSAO, resolved_radius, screen_space_pass

AO_SCENE, GI_SCENE = "cornell-box-ao", "cornell-box"
#: Part 1's settings: (label, renderer spec).
SSAO_SETTINGS = (
    ("crytek 8", "ssao[variant=crytek,samples=8]"),
    ("crytek 16", "ssao[variant=crytek,samples=16]"),
    ("crytek 32", "ssao[variant=crytek,samples=32]"),
    ("hemisphere 8", "ssao[variant=hemisphere,samples=8]"),
    ("hemisphere 16", "ssao[variant=hemisphere,samples=16]"),
    ("hemisphere 32", "ssao[variant=hemisphere,samples=32]"),
    ("gtao 2×4", "ssao[variant=gtao,slices=2,steps=4]"),
    ("gtao 4×8 (default)", "ssao"),
    ("gtao 8×12", "ssao[variant=gtao,slices=8,steps=12]"),
    ("gtao 16×16", "ssao[variant=gtao,slices=16,steps=16]"),
    ("gtao 4×8, thickness 0.1", "ssao[variant=gtao,thickness=0.1]"),
    ("gtao 4×8, thickness 0.25", "ssao[variant=gtao,thickness=0.25]"),
    ("crytek 16, thickness 0.1", "ssao[variant=crytek,thickness=0.1]"),
    ("hemisphere 16, thickness 0.1", "ssao[variant=hemisphere,thickness=0.1]"),
)
#: Part 4's renderers (the path tracer is added at equal time).
AMBIENT_SPECS = ("ambient", "ambient[ambient=oracle]", "ambient[ambient=none]", "pyrender")
#: Width of the centred crop of the screen-border experiment, and the band along its edge that is scored.
CROP, BAND = 192, 16
#: Thickness of the halo experiment (scene units), and the ring around the boxes' silhouettes it scores (pixels).
THICKNESS, RING = 0.1, 24
#: Signed error maps show ±this (SSAO − reference); beyond it the colour saturates.
ERROR_RANGE = 0.5
#: How the docs' tables name part 4's renderers, and the notes on their spp and time.
AMBIENT_LABELS = {"ambient": ("`ambient` (radiosity ambient)", "", ""),
                  "ambient[ambient=oracle]": ("`ambient[ambient=oracle]`", "", " (2 renders)"),
                  "ambient[ambient=none]": ("`ambient[ambient=none]` (direct only)", "", ""),
                  "pyrender": ("`pyrender` (direct only, raster)", " (8×8 supersampling)", "")}
#: How the docs name the halo experiment's settings.
HALO_LABELS = {"ssao[variant=crytek]": "crytek 16", f"ssao[variant=crytek,thickness={THICKNESS}]":
               f"crytek 16, thickness {THICKNESS}", "ssao[variant=hemisphere]": "hemisphere 16",
               f"ssao[variant=hemisphere,thickness={THICKNESS}]": f"hemisphere 16, thickness {THICKNESS}",
               "ssao": "gtao 4×8", f"ssao[variant=gtao,thickness={THICKNESS}]": f"gtao 4×8, thickness {THICKNESS}"}
#: BENCHMARKS.md's summary of part 1: (label, spec); the best setting by RMSE is added.
SUMMARY_SSAO = (("ssao crytek, 16 samples", "ssao[variant=crytek,samples=16]"),
                ("ssao hemisphere, 16 samples", "ssao[variant=hemisphere,samples=16]"),
                ("ssao gtao 4×8 (default)", "ssao"))


# -- small helpers ------------------------------------------------------------------------------------------

def cached(path: Path, compute):
    """The JSON at ``path``, or ``compute()`` written there first (the output folder makes a run resumable)."""
    if path.exists():
        return json.loads(path.read_text())
    value = compute()
    write_json_atomic(path, value)
    return value


def slug(spec: str) -> str:
    return spec.replace("[", "_").replace("]", "").replace("=", "-").replace(",", "_")


def fmt(x: float, digits: int = 4) -> str:
    return "n/a" if x is None or not math.isfinite(x) else f"{x:.{digits}g}"


def ssao_settings(spec: str) -> dict:
    entry, = resolve([spec])
    return dict(entry.settings)


def ssao_image(scene, spec: str, threads: int, frames: int = 0) -> tuple[np.ndarray, list[float]]:
    """A (H, W) of ssao ``spec`` on ``scene`` (miss_value where nothing is hit) and, with ``frames``, the
    wall times (s) of that many frames of the screen-space pass after one warm-up frame, as the adapter
    times one (:meth:`cornell_harness.renderers.ssao.SSAO.render`)."""
    s = resolve_settings(SSAO(), ssao_settings(spec))
    g = gbuffer(scene, SceneGeometry(scene))
    pos, nrm = view_space(g, scene.camera)
    with ThreadPoolExecutor(threads) as pool:
        frame = screen_space_pass(s["variant"], pos, nrm, scene, resolved_radius(scene, s["radius"]), s["thickness"],
                                  s["samples"], s["slices"], s["steps"], pool if threads > 1 else None, threads)
        a = frame()
        times = []
        for _ in range(frames):
            t = time.perf_counter()
            a = frame()
            times.append(time.perf_counter() - t)
    return np.where(g.prim >= 0, a, scene.ambient_occlusion.miss_value), times


# -- 1. SSAO variants ---------------------------------------------------------------------------------------

def ssao_table(scene, reference, frames: int, threads: int, out: Path) -> list[dict]:
    rows = []
    for label, spec in SSAO_SETTINGS:
        def measure():
            entry, = resolve([spec])
            rec = runner.run_one(entry, scene, 1, 0, reference)
            assert rec.status == "ok", rec.reason
            a, times = ssao_image(scene, spec, threads, frames)
            # The frames timed here are the adapter's own image (deterministic).
            assert np.array_equal(a.astype(np.float32), rec.image[..., 0]), spec
            return {"label": label, "spec": spec, "ms": [1e3 * t for t in times],
                    "adapter_ms": rec.info["screen_space_ms"], "gbuffer_s": rec.info["gbuffer_s"],
                    **{k: rec.metrics[k] for k in ("rmse", "rel_mse", "ssim", "psnr")},
                    "regions": {r: v["rmse"] for r, v in rec.regions.items()}}
        rows.append(cached(out / "ssao" / f"{slug(spec)}.json", measure))
    print(f"## 1. SSAO on {scene.name} ({scene.camera.width}², {threads} threads): error against ms per frame\n")
    print(f"ms per frame: median of {frames} frames after one warm-up; RMSE per region.\n")
    print("\n".join(ssao_markdown(rows)) + "\n")
    return rows


def ssao_markdown(rows: list[dict]) -> list[str]:
    """Part 1's table; the default and the best setting (by RMSE) in bold."""
    regions = list(rows[0]["regions"])
    best = min(rows, key=lambda r: r["rmse"])
    lines = ["| variant | ms/frame | RMSE | relMSE | SSIM | " + " | ".join(regions) + " |",
             "|---|---|---|---|---|" + "---|" * len(regions)]
    for r in rows:
        b = r is best or r["spec"] == "ssao"
        ms, rmse, ssim = format(statistics.median(r["ms"]), ".1f"), format(r["rmse"], ".4f"), format(r["ssim"], ".3f")
        lines.append(f"| {bold(r['label'], b)} | {bold(ms, b)} | {bold(rmse, b)} | {r['rel_mse']:.4f} | "
                     f"{bold(ssim, b)} | " + " | ".join(f"{r['regions'][k]:.4f}" for k in regions) + " |")
    return lines


def summary_ssao_markdown(rows: list[dict], ao: dict) -> list[str]:
    """BENCHMARKS.md's summary of parts 1 and 2: a few SSAO settings, and ao at 16 spp and the top spp."""
    by_spec = {r["spec"]: r for r in rows}
    best = min(rows, key=lambda r: r["rmse"])
    picked = [(label, by_spec[spec]) for label, spec in SUMMARY_SSAO]
    picked.append((f"ssao {best['label'].replace(' (default)', '')} (best)", best))

    def ms(r):
        m = statistics.median(r["ms"])
        return f"{m:.1f}" if m < 50 else f"{m:.0f}"

    lines = ["| `cornell-box-ao`, 256² | ms/frame | RMSE | SSIM |", "|---|---|---|---|"]
    lines += [f"| {label} | {ms(r)} | {r['rmse']:.3g} | {r['ssim']:.3f} |" for label, r in picked]
    by_spp = {int(k): v for k, v in ao["by_spp"].items()}
    hi = max(by_spp)
    lo = min(16, hi)
    a, b = by_spp[lo], by_spp[hi]
    lines.append(f"| `ao`, {lo} spp / {hi} spp (median of seeds 0-{ao['seeds'] - 1}; render time) | "
                 f"{1e3 * a['time_s']:.0f} / {1e3 * b['time_s']:.0f} | {a['rmse']:.3g} / {b['rmse']:.3g} | "
                 f"{a['ssim']:.3f} / {b['ssim']:.3f} |")
    return lines


# -- 2. ao against spp and time; 3. the crossover -------------------------------------------------------------

def ao_experiment(scene, reference, seeds: int, max_spp: int, out: Path):
    spps = parse_spp_list(f"1,2,4,...,{max_spp}")
    table = run_experiment(out / "ao", scene, reference, resolve(["ao"]), spps, list(range(seeds)),
                           command=f"benchmarks/ambient_occlusion.py (seeds {seeds}, spp 1..{max_spp})")
    g = table[(table["status"] == "ok") & (table["renderer"] == "ao")].copy()
    print(f"## 2. ao on {scene.name}: error against spp and time (median over seeds 0-{seeds - 1})\n")
    med = g.groupby("spp")[["time_s", "rmse", "ssim", "rel_mse"]].median()
    print("\n".join(ao_markdown(med.to_dict("index"))))
    s_spp, ci_spp = slope_over_seeds(g, "rmse", "spp")
    s_t, ci_t = slope_over_seeds(g, "rmse", "time_s")
    print(f"\nlog-log slope of RMSE: against spp {s_spp:.3f} ± {ci_spp:.3f}, against time {s_t:.3f} ± {ci_t:.3f} "
          f"(mean over seeds, 95% CI; unbiased: -0.5)\n")
    return g, {"slope_spp": s_spp, "slope_spp_ci": ci_spp, "slope_time": s_t, "slope_time_ci": ci_t,
               "seeds": seeds, "by_spp": {int(k): v for k, v in med.to_dict("index").items()}}


def ao_markdown(by_spp: dict) -> list[str]:
    """Part 2's table: medians over seeds per spp."""
    return ["| spp | time (s) | RMSE | SSIM | relMSE |", "|---|---|---|---|---|"] + [
        f"| {spp} | {r['time_s']:.3f} | {r['rmse']:.4f} | {r['ssim']:.3f} | {r['rel_mse']:.5f} |"
        for spp, r in sorted(by_spp.items(), key=lambda kv: int(kv[0]))]


def crossover(g, ssao_rows: list[dict]) -> dict:
    """spp and time at which ao's RMSE (SSIM) first beats an SSAO setting's (the best, and gtao's default), per
    seed, median over seeds."""
    g = g.assign(one_minus_ssim=1.0 - g["ssim"])
    by_spp = g.assign(time_s=g["spp"].astype(float))
    default = next(r for r in ssao_rows if r["spec"] == "ssao")
    cases = (("rmse", "best", min(ssao_rows, key=lambda r: r["rmse"])), ("ssim", "best", max(ssao_rows, key=lambda r: r["ssim"])),
             ("rmse", "default", default), ("ssim", "default", default))
    out = {}
    print("## 3. Crossover: where ao (ray traced) becomes more accurate than SSAO\n")
    for key, which, row in cases:
        value = row[key]
        metric, target = ("rmse", value) if key == "rmse" else ("one_minus_ssim", 1.0 - value)
        spp, t = time_to_target(by_spp, metric, target), time_to_target(g, metric, target)
        ms = statistics.median(row["ms"])
        out[f"{key}_{which}"] = {"ssao": row["label"], "value": value, "ms": ms, "spp": spp, "time_s": t}
    print("\n".join(crossover_markdown(out)))
    print("\n(interpolated log-log between the checkpoints around the crossing, per seed; median over seeds)\n")
    return out


def crossover_markdown(cross: dict) -> list[str]:
    """Part 3's table (``crossover``'s result); the crossings of the best setting in bold."""
    lines = ["| figure | SSAO setting | its value | its ms/frame | `ao` reaches it at spp | at time |",
             "|---|---|---|---|---|---|"]
    for case, c in cross.items():
        key, which = case.split("_")
        spp, t = c["spp"], c["time_s"]
        reached = spp is not None and math.isfinite(spp)
        at_spp = bold(fmt(spp, 3), which == "best") if reached else "not reached"
        at_t = bold(f"{t:.2f} s" if t < 1 else f"{t:.1f} s", which == "best") if reached else "not reached"
        value = f"{c['value']:.4f}" if key == "rmse" else f"{c['value']:.3f}"
        lines.append(f"| {key.upper()} | {which}: {c['ssao'].replace(' (default)', '')} | {value} | {c['ms']:.0f} | "
                     f"{at_spp} | {at_t} |")
    return lines


# -- 4. ambient against full GI ----------------------------------------------------------------------------

def ambient_table(spp: int, out: Path) -> list[dict]:
    scene = resolve_scene(GI_SCENE)
    reference = load_reference(scene)

    def record(spec: str, n: int, extra: dict | None = None) -> dict:
        entry, = resolve([spec])
        rec = runner.run_one(entry, scene, n, 0, reference)
        assert rec.status == "ok", (spec, rec.reason)
        return {"renderer": spec, "spp": n, "time_s": rec.time_s, **(extra or {}),
                "delta_e": rec.metrics["delta_e2000_mean"], "mean_err": rec.metrics["mean_radiance_rel_error"],
                "regions": {r: v["delta_e2000_mean"] for r, v in rec.regions.items()},
                "la": rec.info.get("ambient_radiance")}

    rows = [cached(out / "ambient" / f"{slug(s)}_{spp}.json", lambda s=s: record(s, spp)) for s in AMBIENT_SPECS]
    budget = rows[0]["time_s"]

    def equal_time():
        entry, = resolve(["pathtracer"])
        n = spp_for_time_budget(entry, scene, budget, 0)
        return record("pathtracer", n, {"budget_s": budget})

    rows.append(cached(out / "ambient" / f"pathtracer_equal_time_{spp}.json", equal_time))
    print(f"## 4. ambient against full GI on {GI_SCENE} (ΔE2000 mean, seed 0)\n")
    print("\n".join(ambient_markdown(rows)))
    print(f"\nThe path tracer's spp is the one `cbox compare --time-budget {budget:.2f}s` picks "
          f"(two calibration renders, not counted) for ambient's {budget:.2f} s.\n")
    return rows


def ambient_markdown(rows: list[dict]) -> list[str]:
    """Part 4's table: ΔE mean image-wide and per region, and the mean radiance's relative error."""
    regions = list(rows[0]["regions"])
    lines = ["| renderer | spp | time | ΔE mean | " + " | ".join(regions) + " | mean radiance error |",
             "|---|---|---|---|" + "---|" * len(regions) + "---|"]
    for r in rows:
        pt = "budget_s" in r
        name, spp_note, time_note = (("**`pathtracer`, equal time**", "", "") if pt
                                     else AMBIENT_LABELS.get(r["renderer"], (f"`{r['renderer']}`", "", "")))
        de, err = format(r["delta_e"], ".2f"), minus(format(r["mean_err"], "+.1%"))
        lines.append(f"| {name} | {r['spp']}{spp_note} | {r['time_s']:.2f} s{time_note} | {bold(de, pt)} | "
                     + " | ".join(f"{r['regions'][k]:.2f}" for k in regions) + f" | {err} |")
    return lines


def summary_ambient_markdown(rows: list[dict]) -> list[str]:
    """BENCHMARKS.md's summary of part 4."""
    by = {r["renderer"]: r for r in rows if "budget_s" not in r}
    pt = next(r for r in rows if "budget_s" in r)
    a, o, n, p = by["ambient"], by["ambient[ambient=oracle]"], by["ambient[ambient=none]"], by["pyrender"]
    return ["| `cornell-box`, seed 0 | spp | time | ΔE mean |", "|---|---|---|---|",
            f"| `ambient` (direct light + radiosity ambient × AO) | {a['spp']} | {a['time_s']:.2f} s | "
            f"{a['delta_e']:.2f} |",
            f"| `ambient[ambient=oracle]` (best constant ambient) | {o['spp']} | {o['time_s']:.2f} s | "
            f"{o['delta_e']:.2f} |",
            f"| `ambient[ambient=none]` / `pyrender` (direct only) | {n['spp']} | {n['time_s']:.2f} s / "
            f"{p['time_s']:.2f} s | {n['delta_e']:.2f} / {p['delta_e']:.2f} |",
            f"| **`pathtracer` at equal time** (`spp_for_time_budget`, as `cbox compare --time-budget "
            f"{pt['budget_s']:.1f}s`) | {pt['spp']} | {pt['time_s']:.2f} s | **{pt['delta_e']:.2f}** |"]


# -- 5. artefacts ------------------------------------------------------------------------------------------

def _font(size: int = 11):
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow without FreeType: the bitmap font
        return ImageFont.load_default()


def grey(a: np.ndarray) -> np.ndarray:
    v = np.round(np.clip(np.nan_to_num(a), 0.0, 1.0) * 255).astype(np.uint8)
    return np.repeat(v[..., None], 3, axis=2)


def signed(e: np.ndarray, lim: float = ERROR_RANGE) -> np.ndarray:
    """Diverging colours of e = SSAO − reference: blue where SSAO is darker, red where lighter, white at 0."""
    t = np.clip(np.nan_to_num(e) / lim, -1.0, 1.0)
    rgb = np.stack([np.where(t > 0, 1.0, 1.0 + t), 1.0 - np.abs(t), np.where(t < 0, 1.0, 1.0 - t)], axis=-1)
    return np.round(rgb * 255).astype(np.uint8)


def figure(path: Path, panels: list[tuple[str, np.ndarray]], scale: int = 1, legend: bool = True,
           lim: float = ERROR_RANGE, note: str = "", colours: int = 96) -> int:
    """Panels side by side (each titled, enlarged ``scale``× without smoothing), the signed error's colour bar
    below; written as an optimised PNG of ``colours`` palette entries, recorded in its folder's manifest
    (``figure_manifest``). Returns its size in bytes."""
    font = _font(11)
    h, w = panels[0][1].shape[:2]
    W, H, gap, top = w * scale, h * scale, 4, 16
    bar_h = 30 if legend else 0
    canvas = Image.new("RGB", (len(panels) * (W + gap) - gap, top + H + bar_h + (18 if note else 0)), "white")
    d = ImageDraw.Draw(canvas)
    for i, (title, img) in enumerate(panels):
        x = i * (W + gap)
        d.text((x + 2, 2), title, fill="black", font=font)
        canvas.paste(Image.fromarray(img).resize((W, H), Image.NEAREST), (x, top))
    y = top + H + 4
    if legend:
        bw = min(240, canvas.width - 120)
        ramp = signed(np.linspace(-lim, lim, bw)[None, :].repeat(8, 0), lim)
        x0 = (canvas.width - bw) // 2
        canvas.paste(Image.fromarray(ramp), (x0, y))
        d.text((x0 - 4, y + 10), f"-{lim:g}: SSAO darker", fill="black", font=font, anchor="ra")
        d.text((x0 + bw + 4, y + 10), f"+{lim:g}: SSAO lighter", fill="black", font=font)
        d.text((x0 + bw // 2, y + 10), "0", fill="black", font=font, anchor="ma")
        y += bar_h
    if note:
        d.text((2, y), note, fill="black", font=font)
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.quantize(colours, dither=Image.Dither.NONE).save(path, optimize=True)
    figure_manifest.record([path], markdown_blocks.command_line())
    return path.stat().st_size


def _stats(a: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> dict:
    e = a[mask] - ref[mask]
    return {"pixels": int(mask.sum()), "ref_mean": float(ref[mask].mean()), "ssao_mean": float(a[mask].mean()),
            "signed": float(e.mean()), "rmse": float(np.sqrt(np.mean(e * e)))}


def screen_border(scene, ref: np.ndarray, threads: int, images: Path | None) -> dict:
    """The same pixels as the full frame and as a centred CROP² frame: what the crop's edge cuts away stops
    occluding. Pixel centres coincide exactly (a centred crop of a pinhole image is a narrower field of view)."""
    cam = scene.camera
    off = (cam.width - CROP) // 2
    half = math.radians(cam.fov_deg) / 2
    fov = 2 * math.degrees(math.atan(math.tan(half) * CROP / cam.width))
    crop_scene = dataclasses.replace(scene, name=f"{scene.name}-crop{CROP}", regions={},
                                     camera=dataclasses.replace(cam, fov_deg=fov, width=CROP, height=CROP))
    sl = (slice(off, off + CROP), slice(off, off + CROP))
    g_full, g_crop = gbuffer(scene), gbuffer(crop_scene)
    assert np.array_equal(g_full.prim[sl], g_crop.prim), "crop pixels must see what the full frame's see"
    r = ref[sl]
    band = np.zeros((CROP, CROP), bool)
    band[:BAND], band[-BAND:], band[:, :BAND], band[:, -BAND:] = True, True, True, True
    band &= g_crop.prim >= 0
    out = {}
    for spec in ("ssao", "ssao[variant=hemisphere]"):
        full = ssao_image(scene, spec, threads)[0][sl]
        crop = ssao_image(crop_scene, spec, threads)[0]
        out[spec] = {"full": _stats(full, r, band), "crop": _stats(crop, r, band),
                     "changed": int((np.abs(crop - full) > 0.01).sum())}
        if spec == "ssao" and images:
            out["png_bytes"] = figure(images / "ao-screen-border.png", [
                ("reference (crop)", grey(r)), ("gtao, full frame", grey(full)),
                ("gtao, cropped frame", grey(crop)), ("cropped - full frame", signed(crop - full))])
    print(f"### Screen border: the central {CROP}² pixels rendered as the full frame and as a {CROP}² frame\n")
    print(f"Pixels within {BAND} px of the crop's edge ({out['ssao']['full']['pixels']}); reference mean "
          f"{out['ssao']['full']['ref_mean']:.3f}.\n")
    print("| variant | frame | mean A | signed error | RMSE | pixels changed by > 0.01 |\n|---|---|---|---|---|---|")
    for spec in ("ssao", "ssao[variant=hemisphere]"):
        for k in ("full", "crop"):
            s = out[spec][k]
            print(f"| {spec} | {k} | {s['ssao_mean']:.3f} | {s['signed']:+.4f} | {s['rmse']:.4f} | "
                  f"{out[spec]['changed'] if k == 'crop' else ''} |")
    print()
    return out


def _box_distance(scene, points: np.ndarray) -> np.ndarray:
    """Distance from each point (…, 3) to the nearest point of either box's surface (dense surface samples)."""
    rng = np.random.default_rng(0)
    samples = []
    for m in scene.meshes:
        if m.name not in ("small-box", "large-box"):
            continue
        for tri in m.triangles:
            a, b, c = m.vertices[tri]
            u, v = rng.random(20000), rng.random(20000)
            flip = u + v > 1
            u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
            samples.append(a + u[:, None] * (b - a) + v[:, None] * (c - a))
    d, _ = cKDTree(np.concatenate(samples)).query(np.nan_to_num(points.reshape(-1, 3), nan=1e9))
    return d.reshape(points.shape[:-1])


def haloes(scene, ref: np.ndarray, threads: int, images: Path | None) -> dict:
    """SSAO with and without the boxes, on the pixels that see the same surface in both, more than the radius
    from either box (so the boxes cannot occlude them: the true difference is exactly 0) and within RING
    pixels of the boxes' silhouettes: whatever the boxes change there is a halo."""
    empty = dataclasses.replace(scene, name=f"{scene.name}-no-boxes", regions={},
                                meshes=tuple(m for m in scene.meshes if m.name not in ("small-box", "large-box")))
    geom = SceneGeometry(scene)
    g, g0 = gbuffer(scene, geom), gbuffer(empty)
    names = scene.object_names()
    obj = np.where(g.prim >= 0, geom.object[np.maximum(g.prim, 0)], -1)
    boxes = np.isin(obj, [names.index("small-box"), names.index("large-box")])
    radius = scene.ambient_occlusion.max_distance
    same = (g.prim >= 0) & ~boxes & np.all(np.isclose(g.position, g0.position, atol=1e-9), axis=-1)
    far = _box_distance(scene, g.position) > radius * 1.02
    ring = same & far & binary_dilation(boxes, iterations=RING)
    out = {"pixels": int(ring.sum())}
    maps = {}
    for spec in ("ssao[variant=crytek]", f"ssao[variant=crytek,thickness={THICKNESS}]", "ssao[variant=hemisphere]",
                 f"ssao[variant=hemisphere,thickness={THICKNESS}]", "ssao", f"ssao[variant=gtao,thickness={THICKNESS}]"):
        with_boxes, without = ssao_image(scene, spec, threads)[0], ssao_image(empty, spec, threads)[0]
        diff = with_boxes - without
        maps[spec] = (with_boxes, diff)
        whole = np.sqrt(np.mean((with_boxes - ref) ** 2))
        out[spec] = {"halo_mean": float(diff[ring].mean()), "halo_min": float(diff[ring].min()),
                     "darkened_frac": float((diff[ring] < -0.05).mean()),
                     "lightened_frac": float((diff[ring] > 0.05).mean()), "image_rmse": float(whole)}
    if images:
        sl = (slice(60, 236), slice(20, 236))
        dots = ring[sl] & (np.indices(ring[sl].shape).sum(0) % 4 == 0)
        ringed = np.where(dots[..., None], np.array([230, 170, 0], np.uint8), grey(ref[sl]))
        effect = lambda spec: np.where(same[sl][..., None], signed(maps[spec][1][sl]), np.uint8(160))
        out["png_bytes"] = figure(images / "ao-haloes.png", [
            ("reference, scored ring", ringed), ("crytek 16", grey(maps["ssao[variant=crytek]"][0][sl])),
            ("crytek: boxes' effect", effect("ssao[variant=crytek]")),
            (f"crytek, thickness {THICKNESS}: effect", effect(f"ssao[variant=crytek,thickness={THICKNESS}]")),
            ("gtao 4x8: boxes' effect", effect("ssao"))],
            note="effect = SSAO with the boxes - SSAO without them (grey: the pixel sees another surface without "
                 "them); yellow dots: the ring scored, > the radius from both boxes, where the truth's effect is 0")
    print(f"### Haloes: what the boxes change where they cannot occlude ({out['pixels']} pixels: within {RING} px "
          f"of their silhouettes, > {radius:g} from both)\n")
    print("\n".join(haloes_markdown(out)) + "\n")
    return out


def haloes_markdown(res: dict) -> list[str]:
    """The halo experiment's table (``haloes``'s result)."""
    lines = ["| setting | mean change | most darkened | darkened > 0.05 | lightened > 0.05 | image RMSE |",
             "|---|---|---|---|---|---|"]
    for spec, s in res.items():
        if isinstance(s, dict):
            mean, darkest = minus(format(s["halo_mean"], "+.3f")), minus(format(s["halo_min"] + 0.0, ".3f"))
            lines.append(f"| {HALO_LABELS.get(spec, spec)} | {mean} | {darkest} | {s['darkened_frac']:.1%} | "
                         f"{s['lightened_frac']:.1%} | {s['image_rmse']:.3g} |")
    return lines


def thin_geometry(scene, ref: np.ndarray, threads: int, images: Path | None) -> dict:
    """The light quad, 0.01 below the ceiling: the ceiling around and inside the gap (region light-rim,
    ceiling or light pixels within a box about the quad, the quad's own interior left out)."""
    rim = Region("light-rim", ("ceiling", "light"), ((-0.30, 0.98, -0.26), (0.30, 1.01, 0.28)))
    masks = region_masks(dataclasses.replace(scene, regions={**scene.regions, "light-rim": rim}))
    mask = masks["light-rim"] & ~masks["light"]
    gap = mask & (ref < 0.5)
    out = {}
    for spec in ("ssao", "ssao[variant=gtao,slices=16,steps=16]", "ssao[variant=hemisphere,samples=32]"):
        a = ssao_image(scene, spec, threads)[0]
        out[spec] = {"rim": _stats(a, ref, mask), "gap": _stats(a, ref, gap)}
        if spec == "ssao" and images:
            sl = (slice(16, 48), slice(92, 168))
            out["png_bytes"] = figure(images / "ao-thin-geometry.png", [
                ("reference", grey(ref[sl])), ("gtao 4x8 (default)", grey(a[sl])), ("gtao - reference", signed(a[sl] - ref[sl]))],
                scale=4, note=f"rows {sl[0].start}-{sl[0].stop - 1}, columns {sl[1].start}-{sl[1].stop - 1}, 4x: the light "
                              "quad seen from below; the dark row is the ceiling inside the 0.01 gap")
    print(f"### Thin geometry: the ceiling around the light quad (0.01 below it): {out['ssao']['rim']['pixels']} rim "
          f"pixels, of which {out['ssao']['gap']['pixels']} look into the gap (reference < 0.5)\n")
    print("| setting | rim: ref mean | rim: SSAO mean | rim RMSE | gap: ref mean | gap: SSAO mean |\n|---|---|---|---|---|---|")
    for spec, s in out.items():
        if isinstance(s, dict):
            print(f"| {spec} | {s['rim']['ref_mean']:.3f} | {s['rim']['ssao_mean']:.3f} | {s['rim']['rmse']:.4f} | "
                  f"{s['gap']['ref_mean']:.3f} | {s['gap']['ssao_mean']:.3f} |")
    print()
    return out


def crytek_half(scene, ref: np.ndarray, threads: int, images: Path | None) -> dict:
    """Crytek's sphere test on open flat surfaces (reference >= 0.995: nothing within the radius), per object."""
    geom = SceneGeometry(scene)
    g = gbuffer(scene, geom)
    obj = np.where(g.prim >= 0, geom.object[np.maximum(g.prim, 0)], -1)
    a = ssao_image(scene, "ssao[variant=crytek]", threads)[0]
    flat = (g.prim >= 0) & (ref >= 0.995)
    hit = g.prim >= 0
    fixed = np.minimum(1.0, 2.0 * a)
    out = {"flat": _stats(a, ref, flat), "hit": _stats(a, ref, hit),
           "rescaled_rmse": float(np.sqrt(np.mean((fixed[hit] - ref[hit]) ** 2))), "objects": {}}
    for i, name in enumerate(scene.object_names()):
        m = flat & (obj == i)
        if m.sum():
            out["objects"][name] = {"pixels": int(m.sum()), "median": float(np.median(a[m])),
                                    "p25": float(np.percentile(a[m], 25)), "p75": float(np.percentile(a[m], 75)),
                                    "half": float(np.mean(a[m] == 0.5))}
    if images:
        out["png_bytes"] = figure(images / "ao-crytek-half.png", [
            ("reference", grey(ref)), ("crytek 16", grey(a)), ("crytek - reference", signed(a - ref))], colours=64)
    f = out["flat"]
    print(f"### Crytek's flat 1/2: {f['pixels']} open flat pixels (reference >= 0.995, mean {f['ref_mean']:.3f})\n")
    print("| object | open pixels | crytek median (quartiles) | share reading exactly 0.5 |\n|---|---|---|---|")
    for name, o in out["objects"].items():
        print(f"| {name} | {o['pixels']} | {o['median']:.3f} ({o['p25']:.3f}-{o['p75']:.3f}) | {o['half']:.1%} |")
    print(f"\nOver every hit pixel crytek's signed error is {out['hit']['signed']:+.3f} (RMSE {out['hit']['rmse']:.4f}); "
          f"read as min(1, 2A) its RMSE would be {out['rescaled_rmse']:.4f}.\n")
    return out


def artefacts(scene, reference, threads: int, images: Path | None, out: Path) -> dict:
    ref = reference.image[..., 0].astype(np.float64)
    print(f"## 5. SSAO's artefacts on {scene.name}\n")
    res = {}
    for name, fn in (("screen_border", screen_border), ("haloes", haloes), ("thin_geometry", thin_geometry),
                     ("crytek_half", crytek_half)):
        res[name] = fn(scene, ref, threads, images)
    write_json_atomic(out / "artefacts.json", res)
    if images:
        sizes = {k: v.get("png_bytes") for k, v in res.items()}
        print("Figures (bytes): " + ", ".join(f"{k} {v}" for k, v in sizes.items()) + "\n")
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("out/bench-ao"),
                    help="results folder; cached results in it are reused (delete it to measure again)")
    ap.add_argument("--frames", type=int, default=7,
                    help="timed SSAO frames per setting (after one warm-up frame); the median is reported")
    ap.add_argument("--seeds", type=int, default=3, help="seeds of the ao convergence experiment (part 2)")
    ap.add_argument("--max-spp", type=int, default=1024,
                    help="highest spp of the ao experiment: checkpoints 1, 2, 4, ..., this (a power of two)")
    ap.add_argument("--ambient-spp", type=int, default=256,
                    help="spp of ambient, its variants and pyrender on cornell-box (part 4); the path tracer "
                         "gets ambient's wall time instead")
    ap.add_argument("--images", type=Path, default=Path("docs/images"),
                    help="where the artefact figures (PNG) are written")
    ap.add_argument("--no-images", action="store_true", help="measure the artefacts, write no figures")
    ap.add_argument("--skip", action="append", default=[], choices=["ssao", "ao", "ambient", "artefacts"],
                    help="leave a part out (repeatable); the crossover needs both ssao and ao")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the tables of the parts run into this file's blocks (repeatable)")
    args = ap.parse_args()
    if args.max_spp < 1 or args.max_spp & (args.max_spp - 1) or args.frames < 1 or args.seeds < 1:
        ap.error("--max-spp must be a power of two; --frames and --seeds at least 1")
    t0 = time.perf_counter()
    threads = default_threads()
    scene = resolve_scene(AO_SCENE)
    reference = load_reference(scene)
    print(f"Threads: {threads}. Output: {args.out}.\n")
    summary_path = args.out / "summary.json"  # parts left out keep their last figures
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    rows = ssao_table(scene, reference, args.frames, threads, args.out) if "ssao" not in args.skip else None
    blocks = {}  # the docs' tables of the parts that ran (markdown_blocks)
    if rows:
        blocks["ambient_occlusion.py#ssao"] = ssao_markdown(rows)
    if "ao" not in args.skip:
        g, summary["ao"] = ao_experiment(scene, reference, args.seeds, args.max_spp, args.out)
        blocks["ambient_occlusion.py#ao"] = ao_markdown(summary["ao"]["by_spp"])
        if rows:
            summary["crossover"] = crossover(g, rows)
            blocks["ambient_occlusion.py#crossover"] = crossover_markdown(summary["crossover"])
            blocks["ambient_occlusion.py#summary-ssao"] = summary_ssao_markdown(rows, summary["ao"])
    if "ambient" not in args.skip:
        summary["ambient"] = ambient_table(args.ambient_spp, args.out)
        blocks["ambient_occlusion.py#ambient"] = ambient_markdown(summary["ambient"])
        blocks["ambient_occlusion.py#summary-ambient"] = summary_ambient_markdown(summary["ambient"])
    if "artefacts" not in args.skip:
        res = artefacts(scene, reference, threads, None if args.no_images else args.images, args.out)
        blocks["ambient_occlusion.py#haloes"] = haloes_markdown(res["haloes"])
    write_json_atomic(summary_path, json.loads(json.dumps(summary, default=float).replace("NaN", "null")))
    markdown_blocks.write_blocks(args.markdown, {k: "\n".join(v) for k, v in blocks.items()})
    print(f"Total wall time of this run: {time.perf_counter() - t0:.0f} s (cached results are not re-measured).")


if __name__ == "__main__":
    main()

"""Denoised path tracing (OIDN): error against spp and time, the bias it keeps per region, time to equal quality.

The issue's experiment (docs/denoising.md explains it). On ``cornell-box`` and ``cornell-box-caustics``, at spp
1, 2, 4, ..., ``--max-spp`` over ``--seeds`` seeds, ``pathtracer`` against ``pathtracer+oidn`` (OIDN with
prefiltered albedo and normal, its recommended mode) and, to show what the auxiliary images buy,
``pathtracer+oidn[aux=noisy]`` (passed as rendered) and ``pathtracer+oidn[aux=none]`` (the beauty alone):

1. **Error** (medians over seeds): ΔE2000 mean and p95, relMSE, FLIP, SSIM and the render time (the denoise
   included) at each spp; figures of ΔE mean and relMSE against spp and against time.
2. **Bias per region**: the signed error of each region's mean radiance (``region.<name>.mean_radiance_rel_error``,
   the mean over seeds with its standard error), at each spp, for the denoised renderer and the path tracer
   beside it; and converge's bias²/variance split per region at the top spp; a figure of where the bias sits
   (the seeds' mean image against the reference).
3. **Equal quality**: for ΔE mean <= 2, ΔE mean <= 1 and relMSE <= 1e-2, the spp each renderer needs
   (:func:`cornell_harness.evaluate.convergence.time_to_target` with spp as the clock: per seed, interpolated log-log;
   median) and the time that takes by a cost model measured quietly (part 5), beside the runs' own times.
4. **Beside each other**: the path tracer and the denoiser at 4 spp, the denoiser at ``--max-spp`` and the
   reference (seed 0), for each scene.
5. **Costs**, per scene: the path tracer's render time with and without the AOVs (64 spp, interleaved
   repeats, medians and their ratio), and one denoise of a 256² image per quality and ``aux`` mode: the cost
   model of part 3.

Everything runs through the harness's converge workflow in-process
(:func:`cornell_harness.workflows.converge.run_experiment`, what ``cbox converge`` runs; ``cbox report OUT/<scene>`` gives
the HTML report of either experiment). Results are cached in ``--out``: running again renders only what is missing.

Run: ``.venv/bin/python benchmarks/denoising.py --summary BENCHMARKS.md``: writes docs/denoising.md whole
(``--markdown``; its first line names the command, ``benchmarks/markdown_blocks.py``), its figures, and the
summary table into BENCHMARKS.md's block ``denoising.py#summary`` (``--summary``); figures go to ``--images``;
``--quick`` for a check of the script (2 seeds, spp <= 4, into ``OUT-quick``).
"""

from __future__ import annotations

import argparse
import io
import math
import os
import re
import sys
import time
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pandas as pd
from PIL import Image, ImageDraw

from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.convergence import time_to_target
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows.spp_list import parse_spp_list
import figure_manifest
import markdown_blocks
from irradiance_probes import COLOURS, PT_COLOUR, bias_figure, experiment, fmt, write_svg
from cornell_harness.reports.charts import convergence_table
from cornell_harness.reports.plots import Series, line_plot_svg
from cornell_harness.adapters.api import default_threads
from cornell_harness.renderers.oidn import denoise

SCENES = {"cornell-box": ("walls", "boxes", "floor", "back-edge", "light"),
          "cornell-box-caustics": ("caustic", "glass-shadow", "walls", "mirror", "glass")}
DENOISED = "pathtracer+oidn"
RENDERERS = {"pathtracer": "path tracer", DENOISED: "OIDN, prefiltered aux",
             "pathtracer+oidn[aux=noisy]": "OIDN, noisy aux", "pathtracer+oidn[aux=none]": "OIDN, no aux"}
METRICS = (("delta_e2000_mean", "ΔE mean", ".2f"), ("delta_e2000_p95", "ΔE p95", ".2f"),
           ("rel_mse", "relMSE", ".2e"), ("flip_mean", "FLIP", ".3f"), ("ssim", "SSIM", ".3f"))
TARGETS = (("delta_e2000_mean", 2.0), ("delta_e2000_mean", 1.0), ("rel_mse", 1e-2))
SIDE_SPP = 4


def error_table(runs: pd.DataFrame, names: dict) -> None:
    print("| renderer | spp | time (s) | " + " | ".join(m[1] for m in METRICS) + " |\n|" + "---|" * (3 + len(METRICS)))
    for name, lab in names.items():
        med = runs[runs["renderer"] == name].groupby("spp").median(numeric_only=True)
        for spp, r in med.iterrows():
            print(f"| {lab} | {int(spp)} | {r['time_s']:.2f} | "
                  + " | ".join(fmt(r[k], spec) for k, _, spec in METRICS) + " |")
    print("\nMedians over seeds; time: the render's wall time, the denoise of that checkpoint included.\n")


def figures(runs: pd.DataFrame, names: dict, scene: str, images: Path) -> None:
    conv = convergence_table(runs[runs["renderer"].isin(list(names))], ["delta_e2000_mean", "rel_mse"])
    for metric, ylabel in (("delta_e2000_mean", "ΔE2000 mean"), ("rel_mse", "relMSE")):
        for x, xlabel in (("spp", "samples per pixel"), ("time_s", "wall time (s)")):
            series = []
            for i, (name, lab) in enumerate(names.items()):
                g = conv[conv["renderer"] == name].sort_values("spp")
                series.append(Series(lab, PT_COLOUR if name == "pathtracer" else COLOURS[i % len(COLOURS)],
                                     g[x].astype(float).tolist(), g[metric].tolist(), g[metric + "_min"].tolist(),
                                     g[metric + "_max"].tolist()))
            key = f"denoising-{scene}-{'de' if metric.startswith('delta') else 'relmse'}-{'spp' if x == 'spp' else 'time'}"
            write_svg(images / f"{key}.svg", line_plot_svg(series, uid=key, xlabel=xlabel, ylabel=ylabel,
                                                           xbase2=x == "spp"))


def region_bias(runs: pd.DataFrame, summary: pd.DataFrame, names: dict, regions, seeds, spps) -> dict:
    """Signed error of each region's mean radiance, mean over seeds ± its standard error, per spp."""
    out = {}
    print("| renderer | region | " + " | ".join(f"{s} spp" for s in spps) + " | bias² / variance at the top spp |\n|"
          + "---|" * (3 + len(spps)))
    for name in ("pathtracer", DENOISED):
        g = runs[runs["renderer"] == name]
        for reg in regions:
            col = f"region.{reg}.mean_radiance_rel_error"
            cells = []
            for s in spps:
                v = g[g["spp"] == s][col].to_numpy(float)
                m, se = float(np.mean(v)), float(np.std(v, ddof=1) / math.sqrt(len(v)))
                out[(name, reg, s)] = (m, se)
                cells.append(f"{m:+.2%} ± {se:.2%}")
            sm = summary.loc[name]
            print(f"| {names[name]} | {reg} | " + " | ".join(cells)
                  + f" | {sm[f'region.{reg}.bias2']:.1e} / {sm[f'region.{reg}.variance']:.1e} |")
    print(f"\nEach cell: the region's mean radiance against the reference's, signed, as a fraction of it: the mean over "
          f"{len(seeds)} seeds ± its standard error (the seeds' spread / √{len(seeds)}). A bias is an error several "
          "standard errors from 0 that does not shrink with spp. bias², variance: converge's per-region split of "
          "the top-spp images (squared linear radiance, per pixel and channel; bias² < 0 means none measurable).\n")
    return out


def equal_quality(runs: pd.DataFrame, names: dict, cost: dict) -> list[tuple]:
    """For each target, the spp each renderer needs (per seed, interpolated log-log; median) and the time that
    takes by the cost model measured in :func:`costs` (the experiment's own times are printed beside it)."""
    print("| target | renderer | spp needed | time, cost model (s) | time, measured in the runs (s) | path tracer's "
          "time / this one's |\n|---|---|---|---|---|---|")
    rows = []
    for metric, value in TARGETS:
        label = f"{'ΔE mean' if metric.startswith('delta') else 'relMSE'} <= {value:g}"
        model = {}
        for name, lab in names.items():
            g = runs[runs["renderer"] == name]
            spp = time_to_target(g.assign(time_s=g["spp"].astype(float)), metric, value)
            model[name] = modelled_time(cost, name, spp)
            measured = time_to_target(g, metric, value)
            ratio = model["pathtracer"] / model[name]
            rows.append((label, name, spp, model[name], measured, ratio))
            print(f"| {label} | {lab} | {fmt(spp, '.1f')} | {fmt(model[name], '.2f')} | {fmt(measured, '.2f')} | "
                  f"{fmt(ratio, '.1f') + 'x' if name != 'pathtracer' and math.isfinite(ratio) else ''} |")
    print("\nspp needed: where the error first reaches the target (per seed, interpolated log-log between "
          "checkpoints; median over seeds); n/a: not reached by the top spp. Cost model: the path tracer's time per "
          "spp at 64 spp, times the AOVs' ratio for the denoisers, plus one denoise (the Costs section; measured "
          "interleaved, medians, so a busy machine moves both alike). The runs' own times are given beside it: "
          "they were taken while other work shared the 2 cores, unevenly. Last column: > 1 means the denoiser "
          "gets there sooner.\n")
    return rows


def modelled_time(cost: dict, name: str, spp: float) -> float:
    """Seconds to render ``spp`` with ``name`` by the cost model (:func:`costs`)."""
    if name == "pathtracer":
        return cost["per_spp"] * spp
    aux = re.search(r"aux=\W*(\w+)", name)
    return cost["per_spp"] * cost["aov_ratio"] * spp + cost["denoise"][("high", aux.group(1) if aux else "prefiltered")]


def side_by_side(scene, ref, path: Path, max_spp: int, size: int = 192) -> None:
    """Path traced and denoised at SIDE_SPP spp, denoised at max_spp, and the reference, at display exposure."""
    pt = resolve(["pathtracer"])[0]
    exposure = metrics.display_exposure(ref.image, ref.quantity)
    low = pt.renderer.render(scene, max_spp, 0, checkpoints=[SIDE_SPP], settings=dict(pt.settings), aovs=("albedo",))
    shot = next(c for c in low.checkpoints if c.spp == SIDE_SPP)
    panels = [(f"path traced, {SIDE_SPP} spp", shot.image),
              (f"denoised, {SIDE_SPP} spp", denoise(shot.image, shot.aovs["albedo"], shot.aovs["normal"])),
              (f"denoised, {max_spp} spp", denoise(low.image, low.aovs["albedo"], low.aovs["normal"])),
              ("reference", ref.image)]
    canvas = Image.new("RGB", (len(panels) * (size + 4), size + 18), "white")
    d = ImageDraw.Draw(canvas)
    for i, (lab, img) in enumerate(panels):
        shown = np.round(metrics.display_encode(img, exposure) * 255).astype(np.uint8)
        d.text((i * (size + 4) + 2, 2), lab, fill="black")
        canvas.paste(Image.fromarray(shown).resize((size, size), Image.BILINEAR), (i * (size + 4), 16))
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.save(path, optimize=True)
    figure_manifest.record([path], markdown_blocks.command_line())


def costs(scene, spp: int, repeats: int) -> dict:
    """What the AOVs add to a path tracer render, and what one denoise takes, per mode: medians of interleaved
    repeats, so the machine's drift hits both sides of each ratio alike. Returns the cost model
    (:func:`modelled_time`): seconds per spp, the AOVs' time ratio, seconds per denoise by (quality, aux)."""
    from cornell_harness.renderers.pathtracer import PathTracer

    pt, times = PathTracer(), {"plain": [], "aovs": []}
    pt.render(scene, 1, 0, aovs=("albedo",))  # compiles and warms both
    r = None
    for k in range(repeats):
        times["plain"].append(pt.render(scene, spp, k).time_s)
        r = pt.render(scene, spp, k, aovs=("albedo",))
        times["aovs"].append(r.time_s)
    plain, aovs = (float(np.median(times[k])) for k in ("plain", "aovs"))
    print("| render | path tracer (s) | with AOVs (s) | ratio |\n|---|---|---|---|")
    print(f"| {scene.name} at {spp} spp | {plain:.2f} | {aovs:.2f} | {aovs / plain:.3f} |\n")
    print("| quality | aux | denoise (s) |\n|---|---|---|")
    denoise_s = {}
    for quality in ("high", "balanced", "fast"):
        for aux in ("prefiltered", "noisy", "none"):
            ts = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                denoise(r.image, r.aovs["albedo"], r.aovs["normal"], quality=quality, aux=aux)
                ts.append(time.perf_counter() - t0)
            denoise_s[(quality, aux)] = float(np.median(ts))
            print(f"| {quality} | {aux} | {denoise_s[(quality, aux)]:.3f} |")
    print(f"\nMedians of {repeats} runs each; {scene.camera.width}x{scene.camera.height} pixels, "
          f"{default_threads()} threads.\n")
    return {"per_spp": plain / spp, "aov_ratio": aovs / plain, "denoise": denoise_s, "spp": spp, "repeats": repeats}


PAGE_HEAD = """# Denoised path tracing (OIDN): what it buys, what it costs, the bias it keeps

The issue's experiment, written by `{command}` (it regenerates this whole page; cached cells in `--out` are
not rendered again). `pathtracer+oidn` (`src/cornell_harness/renderers/oidn.py`) is our path tracer's image denoised by Intel Open
Image Denoise 2.5 (CPU device, `hdr`, quality `high`) with the albedo and normal the path tracer writes at each
path's first non-delta hit, following mirrors and glass. Three ways of using those auxiliary images are compared:
`prefiltered` (the default and OIDN's recommended mode: albedo and normal denoised first, then the beauty with
`cleanAux`), `noisy` (passed as rendered) and `none` (the beauty alone). The path tracer (`pmj02` sampler) is
the baseline; every image is scored against the stored Mitsuba reference of the scene (16384 spp).

Method: the harness's converge workflow in-process (`cornell_harness.workflows.converge.run_experiment`, what `cbox
converge` runs), spp 1, 2, 4, ... {max_spp} for the denoisers and up to {pt_max_spp} for the path tracer (so that
it reaches the targets), seeds 0..{last_seed}. A denoiser is biased: what it keeps wrong is read from the mean over
seeds (each seed's error is a bias plus noise; the mean's standard error says how much of a difference is noise).
The denoiser is declared `biased`: no variance, never a z-test; the gate holds it to budgets and a consistency
check (`gate.toml`).

The regions are the scenes' own (`src/cornell_harness/evaluate/regions.py`): on `cornell-box`, `back-edge` is the line where
the back wall meets the floor (contact shadow), `boxes` carries the colour bled from the red and green walls, and
`light` is the emitter seen directly; on `cornell-box-caustics`, `caustic` is the light focused under the glass
sphere, `glass-shadow` the shadow beside it, `glass` and `mirror` the spheres themselves.

ΔE is ΔE2000 at the reference's display exposure; relMSE is (x - r)² / (r² + 0.01) per pixel; FLIP is HDR-FLIP
with explicit exposures (`src/cornell_harness/evaluate/flip.py`).

"""


def findings(bias: dict, quality_rows: list, cost: dict, regions, spps, pt_top: int) -> None:
    """The numbers above in sentences: equal quality, the biases that stay, what the AOVs cost."""
    print("### What this shows\n")
    for label, name, spp, model, _, ratio in quality_rows:
        if name == DENOISED:
            pt = next(r for r in quality_rows if r[0] == label and r[1] == "pathtracer")
            if math.isfinite(model) and math.isfinite(pt[3]):
                print(f"- {label}: the path tracer needs {pt[2]:.0f} spp ({pt[3]:.1f} s), the denoiser {spp:.1f} spp "
                      f"({model:.2f} s): **{ratio:.1f}x sooner**.")
            elif math.isfinite(model):
                print(f"- {label}: the denoiser gets there at {spp:.1f} spp ({model:.2f} s); the path tracer not "
                      f"by {pt_top} spp.")
            else:
                print(f"- {label}: the denoiser does not get there by {spps[-1]} spp.")
    for s_ in (spps[0], spps[-1]):
        kept = [(reg, *bias[(DENOISED, reg, s_)]) for reg in regions
                if abs(bias[(DENOISED, reg, s_)][0]) > 3 * bias[(DENOISED, reg, s_)][1]]
        if kept:
            print(f"- At {s_} spp the denoiser's region means are off by more than 3 standard errors in "
                  + ", ".join(f"{reg} ({m:+.2%} ± {se:.2%})" for reg, m, se in kept) + ".")
        else:
            print(f"- At {s_} spp no region mean of the denoiser is off by more than 3 standard errors.")
    print(f"- The AOVs cost {cost['aov_ratio'] - 1:+.1%} of the path tracer's time at 64 spp (noise of a few "
          f"percent either way); one denoise of 256² takes {cost['denoise'][('high', 'prefiltered')]:.2f} s "
          f"prefiltered, {cost['denoise'][('high', 'noisy')]:.2f} s with the auxiliary images as rendered.\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/bench-denoising"), help="experiment folders (cached)")
    ap.add_argument("--images", type=Path, default=Path("docs/images"), help="where the figures go")
    ap.add_argument("--seeds", type=int, default=4, help="seeds 0 .. N-1 (at least 2 for the standard errors)")
    ap.add_argument("--max-spp", type=int, default=64, help="spp 1, 2, 4, ... up to this")
    ap.add_argument("--pt-max-spp", type=int, default=1024,
                    help="the path tracer's spp go up to this (so that it reaches the equal-quality targets)")
    ap.add_argument("--markdown", type=Path, default=Path("docs/denoising.md"), help="the page this writes")
    ap.add_argument("--summary", type=Path, action="append", default=[],
                    help="write the summary table into this file's block denoising.py#summary (BENCHMARKS.md)")
    ap.add_argument("--quick", action="store_true", help="2 seeds, spp <= 4, into OUT-quick (page and figures "
                                                         "too): a check of the script")
    a = ap.parse_args()
    seeds, max_spp, pt_max_spp, out, images, page = a.seeds, a.max_spp, a.pt_max_spp, a.out, a.images, a.markdown
    if a.quick:
        seeds, max_spp, pt_max_spp, out = 2, 4, 8, out.with_name(out.name + "-quick")
        images, page = out / "images", out / "denoising.md"
    spps, pt_spps = parse_spp_list(f"1-{max_spp}"), parse_spp_list(f"1-{pt_max_spp}")
    command = "benchmarks/denoising.py " + " ".join(sys.argv[1:])
    t0 = time.perf_counter()
    body = io.StringIO()
    with redirect_stdout(body):
        per_scene = run(out, images, page, seeds, spps, pt_spps, command, a.quick)
    text = PAGE_HEAD.format(command=markdown_blocks.command_line(), max_spp=spps[-1],
                            pt_max_spp=pt_spps[-1], last_seed=seeds - 1) + body.getvalue()
    markdown_blocks.write_page(page, text)  # its first line names the command
    markdown_blocks.write_blocks(a.summary, {"denoising.py#summary": "\n".join(
        summary_markdown(per_scene, pt_spps[-1], spps[-1]))})
    print(text)
    print(f"(all of it: {time.perf_counter() - t0:.0f} s; the page: {page})", file=sys.stderr)


def summary_markdown(per_scene: dict, pt_top: int, dn_top: int) -> list[str]:
    """BENCHMARKS.md's summary, a column per scene: the AOVs' cost, one denoise per aux mode, and for each target
    the spp the path tracer and the denoiser (prefiltered) need with the ratio of their modelled times."""
    scenes = list(per_scene)
    first = next(iter(per_scene.values()))[0]
    lines = ["| | " + " | ".join(scenes) + " |", "|---|" + "---|" * len(scenes),
             f"| path tracer with AOVs / without, {first['spp']} spp (median of {first['repeats']}, interleaved) | "
             + " | ".join(f"{cost['aov_ratio']:.3f}" for cost, _ in per_scene.values()) + " |",
             "| one denoise, quality high: prefiltered / noisy aux / no aux (s) | "
             + " | ".join(" / ".join(f"{cost['denoise'][('high', aux)]:.2f}" for aux in ("prefiltered", "noisy", "none"))
                          for cost, _ in per_scene.values()) + " |"]
    for k, (metric, value) in enumerate(TARGETS):
        label = f"{'ΔE mean' if metric.startswith('delta') else 'relMSE'} <= {value:g}"
        cells = []
        for _, rows in per_scene.values():
            by = {r[1]: r for r in rows if r[0] == label}
            pt, dn = by["pathtracer"][2], by[DENOISED][2]
            cell = (f"{pt:.0f}" if math.isfinite(pt) else f"not by {pt_top}") + " / " + (
                f"{dn:.1f}" if math.isfinite(dn) else f"not by {dn_top}")
            cells.append(cell + (f"; **{by[DENOISED][5]:.2g}x**" if math.isfinite(pt) and math.isfinite(dn) else ""))
        head = f"{label}: spp path tracer / denoised; time ratio" if k == 0 else label
        lines.append(f"| {head} | " + " | ".join(cells) + " |")
    return lines


def figure_links(page: Path, images: Path, name: str) -> None:
    rel = os.path.relpath(images, page.parent)
    print(f"![ΔE mean against time]({rel}/denoising-{name}-de-time.svg) "
          f"![ΔE mean against spp]({rel}/denoising-{name}-de-spp.svg)\n")
    print(f"![relMSE against time]({rel}/denoising-{name}-relmse-time.svg) "
          f"![relMSE against spp]({rel}/denoising-{name}-relmse-spp.svg)\n")
    print(f"![path traced and denoised at {SIDE_SPP} spp, denoised at the top spp, the reference]"
          f"({rel}/denoising-{name}-side.png)\n")


def run(out: Path, images: Path, page: Path, seeds: int, spps, pt_spps, command: str, quick: bool) -> dict:
    """Print the page's sections; return {scene: (cost model, equal-quality rows)} for the summary."""
    max_spp = spps[-1]
    per_scene = {}
    for name, regions in SCENES.items():
        scene = resolve_scene(name)
        ref = load_reference(scene)
        entries = resolve(list(RENDERERS))
        names = {e.name: RENDERERS[spec] for spec, e in zip(RENDERERS, entries)}
        pt_runs, pt_summary = experiment(out / f"{name}-pathtracer", scene, ref, entries[:1], pt_spps,
                                         list(range(seeds)), command)
        dn_runs, dn_summary = experiment(out / name, scene, ref, entries[1:], spps, list(range(seeds)), command)
        runs, summary = pd.concat([pt_runs, dn_runs], ignore_index=True), pd.concat([pt_summary, dn_summary])
        print(f"## {name}\n\n### Error against spp and time\n")
        figures(runs, names, name, images)
        side_by_side(scene, ref, images / f"denoising-{name}-side.png", max_spp)
        figure_links(page, images, name)
        error_table(runs, names)
        print("### Bias per region\n")
        bias = region_bias(runs, summary, names, regions, range(seeds), spps)
        bias_figure(out / name, ref, dn_runs, dict(list(names.items())[1:]), images / f"denoising-{name}-bias.png",
                    lim=0.1)
        print(f"![where the bias sits]({os.path.relpath(images, page.parent)}/denoising-{name}-bias.png)\n")
        print("### Costs\n")
        cost = costs(scene, 64 if not quick else 4, 5 if not quick else 2)
        print("### Equal quality\n")
        rows = equal_quality(runs, names, cost)
        findings(bias, rows, cost, regions, spps, pt_spps[-1])
        per_scene[name] = (cost, rows)
    return per_scene


if __name__ == "__main__":
    main()

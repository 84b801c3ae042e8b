"""Irradiance probes (DDGI): error against time, the equal-time crossover with the path tracer, the heuristics' bias.

Three measurements on ``cornell-box``, each printed as markdown tables (docs/irradiance-probes.md explains them),
all from :func:`cornell_harness.workflows.converge.run_experiment` called in-process (the code ``cbox converge`` runs;
sweeps built by :func:`cornell_harness.adapters.registry.sweep`, as ``--sweep`` does), then
:func:`cornell_harness.evaluate.summary.summary_table` (the ``summary.parquet`` ``cbox converge`` writes, with the
bias²/variance split per region; ``cbox report OUT/probes`` adds the HTML report):

1. **Error against time and spp** for ``probes`` at grid 4, 6, 8, 12 (rays 256), rays_per_probe 64, 256, 1024
   (grid 8) and iterations 0, 16, 48, spp 1, 2, 4, ..., ``--max-spp``, seeds 0 .. ``--seeds``-1: per configuration
   the probe updates' time, ΔE2000 mean at 1, 16 and max spp, where it plateaus (the spp at which ΔE mean is within
   10% of its max-spp value, per seed, median: :func:`cornell_harness.evaluate.convergence.time_to_target` with spp as the
   clock), the log-log slope of ΔE mean over the last two octaves (0: a plateau), ΔE of the seeds' mean image (half
   the camera and probe noise), the signed error of the mean radiance, and bias² and variance in the walls and boxes
   (the summary's per-region split: what no spp removes, and the seed-to-seed noise of camera and probes).
2. **Against the path tracer at equal time** (``pathtracer``, spp 1 ... ``--pt-max-spp``, same seeds): for each
   time budget, the error of the best configuration of part 1 within that time (medians over seeds, interpolated
   log-log in time between checkpoints, the last checkpoint held beyond its time) against the path tracer's,
   image-wide and per region; the budgets between which probes are more accurate; and the time the path tracer
   needs to reach the best probes plateau (``time_to_target``, per seed, median).
3. **Each heuristic switched off, one at a time**, at the default settings (grid 8, rays 256): ΔE mean, the signed
   error of the mean radiance per region (mean over seeds = the mean image's) and bias² per region from the
   summary; figures of where the bias sits.
4. **Light leaks** on ``two-rooms`` (a thin wall; the right room exactly black), ``probes`` with Chebyshev
   visibility on and off at 64 spp: each floor's mean luminance and the dark one's as a fraction of the lit one.

Figures (``--images``, default docs/images): ``probes-{grid,rays,iterations}.svg`` (ΔE mean against time, with the
path tracer), ``probes-spp.svg`` (against spp), ``probes-equal-time.svg``, ``probes-heuristics.svg`` (bias² per
region): the harness's own charts (:mod:`cornell_harness.reports.plots`), made standalone on a white page; ``probes-bias.png``
(where the bias sits) and ``probes-leak.png`` (two-rooms, visibility on and off).

Results are cached in ``--out`` (the experiments' parquet cells and EXR images): running the command again renders
only what is missing. ``--quick`` runs a tiny version (grid 4 and 6, 2+2 updates, spp <= 8) into ``OUT-quick``
(figures in ``OUT-quick/images``).

``--markdown FILE`` (repeatable) writes the tables into the file's blocks (``benchmarks/markdown_blocks.py``):
docs/irradiance-probes.md holds ``irradiance_probes.py#plateau``, ``#equal-time``, ``#heuristics-error``,
``#heuristics-bias`` and ``#light-leak``; BENCHMARKS.md the summary ``#summary``. (The page's table of the budgets
where probes win sets two runs side by side by hand.)

Run: ``.venv/bin/python benchmarks/irradiance_probes.py --markdown docs/irradiance-probes.md --markdown
BENCHMARKS.md`` (13 minutes on 2 quiet cores from an empty ``--out``: 763 s
and 792 s in two runs; 2 seeds, the fewest a bias/variance split allows, to stay near the 15-minute budget).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from PIL import Image, ImageDraw
from scipy.ndimage import gaussian_filter

import figure_manifest
import markdown_blocks
from markdown_blocks import bold, minus
from cornell_harness.adapters.registry import resolve, sweep
from cornell_harness.adapters.settings import parse_sweep
from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.convergence import slope_over_seeds, time_to_target
from cornell_harness.evaluate.regions import region_masks
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.atomic import atomic_path
from cornell_harness.store.experiments import SUMMARY_FILE, cell_name, final_images
from cornell_harness.store.exr import read_exr
from cornell_harness.store.references import load_reference
from cornell_harness.evaluate.summary import summary_table
from cornell_harness.workflows.converge import run_experiment
from cornell_harness.workflows.spp_list import parse_spp_list
from cornell_harness.reports.charts import convergence_table
from cornell_harness.reports.bars import BarGroup, bars_svg
from cornell_harness.reports.plots import Series, line_plot_svg

SCENE = "cornell-box"
LEAK_SCENE, LEAK_SPP = "two-rooms", 64
DE = "delta_e2000_mean"
#: (base renderer, sweeps {figure name: sweep}, heuristics switched off one at a time: (label, setting)).
FULL = ("probes", {"grid": "probes.grid=4,6,8,12", "rays": "probes.rays_per_probe=64,256,1024",
                   "iterations": "probes.iterations=0,16,48"},
        (("gamma_blending off", "gamma_blending=false"), ("half_normalisation off", "half_normalisation=false"),
         ("weight_floor off", "weight_floor=false"), ("crush off", "crush=false"),
         ("visibility off", "visibility=false"), ("averaging exact", "averaging=exact"),
         ("hysteresis 0 (none)", "hysteresis=0")))
QUICK = ("probes[grid=4,bounces=2,iterations=2]", {"grid": "probes.grid=4,6", "rays": "probes.rays_per_probe=64,256"},
         (("visibility off", "visibility=false"),))
#: Dark enough on white (Okabe & Ito, then Tableau); the path tracer is black.
COLOURS = ("#0072b2", "#d55e00", "#009e73", "#cc79a7", "#e69f00", "#56b4e9", "#8c564b", "#7f7f7f", "#bcbd22")
PT_COLOUR = "#000000"
#: The charts' classes, themed light for a standalone file (the report's stylesheet themes them dark).
STYLE = ("<style>text{font-family:system-ui,sans-serif;font-size:11.5px;fill:#444}text.label,text.legend-label"
         "{fill:#111;font-size:12.5px}.plot-bg{fill:#fff}.grid{stroke:#e4e4e4;stroke-width:1}.axis{stroke:#888}"
         ".guide{stroke:#999;stroke-width:1.6}.point{stroke:#fff;stroke-width:1}.bar-note{fill:#111}</style>")
BUDGETS = (0.5, 1, 2, 4, 8, 16, 32, 64)
PLATEAU = 1.1  # "plateaued": ΔE mean within 10% of its max-spp value
CELLS = {"done": 0, "stored": 0}


def label(entry, default) -> str:
    """A short name of a configuration: the settings it changes from ``default``'s ("grid 4", "rays 64")."""
    diff = [(k, v) for k, v in entry.settings.items() if default.settings[k] != v]
    return ", ".join(f"{k.replace('_per_probe', '')} {v}" for k, v in diff) or "grid {grid}, rays " \
        "{rays_per_probe} (default)".format(**default.settings)


def fmt(x, spec: str = ".3g", missing: str = "n/a") -> str:
    return missing if x is None or not math.isfinite(x) else format(x, spec)


def spacing(runs, name: str) -> float:
    """The smallest probe spacing of configuration ``name`` (its renders' info)."""
    return min(json.loads(runs.loc[runs["renderer"] == name, "info_probe_spacing"].iloc[0]))


def doc_label(name: str, configs: dict, runs, default, grid_names: list[str]) -> str:
    """How the page names a configuration: grids with their spacing, the default with its settings, in bold."""
    s = default.settings
    if name == default.name:
        return bold(f"grid {s['grid']} ({spacing(runs, name):.2f}), rays {s['rays_per_probe']}, "
                    f"iterations {s['iterations']}: default")
    if name in grid_names:
        first = name == grid_names[0]
        return f"{configs[name]} ({'spacing ' if first else ''}{spacing(runs, name):.2f})"
    return configs[name]


def write_svg(path: Path, svg: str) -> None:
    """A report chart as a standalone file: the SVG namespace, a size, a white page and light styles; recorded,
    with the command running, in its folder's manifest (``figure_manifest``)."""
    head, rest = svg.split(">", 1)
    head = head.replace("<svg ", '<svg xmlns="http://www.w3.org/2000/svg" width="640" height="400" ', 1)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(head + ">" + STYLE + '<rect width="100%" height="100%" fill="#fff"/>' + rest + "\n")
    figure_manifest.record([path], markdown_blocks.command_line())


def experiment(out: Path, scene, ref, entries, spps, seeds, command: str):
    """run_experiment (resumable cells) and the summary cbox converge writes after it (summary_table, with the
    bias²/variance split per region; ``cbox report FOLDER`` adds the HTML report); (rows, summary)."""
    t0 = time.perf_counter()

    def on_cell(name: str, cached: bool) -> None:
        CELLS["stored" if cached else "done"] += 1
        print(f"  {out.name}: {name} {'(stored)' if cached else 'done'} at {time.perf_counter() - t0:.0f} s",
              file=sys.stderr, flush=True)

    runs = run_experiment(out, scene, ref, entries, spps, seeds, command=command, on_cell=on_cell)
    bad = runs[runs["status"] != "ok"]
    assert bad.empty, bad[["renderer", "status", "reason"]].to_string()
    summary = summary_table(runs, final_images(out, runs), ref, scene)
    with atomic_path(out / SUMMARY_FILE) as tmp:
        summary.to_parquet(tmp, index=False)
    return runs, summary.set_index("renderer")


def curves(conv: pd.DataFrame, keys) -> dict:
    """Per configuration: its checkpoints' median times (made non-decreasing) and median errors, by spp."""
    out = {}
    for name, g in conv.groupby("renderer", sort=False):
        g = g.sort_values("spp")
        out[name] = (np.maximum.accumulate(g["time_s"].to_numpy(float)), {k: g[k].to_numpy(float) for k in keys})
    return out


def at_time(cv: dict, name: str, metric: str, t: float) -> float:
    """One configuration's median error at wall time t: log-log between checkpoints, NaN before the first, the
    last one's beyond it (a renderer of fixed settings does not improve past what it rendered)."""
    ts, es = cv[name][0], cv[name][1][metric]
    if t < ts[0]:
        return math.nan
    return float(np.exp(np.interp(math.log(t), np.log(ts), np.log(es))))


def best_at(cv, names, metric, t) -> tuple[float, str]:
    """The lowest error any of ``names`` reaches within time t, and which one."""
    vals = [(at_time(cv, n, metric, t), n) for n in names]
    vals = [v for v in vals if math.isfinite(v[0])]
    return min(vals) if vals else (math.nan, "")


def probes_win(cv, names, metric, t0, t1) -> list[tuple[float, float]]:
    """The time intervals inside [t0, t1] in which the best probes configuration beats the path tracer."""
    ts = np.geomspace(t0, t1, 600)
    best = np.array([best_at(cv, names, metric, t)[0] for t in ts])
    d = np.where(np.isfinite(best), np.log(best / np.array([at_time(cv, "pathtracer", metric, t) for t in ts])), 1)
    out, start = [], None
    for i, t in enumerate(ts):
        win = d[i] < 0
        if win and start is None:
            start = t if i == 0 else float(np.exp(np.interp(0, [d[i], d[i - 1]], np.log(ts[[i, i - 1]]))))
        if not win and start is not None:
            out.append((start, float(np.exp(np.interp(0, [d[i - 1], d[i]], np.log(ts[[i - 1, i]]))))))
            start = None
    return out + ([(start, math.inf)] if start is not None else [])


# -- 1. sweeps ---------------------------------------------------------------------------------------------------

def mean_image_de(out: Path, name: str, seeds, ref) -> float:
    """ΔE2000 mean of the seeds' mean image: the camera noise of len(seeds)·max spp, the probe noise averaged."""
    mean = np.mean([read_exr(out / "images" / f"{cell_name(name, s)}.exr") for s in seeds], axis=0)
    return metrics.delta_e2000(mean, ref.image)


def plateau_table(runs, summary, configs: dict, max_spp: int, out: Path, ref) -> list[dict]:
    rows = []
    seeds = sorted(runs["seed"].dropna().astype(int).unique())
    print("## 1. Error against spp and time, and the plateau (medians over seeds; ΔE = ΔE2000 mean)\n")
    for name, lab in configs.items():
        g = runs[runs["renderer"] == name]
        med = g.groupby("spp").median(numeric_only=True)
        final = med[DE].iloc[-1]
        onset = time_to_target(g.assign(time_s=g["spp"].astype(float)), DE, PLATEAU * final)
        onset_t = time_to_target(g, DE, PLATEAU * final)
        slope, _ = slope_over_seeds(g[g["spp"] >= max_spp / 4], DE, "spp")
        sm = summary.loc[name]
        r = {"name": name, "label": lab, "probes_s": float(g["info_probes_s"].median()),
             "time_max": float(med["time_s"].iloc[-1]), "de1": float(med[DE].iloc[0]),
             "de16": float(med[DE].get(16, math.nan)), "de_max": float(final), "onset_spp": onset,
             "onset_s": onset_t, "slope": slope, "de_mean_image": mean_image_de(out, name, seeds, ref),
             "mean_err": float(g[g["spp"] == max_spp]["mean_radiance_rel_error"].mean()),
             **{f"{k}.{x}": float(sm[f"region.{k}.{x}"]) for k in ("walls", "boxes") for x in ("bias2", "variance")},
             **{k: float(med[f"region.{k}.{DE}"].iloc[-1]) for k in ("walls", "boxes")}}
        rows.append(r)
    print(f"\nplateau from: the spp (and time) at which ΔE mean first comes within {PLATEAU - 1:.0%} of its value "
          f"at {max_spp} spp (per seed, interpolated log-log; median). ΔE slope: log-log against spp from "
          f"{max_spp // 4} spp, mean over seeds (an unbiased renderer: about -0.5; a plateau: 0). ΔE of the seeds' "
          f"mean image: {len(seeds)}·{max_spp} camera samples, the probes' own noise averaged over {len(seeds)} "
          "seeds. Mean radiance: signed relative error, mean over seeds. bias², variance: converge's summary "
          f"at {max_spp} spp (variance: between seeds, the camera's and the probes' noise).\n")
    return rows


def scale_row(pt_runs, max_spp: int) -> dict:
    """The path tracer's figures of part 1's table, up to the probes' top spp (for scale)."""
    g = pt_runs[pt_runs["spp"] <= max_spp]
    med = g.groupby("spp").median(numeric_only=True)
    return {"time_max": float(med["time_s"].iloc[-1]), "de1": float(med[DE].iloc[0]),
            "de16": float(med[DE].get(16, math.nan)), "de_max": float(med[DE].iloc[-1]),
            "slope": slope_over_seeds(g[g["spp"] >= max_spp / 4], DE, "spp")[0],
            "mean_err": float(g[g["spp"] == max_spp]["mean_radiance_rel_error"].mean()),
            **{k: float(med[f"region.{k}.{DE}"].iloc[-1]) for k in ("walls", "boxes")}}


def plateau_markdown(rows: list[dict], labels: dict, pt: dict, max_spp: int) -> list[str]:
    """Part 1's table (``plateau_table``'s rows, page labels by name), the path tracer last for scale."""
    lines = [f"| configuration | probe updates (s) | time at {max_spp} spp (s) | ΔE 1 spp | ΔE 16 spp | ΔE {max_spp} spp "
             f"| within {PLATEAU - 1:.0%} of it from spp (s) | ΔE slope, {max_spp // 4}-{max_spp} spp | ΔE of the "
             "seeds' mean | mean radiance | walls ΔE | boxes ΔE | walls bias² / variance | boxes bias² / variance |",
             "|" + "---|" * 14]
    for r in rows:
        lines.append(
            f"| {labels[r['name']]} | {r['probes_s']:.2f} | {r['time_max']:.1f} | {r['de1']:.2f} | "
            f"{fmt(r['de16'], '.2f')} | **{r['de_max']:.2f}** | {fmt(r['onset_spp'], '.0f')} "
            f"({fmt(r['onset_s'], '.1f')}) | {minus(fmt(r['slope'], '+.3f'))} | {r['de_mean_image']:.2f} | "
            f"{minus(format(r['mean_err'], '+.1%'))} | {r['walls']:.2f} | {r['boxes']:.2f} | "
            + " | ".join(f"{r[k + '.bias2']:.1e} / {r[k + '.variance']:.1e}" for k in ("walls", "boxes")) + " |")
    lines.append(f"| *path tracer (for scale)* | — | {pt['time_max']:.1f} | {pt['de1']:.1f} | {fmt(pt['de16'], '.2f')} | "
                 f"{pt['de_max']:.2f} | — | {minus(fmt(pt['slope'], '+.2f'))} | — | "
                 f"{minus(format(pt['mean_err'], '+.1%'))} | {pt['walls']:.2f} | {pt['boxes']:.2f} | — | — |")
    return lines


def summary_markdown(rows: list[dict], pt: dict, default, grid_names: list[str], max_spp: int) -> list[str]:
    """BENCHMARKS.md's summary of part 1: the coarsest and finest grid, the default, the path tracer."""
    by = {r["name"]: r for r in rows}
    s = default.settings
    picked = [(f"`{grid_names[0]}`", by[grid_names[0]]),
              (f"`{default.name}` (default: grid {s['grid']}, {s['rays_per_probe']} rays, {s['bounces']} bounces "
               f"+ {s['iterations']} blended updates)", by[default.name]),
              (f"`{grid_names[-1]}`", by[grid_names[-1]])]
    lines = [f"| `{SCENE}`, 256² | probe updates | ΔE mean at 16 / {max_spp} spp (plateau) | time at {max_spp} spp |",
             "|---|---|---|---|"]
    lines += [f"| {lab} | {r['probes_s']:#.3g} s | {fmt(r['de16'], '.2f')} / {r['de_max']:.2f} | "
              f"{r['time_max']:.1f} s |" for lab, r in picked]
    lines.append(f"| `pathtracer` (for scale) | — | {fmt(pt['de16'], '.2f')} / {pt['de_max']:.2f} | "
                 f"{pt['time_max']:.1f} s |")
    return lines


def time_figures(conv, configs: dict, groups: dict, images: Path, metric: str = DE) -> None:
    """One ΔE-against-time chart per sweep (with the path tracer), and ΔE against spp for everything swept."""
    def series(names, x):
        out = []
        for i, n in enumerate(names):
            g = conv[conv["renderer"] == n].sort_values("spp")
            colour = PT_COLOUR if n == "pathtracer" else COLOURS[i % len(COLOURS)]
            out.append(Series(configs.get(n, n).replace(" (default)", ""), colour, g[x].astype(float).tolist(),
                              g[metric].tolist(), g[metric + "_min"].tolist(), g[metric + "_max"].tolist()))
        return out
    for key, names in groups.items():
        write_svg(images / f"probes-{key}.svg", line_plot_svg(series([*names, "pathtracer"], "time_s"),
                  uid=f"probes-{key}", xlabel="wall time (s)", ylabel="ΔE2000 mean"))
    swept = list(dict.fromkeys(n for names in groups.values() for n in names))
    write_svg(images / "probes-spp.svg", line_plot_svg(series([*swept, "pathtracer"], "spp"), uid="probes-spp",
              xlabel="samples per pixel", ylabel="ΔE2000 mean", xbase2=True))


# -- 2. equal time -----------------------------------------------------------------------------------------------

def equal_time(conv, pt_runs, plateau_rows, configs: dict, regions: list[str], images: Path) -> dict:
    names = list(configs)
    keys = [DE] + [f"region.{r}.{DE}" for r in regions]
    cv = curves(conv, keys)
    pt = conv[conv["renderer"] == "pathtracer"]
    t0, t1 = float(pt["time_s"].min()), float(pt["time_s"].max())
    out = {"budgets": {}, "windows": {}, "pt_to_plateau": {}}
    print("## 2. Probes against the path tracer at equal time (ΔE2000 mean; medians over seeds)\n")
    print("Best probes configuration within each budget (of part 1's) against the path tracer:\n")
    for b in BUDGETS:
        if b > t1 * 1.01:
            break
        row = {k: (best_at(cv, names, k, b), at_time(cv, "pathtracer", k, b)) for k in keys}
        (e, who), p = row[DE]
        out["budgets"][b] = {k: {"probes": v[0][0], "config": v[0][1], "pathtracer": v[1]} for k, v in row.items()}
    print("\n".join(equal_time_markdown(out["budgets"], configs)))
    cam = np.median([(r["time_max"] - r["probes_s"]) / conv.loc[conv["renderer"] == r["name"], "spp"].max()
                     for r in plateau_rows])
    pt_cost = float(pt["time_s"].max() / pt["spp"].max())
    out["camera_s_per_spp"] = {"probes": float(cam), "pathtracer": pt_cost}
    print(f"\nA camera sample of probes (after the updates) costs {1e3 * cam:.1f} ms per spp (median over the "
          f"configurations), a path-traced one {1e3 * pt_cost:.1f} ms: ratio {cam / pt_cost:.2f}.\n")
    print(f"Where probes are more accurate (budgets from the path tracer's 1 spp, {t0:.2f} s, to its "
          f"{int(pt['spp'].max())} spp, {t1:.0f} s), and when the path tracer reaches the best probes plateau:\n")
    print("| error | probes better between (s) | best probes plateau (config) | path tracer reaches it at (s), "
          "spp |\n|---|---|---|---|")
    for k in keys:
        win = probes_win(cv, names, k, t0, t1)
        best = min(plateau_rows, key=lambda r: conv[(conv["renderer"] == r["name"])][k].iloc[-1])
        level = float(conv[conv["renderer"] == best["name"]].sort_values("spp")[k].iloc[-1])
        t_pt = time_to_target(pt_runs, k, level)
        n_pt = time_to_target(pt_runs.assign(time_s=pt_runs["spp"].astype(float)), k, level)
        out["windows"][k] = win
        out["pt_to_plateau"][k] = {"level": level, "config": best["name"], "time_s": t_pt, "spp": n_pt}
        span = ", ".join(f"{a:.2f}–{fmt(z, '.1f') if math.isfinite(z) else 'beyond'}" for a, z in win) or "never"
        print(f"| {k.replace('.' + DE, '').replace(DE, 'image')} | {span} | {level:.2f} ({configs[best['name']]}) "
              f"| {fmt(t_pt, '.1f')}, {fmt(n_pt, '.0f')} |")
    print("\n(per-budget errors: log-log in time between checkpoints; a configuration's last checkpoint is held "
          "beyond its time. Path tracer's time to the plateau: time_to_target per seed, median.)\n")
    ts = np.geomspace(t0, t1, 28)
    colour = dict(zip(keys, ("#0072b2", "#d55e00", "#009e73")))
    series = [Series(f"{who} {k.replace('.' + DE, '').replace('region.', '').replace(DE, 'image')}",
                     colour[k] if who == "probes" else colour[k] + "88", ts.tolist(), ys)
              for k in keys[:3] for who, ys in (
                  ("probes", [best_at(cv, names, k, t)[0] for t in ts]),
                  ("PT", [at_time(cv, "pathtracer", k, t) for t in ts]))]
    write_svg(images / "probes-equal-time.svg", line_plot_svg(series, uid="probes-equal-time", xlabel="time budget (s)",
              ylabel="ΔE2000 mean (best probes config / path tracer)"))
    return out


def equal_time_markdown(budgets: dict, configs: dict) -> list[str]:
    """Part 2's table of budgets (``equal_time``'s ``budgets``): the best probes configuration against the path
    tracer, image-wide and on the walls and boxes."""
    lines = ["| budget | best probes configuration | its ΔE | path tracer ΔE | ratio | walls: probes / PT | "
             "boxes: probes / PT |", "|---|---|---|---|---|---|---|"]
    for b, row in budgets.items():
        e, p = row[DE]["probes"], row[DE]["pathtracer"]
        who = row[DE]["config"]
        lab = configs.get(who, "none has an image yet")
        if lab.endswith(" (default)"):
            lab = f"default ({lab.removesuffix(' (default)')})"
        w, x = row[f"region.walls.{DE}"], row[f"region.boxes.{DE}"]
        lines.append(f"| {b:g} s | {lab} | {fmt(e, '.2f', '—')} | {p:.2f} | {fmt(e / p, '.2f', '—')} | "
                     f"{fmt(w['probes'], '.2f', '—')} / {w['pathtracer']:.2f} | "
                     f"{fmt(x['probes'], '.2f', '—')} / {x['pathtracer']:.2f} |")
    return lines


# -- 3. heuristics -----------------------------------------------------------------------------------------------

def heuristics(runs, summary, base: str, heur: dict, regions: list[str], images: Path) -> dict:
    top = runs[runs["spp"] == runs["spp"].max()]
    res = {}
    for name, lab in {base: "default (RTXGI)", **heur}.items():
        g = top[top["renderer"] == name]
        res[name] = {"label": lab, "de": float(g[DE].median()), "mean_err": float(g["mean_radiance_rel_error"].mean()),
                     "bias2": float(summary.loc[name, "bias2"]),
                     **{f"{r}.err": float(g[f"region.{r}.mean_radiance_rel_error"].mean()) for r in regions},
                     **{f"{r}.de": float(g[f"region.{r}.{DE}"].median()) for r in regions},
                     **{f"{r}.bias2": float(summary.loc[name, f"region.{r}.bias2"]) for r in regions}}
    print(f"## 3. Each heuristic off, one at a time (the rest as `{base}`, {int(top['spp'].max())} spp)\n")
    print("Signed error of the mean radiance (mean over seeds: the mean image's), image-wide and per region; ΔE "
          "mean median over seeds:\n")
    error, bias = heuristics_markdown(res, base, regions)
    print("\n".join(error))
    print("\nbias² per region (converge's summary: squared error of the seeds' mean image, less its noise and "
          "the reference's), and ΔE mean per region:\n")
    print("\n".join(bias) + "\n")
    shown = [r for r in regions if r != "light"]
    write_svg(images / "probes-heuristics.svg", bars_svg(
        [BarGroup("image", [r["bias2"] for r in res.values()])]
        + [BarGroup(k, [r[f"{k}.bias2"] for r in res.values()]) for k in shown],
        [(r["label"], c) for r, c in zip(res.values(), ("#000000",) + COLOURS)], uid="probes-heuristics",
        ylabel="bias² (RGB radiance²)"))
    return res


def heuristics_markdown(res: dict, base: str, regions: list[str]) -> tuple[list[str], list[str]]:
    """Part 3's two tables (``heuristics``'s result): the signed errors with ΔE mean, and bias² (ΔE) per region."""
    d0 = res[base]["de"]
    error = ["| setting | ΔE mean | change | mean radiance | " + " | ".join(regions) + " |",
             "|---|---|---|---|" + "---|" * len(regions)]
    bias = ["| setting | bias² image | " + " | ".join(regions) + " |", "|---|---|" + "---|" * len(regions)]
    for name, r in res.items():
        is_base = name == base
        change = "" if is_base else minus(format(r["de"] - d0, "+.2f"))
        error.append(f"| {bold(r['label'], is_base)} | {bold(format(r['de'], '.2f'), is_base)} | {change} | "
                     f"{minus(format(r['mean_err'], '+.1%'))} | "
                     + " | ".join(minus(format(r[f"{k}.err"], "+.1%")) for k in regions) + " |")
        bias.append(f"| {bold(r['label'], is_base)} | {r['bias2']:.2e} | "
                    + " | ".join(f"{r[f'{k}.bias2']:.2e} ({r[f'{k}.de']:.2f})" for k in regions) + " |")
    return error, bias


def bias_figure(out: Path, ref, runs, names: dict, path: Path, lim: float = 0.25, size: int = 192) -> None:
    """Per configuration, the seeds' mean image against the reference: relative luminance error, smoothed (a
    Gaussian of 1 pixel: what is left of the camera noise), blue where darker, red where lighter (±lim
    saturates); the reference first."""
    r_lum = metrics.luminance(ref.image)
    seeds = sorted(runs["seed"].dropna().astype(int).unique())
    shown = metrics.display_encode(ref.image, metrics.display_exposure(ref.image, ref.quantity))
    panels = [("reference", np.round(shown * 255).astype(np.uint8))]
    for name, lab in names.items():
        mean = np.mean([read_exr(out / "images" / f"{cell_name(name, s)}.exr") for s in seeds], axis=0)
        t = np.clip(gaussian_filter((metrics.luminance(mean) - r_lum) / np.maximum(r_lum, 1e-3), 1.0) / lim, -1, 1)
        rgb = np.stack([np.where(t > 0, 1, 1 + t), 1 - np.abs(t), np.where(t < 0, 1, 1 - t)], axis=-1)
        panels.append((lab, np.round(rgb * 255).astype(np.uint8)))
    cols = 4
    rows = math.ceil(len(panels) / cols)
    canvas = Image.new("RGB", (cols * (size + 4), rows * (size + 18) + 18), "white")
    d = ImageDraw.Draw(canvas)
    for i, (lab, img) in enumerate(panels):
        x, y = (i % cols) * (size + 4), (i // cols) * (size + 18)
        d.text((x + 2, y + 2), lab, fill="black")
        canvas.paste(Image.fromarray(img).resize((size, size), Image.BILINEAR), (x, y + 16))
    d.text((2, rows * (size + 18) + 2), f"(mean over seeds - reference) / reference, luminance, smoothed 1 px: "
           f"blue darker, red lighter, saturating at ±{lim:.0%}", fill="black")
    path.parent.mkdir(parents=True, exist_ok=True)
    canvas.quantize(256, method=Image.Quantize.FASTOCTREE).save(path, optimize=True)
    figure_manifest.record([path], markdown_blocks.command_line())


def light_leak(out: Path, images: Path, seeds, spp: int, command: str) -> list[dict]:
    """Part 4, ``two-rooms`` (its right room is exactly black): each floor's mean luminance with Chebyshev visibility
    on and off (seeds' mean), the dark floor's as a fraction of the lit floor's, and ``probes-leak.png``: reference
    and both renders exposed for the lit floor and 32 times brighter (where the leak shows)."""
    scene = resolve_scene(LEAK_SCENE)
    ref = load_reference(scene)
    default = resolve(["probes"])[0]
    entries = {"visibility on (default)": default, "visibility off": default.with_settings({"visibility": False})}
    experiment(out / LEAK_SCENE, scene, ref, list(entries.values()), [spp], seeds, command)
    masks = region_masks(scene)
    shown, rows = [], []
    folder = out / LEAK_SCENE / "images"
    images_of = {"reference": ref.image}
    for lab, e in entries.items():
        images_of[lab] = np.mean([read_exr(folder / f"{cell_name(e.name, s)}.exr") for s in seeds], axis=0)
    for lab, mean in images_of.items():
        lit, dark = (float(metrics.luminance(mean)[masks[r]].mean()) for r in ("lit-floor", "dark-floor"))
        rows.append({"label": lab, "lit_floor": lit, "dark_floor": dark, "dark_over_lit": dark / lit})
        shown.append((lab, mean))
    print(f"\n## 4. Light leaks on {LEAK_SCENE} ({spp} spp, seeds' mean)\n")
    print("\n".join(leak_markdown(rows)))
    # The dark half would drive an image-wide exposure to saturate the lit room: expose for the lit floor instead.
    k, zoom = 0.18 / rows[0]["lit_floor"], 2
    h, w = (zoom * n for n in ref.image.shape[:2])
    canvas = Image.new("RGB", (len(shown) * (w + 4), 2 * (h + 16) + 16), "white")
    d = ImageDraw.Draw(canvas)
    for i, (lab, img) in enumerate(shown):
        for j, gain in enumerate((1, 32)):
            x, y = i * (w + 4), j * (h + 16)
            d.text((x + 2, y + 2), f"{lab}, x{gain}" if gain > 1 else lab, fill="black")
            px = np.round(metrics.display_encode(img, k * gain) * 255).astype(np.uint8)
            canvas.paste(Image.fromarray(px).resize((w, h), Image.NEAREST), (x, y + 14))
    d.text((2, 2 * (h + 16) + 2), "top: exposed for the lit floor (left room); bottom: 32 times brighter. The right "
           "room is exactly black: what shows there leaked through the wall.", fill="black")
    canvas.save(images / "probes-leak.png", optimize=True)
    figure_manifest.record([images / "probes-leak.png"], markdown_blocks.command_line())
    return rows


def leak_markdown(rows: list[dict]) -> list[str]:
    """Part 4's table (``light_leak``'s rows); an exact 0 is written 0."""
    def small(x):
        return "0" if x == 0 else fmt(x, ".2e")
    return ["| probes | lit floor (mean luminance) | dark floor | dark / lit |", "|---|---|---|---|"] + [
        f"| {r['label']} | {fmt(r['lit_floor'], '.4f')} | {small(r['dark_floor'])} | {small(r['dark_over_lit'])} |"
        for r in rows]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/bench-probes"))
    ap.add_argument("--images", type=Path, help="where the figures go (default docs/images; OUT-quick/images)")
    ap.add_argument("--seeds", type=int, default=2, help="seeds 0..N-1 (bias and variance need 2 or more)")
    ap.add_argument("--max-spp", type=int, default=256)
    ap.add_argument("--pt-max-spp", type=int, default=1024)
    ap.add_argument("--quick", action="store_true", help="tiny settings, to check the script (OUT-quick)")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the tables into this file's blocks irradiance_probes.py#... (repeatable)")
    a = ap.parse_args()
    base, sweeps, heur = QUICK if a.quick else FULL
    out, max_spp, pt_max = a.out, a.max_spp, a.pt_max_spp
    if a.quick:
        out, max_spp, pt_max = out.with_name(out.name + "-quick"), min(max_spp, 8), min(pt_max, 16)
    images = a.images or (out / "images" if a.quick else Path("docs/images"))
    t_start = time.perf_counter()
    scene = resolve_scene(SCENE)
    ref = load_reference(scene)
    regions = list(scene.regions)
    default = resolve([base])[0]
    swept = {key: sweep([default], *parse_sweep(text)) for key, text in sweeps.items()}
    heur_entries = [default.with_settings(dict([s.split("=")])) for _, s in heur]
    entries = list({e.name: e for e in [e for es in swept.values() for e in es] + heur_entries}.values())
    configs = {e.name: label(e, default) for es in swept.values() for e in es}
    heur_names = {e.name: lab for e, (lab, _) in zip(heur_entries, heur)}
    seeds = list(range(a.seeds))
    print(f"# Irradiance probes on {SCENE}: seeds {seeds}, probes spp 1..{max_spp}, path tracer 1..{pt_max}\n\n"
          f"Load average at the start (1, 5, 15 min): {', '.join(f'{v:.2f}' for v in os.getloadavg())}; "
          f"{os.cpu_count()} CPUs.\n")
    command = f"benchmarks/irradiance_probes.py --seeds {a.seeds}"
    runs, summary = experiment(out / "probes", scene, ref, entries, parse_spp_list(f"1,2,4,...,{max_spp}"), seeds,
                               command + f" --max-spp {max_spp}")
    pt_runs, _ = experiment(out / "pathtracer", scene, ref, resolve(["pathtracer"]),
                            parse_spp_list(f"1,2,4,...,{pt_max}"), seeds, command + f" --pt-max-spp {pt_max}")
    keys = [DE, "mse"] + [f"region.{r}.{DE}" for r in regions]
    conv = convergence_table(pd.concat([runs, pt_runs], ignore_index=True), keys)
    plateau = plateau_table(runs, summary, configs, max_spp, out / "probes", ref)
    grid_names = [e.name for e in swept["grid"]]
    labels = {name: doc_label(name, configs, runs, default, grid_names) for name in configs}
    pt_row = scale_row(pt_runs, max_spp)
    print("\n".join(plateau_markdown(plateau, labels, pt_row, max_spp)) + "\n")
    time_figures(conv, configs, {k: [e.name for e in es] for k, es in swept.items()}, images)
    crossing = equal_time(conv, pt_runs, plateau, configs, regions, images)
    heur_res = heuristics(runs, summary, default.name, heur_names, regions, images)
    ends = {e.name: configs[e.name] for e in (swept["grid"][0], swept["grid"][-1])}
    bias_figure(out / "probes", ref, runs, {default.name: "default (RTXGI)", **ends, **heur_names},
                images / "probes-bias.png")
    leak = light_leak(out, images, seeds, LEAK_SPP if not a.quick else 4, command)
    total = time.perf_counter() - t_start
    (out / "summary.json").write_text(json.dumps({"plateau": plateau, "equal_time": crossing, "heuristics": heur_res,
                                                  "light_leak": leak, "wall_s": total}, indent=1, default=str))
    blocks = {"irradiance_probes.py#plateau": plateau_markdown(plateau, labels, pt_row, max_spp),
              "irradiance_probes.py#equal-time": equal_time_markdown(crossing["budgets"], configs),
              "irradiance_probes.py#heuristics-error": heuristics_markdown(heur_res, default.name, regions)[0],
              "irradiance_probes.py#heuristics-bias": heuristics_markdown(heur_res, default.name, regions)[1],
              "irradiance_probes.py#light-leak": leak_markdown(leak),
              "irradiance_probes.py#summary": summary_markdown(plateau, pt_row, default, grid_names, max_spp)}
    markdown_blocks.write_blocks(a.markdown, {k: "\n".join(v) for k, v in blocks.items()})
    print(f"Total wall time {total:.0f} s ({CELLS['done']} cells rendered, {CELLS['stored']} stored); results in "
          f"{out} (`cbox report {out}/probes` builds that experiment's HTML report).")


if __name__ == "__main__":
    main()

"""Recursive (Whitted) ray tracing and its hacks, measured (issue 32): what each approximation gets wrong per
region, and what soft shadows cost. Writes docs/whitted.md whole and its figure docs/images/whitted-penumbra.svg.

1. **The table.** On ``cornell-box`` and ``cornell-box-caustics``, at equal time: every renderer gets
   ``--budget`` seconds (wall), its spp chosen from calibration renders as ``cbox compare --time-budget``
   chooses it (:func:`cornell_harness.workflows.compare.calibrate_time_budget`, seed 0), then renders ``--seeds``
   seeds (:func:`cornell_harness.workflows.runner.run_one`). Per region (the scene's own and the study's,
   :mod:`cornell_harness.evaluate.missing_light`): the share of the reference's light missing and the bias of the
   region's mean radiance, each ± its standard error *over seeds* (with the reference's own error), and the
   mean ΔE00 over seeds. Columns: ``whitted`` with each ``transparent_shadows`` mode at ``ambient=none`` (so
   that the shadow rule's light is all there is) and each ``ambient`` mode at ``transparent_shadows=attenuate``
   (the default; 5 variants, attenuate without ambient shared), ``ambient``, ``probes``, ``photonmap``,
   ``pathtracer``. The calibration takes 3 rounds (medians), as ``cbox compare --time-budget`` does.
2. **The soft-shadow cost curve.** On ``cornell-box``'s ``penumbra`` (floor pixels that see part of the light):
   relMSE against the reference, and against whitted's own converged direct light (``--converged`` light
   samples, same seed, so the same camera rays: the soft-shadow noise alone), for ``whitted[light_samples=N]``
   at 1 spp, N = 1, 2, 4, ..., against wall time; beside it the path tracer at 1, 2, 4, ... spp. Seed 0.

Run: ``.venv/bin/python benchmarks/whitted.py`` (about 10 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

import markdown_blocks
from irradiance_probes import write_svg
from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate import metrics
from cornell_harness.evaluate.convergence import time_to_target
from cornell_harness.evaluate.missing_light import region_table, study_columns, study_masks
from cornell_harness.evaluate.regions import region_noise
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows import compare, runner
from cornell_harness.reports.plots import PALETTE, Series, line_plot_svg

ROOT = Path(__file__).resolve().parents[1]
#: The Whitted renderer's spec: its entry point where installed, else its class (an older editable install).
WHITTED = "whitted"
#: (settings, label) of the table's columns.
COLUMNS = (
    (f"{WHITTED}[transparent_shadows=boolean,ambient=none]", "whitted boolean, no ambient"),
    (f"{WHITTED}[transparent_shadows=attenuate,ambient=none]", "whitted attenuate, no ambient"),
    (f"{WHITTED}[transparent_shadows=ignore,ambient=none]", "whitted ignore, no ambient"),
    (f"{WHITTED}[transparent_shadows=attenuate,ambient=constant]", "whitted attenuate, constant (default)"),
    (f"{WHITTED}[transparent_shadows=attenuate,ambient=ao]", "whitted attenuate, ao"),
    ("ambient", "ambient"),
    ("probes", "probes"),
    ("photonmap", "photonmap"),
    ("pathtracer", "path tracer"),
)
REGIONS = {"cornell-box": ("floor", "walls", "boxes", "back-edge", "penumbra"),
           "cornell-box-caustics": ("caustic", "glass-shadow", "mirror", "glass", "floor", "walls", "back-edge")}
PENUMBRA = "region.penumbra.rel_mse"


def pct(x: float, se: float | None = None) -> str:
    if not math.isfinite(x):
        return "n/a"
    text = markdown_blocks.minus(f"{100 * x:+.1f}%")
    return text if se is None else f"{text} ± {100 * se:.1f}%"


def g3(x: float, se: float | None = None) -> str:
    if not math.isfinite(x):
        return "n/a"
    text = markdown_blocks.minus(f"{x:+.3g}")
    return text if se is None else f"{text} ± {se:.2g}"


def scored(entry, sc, ref, spp: int, seed: int, masks, repeats: int = 1) -> dict:
    """One render's results row, with the study's regions (the scene's own are the record's); with
    ``repeats`` its time is the median of that many renders (the same image each time: same seed)."""
    rec = runner.run_one(entry, sc, spp, seed, ref)
    if rec.status != "ok":
        raise SystemExit(f"whitted.py: {entry.name} on {sc.name}: {rec.status}: {rec.reason}")
    times = [rec.time_s] + [runner.render_timed(entry, sc, spp, seed)[0].time_s for _ in range(repeats - 1)]
    return {**rec.row(), **study_columns(sc, rec.image, ref, spp, masks), "_image": rec.image,
            "time_s": float(np.median(times))}


def equal_time_rows(scene: str, budget: float, seeds: int) -> tuple[list[dict], dict]:
    """Every column's rows (one per seed) at equal time on ``scene``; and the reference's region noise."""
    sc = resolve_scene(scene)
    ref = load_reference(sc)
    masks = study_masks(sc)
    entries = resolve([spec for spec, _ in COLUMNS])
    choices = compare.calibrate_time_budget(entries, sc, budget, 0, repeats=3)
    rows = []
    for (spec, label), entry, choice in zip(COLUMNS, entries, choices):
        if isinstance(choice, Exception):
            raise SystemExit(f"whitted.py: calibrating {label} on {scene}: {choice}")
        for seed in range(seeds):
            row = scored(entry, sc, ref, choice.spp, seed, masks)
            row.pop("_image")
            rows.append({**row, "label": label})
            print(f"  {scene} {label} seed {seed}: {choice.spp} spp, {row['time_s']:.2f} s", flush=True)
    return rows, region_noise(ref.image, ref.variance, masks)


def table_markdown(scene: str, rows: list[dict], noise: dict) -> tuple[str, dict]:
    """The scene's table (rows: region × figure, columns: renderers) and its figures by (label, region)."""
    figs = {(f["label"], f["region"]): f for f in region_table(rows, REGIONS[scene], noise, label="label")}
    labels = [label for _, label in COLUMNS]
    out = ["| region | figure | " + " | ".join(labels) + " |", "|---|---|" + "---|" * len(labels)]
    first = {label: figs[(label, REGIONS[scene][0])] for label in labels}
    out.append("| (all) | spp; median time (s) | " + " | ".join(
        f"{first[lab]['spp']}; {first[lab]['time_s']:.2f}" for lab in labels) + " |")
    for region in REGIONS[scene]:
        ref_mean = noise[region]["mean"]
        cells = {lab: figs[(lab, region)] for lab in labels}
        out.append(f"| {region} ({noise[region]['pixels']} px, mean {ref_mean:.3g}) | light missing | "
                   + " | ".join(pct(c["share"], c["share_se"]) for c in cells.values()) + " |")
        out.append("| | bias of the mean | " + " | ".join(g3(c["bias"], c["bias_se"]) for c in cells.values())
                   + " |")
        out.append("| | ΔE00 mean | " + " | ".join(f"{c['delta_e']:.2f}" for c in cells.values()) + " |")
    return "\n".join(out), figs


def soft_shadow_curve(light_samples: list[int], pt_spp: list[int], converged: int) -> pd.DataFrame:
    """Penumbra relMSE (to the reference; for whitted also to its own converged image) and time per point."""
    sc = resolve_scene("cornell-box")
    ref = load_reference(sc)
    masks = study_masks(sc)
    pen = masks["penumbra"]
    t0 = time.perf_counter()
    (conv_entry,) = resolve([f"{WHITTED}[light_samples={converged}]"])
    own = scored(conv_entry, sc, ref, 1, 0, masks)["_image"]
    print(f"  whitted converged ({converged} light samples): {time.perf_counter() - t0:.1f} s", flush=True)
    out = []
    for n in light_samples:
        (entry,) = resolve([f"{WHITTED}[light_samples={n}]"])
        row = scored(entry, sc, ref, 1, 0, masks, repeats=3)
        noise_only = metrics.rel_mse(metrics.masked_pixels(row["_image"], pen), metrics.masked_pixels(own, pen))
        out.append({"renderer": "whitted", "x": n, "spp": 1, "seed": 0, "time_s": row["time_s"],
                    PENUMBRA: row[PENUMBRA], "noise_rel_mse": noise_only})
        print(f"  whitted light_samples={n}: {row['time_s']:.2f} s, penumbra relMSE {row[PENUMBRA]:.3g}", flush=True)
    (pt,) = resolve(["pathtracer"])
    for spp in pt_spp:
        row = scored(pt, sc, ref, spp, 0, masks, repeats=3)
        out.append({"renderer": "pathtracer", "x": spp, "spp": spp, "seed": 0, "time_s": row["time_s"],
                    PENUMBRA: row[PENUMBRA], "noise_rel_mse": math.nan})
        print(f"  pathtracer {spp} spp: {row['time_s']:.2f} s, penumbra relMSE {row[PENUMBRA]:.3g}", flush=True)
    return pd.DataFrame(out)


def curve_figure(curve: pd.DataFrame, path: Path) -> None:
    w = curve[curve["renderer"] == "whitted"]
    p = curve[curve["renderer"] == "pathtracer"]
    series = [
        Series("whitted: penumbra relMSE to the reference", PALETTE[0], w["time_s"].tolist(), w[PENUMBRA].tolist(),
               labels=[f"light_samples {n}" for n in w["x"]]),
        Series("whitted: shadow noise alone (to its own converged image)", PALETTE[1], w["time_s"].tolist(),
               w["noise_rel_mse"].tolist(), labels=[f"light_samples {n}" for n in w["x"]]),
        Series("path tracer: penumbra relMSE to the reference", PALETTE[2], p["time_s"].tolist(),
               p[PENUMBRA].tolist(), labels=[f"{n} spp" for n in p["x"]]),
    ]
    write_svg(path, line_plot_svg(series, uid="whitted-penumbra", xlabel="wall time (s)",
                                  ylabel="relMSE in the penumbra", guide_slope=-1.0, guide_label="slope −1 (∝ 1/N)"))


def curve_findings(curve: pd.DataFrame) -> tuple[str, list[str]]:
    """The curve's table and its sentences, from the numbers."""
    w = curve[curve["renderer"] == "whitted"].reset_index(drop=True)
    p = curve[curve["renderer"] == "pathtracer"].reset_index(drop=True)
    lines = ["| renderer | light samples / spp | time (s) | penumbra relMSE (to the reference) | "
             "shadow noise alone (relMSE to whitted's converged image) |", "|---|---|---|---|---|"]
    for _, r in w.iterrows():
        lines.append(f"| whitted | {r['x']} light samples | {r['time_s']:.2f} | {r[PENUMBRA]:.3g} | "
                     f"{r['noise_rel_mse']:.3g} |")
    for _, r in p.iterrows():
        lines.append(f"| path tracer | {r['x']} spp | {r['time_s']:.2f} | {r[PENUMBRA]:.3g} | |")
    one, last = w.iloc[0], w.iloc[-1]
    floor = float(w[PENUMBRA].min())
    sentences = [
        f"Whitted's shadow noise in the penumbra falls from relMSE {one['noise_rel_mse']:.3g} at 1 light sample "
        f"({one['time_s']:.2f} s) to {last['noise_rel_mse']:.3g} at {last['x']} ({last['time_s']:.2f} s, "
        f"{last['time_s'] / one['time_s']:.0f}× the time): {one['noise_rel_mse'] / last['noise_rel_mse']:.0f}× less "
        f"noise for {last['x']}× the shadow rays."]
    for target in (1e-2, 1e-3):
        t_w = time_to_target(w.rename(columns={"noise_rel_mse": "noise"}), "noise", target)
        t_p = time_to_target(p, PENUMBRA, target)
        reach = w[w["noise_rel_mse"] <= target]
        what = (f"whitted needs {reach.iloc[0]['x']} light samples per hit, {t_w:.2f} s "
                f"({t_w / one['time_s']:.1f}× its 1-sample render)" if len(reach) else
                f"whitted does not get there with {last['x']} light samples ({last['time_s']:.2f} s)")
        pt = (f"the path tracer brings its whole penumbra error (to the reference) there in {t_p:.2f} s"
              if math.isfinite(t_p) else f"the path tracer does not within {p['x'].max()} spp")
        sentences.append(f"Soft shadows are expensive: for shadow noise under relMSE {target:g}, {what}; {pt}.")
    below = p[p[PENUMBRA] <= floor]
    sentences.append(
        f"Whatever the light samples, whitted's penumbra stays at relMSE {floor:.3g} from the reference (its bias: "
        f"no interreflected light, a constant ambient instead)"
        + (f"; the path tracer is below that from {below.iloc[0]['x']} spp ({below.iloc[0]['time_s']:.2f} s)."
           if len(below) else "."))
    return "\n".join(lines), sentences


def missed(fig: dict) -> str:
    """``misses 12.3% ± 0.4%`` of the reference's light, or ``adds ...`` where the share is negative."""
    if not math.isfinite(fig["share"]):
        return "has no figure for"
    verb = "misses" if fig["share"] >= 0 else "adds"
    return f"{verb} {100 * abs(fig['share']):.1f}% ± {100 * fig['share_se']:.1f}%"


def table_findings(figs: dict[str, dict], budget: float) -> list[str]:
    """Sentences from the caustics and cornell-box tables' numbers."""
    c, box = figs["cornell-box-caustics"], figs["cornell-box"]
    modes = ("boolean", "attenuate", "ignore")
    out = []
    cb, ca, ci = (c[(f"whitted {m}, no ambient", "caustic")] for m in modes)
    recovered = (cb["share"] - ca["share"]) / cb["share"] if cb["share"] > 0 else math.nan
    out.append(
        f"The caustic (direct light only, no ambient): with boolean shadow rays whitted {missed(cb)} of the "
        f"reference's light; Pierce's attenuation {missed(ca)}, so it recovers {100 * recovered:.0f}% of what "
        f"boolean loses, and ignoring the glass {missed(ci)}: no shadow rule focuses light, the caustic stays "
        f"missing (ΔE00 {cb['delta_e']:.1f}, {ca['delta_e']:.1f}, {ci['delta_e']:.1f}).")
    gb, ga, gi = (c[(f"whitted {m}, no ambient", "glass-shadow")] for m in modes)
    out.append(
        f"The glass sphere's shadow beside it: boolean {missed(gb)}, attenuate {missed(ga)}, ignore {missed(gi)} "
        f"(ΔE00 {gb['delta_e']:.1f}, {ga['delta_e']:.1f}, {gi['delta_e']:.1f}).")
    pt, pm = c[("path tracer", "caustic")], c[("photonmap", "caustic")]
    out.append(f"In the same time the path tracer {missed(pt)} of the caustic (ΔE00 {pt['delta_e']:.1f}: noise) and "
               f"the photon map {missed(pm)} (ΔE00 {pm['delta_e']:.1f}).")
    n, k, ao = (box[(lab, "walls")] for lab in ("whitted attenuate, no ambient", "whitted attenuate, constant "
                                                 "(default)", "whitted attenuate, ao"))
    out.append(
        f"The ambient term is a hack: on cornell-box's walls whitted without it {missed(n)} of the light (the "
        f"interreflected part); its constant ambient {missed(k)} (ΔE00 {k['delta_e']:.1f}) and ambient occlusion "
        f"{missed(ao)} (ΔE00 {ao['delta_e']:.1f}); the path tracer {missed(box[('path tracer', 'walls')])}.")
    mn, mk = c[("whitted attenuate, no ambient", "mirror")], c[("whitted attenuate, constant (default)", "mirror")]
    out.append(f"Light off the mirror follows the same rules: whitted's mirror sphere {missed(mn)} without ambient "
               f"and {missed(mk)} with the constant one.")
    slow = sorted({f["label"] for fs in figs.values() for f in fs.values()
                   if f["time_s"] > 1.25 * budget and f["spp"] <= 2})
    if slow:
        out.append(f"Over the budget ({budget:g} s) at 1 or 2 spp: {'; '.join(slow)} (its set-up alone takes about "
                   f"the budget; the table's time column says by how much).")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--budget", type=float, default=2.0, help="wall seconds each render gets (default 2)")
    ap.add_argument("--seeds", type=int, default=3, help="seeds 0 .. N-1 per renderer (default 3)")
    ap.add_argument("--light-samples", default="1,2,4,8,16,32,64,128,256",
                    help="whitted's light_samples of the curve")
    ap.add_argument("--pt-spp", default="1,2,4,8,16,32,64,128", help="the path tracer's spp of the curve")
    ap.add_argument("--converged", type=int, default=1024,
                    help="light samples of whitted's converged image (the shadow-noise yardstick; default 1024)")
    ap.add_argument("--page", type=Path, default=ROOT / "docs" / "whitted.md", help="the page written whole")
    ap.add_argument("--images", type=Path, default=ROOT / "docs" / "images", help="folder of the figure")
    args = ap.parse_args()
    started = time.perf_counter()
    tables, figs = {}, {}
    for scene in REGIONS:
        print(f"{scene}: equal time, {args.budget:g} s each, {args.seeds} seeds", flush=True)
        rows, noise = equal_time_rows(scene, args.budget, args.seeds)
        tables[scene], figs[scene] = table_markdown(scene, rows, noise)
    print("the soft-shadow curve", flush=True)
    curve = soft_shadow_curve([int(x) for x in args.light_samples.split(",")],
                              [int(x) for x in args.pt_spp.split(",")], args.converged)
    curve_figure(curve, args.images / "whitted-penumbra.svg")
    curve_table, curve_sentences = curve_findings(curve)
    findings = table_findings(figs, args.budget)
    image = Path("images") / "whitted-penumbra.svg"
    body = PAGE.format(budget=args.budget, seeds=args.seeds, box=tables["cornell-box"],
                       caustics=tables["cornell-box-caustics"], findings="\n".join(f"- {s}" for s in findings),
                       curve=curve_table, curve_findings="\n".join(f"- {s}" for s in curve_sentences),
                       image=image.as_posix(), converged=args.converged, minutes=(time.perf_counter() - started) / 60,
                       command=markdown_blocks.command_line())
    markdown_blocks.write_page(args.page, body)
    print(body)


PAGE = """# Recursive ray tracing and its hacks, measured

Issue 32: `whitted` (`src/cornell_harness/renderers/whitted.py`) is recursive ray tracing as the lecture argues against it: perfect
mirror and glass recursion with Fresnel to `max_depth`, direct light from the area light by `light_samples`
shadow rays per hit, no diffuse interreflection, and an ambient term (`none`, `constant`, `ao`). A shadow ray
that meets glass follows `transparent_shadows`: `boolean` (blocked), `attenuate` (Pierce's shadow attenuation:
straight through, scaled by the Fresnel transmittance at both interfaces) or `ignore`. This page measures what
each of these approximations, and the harness's other ones, gets wrong, region by region.

Written by `{command}` (the whole page; {minutes:.0f} minutes on 2 shared cores).

## What each approximation gets wrong

At equal time: every renderer gets {budget:g} s of wall time per render, its spp chosen from calibration
renders as `cbox compare --time-budget` chooses it (3 rounds, medians; seed 0); then {seeds} seeds each. The
machine (2 cores) was shared with other work, so the times scatter around the budget: the table gives each
column's spp and median time. Whitted's shadow rules are compared without an ambient term, so the light in a
region is the rule's alone; its ambient terms with the default rule, `attenuate`. Per region:

- **light missing**: 1 − mean(renderer) / mean(reference) of the region's mean radiance (negative: light
  added), from the results rows' `region.<name>.mean_radiance_rel_error`;
- **bias of the mean**: mean(renderer) − mean(reference), radiance;
- each ± one standard error **over the seeds** (their spread, plus the reference's own error from its
  per-pixel variance; `src/cornell_harness/evaluate/missing_light.py`); a renderer whose image does not change with the
  seed has only the reference's;
- **ΔE00 mean**: the region's mean CIEDE2000 (`region.<name>.delta_e2000_mean`), mean over seeds.

Regions are the scenes' own, plus the study's (`src/cornell_harness/evaluate/missing_light.py`, not written into the
scene files, whose region lists other tests and the gate pin; regions are not in the content hash): on
`cornell-box-caustics` `floor` and `back-edge` (as on `cornell-box`), and on `cornell-box` `penumbra`, the floor
pixels whose centre sees more than 5% and less than 95% of the light's area: the boxes' soft shadow edges.

### cornell-box

{box}

### cornell-box-caustics

{caustics}

### Findings

{findings}

## Soft shadows are expensive

`cornell-box`'s penumbra: relMSE in the region against the reference, for `whitted[light_samples=N]` at 1 spp,
and the same region's relMSE against whitted's own converged image ({converged} light samples, the same seed,
so the same camera rays): the shadow noise alone. The N-sample image shares its N light samples with the
converged one, so that relMSE is (1 − N/{converged}) of the N-sample image's noise (0.75 at 256). Beside it
the path tracer at 1, 2, 4, ... spp. One seed per point; a point's time is the median wall time of 3 renders.

![penumbra relMSE against time]({image})

{curve}

{curve_findings}
"""


if __name__ == "__main__":
    main()

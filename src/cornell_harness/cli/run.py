"""``cbox render``, ``cbox compare`` (equal spp, equal time, equal quality) and ``cbox demo``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.adapters.registry import RendererError, missing_features, resolve
from cornell_harness.adapters.settings import canonical
from cornell_harness.cli.common import (RendererFilesOpt, RenderersOpt, SceneOpt, SeedOpt, SetOpt, SppOpt,
                                        TimeLimitOpt, TitleOpt, app, check_output_file, command_line, out_folder_option, render_failed)
from cornell_harness.cli.figures import CropOpt, SeriesLabelOpt, keep_report_options, parse_crops, series_labels_for
from cornell_harness.cli.output import Progress, info
from cornell_harness.cli.timing import CompareTimeBasisOpt, time_repeats_option, warn_contention
from cornell_harness.extras import require_a_renderer
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.exr import write_exr
from cornell_harness.store.image_files import SPP_ATTRIBUTE
from cornell_harness.store.references import load_reference
# Heavy modules (SciPy, pandas, the report) are imported inside the commands that use them: `cbox gate` on
# a misspelt config, or `cbox --help`, must answer in a second.

#: The metrics of the table `cbox compare` (and `cbox compare-image`) prints, those a row has.
TABLE_METRICS = ("delta_e2000_mean", "noise_delta_e2000_mean", "flip_mean", "ssim", "rel_mse",
                 "mean_radiance_rel_error", "nan_count")


@app.command()
def render(
    scene: str = SceneOpt,
    overrides: Optional[List[str]] = SetOpt,
    renderer: str = typer.Option(..., "--renderer", "-r", help="Registered renderer name or package.module:ClassName, "
                                                             "with settings as NAME\\[setting=value,...]."),
    renderer_files: Optional[List[Path]] = RendererFilesOpt,
    spp: int = SppOpt,
    seed: int = SeedOpt,
    out: Path = typer.Option(..., "--out", "-o", help="Output OpenEXR file (float32 linear sRGB); its name must "
                                                      "end in .exr (other formats are refused, not converted)."),
    time_limit: Optional[str] = TimeLimitOpt,  # seconds (float), by the option's callback
    variance_out: Optional[Path] = typer.Option(None, "--variance-out", help="Also write the per-pixel variance of "
                                                "the image (of the mean, float32 EXR, per channel) where the renderer "
                                                "gives one; one line says so where it does not, and no file is written."),
) -> None:
    """Render one scene with one renderer and write the HDR image (and, with --variance-out, its variance).

    Exit code 1, with one line saying why, if the render fails (the renderer raised, or passed --time-limit)."""
    check_output_file(out)  # before any rendering: .exr, not a folder, writable
    if variance_out is not None:
        check_output_file(variance_out, "--variance-out")
        if Path(variance_out).resolve() == Path(out).resolve():
            raise typer.BadParameter(f"{variance_out}: is the --out file too; give the variance a name of its own",
                                     param_hint="--variance-out")
    sc = resolve_scene(scene, overrides)
    (entry,) = resolve([renderer])
    if not entry.available:
        raise RendererError(f"renderer {entry.name!r} is unavailable: {entry.reason}")
    if missing := missing_features(entry.renderer, sc):
        raise RendererError(f"renderer {entry.name!r} does not model {', '.join(missing)}, which {sc.name} uses")
    from cornell_harness.workflows.runner import render_timed

    with render_failed(entry.name):
        result, _ = render_timed(entry.with_time_limit(time_limit), sc, spp, seed)
    meta = {"cbox:renderer": entry.name, "cbox:settings": canonical(entry.settings), SPP_ATTRIBUTE: str(spp),
            "cbox:seed": str(seed), "cbox:scene_hash": sc.content_hash()}
    write_exr(out, result.image, meta)
    info(f"wrote {out} ({sc.camera.width}x{sc.camera.height}, {spp} spp, {result.time_s:.2f} s)")
    if variance_out is None:
        return
    if result.variance is None:
        # Not info(): asked for a file that is not there, the user must hear why, even with --quiet.
        typer.echo(f"cbox: no variance written: renderer {entry.name!r} reports no variance of its image "
                   f"at {spp} spp, so {variance_out} was not written", err=True)
        return
    write_exr(variance_out, result.variance, {**meta, "cbox:quantity": "variance of the mean"})
    info(f"wrote {variance_out} (per-pixel variance of the image's mean)")


def write_compare_outputs(out: Path, sc, ref, records, command: str, sections=(), title=None,
                          time_basis: str = "wall", time_repeats: int = 1) -> Path:
    """Store a comparison as an experiment folder (results, images, CSV/JSON) and build its report."""
    from cornell_harness.workflows.compare import store_comparison
    from cornell_harness.workflows.converge import experiment_results
    from cornell_harness.reports.experiment import write_experiment_report

    store_comparison(out, sc, records, command, time_basis, time_repeats)
    results = experiment_results(out, sc, ref, summary_dir=out)
    return write_experiment_report(out, sc, ref, results=results, sections=sections, title=title)


def _run_compare(scene: str, renderer: Optional[List[str]], spp: int, seed: int, out: Path, as_json: bool,
                 time_budget: Optional[str] = None, target_error: Optional[str] = None, max_spp: int = 4096,
                 sections=(), overrides: Optional[List[str]] = None, title: Optional[str] = None,
                 time_repeats: Optional[int] = None, time_basis: str = "wall", series_label: Optional[List[str]] = None,
                 crop: Optional[List[str]] = None, time_limit: float | None = None) -> tuple[int, list, object, object]:
    """``cbox compare``'s body (and each of ``cbox demo``'s comparisons): the options parsed, the comparison run
    (:func:`cornell_harness.workflows.compare.run_comparison`), its folder and report written, its table
    printed; (exit code, run records, scene, reference)."""
    from cornell_harness.workflows import compare as cmp
    from cornell_harness.workflows import runner

    comparison = _comparison(scene, overrides, renderer, spp, seed, time_budget, target_error, max_spp,
                             time_repeats, time_basis, time_limit)
    sc, ref = comparison.scene, comparison.reference
    keep_report_options(out, series_labels_for(series_label, [e.name for e in comparison.entries]),
                        parse_crops(crop, sc.camera.width, sc.camera.height))
    bar = Progress(comparison.renders, f"{sc.name} @ {comparison.mode}", "render")
    streamed = as_json and comparison.repeats == 1  # each record as it finishes; with repeats, once all are in
    records = cmp.run_comparison(comparison, on_start=bar.start, on_render=bar.advance, on_record=(
        lambda rec: bar.write(json.dumps(runner.json_record(rec), allow_nan=False))) if streamed else None)
    if as_json and not streamed:
        for rec in records:
            bar.write(json.dumps(runner.json_record(rec), allow_nan=False))
    bar.close()
    warn_contention(runner.rows_frame(records))
    report = write_compare_outputs(out, sc, ref, records, command_line(), sections=sections, title=title,
                                   time_basis=comparison.time_basis, time_repeats=comparison.repeats)
    if not as_json:
        typer.echo(compare_table([r.row() for r in records], comparison.time_basis, time_basis == "auto"))
        for r in records:
            if r.status != "ok":
                typer.echo(f"{r.renderer}: {r.status}: {r.reason}")
    info(f"report: {report}")
    return (1 if any(r.status == "failed" for r in records) else 0), records, sc, ref


def _parsed(parse, text: Optional[str], option: str):
    """``parse(text)``, None without the option; a ValueError is a usage error naming ``option``. An empty
    value is parsed too (and refused), not taken for the option's absence."""
    if text is None:
        return None
    try:
        return parse(text)
    except ValueError as e:
        raise typer.BadParameter(str(e), param_hint=option) from None


def _comparison(scene: str, overrides, renderer, spp: int, seed: int, time_budget: Optional[str],
                target_error: Optional[str], max_spp: int, time_repeats: Optional[int], time_basis: str,
                time_limit: float | None):
    """The comparison the options ask for (:class:`cornell_harness.workflows.compare.Comparison`): a bad
    --time-budget or --target-error is a usage error; with ``time_limit`` every render is ended at it."""
    from cornell_harness.evaluate.convergence import parse_target
    from cornell_harness.durations import parse_duration
    from cornell_harness.workflows.compare import Comparison, default_time_repeats

    budget = _parsed(parse_duration, time_budget, "--time-budget")
    target = _parsed(parse_target, target_error, "--target-error")
    sc = resolve_scene(scene, overrides)
    entries = [e.with_time_limit(time_limit) for e in resolve(renderer)]
    return Comparison(sc, load_reference(sc), entries, spp, seed, budget, target, max_spp,
                      time_repeats or default_time_repeats(budget, target), time_basis)


def compare_table(rows: list[dict], time_basis: str = "wall", auto: bool = False) -> str:
    """The table ``cbox compare`` prints: per renderer its status, spp, time and scores; an spp chosen for a
    time budget and a time taken more than once show their 95% intervals, ``412 [380, 440]``, with a line
    saying what they are; and a line naming the ``time_basis`` used (chosen by ``--time-basis auto`` when
    ``auto``). With the cpu basis, CPU time (``cpu_time_s``) beside wall time."""
    import pandas as pd

    frame = pd.DataFrame(rows)
    times = ("time_s", "cpu_time_s") if time_basis == "cpu" else ("time_s",)
    cols = [c for c in ("renderer", "status", "spp", *times, *TABLE_METRICS, "agreement", "info_target_reached")
            if c in frame]
    shown = frame[cols].copy()
    notes = []
    if "info_spp_low" in frame and frame["info_spp_low"].notna().any():
        shown["spp"] = [_with_interval(s, lo, hi, "{:.0f}") for s, lo, hi in
                        zip(frame["spp"], frame["info_spp_low"], frame["info_spp_high"])]
        notes.append("spp [95% interval of what the time budget buys, from its calibration rounds]")
    for col in times:
        if col in frame and f"{col}_low" in frame and frame[f"{col}_low"].notna().any():
            shown[col] = [_with_interval(t, lo, hi, "{:.3g}") for t, lo, hi in
                          zip(frame[col], frame[f"{col}_low"], frame[f"{col}_high"])]
            notes.append(f"{col}: median of {int(frame['time_repeats'].max())} timings [95% interval]")
    notes.append(_basis_note(time_basis, auto, "info_time_budget_s" in frame))
    return shown.to_string(index=False) + "".join(f"\n{n}" for n in notes)


def _basis_note(time_basis: str, auto: bool, budget: bool) -> str:
    """The table's line naming the clock: ``time basis: cpu, the budget and times in CPU seconds (...)``."""
    clock = "CPU seconds (cpu_time_s)" if time_basis == "cpu" else "wall seconds (time_s)"
    renders = "calibration renders" if budget else "timed renders"
    why = "" if not auto else (f" (--time-basis auto: other processes took cores from the {renders})"
                               if time_basis == "cpu" else f" (--time-basis auto: no other work beside the {renders})")
    return f"time basis: {time_basis}, {'the budget and ' if budget else ''}times in {clock}{why}"


def _with_interval(value, low, high, fmt: str) -> str:
    """``412 [380, 440]``; the value alone where there is no interval (one timing, a run that did not run)."""
    import math

    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "NaN"
    if low is None or high is None or math.isnan(float(low)) or math.isnan(float(high)):
        return fmt.format(value)
    return f"{fmt.format(value)} [{fmt.format(low)}, {fmt.format(high)}]"


@app.command()
def compare(
    scene: str = SceneOpt,
    overrides: Optional[List[str]] = SetOpt,
    renderer: Optional[List[str]] = RenderersOpt,
    renderer_files: Optional[List[Path]] = RendererFilesOpt,
    spp: int = SppOpt,
    seed: int = SeedOpt,
    out: Path = out_folder_option(Path("out"), "Folder for report.html, metrics.csv, metrics.json, "
                                                               "results.parquet and the images."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON record per run on stdout."),
    time_budget: Optional[str] = typer.Option(
        None, "--time-budget", help="Equal-time mode: every renderer gets this time (e.g. 10s, 2m; wall seconds, "
                                    "CPU seconds with --time-basis cpu, or auto on a busy machine); its spp is chosen from two short "
                                    "calibration renders (1 and 4 spp), --time-repeats rounds of them "
                                    "interleaved over the renderers, and reported with a 95% interval "
                                    "(info_spp_low/high). Overrides --spp."),
    target_error: Optional[str] = typer.Option(
        None, "--target-error", help="Equal-quality mode: METRIC=VALUE (e.g. delta_e2000_mean=1, rel_mse=1e-3; "
                                     "a bare number means ΔE mean). Each renderer renders at 1, 2, 4, ... spp "
                                     "until the metric is at most VALUE and reports the time it needed (that "
                                     "render timed --time-repeats times)."),
    max_spp: int = typer.Option(4096, "--max-spp", min=1, help="Upper spp limit of --target-error."),
    time_repeats: Optional[int] = time_repeats_option("default 3 with --time-budget or --target-error, else 1"),
    time_basis: str = CompareTimeBasisOpt,
    title: Optional[str] = TitleOpt,
    series_label: Optional[List[str]] = SeriesLabelOpt,
    crop: Optional[List[str]] = CropOpt,
    time_limit: Optional[str] = TimeLimitOpt,  # seconds (float), by the option's callback
) -> None:
    """Render with each renderer, score against the scene's reference, write a report.

    Exit code 1 if a renderer failed; renderers that are unavailable or do not
    model the scene are listed as such and are not failures.
    """
    if time_budget is not None and target_error is not None:
        raise typer.BadParameter("give --time-budget or --target-error, not both")
    raise typer.Exit(_run_compare(scene, renderer, spp, seed, out, as_json, time_budget, target_error, max_spp,
                                  overrides=overrides, title=title, time_repeats=time_repeats,
                                  time_basis=time_basis, series_label=series_label, crop=crop,
                                  time_limit=time_limit)[0])


#: The scenes of ``cbox demo``: a convergence run on the first, whose report leads; each other one is a
#: comparison at the highest spp, a section of that report (in full in a subfolder).
DEMO_SCENES = ("cornell-box", "cornell-box-caustics")


def demo_checkpoints(spp: int) -> list[int]:
    """1, 4, 16, ... up to ``spp`` (and ``spp`` itself): powers of 4 give a slope from a few points, and a
    renderer that is not progressive renders 1.33x its top spp in all instead of 2x with powers of 2."""
    out = [1]
    while out[-1] * 4 <= spp:
        out.append(out[-1] * 4)
    return out if out[-1] == spp else out + [spp]


#: The Whitted variants ``cbox demo`` adds to its caustics comparison, for the section "Recursive ray tracing and
#: its hacks" (src/cornell_harness/reports/whitted.py): each shadow rule for glass, and no ambient term.
DEMO_WHITTED = ("transparent_shadows=boolean", "transparent_shadows=attenuate", "transparent_shadows=ignore",
                "ambient=none")


#: The headline of docs/spectral.md (``benchmarks/spectral.py``), which ``cbox demo`` ends with: the
#: demo renders the RGB box, and this is how far RGB rendering is from the measured, spectral one. A test keeps it
#: equal to the figures in docs/spectral.md.
SPECTRAL_HEADLINE = ("the real Cornell box rendered in RGB (cornell-box-measured, docs/spectral.md): mean ΔE00 8.69 "
                     "per pixel against the spectral reference with mi.cornell_box()'s reflectances, 0.78 with "
                     "reflectances white-balanced to its light; noise floor 0.82")


def demo_caustics_renderers(renderer: Optional[List[str]]) -> List[str]:
    """The caustics comparison's renderers: the demo's (all when none are named; the plain ``whitted`` then
    gives way to its variants) and the :data:`DEMO_WHITTED` variants."""
    from cornell_harness.adapters.registry import declared_commands, registered_names

    names = list(renderer) if renderer else [n for n in [*registered_names(), *declared_commands()] if n != "whitted"]
    return names + [f"whitted[{s}]" for s in DEMO_WHITTED if f"whitted[{s}]" not in names]


@app.command()
def demo(
    out: Path = out_folder_option(Path("out"), "Folder for report.html, results.parquet and summary.parquet, "
                                               ".csv, .tex (the caustics comparison in a subfolder named after "
                                               "its scene)."),
    spp: int = typer.Option(64, "--spp", min=1, help="Highest spp: cornell-box converges at 1, 4, 16, ... up to "
                                                   "it, and cornell-box-caustics is compared at it."),
    seeds: int = typer.Option(2, "--seeds", min=1, help="Seeds of the convergence run (bias and variance need 2)."),
    renderer: Optional[List[str]] = RenderersOpt,
    renderer_files: Optional[List[Path]] = RendererFilesOpt,
) -> None:
    """What the tool is for, in about four minutes on 2 cores once scripts/setup.sh has compiled the kernels
    (it prints its time): every available
    renderer converging on cornell-box (error against spp and time, speed/accuracy, bias and variance) and compared on
    cornell-box-caustics (mirror and glass) → out/report.html, the caustics as a section of it, with the
    Whitted variants against the others per region in "Recursive ray tracing and its hacks"."""
    import time

    from cornell_harness.cli.experiment import print_summary, run_convergence
    from cornell_harness.evaluate.missing_light import study_columns, study_masks
    from cornell_harness.evaluate.regions import region_noise
    from cornell_harness.reports.scenes import scene_section
    from cornell_harness.reports.whitted import TITLE, whitted_section

    if not renderer and not renderer_files:
        require_a_renderer("cbox demo")
    started = time.perf_counter()
    sections, code = [], 0
    for name in DEMO_SCENES[1:]:
        sub_code, records, sc, ref = _run_compare(name, demo_caustics_renderers(renderer), spp, 0, out / name, False)
        code = max(code, sub_code)
        images = {r.renderer: r.image for r in records if r.status == "ok" and r.image is not None}
        sections.append((name, sc.name, scene_section(sc, ref.image, [r.row() for r in records], images,
                                                      f"{name}/report.html")))
        # The Whitted variants against the others, also in the study's regions the scene does not declare.
        masks = study_masks(sc)
        rows = [{**r.row(), **(study_columns(sc, r.image, ref, r.spp, masks) if r.image is not None else {})}
                for r in records]
        noise = region_noise(ref.image, ref.variance, masks)
        sections.append((f"{name}-whitted", TITLE, whitted_section(rows, noise, sc.name)))
    sc = resolve_scene(DEMO_SCENES[0])
    runs, report = run_convergence(out, sc, load_reference(sc), resolve(renderer), demo_checkpoints(spp), seeds,
                                   sections=sections)
    print_summary(out, runs)
    info(f"report: {report}")
    info(SPECTRAL_HEADLINE)
    info(f"demo: {_minutes(time.perf_counter() - started)} in all")
    raise typer.Exit(max(code, 1 if (runs["status"] == "failed").any() else 0))


def _minutes(seconds: float) -> str:
    """``M:SS`` (wall time, as a user reads a clock)."""
    whole = int(round(seconds))
    return f"{whole // 60}:{whole % 60:02d}"

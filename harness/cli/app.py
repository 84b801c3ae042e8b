"""``cbox``: the command-line interface.

Bad input (a malformed scene, an unknown renderer, a stale reference) ends with
a one-line ``cbox: error: ...`` on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import dataclasses
import json
import shlex
import sys
from pathlib import Path
from typing import List, Optional

import typer
from tqdm import tqdm

from harness.adapters.registry import RendererError, missing_features, resolve
from harness.adapters.settings import SettingsError, canonical, declared, describe
from harness.gate.config import GateConfigError
from harness.scenes.library import resolve_scene, scene_names
from harness.scenes.model import FEATURES, SceneError
from harness.store.experiments import CONFIG_FILE, SUMMARY_FILE, ExperimentError, load_results
from harness.store.exr import ImageFileError, write_exr
from harness.store.references import ReferenceError, load_reference
from harness.workflows import runner
from reports.experiment import write_experiment_report

#: The harness's reference renderer: references are built with it.
REFERENCE_RENDERER = "mitsuba"

app = typer.Typer(
    help="Validation harness for renderers on the Cornell box: render, score against a trusted reference, report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
reference_app = typer.Typer(help="Build and inspect stored reference images.", no_args_is_help=True)
app.add_typer(reference_app, name="reference")

USER_ERRORS = (SceneError, ReferenceError, RendererError, ImageFileError, ExperimentError, GateConfigError,
               SettingsError)

SceneOpt = typer.Option(..., "--scene", "-s", help="Stored scene name (see `cbox scenes`) or path to a scene .toml file or folder.")
SppOpt = typer.Option(64, "--spp", min=1, help="Samples per pixel.")
SeedOpt = typer.Option(0, "--seed", min=0, help="Random seed; the same seed gives the same image.")


def _command_line() -> str:
    return " ".join(shlex.quote(a) for a in ["cbox", *sys.argv[1:]])


def _progress(total: int, desc: str) -> tqdm:
    return tqdm(total=total, desc=desc, unit="run", file=sys.stderr, dynamic_ncols=True, leave=False)


@app.command()
def scenes() -> None:
    """List the stored scenes, with the features each uses and whether it has a reference."""
    for name in scene_names():
        try:
            scene = resolve_scene(name)
        except SceneError as e:
            typer.echo(f"{name:16s} INVALID: {e}")
            continue
        try:
            ref = load_reference(scene)
            status = f"reference {ref.spp} spp"
        except ReferenceError as e:
            status = f"no usable reference ({str(e).split(';')[0].split(': ', 1)[-1]})"
        cam = scene.camera
        typer.echo(f"{name:16s} {cam.width}x{cam.height}  max_depth={scene.max_depth}  {status}")
        typer.echo(f"{'':16s} features: {', '.join(sorted(scene.features))}")


@app.command()
def renderers(
    settings: bool = typer.Option(False, "--settings", help="Also list each renderer's settings: name, default, "
                                                            "allowed values and what it does."),
) -> None:
    """List the registered renderers, whether each can run here, and why not."""
    for entry in resolve(None):
        r = entry.renderer
        if entry.available:
            try:
                version = r.version()
            except Exception as e:  # a version probe must not break the listing
                version = f"version unknown ({type(e).__name__})"
            typer.echo(f"{entry.name:12s} available    {version}")
        else:
            typer.echo(f"{entry.name:12s} unavailable  {entry.reason}")
        if r is not None:
            typer.echo(f"{'':12s} models: {', '.join(sorted(r.features))}")
            for a in getattr(r, "approximations", ()):
                typer.echo(f"{'':12s} approximates: {a}")
            if settings:
                for line in describe(declared(r)) or ["(no settings)"]:
                    typer.echo(f"{'':12s} setting: {line}")


@app.command()
def features() -> None:
    """List the scene features a scene can declare and a renderer can model."""
    for name, meaning in FEATURES.items():
        typer.echo(f"{name:16s} {meaning}")


@app.command()
def render(
    scene: str = SceneOpt,
    renderer: str = typer.Option(..., "--renderer", "-r", help="Registered renderer name or package.module:ClassName, "
                                                             "with settings as NAME[setting=value,...]."),
    spp: int = SppOpt,
    seed: int = SeedOpt,
    out: Path = typer.Option(..., "--out", "-o", help="Output OpenEXR file (float32 linear sRGB)."),
) -> None:
    """Render one scene with one renderer and write the HDR image."""
    sc = resolve_scene(scene)
    (entry,) = resolve([renderer])
    if not entry.available:
        raise RendererError(f"renderer {entry.name!r} is unavailable: {entry.reason}")
    if missing := missing_features(entry.renderer, sc):
        raise RendererError(f"renderer {entry.name!r} does not model {', '.join(missing)}, which {sc.name} uses")
    result = runner.render_checked(entry, sc, spp, seed)
    write_exr(out, result.image, {"cbox:renderer": entry.name, "cbox:settings": canonical(entry.settings), "cbox:spp": str(spp), "cbox:seed": str(seed),
                                  "cbox:scene_hash": sc.content_hash()})
    typer.echo(f"wrote {out} ({sc.camera.width}x{sc.camera.height}, {spp} spp, {result.time_s:.2f} s)", err=True)


def _write_compare_outputs(out: Path, sc, ref, records, command: str, sections=(), title=None) -> Path:
    """Store a comparison as an experiment folder (results, images, CSV/JSON) and build its report."""
    from harness.workflows.compare import store_comparison

    store_comparison(out, sc, records, command)
    return write_experiment_report(out, sc, ref, sections=sections, title=title)


def _run_compare(scene: str, renderer: Optional[List[str]], spp: int, seed: int, out: Path, as_json: bool,
                 time_budget: Optional[str] = None, target_error: Optional[str] = None, max_spp: int = 4096) -> int:
    from harness.evaluate.convergence import parse_target
    from harness.workflows import compare as cmp

    try:
        budget = cmp.parse_duration(time_budget) if time_budget else None
        target = parse_target(target_error) if target_error else None
    except ValueError as e:
        raise typer.BadParameter(str(e)) from None
    sc = resolve_scene(scene)
    ref = load_reference(sc)
    entries = resolve(renderer)
    mode = f"{budget:g} s each" if budget else f"to {target[0]}<={target[1]:g}" if target else f"{spp} spp"
    bar = _progress(len(entries), f"{sc.name} @ {mode}")
    records = []
    for entry in entries:
        bar.set_postfix_str(entry.name)
        runnable = entry.available and not missing_features(entry.renderer, sc)
        if budget and runnable:
            rec = runner.run_one(entry, sc, cmp.spp_for_time_budget(entry, sc, budget, seed), seed, ref)
            rec.info["time_budget_s"] = budget
        elif target and runnable:
            rec = cmp.render_to_target(entry, sc, ref, target[0], target[1], seed, max_spp)
        else:
            rec = runner.run_one(entry, sc, spp, seed, ref)
        records.append(rec)
        bar.update(1)
        if as_json:
            typer.echo(json.dumps(runner.json_safe(rec.row()), allow_nan=False))
    bar.close()
    report = _write_compare_outputs(out, sc, ref, records, _command_line())
    if not as_json:
        import pandas as pd

        frame = pd.DataFrame([r.row() for r in records])
        cols = [c for c in ("renderer", "status", "spp", "time_s", "delta_e2000_mean", "noise_delta_e2000_mean",
                            "ssim", "rel_mse", "mean_radiance_rel_error", "nan_count", "info_target_reached")
                if c in frame]
        typer.echo(frame[cols].to_string(index=False))
        for r in records:
            if r.status != "ok":
                typer.echo(f"{r.renderer}: {r.status}: {r.reason}")
    typer.echo(f"report: {report}", err=True)
    return 1 if any(r.status == "failed" for r in records) else 0


@app.command()
def compare(
    scene: str = SceneOpt,
    renderer: Optional[List[str]] = typer.Option(
        None, "--renderer", "-r", help="Renderer to run (repeatable), with settings as "
                                          "NAME[setting=value,...]; default: every registered renderer."),
    spp: int = SppOpt,
    seed: int = SeedOpt,
    out: Path = typer.Option(Path("out"), "--out", "-o", help="Folder for report.html, metrics.csv, metrics.json, "
                                                               "results.parquet and the images."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON record per run on stdout."),
    time_budget: Optional[str] = typer.Option(
        None, "--time-budget", help="Equal-time mode: every renderer gets this wall time (e.g. 10s, 2m); "
                                    "its spp is chosen from two short calibration renders and reported. "
                                    "Overrides --spp."),
    target_error: Optional[str] = typer.Option(
        None, "--target-error", help="Equal-quality mode: METRIC=VALUE (e.g. delta_e2000_mean=1, rel_mse=1e-3; "
                                     "a bare number means ΔE mean). Each renderer renders at 1, 2, 4, ... spp "
                                     "until the metric is at most VALUE and reports the time it needed."),
    max_spp: int = typer.Option(4096, "--max-spp", min=1, help="Upper spp limit of --target-error."),
) -> None:
    """Render with each renderer, score against the scene's reference, write a report.

    Exit code 1 if a renderer failed; renderers that are unavailable or do not
    model the scene are listed as such and are not failures.
    """
    if time_budget and target_error:
        raise typer.BadParameter("give --time-budget or --target-error, not both")
    raise typer.Exit(_run_compare(scene, renderer, spp, seed, out, as_json, time_budget, target_error, max_spp))


@app.command()
def converge(
    scene: str = SceneOpt,
    renderer: Optional[List[str]] = typer.Option(
        None, "--renderer", "-r", help="Renderer to run (repeatable), with settings as "
                                          "NAME[setting=value,...]; default: every registered renderer."),
    spp: str = typer.Option("1,2,4,...,256", "--spp", help="spp checkpoints: 1,2,4,...,256 or 1,4,16 or 1-256 "
                                                         "(powers of two). Progressive renderers give them all "
                                                         "from one render."),
    seeds: int = typer.Option(4, "--seeds", min=1, help="Number of seeds (0 .. N-1); bias and variance need 2 or more."),
    out: Path = typer.Option(Path("out/converge"), "--out", "-o", help="Experiment folder: results.parquet, "
                                                                      "summary.csv, report.html, cells/, images/."),
    target: Optional[List[str]] = typer.Option(
        None, "--target", help="Target error for the time-to-target figure, METRIC=VALUE (repeatable); default: "
                               "delta_e2000_mean=2, delta_e2000_mean=1, rel_mse=0.01, rel_mse=0.001."),
    sweep: Optional[str] = typer.Option(
        None, "--sweep", help="Sweep one renderer setting, RENDERER.SETTING=V1,V2,... (e.g. "
                              "pathtracer.rr_depth=3,5,8): each value is its own series in the table and report. "
                              "See `cbox renderers --settings`."),
) -> None:
    """Convergence experiment: every metric at every spp checkpoint, per renderer and seed.

    Results are a tidy table (one row per scene, renderer, settings, seed and
    spp) in OUT/results.parquet. The run is resumable: finished (renderer,
    seed) cells are written atomically, and running the same command again
    renders only the cells that are missing.
    """
    from harness.adapters.registry import sweep as sweep_entries
    from harness.adapters.settings import parse_sweep
    from harness.evaluate.convergence import DEFAULT_TARGETS, parse_target
    from harness.workflows.converge import parse_spp_list, run_experiment

    try:
        spps = parse_spp_list(spp)
        targets = [parse_target(t) for t in target] if target else DEFAULT_TARGETS
    except ValueError as e:
        raise typer.BadParameter(str(e)) from None
    sc = resolve_scene(scene)
    ref = load_reference(sc)
    entries = resolve(renderer)
    if sweep:
        entries = sweep_entries(entries, *parse_sweep(sweep))
    runnable = [e for e in entries if e.available and not missing_features(e.renderer, sc)]
    cells = sum(1 if getattr(e.renderer, "deterministic", False) else seeds for e in runnable)
    bar = tqdm(total=cells, desc=f"converge {sc.name}", unit="cell", file=sys.stderr,
               dynamic_ncols=True)

    def on_cell(name: str, cached: bool) -> None:
        bar.set_postfix_str(f"{name}{' (stored)' if cached else ''}")
        bar.update(1)

    runs = run_experiment(out, sc, ref, entries, spps, list(range(seeds)), _command_line(), on_cell=on_cell,
                          targets=targets)
    bar.close()
    report = write_experiment_report(out, sc, ref)
    if (out / SUMMARY_FILE).exists():
        import pandas as pd

        summary = pd.read_csv(out / SUMMARY_FILE)
        typer.echo(summary.to_string(index=False, float_format=lambda v: f"{v:.4g}"))
    for _, r in runs[runs["status"] != "ok"].iterrows():
        typer.echo(f"{r['renderer']}: {r['status']}: {r['reason']}")
    typer.echo(f"report: {report}", err=True)
    raise typer.Exit(1 if (runs["status"] == "failed").any() else 0)


@app.command()
def report(
    folder: Path = typer.Argument(..., help="Folder written by cbox converge or cbox compare."),
) -> None:
    """Rebuild FOLDER/report.html (and summary.csv) from stored results, without rendering."""
    config, _ = load_results(folder)
    sc = resolve_scene(config["scene"])
    if sc.content_hash() != config["scene_hash"]:
        raise ExperimentError(
            f"{folder / CONFIG_FILE}: results were made for scene hash {config['scene_hash']}, but "
            f"{config['scene']} now hashes to {sc.content_hash()}; rerun the experiment")
    typer.echo(f"report: {write_experiment_report(folder, sc, load_reference(sc))}", err=True)


@app.command()
def demo(
    out: Path = typer.Option(Path("out"), "--out", "-o", help="Folder for report.html and metrics.csv."),
    spp: int = typer.Option(64, "--spp", min=1, help="Samples per pixel for every renderer."),
    seed: int = SeedOpt,
) -> None:
    """The main job: every available renderer on cornell-box against the stored reference → out/report.html."""
    raise typer.Exit(_run_compare("cornell-box", None, spp, seed, out, False))


@app.command()
def gate(
    config: Path = typer.Option(Path("gate.toml"), "--config", "-c", help="Gate config (TOML): expectations per "
                                                                        "scene, renderer and budget; see harness/gate/checks.py."),
    out: Path = typer.Option(Path("out/gate"), "--out", "-o", help="Folder for report.html, gate-junit.xml and "
                                                                  "gate-summary.md."),
    junit: Optional[Path] = typer.Option(None, "--junit", help="JUnit XML path (default OUT/gate-junit.xml)."),
    markdown: Optional[Path] = typer.Option(None, "--markdown", help="Markdown summary path (default "
                                                                    "OUT/gate-summary.md); also appended to "
                                                                    "$GITHUB_STEP_SUMMARY when that is set."),
    update_baseline: bool = typer.Option(False, "--update-baseline", help="Record this run's metrics as the "
                                                                          "baseline named in the config."),
) -> None:
    """CI quality gate: exit 0 if every expectation holds, 1 if one fails, 2 for a bad config or input.

    Unbiased renderers are tested for statistical agreement with the reference
    (tiled z-tests, family-wise false-alarm rate alpha); others against metric
    budgets; all must have zero NaN/Inf pixels; optionally, convergence slopes
    and regressions against a recorded baseline.
    """
    import os

    from harness.gate import run as gate_run
    from harness.gate.config import load_config
    from harness.store.atomic import write_text_atomic
    from reports.ci import junit_xml, markdown_summary
    from reports.gate import gate_section

    cfg = load_config(config)
    bar = tqdm(total=len(cfg.expectations), desc="gate", unit="check", file=sys.stderr, dynamic_ncols=True)

    def started(exp) -> None:
        bar.set_postfix_str(exp.name)

    outcomes = gate_run.run_gate(cfg, on_start=started)
    bar.update(len(cfg.expectations))
    bar.close()
    if update_baseline:
        typer.echo(f"baseline: {gate_run.write_baseline(cfg, outcomes)}", err=True)
        outcomes = [dataclasses.replace(o, checks=[c for c in o.checks if not c.name.startswith("baseline.")])
                    for o in outcomes]
    md = markdown_summary(outcomes, cfg.alpha)
    write_text_atomic(junit or out / "gate-junit.xml", junit_xml(outcomes))
    write_text_atomic(markdown or out / "gate-summary.md", md)
    if os.environ.get("GITHUB_STEP_SUMMARY"):
        with open(os.environ["GITHUB_STEP_SUMMARY"], "a") as f:
            f.write(md)
    scenes = list(dict.fromkeys(o.expectation.scene for o in outcomes))
    for scene_name in scenes:
        mine = [o for o in outcomes if o.expectation.scene == scene_name]
        folder = out if len(scenes) == 1 else out / Path(scene_name).stem
        sc = resolve_scene(scene_name)
        report = _write_compare_outputs(folder, sc, load_reference(sc), [o.record for o in mine], _command_line(),
                                        sections=[("gate", "Gate", gate_section(mine, cfg.alpha))],
                                        title=f"cbox gate — {sc.name}")
        typer.echo(f"report: {report}", err=True)
    for o in outcomes:
        for c in o.checks:
            typer.echo(f"{'PASS' if c.passed else 'FAIL'}  {o.expectation.name}  {c.name}: {c.message}")
    failed = sum(not c.passed for o in outcomes for c in o.checks)
    typer.echo(f"gate {'passed' if not failed else f'failed: {failed} check(s)'}")
    raise typer.Exit(1 if failed else 0)


@app.command()
def stress(
    renderer: Optional[List[str]] = typer.Option(
        None, "--renderer", "-r", help="Renderer to stress (repeatable); default: every registered renderer."),
    variant: Optional[List[str]] = typer.Option(
        None, "--variant", "-v", help="Variant to run (repeatable); default: all (see harness/stress/variants.py)."),
    out: Path = typer.Option(Path("out/stress"), "--out", "-o", help="Folder for stress.csv and stress.html."),
) -> None:
    """Numerical stability at the extremes: each scene variant with each renderer that models it.

    Checks finite, non-negative output, a time bound, a memory bound and the
    mean radiance against the analytic value or the reference. Exit code 1 if
    any check fails, so CI can run it.
    """
    from harness.stress.suite import print_summary, run_suite
    from reports.stress import write_stress_report

    try:
        run = run_suite(renderer, variant, out)
    except ValueError as e:
        raise typer.BadParameter(str(e), param_hint="--variant") from None
    report = write_stress_report(Path(out) / "stress.html", run.table, run.provenance, _command_line())
    raise typer.Exit(print_summary(run, report))


@reference_app.command("build")
def reference_build(
    scene: str = SceneOpt,
    spp: int = typer.Option(16384, "--spp", min=2, help="Total samples per pixel of the reference."),
    batches: int = typer.Option(128, "--batches", min=2, help="Independent batches; their spread gives the variance image."),
) -> None:
    """Render the scene's reference with Mitsuba and store image, variance and provenance beside the scene."""
    sc = resolve_scene(scene)
    if spp % batches:
        raise typer.BadParameter(f"--spp ({spp}) must be a multiple of --batches ({batches})")
    bar = tqdm(total=batches + 1, desc=f"reference {sc.name}", unit="batch", file=sys.stderr, dynamic_ncols=True)
    from harness.workflows.reference_build import build_reference

    (entry,) = resolve([REFERENCE_RENDERER])
    if not entry.available:
        raise RendererError(f"renderer {entry.name!r} builds references but is unavailable: {entry.reason}")
    ref = build_reference(sc, spp, batches, entry, progress=lambda b, n: bar.update(1))
    bar.close()
    typer.echo(f"wrote {ref.folder} ({spp} spp in {ref.provenance['wall_time_s']:.0f} s, {ref.provenance['renderer_version']})")


@reference_app.command("show")
def reference_show(scene: str = SceneOpt) -> None:
    """Print the provenance of a scene's stored reference (refused if the scene changed)."""
    ref = load_reference(resolve_scene(scene))
    typer.echo(json.dumps(ref.provenance, indent=1))


def main() -> None:
    """Console entry point: user errors become one line on stderr and exit code 2."""
    try:
        app()
    except USER_ERRORS as e:
        print(f"cbox: error: {e}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("cbox: interrupted", file=sys.stderr)
        sys.exit(130)

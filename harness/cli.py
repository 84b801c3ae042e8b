"""``cbox``: the command-line interface.

Bad input (a malformed scene, an unknown renderer, a stale reference) ends with
a one-line ``cbox: error: ...`` on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import List, Optional

import typer
from tqdm import tqdm

from harness.adapter import RendererError, missing_features, resolve
from harness.atomic import atomic_path, write_json_atomic
from harness.exr import ImageFileError, write_exr
from harness.reference import ReferenceError, build_reference, load_reference, resolve_scene, scene_names
from harness.scene import FEATURES, SceneError

app = typer.Typer(
    help="Validation harness for renderers on the Cornell box: render, score against a trusted reference, report.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
reference_app = typer.Typer(help="Build and inspect stored reference images.", no_args_is_help=True)
app.add_typer(reference_app, name="reference")

USER_ERRORS = (SceneError, ReferenceError, RendererError, ImageFileError)

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
def renderers() -> None:
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


@app.command()
def features() -> None:
    """List the scene features a scene can declare and a renderer can model."""
    for name, meaning in FEATURES.items():
        typer.echo(f"{name:16s} {meaning}")


@app.command()
def render(
    scene: str = SceneOpt,
    renderer: str = typer.Option(..., "--renderer", "-r", help="Registered renderer name, or package.module:ClassName."),
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
    result = entry.renderer.render(sc, spp, seed)
    write_exr(out, result.image, {"cbox:renderer": entry.name, "cbox:spp": str(spp), "cbox:seed": str(seed),
                                  "cbox:scene_hash": sc.content_hash()})
    typer.echo(f"wrote {out} ({sc.camera.width}x{sc.camera.height}, {spp} spp, {result.time_s:.2f} s)", err=True)


def _run_compare(scene: str, renderer: Optional[List[str]], spp: int, seed: int, out: Path, as_json: bool) -> int:
    from harness import runner
    from reports.html import write_report
    import pandas as pd

    sc = resolve_scene(scene)
    ref = load_reference(sc)
    entries = resolve(renderer)
    bar = _progress(len(entries), f"{sc.name} @ {spp} spp")

    def done(rec: runner.RunRecord) -> None:
        bar.update(1)
        if as_json:
            typer.echo(json.dumps(runner.json_safe(rec.row()), allow_nan=False))

    records = runner.compare(sc, entries, spp, seed, ref, on_start=lambda e: bar.set_postfix_str(e.name), on_done=done)
    bar.close()
    out.mkdir(parents=True, exist_ok=True)
    frame = pd.DataFrame([r.row() for r in records])
    with atomic_path(out / "metrics.csv") as tmp:
        frame.to_csv(tmp, index=False)
    write_json_atomic(out / "metrics.json", [runner.json_safe(r.row()) for r in records])
    report = write_report(out / "report.html", scene=sc, reference_image=ref.image,
                          reference_provenance=ref.provenance, records=records, command=_command_line())
    if not as_json:
        cols = [c for c in ("renderer", "status", "spp", "time_s", "delta_e2000_mean", "noise_delta_e2000_mean",
                            "ssim", "rel_mse", "mean_radiance_rel_error", "nan_count") if c in frame]
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
        None, "--renderer", "-r", help="Renderer to run (repeatable); default: every registered renderer."),
    spp: int = SppOpt,
    seed: int = SeedOpt,
    out: Path = typer.Option(Path("out"), "--out", "-o", help="Folder for report.html, metrics.csv and metrics.json."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON record per run on stdout."),
) -> None:
    """Render with each renderer, score against the scene's reference, write a report.

    Exit code 1 if a renderer failed; renderers that are unavailable or do not
    model the scene are listed as such and are not failures.
    """
    raise typer.Exit(_run_compare(scene, renderer, spp, seed, out, as_json))


@app.command()
def demo(
    out: Path = typer.Option(Path("out"), "--out", "-o", help="Folder for report.html and metrics.csv."),
    spp: int = typer.Option(64, "--spp", min=1, help="Samples per pixel for every renderer."),
    seed: int = SeedOpt,
) -> None:
    """The main job: every available renderer on cornell-box against the stored reference → out/report.html."""
    raise typer.Exit(_run_compare("cornell-box", None, spp, seed, out, False))


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
    ref = build_reference(sc, spp, batches, progress=lambda b, n: bar.update(1))
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

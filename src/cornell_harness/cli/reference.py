"""``cbox reference build``, ``show`` and ``verify``: the stored references."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.adapters.registry import RendererError, resolve
from cornell_harness.cli.common import (EXIT_INCONCLUSIVE, REFERENCE_RENDERER, DashboardOpt, HomeOpt, SceneOpt, SchedulerOpt, SetOpt,
                                        TimeLimitOpt, WorkersOpt, check_output_folder, executor_for, reference_app, render_failed)
from cornell_harness.cli.output import Progress
from cornell_harness.scenes.animation import frame_list
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.scenes.model import Scene
from cornell_harness.store.references import ReferenceError, load_reference, reference_folder, reference_folders
# Heavy modules (SciPy, pandas, the report) are imported inside the commands that use them: `cbox gate` on
# a misspelt config, or `cbox --help`, must answer in a second.


FramesOpt = typer.Option(None, "--frames", metavar="LIST", help=(
    "An animated scene's frames to work on, e.g. 0-3,7 (default: every frame): their references, each once; "
    "frames at the same state (a light at rest) share the earliest one's, in frames/NNNN/ of the scene's "
    "reference folder."))


@reference_app.command("build")
def reference_build(
    scene: str = SceneOpt,
    overrides: Optional[List[str]] = SetOpt,
    spp: int = typer.Option(16384, "--spp", min=2, help="Total samples per pixel of the reference (of each frame)."),
    batches: int = typer.Option(128, "--batches", min=2, help="Independent batches; their spread gives the variance image."),
    frames: Optional[str] = FramesOpt,
    workers: Optional[int] = WorkersOpt,
    scheduler: Optional[str] = SchedulerOpt,
    dashboard: Optional[str] = DashboardOpt,
    home: Optional[Path] = HomeOpt,
    time_limit: Optional[str] = TimeLimitOpt,  # seconds (float), by the option's callback
) -> None:
    """Render the scene's reference with Mitsuba and store image, variance and provenance.

    A scene file of yours keeps its reference beside it; a stored scene's goes to the user store (--home),
    the package's stored references staying read-only. With --set, the derived scene's reference goes to
    derived/<content hash>/ there; the scene's own reference is left as it is. An animated scene gets one
    reference per distinct frame (--frames: those of some frames), each in frames/NNNN/ of that folder, built one
    after another; frames at the same state share the earliest one's.
    With --workers or --scheduler the batches render on a Dask cluster and are combined here in batch order: the
    same reference as a build in this process. --time-limit bounds each batch; one past it ends the build, exit 1,
    nothing stored for that frame.
    """
    still = frame_scenes(resolve_scene(scene, overrides), frames)
    if spp % batches:
        raise typer.BadParameter(f"--spp ({spp}) must be a multiple of --batches ({batches})")
    for sc in still:
        _refuse_shadowed_build(sc, home)
    from cornell_harness.workflows.reference_build import build_reference

    (entry,) = resolve([REFERENCE_RENDERER])
    if not entry.available:
        raise RendererError(f"renderer {entry.name!r} builds references but is unavailable: {entry.reason}")
    with executor_for(workers, scheduler, dashboard) as executor, render_failed(entry.name):
        for sc in still:
            label = sc.name if sc.frame is None else f"{sc.name} frame {sc.frame}"
            with Progress(batches + 1, f"reference {label}", "batch", slots=executor.slots) as bar:  # +1: noise
                bar.start(f"{spp // batches} spp per batch")
                ref = build_reference(sc, spp, batches, entry.with_time_limit(time_limit),
                                      folder=reference_folder(sc, home), executor=executor,
                                      progress=lambda done, total, label: bar.advance(label))
            typer.echo(f"wrote {ref.folder} ({spp} spp in {ref.provenance['wall_time_s']:.0f} s, "
                       f"{ref.provenance['renderer_version']})")


def frame_scenes(scene: Scene, frames: str | None) -> list[Scene]:
    """The still scenes whose references a command works on: for an animated ``scene``, those that its frames
    (every frame, or those ``--frames`` names) read, each once, in frame order
    (:meth:`~cornell_harness.scenes.animation.Animation.reference_frame`); a still scene itself. ``--frames`` on
    a still scene, or a malformed one, is a usage error (exit 2)."""
    if scene.animation is None:
        if frames is not None:
            raise typer.BadParameter(f"scene {scene.name!r} is not animated: it has no frames to choose",
                                     param_hint="--frames")
        return [scene]
    try:
        chosen = frame_list(frames, scene.frame_count) if frames is not None else range(scene.frame_count)
    except ValueError as e:
        raise typer.BadParameter(str(e), param_hint="--frames") from None
    return [scene.at_frame(j) for j in sorted({scene.animation.reference_frame(i) for i in chosen})]


def _refuse_shadowed_build(scene: Scene, home: Path | None) -> None:
    """Stop a build no command would read: the package's stored reference of ``scene`` is valid, and read first."""
    stored, built = reference_folders(scene, home)[0], reference_folder(scene, home)
    if stored == built:
        return
    try:
        ref = load_reference(scene, folder=stored)
    except ReferenceError:
        return  # none, or stale: the build is the one read
    raise ReferenceError(
        f"{stored}: the stored reference of {scene.name} ({ref.spp} spp) is valid for the scene and is the one "
        f"every command reads, so a build into {built} would never be read; build a variant with --set, or a "
        "copy of the scene's folder by its path")


@reference_app.command("show")
def reference_show(scene: str = SceneOpt, overrides: Optional[List[str]] = SetOpt, frames: Optional[str] = FramesOpt,
                   home: Optional[Path] = HomeOpt) -> None:
    """Print the provenance of a scene's reference: the stored one, else the user store's (refused if the scene
    changed). For an animated scene, a JSON object of each distinct reference's (--frames: those of some frames),
    by the number of the frame it is stored under."""
    sc = resolve_scene(scene, overrides)
    still = frame_scenes(sc, frames)
    if sc.animation is None:
        typer.echo(json.dumps(load_reference(sc, home=home).provenance, indent=1))
    else:
        typer.echo(json.dumps({str(f.frame): load_reference(f, home=home).provenance for f in still}, indent=1))


@reference_app.command("verify")
def reference_verify(
    scene: str = SceneOpt,
    overrides: Optional[List[str]] = SetOpt,
    engine: str = typer.Option("luxcore", "--engine", "-e", metavar="RENDERER", help=(
        "The second engine: any registered renderer (see `cbox renderers`), with settings as NAME\\[k=v,...]. "
        "An independent, unbiased one (luxcore) tests the reference; mitsuba, the reference's own engine at other "
        "seeds, tests only the noise model.")),
    spp: int = typer.Option(1024, "--spp", min=1, help=(
        "Total samples per pixel of the engine's render, split over --batches. More spp resolve smaller "
        "differences: a region's z grows as √spp for a fixed bias.")),
    batches: int = typer.Option(16, "--batches", min=1, help=(
        "Independent renders whose spread gives the engine's variance of its mean (as the reference's does); "
        "--spp must be a multiple. 1: one render, with the variance the engine itself reports.")),
    workers: Optional[int] = WorkersOpt,
    scheduler: Optional[str] = SchedulerOpt,
    dashboard: Optional[str] = DashboardOpt,
    record: bool = typer.Option(True, "--record/--no-record", help=(
        "Record the verdict in the user store (--home), in verdicts.json of the reference's folder there, "
        "under its engine (default), or only print it. The reference's own files are never written.")),
    report: Optional[Path] = typer.Option(None, "--report", metavar="DIR", help=(
        "Also write DIR/reference-verify-<scene>.html: the two engines' images, the per-pixel |z| map and the "
        "per-region tables; and the engine's image and variance of its mean beside it as "
        "reference-verify-<scene>-image.exr and -variance.exr.")),
    margin: Optional[List[str]] = typer.Option(None, "--margin", metavar="[REGION=]VALUE", help=(
        "The smallest relative bias that matters (repeatable): VALUE for every region and the whole image, or "
        "REGION=VALUE for one (image=VALUE: the whole image). Default: 0.01 for the whole image, 0.05 for a "
        "region.")),
    frames: Optional[str] = FramesOpt,
    home: Optional[Path] = HomeOpt,
    time_limit: Optional[str] = TimeLimitOpt,  # seconds (float), by the option's callback
) -> None:
    """Render the scene with a second engine and compare it with the stored reference, region by region.

    Per region (the scene's named regions and the whole image) and channel: the two means, their difference
    and z from both variances (a region mean's variance is the sum of its pixels' variances / n²); χ² over
    the regions; the spread of the per-pixel z; the relative bias with its interval (simultaneous at 0.99),
    the smallest bias the test detects with power 0.8, and the margin. Exits 1 when any region-channel p is
    below the Šidák-corrected level at family-wise false-alarm rate 0.01 (the engines disagree beyond noise),
    3 when none is but an interval reaches past its margin (inconclusive: more spp would resolve it), 0 when
    every interval lies inside its margin. `cbox scenes` shows the recorded verdicts; docs/references.md has
    the stored references' verdicts and what they found. An animated scene is verified reference by reference
    (--frames: those of some frames; frames that share one verify it once), each verdict recorded on its own
    reference; the exit code is the worst one's.
    """
    if spp % batches:
        raise typer.BadParameter(f"--spp ({spp}) must be a multiple of --batches ({batches})")
    if report is not None:
        check_output_folder(report, "--report")
    sc = resolve_scene(scene, overrides)
    margins = _margins(margin or [], sc)
    still = frame_scenes(sc, frames)
    refs = [load_reference(f, home=home) for f in still]  # refused (with the build command) before anything renders
    (entry,) = resolve([engine])
    if not entry.available:
        raise RendererError(f"engine {entry.name!r} is unavailable: {entry.reason}")
    codes = []
    with executor_for(workers, scheduler, dashboard) as executor, render_failed(entry.name):
        for f, ref in zip(still, refs):
            codes.append(_verify_one(f, ref, entry.with_time_limit(time_limit), spp, batches, executor, margins,
                                     record, report, home))
    raise typer.Exit(max(codes, key=[0, EXIT_INCONCLUSIVE, 1].index))  # the worst frame's: fail, inconclusive, pass


def _verify_one(sc: Scene, ref, entry, spp: int, batches: int, executor, margins: dict, record: bool,
                report: Path | None, home: Path | None) -> int:
    """Verify one (still) scene's reference: print the tables and verdict, record it, write its page; its exit code.

    Over 40 lines: it is the printed report of one verification, line after line."""
    from cornell_harness.store.references import record_verdict
    from cornell_harness.workflows.reference_verify import verify_reference

    label = sc.name if sc.frame is None else f"{sc.name} frame {sc.frame}"
    with Progress(batches, f"verify {label} with {entry.name}", "batch", slots=executor.slots) as bar:
        bar.start(f"{spp // batches} spp per batch")
        result = verify_reference(sc, ref, entry, spp, batches, executor=executor,
                                  progress=lambda done, total, label: bar.advance(label), margins=margins)
    a = result.agreement
    typer.echo(f"{label}: reference {ref.provenance.get('renderer_version')} at {ref.spp} spp against "
               f"{result.record['engine']} {result.record['engine_version']} at {spp} spp "
               f"({result.record['wall_time_s']:.0f} s)")
    for line in a.table() + [""] + a.power_table(result.margins):
        typer.echo("  " + line if line else "")
    typer.echo(f"per-pixel z: sd {a.pixel_z_sd:.3f}, robust spread {a.pixel_z_spread:.3f}, "
               f"{a.pixel_z_tail:.2%} beyond |z| 3 ({a.pixel_z_below:.2%} below −3, {a.pixel_z_above:.2%} above +3; "
               "0.27% for normal z; reported, not judged)")
    if remark := a.spread_remark(batches):
        typer.echo(remark)
    typer.echo(a.verdict_message(result.margins))
    if record:
        path = record_verdict(ref.folder, result.record, home)
        typer.echo(f"recorded in {path} under {result.record['engine']}")
    if report is not None:
        from cornell_harness.reports.reference_verify import write_verify_page

        named = sc if sc.frame is None else dataclasses.replace(sc, name=f"{sc.name}-frame-{sc.frame:04d}")
        path = write_verify_page(report, named, ref, result)  # a page per frame, named after it
        typer.echo(f"wrote {path}")
    return {"pass": 0, "fail": 1}.get(result.verdict, EXIT_INCONCLUSIVE)


def _margins(given: list[str], scene: Scene) -> dict[str, float]:
    """``--margin`` as {region: value} (``image``: the whole image); a bad one is a usage error (exit 2)."""
    out: dict[str, float] = {}
    for text in given:
        region, _, value = text.rpartition("=")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not 0 < number <= 1:
            raise typer.BadParameter(f"{text!r}: expected [REGION=]VALUE with VALUE a relative bias in (0, 1]",
                                     param_hint="--margin")
        if region and region != "image" and region not in scene.regions:
            raise typer.BadParameter(f"{text!r}: scene {scene.name!r} has no region {region!r}; its regions: "
                                     f"{', '.join(scene.regions) or '(none)'}", param_hint="--margin")
        for name in [region] if region else ["image", *scene.regions]:
            out[name] = number
    return out

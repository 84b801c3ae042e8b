"""``cbox compare-image``: score image files made outside the harness against a reference (idiff/FLIP style)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import typer

from harness.cli.common import app, command_line, info, out_folder_option
from harness.cli.run import TABLE_METRICS
from harness.scenes.library import resolve_scene
# Heavy modules (the metrics, pandas, the report) are imported inside the command: `cbox --help` must answer
# in a second.


@app.command("compare-image")
def compare_image(
    images: List[Path] = typer.Argument(..., help="Images to score: OpenEXR or any file OpenImageIO reads. "
                                                  "Floating-point pixels are taken as linear sRGB radiance; "
                                                  "integer ones (PNG, JPEG, 8/16-bit TIFF) need --input-transfer.",
                                        show_default=False),
    reference: Optional[Path] = typer.Option(None, "--reference", help="Reference image file. Noise yardsticks "
                                             "need its variance: only when it is a reference folder's "
                                             "reference.exr with variance.exr, noise.exr and provenance.json "
                                             "beside it. Scored as radiance (for another quantity use --scene)."),
    scene: Optional[str] = typer.Option(None, "--scene", "-s", help="Score against this scene's stored reference "
                                        "(name, .toml file or folder), with its variance and named regions."),
    spp: Optional[int] = typer.Option(None, "--spp", min=1, help="Samples per pixel of the images, for the noise "
                                      "yardsticks, where an image has no cbox:spp header (cbox render writes "
                                      "one); one that contradicts its header is refused. Without either the "
                                      "yardsticks are skipped."),
    input_transfer: Optional[str] = typer.Option(None, "--input-transfer", help="How to linearise display-"
                                                 "referred (integer) images: srgb (the sRGB EOTF, IEC 61966-2-1) "
                                                 "or linear (values as stored, scaled to [0, 1]). Without it "
                                                 "they are refused. Floating-point images are unaffected."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object per image on stdout: metrics, "
                                                       "noise, regions, HDR-FLIP parameters."),
    out: Path = out_folder_option(Path("out/compare-image"), "Folder for each image's ΔE error map "
                                                             "(LABEL.delta_e.png) and, with --report, report.html."),
    report: bool = typer.Option(False, "--report", help="Also write OUT/report.html: the table and the image "
                                                        "viewer with its error maps."),
) -> None:
    """Score image files against a reference with every image metric, as `cbox compare` scores a render.

    Prints a table (or --json), writes a ΔE error map per image. Exit code 0
    when every image was scored, 2 for bad input (display-referred image
    without --input-transfer, a size other than the reference's, ...), found
    before anything is scored.
    """
    if (reference is None) == (scene is None):
        raise typer.BadParameter("give --reference REF or --scene NAME (one of them)", param_hint="--reference")
    from harness.workflows import compare_image as workflow

    if input_transfer is not None and input_transfer not in workflow.INPUT_TRANSFERS:
        raise typer.BadParameter(f"{input_transfer!r}: expected one of {', '.join(workflow.INPUT_TRANSFERS)}",
                                 param_hint="--input-transfer")
    target = (workflow.load_scene_target(resolve_scene(scene)) if scene is not None
              else workflow.load_file_target(reference, input_transfer))
    sources = workflow.load_images(images, target, input_transfer, spp)
    from reports.compare_image import ERROR_MAP_SUFFIX, write_compare_image_report, write_error_map

    scores = []
    for source in sources:
        result = workflow.score(source, target)
        error_map = write_error_map(out, result, target)
        scores.append(result)
        if as_json:
            typer.echo(json.dumps({**result.record(target), "error_map": str(error_map)}, allow_nan=False))
        if result.noise_note:
            info(f"{source.path}: noise yardsticks skipped: {result.noise_note}")
    if not as_json:
        _print_table(scores)
    info(f"error maps: {out}/*{ERROR_MAP_SUFFIX}")
    if report:
        info(f"report: {write_compare_image_report(out / 'report.html', target, scores, command_line())}")


def _print_table(scores) -> None:
    """The metrics `cbox compare` prints, one row per image; then each image's regions, if any."""
    import pandas as pd

    frame = pd.DataFrame([{"image": s.source.label, "spp": s.source.spp, **s.row()} for s in scores])
    frame["spp"] = frame["spp"].astype("Int64")  # unknown spp: <NA>, and 2 rather than 2.0 beside it
    typer.echo(frame[[c for c in ("image", "spp", *TABLE_METRICS) if c in frame]].to_string(index=False))
    for s in scores:
        if s.regions:
            typer.echo(f"\n{s.source.label} per region:\n"
                       + pd.DataFrame.from_dict(s.regions, orient="index").to_string())

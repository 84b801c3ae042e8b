"""``cbox compare-image``: score image files made outside the harness against a reference (idiff/FLIP style)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.cli.choices import choice_callback
from cornell_harness.cli.common import app, command_line, out_folder_option
from cornell_harness.cli.output import info
from cornell_harness.cli.run import TABLE_METRICS
from cornell_harness.scenes.library import resolve_scene
# Heavy modules (the metrics, pandas, the report) are imported inside the command: `cbox --help` must answer
# in a second.


def _transfers() -> tuple[str, ...]:
    from cornell_harness.workflows.compare_image import INPUT_TRANSFERS

    return tuple(INPUT_TRANSFERS)


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
                                      "yardsticks and the regions' mean_z, where an image has no cbox:spp header "
                                      "(cbox render writes one); one that contradicts its header is refused. "
                                      "Without either they are left out, the result says so (its notes, --json's "
                                      "noise_note), and a threshold on them is refused."),
    input_transfer: Optional[str] = typer.Option(
        None, "--input-transfer", metavar="srgb|linear", callback=choice_callback("--input-transfer", _transfers),
        help="How to linearise display-referred (integer) images: srgb (the sRGB EOTF, IEC 61966-2-1) or linear "
             "(values as stored, scaled to [0, 1]), in any case (sRGB). Without it they are refused. "
             "Floating-point images are unaffected."),
    exposure: Optional[float] = typer.Option(
        None, "--exposure", metavar="STOPS", help="The exposure display-referred images were made at: their "
        "linear values (after --input-transfer) are radiance × 2^STOPS, so they are divided by 2^STOPS. Applies "
        "to integer images only (a tonemapped PNG or JPEG), the --reference file too if it is one."),
    fail_at: Optional[List[str]] = typer.Option(
        None, "--fail", metavar="METRIC=V", help="Exit 1 when an image's METRIC is worse than V: above it, or "
        "below it for a metric where higher is better (psnr, ssim), or in magnitude above it for a signed one "
        "(mean_radiance_rel_error). Any per-image metric (the keys of --json's metrics and noise: rmse, "
        "rel_mse, psnr, ssim, delta_e2000_mean, delta_e2000_p95, flip_mean, ...), or region.REGION.METRIC with "
        "--scene. Repeatable; each broken threshold is printed with its value."),
    warn_at: Optional[List[str]] = typer.Option(
        None, "--warn", metavar="METRIC=V", help="As --fail, but a broken threshold prints a warning line and the "
        "exit code stays 0. Repeatable."),
    fail_percent: Optional[float] = typer.Option(
        None, "--fail-percent", metavar="P", min=0.0, max=100.0, help="Exit 1 when more than P percent of the "
        "pixels have a per-pixel error above --pixel-threshold; the per-pixel error is CIEDE2000 (ΔE00) at the "
        "reference's display exposure, the error map's (idiff's -failpercent, on ΔE00 rather than channel "
        "difference). On a scene without colour (ambient occlusion) the per-pixel error is the absolute "
        "difference of its one value (|Δ|), and thresholds on ΔE00 and flip_mean are refused."),
    pixel_threshold: Optional[float] = typer.Option(
        None, "--pixel-threshold", metavar="T", min=0.0, help="The per-pixel ΔE00 --fail-percent counts pixels "
        "above (2.3 is a just-noticeable difference); |Δ| on a scene without colour."),
    as_json: bool = typer.Option(False, "--json", help="Print one JSON object per image on stdout: metrics, "
                                                       "noise, regions, HDR-FLIP parameters, and with thresholds "
                                                       "its verdict."),
    out: Path = out_folder_option(Path("out/compare-image"), "Folder for each image's ΔE error map "
                                                             "(LABEL.delta_e.png, see --error-map) and, with "
                                                             "--report, report.html."),
    report: bool = typer.Option(False, "--report", help="Also write OUT/report.html: the table and the image "
                                                        "viewer with its error maps."),
    with_flip: bool = typer.Option(False, "--flip", help="Also score HDR-FLIP (flip_mean): about 1 s per 256² "
                                   "image (8 exposures), more than every other metric together, so it is left "
                                   "out unless asked for here, by a --fail/--warn on flip_mean, or by --report."),
    all_metrics: bool = typer.Option(False, "--all-metrics", help="With --fail, --warn or --fail-percent, score "
                                     "every metric, as without them. By default such a check scores what its "
                                     "thresholds name and the cheap metrics (rmse, mse, rel_mse, the mean "
                                     "radiance and its error, the NaN/Inf/negative counts), so that it costs "
                                     "about what idiff's does: the ΔE00 map, SSIM, PSNR, the noise yardsticks "
                                     "and the regions only when a threshold (or --error-map) needs them. "
                                     "--report scores every metric too."),
    error_map: Optional[bool] = typer.Option(
        None, "--error-map/--no-error-map", help="Write each image's ΔE00 error map, OUT/LABEL.delta_e.png "
        "(viridis on 0..10, the report's). Default: written, except by a check (--fail, --warn, "
        "--fail-percent), which writes it only when asked, as idiff writes its difference image with -o.",
        show_default=False),
) -> None:
    """Score image files against a reference with every image metric, as `cbox compare` scores a render.

    Prints a table (or --json), writes a ΔE error map per image. Exit code 0
    when every image was scored and no --fail threshold is broken (a broken
    --warn prints a warning line), 1 when one is (each printed on stderr with
    its value), 2 for bad input (display-referred image without
    --input-transfer, a size other than the reference's, an unknown metric,
    ...), found before anything is scored. With thresholds it is a check:
    it scores what they name and the cheap metrics (--all-metrics: every
    one) and writes no error map unless --error-map asks for it.
    """
    if (reference is None) == (scene is None):
        raise typer.BadParameter("give --reference REF or --scene NAME (one of them)", param_hint="--reference")
    if (fail_percent is None) != (pixel_threshold is None):
        raise typer.BadParameter("give --fail-percent P and --pixel-threshold T together",
                                 param_hint="--fail-percent" if pixel_threshold is None else "--pixel-threshold")
    from cornell_harness.workflows import compare_image as workflow

    checks = workflow.Checks(_thresholds(fail_at, warn_at), fail_percent, pixel_threshold)
    try:
        run = workflow.compare_images(images, resolve_scene(scene) if scene is not None else None, reference,
                                      input_transfer, spp, exposure, checks, with_flip or report,
                                      every=all_metrics or report, error_maps=error_map)
    except workflow.OptionError as e:
        raise typer.BadParameter(str(e), param_hint=e.option) from None
    _show(run, out, as_json, [t.metric for t in checks.thresholds])
    if report:
        from cornell_harness.reports.compare_image import write_compare_image_report

        scores = [c.score for c in run.images]
        info(f"report: {write_compare_image_report(out / 'report.html', run.target, scores, command_line())}")
    if run.failed:
        raise typer.Exit(1)


#: The fraction of a display-referred image's pixels clipped above which a warning is printed (0.1%).
CLIPPED_WARNING = 1e-3


def warn(message: str) -> None:
    """``cbox: warning: MESSAGE`` on stderr; not dropped by --quiet (a result a CI log must show)."""
    typer.echo(f"cbox: warning: {message}", err=True)


def _thresholds(fail_at, warn_at) -> list:
    from cornell_harness.evaluate.thresholds import ThresholdError, parse_threshold

    out = []
    for level, given in (("fail", fail_at), ("warn", warn_at)):
        for text in given or ():
            try:
                out.append(parse_threshold(text, level))
            except ThresholdError as e:
                raise typer.BadParameter(str(e), param_hint=f"--{level}") from None
    return out


def _show(run, out: Path, as_json: bool, named: list[str]) -> None:
    """Per image: its clipping and orientation warnings, the error map written, the broken criteria (stderr),
    the --json line (which holds why there are no noise yardsticks, and the orientation note); then the table
    (without --json) with those notes under it, and where the error maps are."""
    from cornell_harness.reports.compare_image import ERROR_MAP_SUFFIX, write_error_map

    _warn_clipped(run.target.path, run.target.clipped)
    for checked in run.images:
        result = checked.score
        _warn_clipped(result.source.path, result.source.clipped)
        if result.orientation_note:
            warn(f"{result.source.path}: {result.orientation_note}")
        written = write_error_map(out, result, run.target, result.delta_e_map) if run.error_maps else None
        for level, line in checked.broken:
            typer.echo(f"cbox: fail: {line}" if level == "fail" else f"cbox: warning: {line}", err=True)
        if as_json:
            record = {**result.record(run.target), "error_map": None if written is None else str(written)}
            if checked.verdict is not None:
                record["verdict"] = checked.verdict
            typer.echo(json.dumps(record, allow_nan=False))
    if not as_json:
        _print_table([c.score for c in run.images], named)
        _print_notes([c.score for c in run.images])
    if run.error_maps:
        info(f"error maps: {out}/*{ERROR_MAP_SUFFIX}")


def _warn_clipped(path: Path, clipped: float | None) -> None:
    """The warning line of a display-referred file with more than :data:`CLIPPED_WARNING` of its pixels clipped."""
    if clipped is not None and clipped > CLIPPED_WARNING:
        warn(f"{path}: {100 * clipped:.3g}% of the pixels are clipped (a channel at 0 or at the maximum code "
             "value): their errors are the encoding's, not the renderer's")


def _print_table(scores, named: list[str]) -> None:
    """The metrics `cbox compare` prints, and those the thresholds name, one row per image (those scored); then
    each image's regions, if any.

    Laid out as pandas' ``to_string`` lays a frame out, without pandas (its import is ~0.5 s of this
    command's time)."""
    shown = dict.fromkeys([*TABLE_METRICS, *(m for m in named if "." not in m)])
    columns = ["image", "spp", *(c for c in shown if any(c in s.row() for s in scores))]
    rows = [[s.source.label, s.source.spp, *(s.row().get(c) for c in columns[2:])] for s in scores]
    typer.echo(_format_table(columns, rows))
    for s in scores:
        if s.regions:
            names = list(dict.fromkeys(k for values in s.regions.values() for k in values))
            typer.echo(f"\n{s.source.label} per region:\n" + _format_table(
                ["", *names], [[region, *(values.get(k) for k in names)] for region, values in s.regions.items()],
                left_first=True))


def _print_notes(scores) -> None:
    """Under the table, part of the result (--quiet keeps it): per image, why its noise yardsticks and region
    z are missing, and its orientation note."""
    lines = [f"{s.source.label}: {what}" for s in scores
             for what in (s.noise_note and f"noise yardsticks skipped: {s.noise_note}", s.orientation_note) if what]
    if lines:
        typer.echo("\nnotes:\n" + "\n".join(lines))


def _cell(value) -> str:
    if value is None:
        return "<NA>"
    if isinstance(value, float):
        return "NaN" if value != value else f"{value:.6f}"
    return str(value)


def _format_table(columns: list[str], rows: list[list], left_first: bool = False) -> str:
    """Right-aligned columns two spaces apart (the first left-aligned when it is an index of names)."""
    cells = [[_cell(v) for v in row] for row in rows]
    widths = [max(len(c), *(len(r[i]) for r in cells)) for i, c in enumerate(columns)]

    def line(values):
        return "  ".join(v.ljust(w) if (i == 0 and left_first) else v.rjust(w)
                         for i, (v, w) in enumerate(zip(values, widths))).rstrip()

    return "\n".join([line(columns), *(line(r) for r in cells)])

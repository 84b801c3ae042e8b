"""``cbox stress``: numerical stability at the extremes, and its report."""

from __future__ import annotations

from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.cli.common import (REFERENCE_RENDERER, RendererFilesOpt, app, command_line, out_folder_option,
                                        time_limit_seconds)
from cornell_harness.cli.output import Progress


@app.command()
def stress(
    renderer: Optional[List[str]] = typer.Option(
        None, "--renderer", "-r", help="Renderer to stress (repeatable); default: every registered renderer."),
    renderer_files: Optional[List[Path]] = RendererFilesOpt,
    variant: Optional[List[str]] = typer.Option(
        None, "--variant", "-v", help="Variant to run (repeatable); default: all (see src/cornell_harness/stress/variants.py)."),
    out: Path = out_folder_option(Path("out/stress"), "Folder for stress.csv and stress.html."),
    time_limit: Optional[str] = typer.Option(
        None, "--time-limit", metavar="DURATION", callback=time_limit_seconds,
        help="Each render's time bound instead of its variant's own (e.g. 90s, 10m): a render past it is ended, "
             "with every process it started, and fails the time check."),  # seconds (float), by the callback
) -> None:
    """Numerical stability at the extremes: each scene variant with each renderer that models it.

    Checks finite, non-negative output, a time bound, a memory bound and the
    mean radiance against the analytic value or the reference. Exit code 1 if
    any check fails, so CI can run it.
    """
    from cornell_harness.stress.suite import print_summary, run_suite
    from cornell_harness.reports.stress import write_stress_report

    bars: list[Progress] = []  # made as the runs start, when the count of runs is known

    def progress(done: int, total: int, label: str) -> None:
        if not bars:
            bars.append(Progress(total, "stress", "run"))
        if done:
            bars[0].advance(label)
        else:
            bars[0].start(label)

    try:
        run = run_suite(renderer, variant, out, progress, reference_renderer=REFERENCE_RENDERER,
                        time_limit_s=time_limit)
    except ValueError as e:
        raise typer.BadParameter(str(e), param_hint="--variant") from None
    finally:
        for bar in bars:
            bar.close()
    report = write_stress_report(Path(out) / "stress.html", run.table, run.provenance, command_line())
    raise typer.Exit(print_summary(run, report))

"""``cbox gate``: the CI gate, its verdict as exit code, JUnit, Markdown and the per-scene reports."""

from __future__ import annotations

import dataclasses
import logging
import os
from pathlib import Path
from typing import List, Optional

import typer

from cornell_harness.cli.common import (EXIT_INCONCLUSIVE, RENDERER_FILES_HELP, USER_ERRORS, DashboardOpt,
                                        SchedulerOpt, WorkersOpt, app, command_line, executor_for, out_folder_option,
                                        print_json)
from cornell_harness.cli.output import Progress, info
from cornell_harness.cli.run import write_compare_outputs
from cornell_harness.reports.ci import no_bound_note
from cornell_harness.gate.config import GateConfigError, load_config
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.atomic import write_text_atomic
from cornell_harness.store.references import load_reference

log = logging.getLogger(__name__)

# Heavy modules (SciPy, pandas, the report) are imported inside the commands that use them: `cbox gate` on
# a misspelt config, or `cbox --help`, must answer in a second.


@app.command()
def gate(
    config: Path = typer.Option(Path("gate.toml"), "--config", "-c", help="Gate config (TOML): expectations per "
                                                                        "scene, renderer and budget; see src/cornell_harness/gate/config.py."),
    renderer_files: Optional[List[Path]] = typer.Option(None, "--renderers", metavar="FILE",
                                                        help=RENDERER_FILES_HELP),
    out: Path = out_folder_option(Path("out/gate"), "Folder for report.html (index.html when "
                                                                  "there are several scenes), gate-junit.xml and "
                                                                  "gate-summary.md."),
    junit: Optional[Path] = typer.Option(None, "--junit", help="JUnit XML path (default OUT/gate-junit.xml)."),
    markdown: Optional[Path] = typer.Option(None, "--markdown", help="Markdown summary path (default "
                                                                    "OUT/gate-summary.md); also appended to "
                                                                    "$GITHUB_STEP_SUMMARY when that is set."),
    update_baseline: bool = typer.Option(False, "--update-baseline", help="Record this run's metrics as the "
                                                                          "baseline named in the config (creating "
                                                                          "the file; without this option a "
                                                                          "baseline named but missing is exit 2); "
                                                                          "refused when a check other than a "
                                                                          "baseline check fails."),
    force: bool = typer.Option(False, "--force", help="With --update-baseline: record the baseline even though "
                                                      "checks failed."),
    overrides: Optional[List[str]] = typer.Option(
        None, "--set", metavar="KEY=VALUE", help="Override a value of every scene of the run (repeatable), as in "
                                                 "cbox compare --set: each derived scene needs its own reference. "
                                                 "The baseline, recorded on the config's scenes, is not compared, "
                                                 "and --update-baseline is refused."),
    as_json: bool = typer.Option(False, "--json", help="Print the verdict on stdout as one JSON object (each "
                                                       "expectation with its checks and its run) instead of the "
                                                       "PASS/FAIL lines."),
    plan: bool = typer.Option(False, "--plan", help="Render a short pilot per unbiased expectation (its spp / "
                                                    "16, one seed) and print, per region, about the spp and time "
                                                    "that resolve its margin with power 0.8, and the expectations "
                                                    "whose budget cannot (or whose reference's variance forbids "
                                                    "it); writes nothing. Exit 0, or 2 for a bad config. With "
                                                    "--set, the derived scenes'."),
    pilot_spp: Optional[int] = typer.Option(None, "--pilot-spp", min=1, help="With --plan: the pilot's spp "
                                                                             "(default: each expectation's spp / "
                                                                             "16)."),
    workers: Optional[int] = WorkersOpt,
    scheduler: Optional[str] = SchedulerOpt,
    dashboard: Optional[str] = DashboardOpt,
) -> None:
    """CI quality gate: exit 0 if every expectation holds, 1 if one fails, 2 for a bad config or input,
    3 if none fails and one is inconclusive (a bias interval straddles its margin).

    Unbiased renderers are tested for statistical agreement with the reference
    (z-tests on tiles, the scene's named regions and the whole image), for a
    reported variance that matches their residuals, and for single outlier
    pixels (family-wise false-alarm rate alpha over the three); with margins, every
    region's bias interval must lie inside its margin to pass. An expectation with
    max_spp is sequential: it looks at doubling spp and stops at the first verdict
    (docs/gate-detection.md, "Sequential stopping"). Others against metric
    budgets (image-wide or per named region) and, for consistent renderers
    (photon mapping, SPPM), a check that their error falls as the budget grows;
    all must have zero NaN/Inf pixels; optionally, convergence slopes
    and regressions against a recorded baseline. Each render runs in a child
    process killed at its time limit (with --workers or --scheduler, on a Dask
    worker; the checks run here). JUnit and Markdown are written for every
    run, a config error included.
    """
    if plan or pilot_spp is not None:
        _plan(config, renderer_files, pilot_spp, overrides or (), plan, update_baseline or as_json)
        return
    if overrides and update_baseline:
        raise typer.BadParameter("--update-baseline records the config's own scenes; not with --set", param_hint="--set")
    try:
        if renderer_files:  # here, not as it is parsed: a bad file is reported in the CI files too
            from cornell_harness.adapters.registry import use_renderer_files

            use_renderer_files(renderer_files)
        cfg = load_config(config)
        if update_baseline and cfg.baseline is None:
            raise GateConfigError(cfg.path, "baseline", "--update-baseline needs baseline = \"FILE.json\"")
        if cfg.baseline is not None and not update_baseline and not cfg.baseline.exists():
            # Named but missing (a typo, or never recorded): comparing with nothing would pass in silence.
            raise GateConfigError(cfg.path, "baseline", f"{cfg.baseline}: no such file; record it with "
                                  "cbox gate --update-baseline")
        with executor_for(workers, scheduler, dashboard) as executor:
            outcomes = _run_with_progress(cfg, skip_baseline=update_baseline, scene_overrides=overrides or (),
                                          check_lines=not as_json, executor=executor)
    except USER_ERRORS as e:
        _write_ci_files([], 0.0, out, junit, markdown, config_error=str(e))
        raise
    failed = sum(c.failed for o in outcomes for c in o.checks)
    open_ = sum(c.inconclusive and not c.passed for o in outcomes for c in o.checks)
    code = 1 if failed else EXIT_INCONCLUSIVE if open_ else 0
    if update_baseline:
        code = _update_baseline(cfg, outcomes, force) or code
    _write_ci_files(outcomes, cfg.alpha, out, junit, markdown)
    _write_reports(outcomes, cfg.alpha, out, overrides)
    skipped = sum(c.skipped for o in outcomes for c in o.checks)
    if as_json:
        print_json(_verdict(cfg, outcomes, failed))
    else:
        verdict = (f"failed: {failed} check(s)" if failed else f"inconclusive: {open_} check(s)" if open_
                   else "passed")
        if note := no_bound_note(outcomes):
            typer.echo(note)
        typer.echo(f"gate {verdict}" + (f" ({skipped} skipped)" if skipped else ""))
    raise typer.Exit(code)


def _plan(config: Path, renderer_files, pilot_spp: int | None, scene_overrides, plan: bool, other: bool) -> None:
    """``cbox gate --plan``: the pilots' plan, printed (config errors propagate: exit 2)."""
    if not plan:
        raise typer.BadParameter("goes with --plan", param_hint="--pilot-spp")
    if other:
        raise typer.BadParameter("--plan renders pilots only: not with --update-baseline or --json",
                                 param_hint="--plan")
    from cornell_harness.gate.plan import plan_gate, plan_lines

    if renderer_files:
        from cornell_harness.adapters.registry import use_renderer_files

        use_renderer_files(renderer_files)
    for line in plan_lines(plan_gate(load_config(config), pilot=pilot_spp, scene_overrides=scene_overrides)):
        typer.echo(line)


def _verdict(cfg, outcomes, failed: int) -> dict:
    """``cbox gate --json``: the verdict, then each expectation with its checks and its run."""
    from cornell_harness.workflows.runner import json_record

    from cornell_harness.evaluate.equivalence import combine

    verdict = combine([o.verdict for o in outcomes])
    return {"passed": verdict == "pass", "verdict": verdict, "failed_checks": failed,
            "config": cfg.path, "alpha": cfg.alpha,
            "expectations": [{"name": o.expectation.name, "scene": o.expectation.scene,
                              "renderer": o.expectation.renderer, "passed": o.passed, "verdict": o.verdict,
                              "checks": [{"name": c.name, "passed": c.passed, "error": c.error, "skipped": c.skipped,
                                          "inconclusive": c.inconclusive,
                                          "message": c.message, "value": c.value, "limit": c.limit,
                                          "traceback": c.traceback or None} for c in o.checks],
                              "run": json_record(o.record)} for o in outcomes]}


def _run_with_progress(cfg, skip_baseline: bool, scene_overrides=(), check_lines: bool = True, executor=None):
    """Run the gate; a PASS or FAIL line per check as each expectation finishes (``check_lines``), and progress.

    The progress starts with the first render, so a config error found while resolving is a clean line.
    """
    from cornell_harness.gate import run as gate_run

    bars = []

    def start(exp) -> None:
        if not bars:
            bars.append(Progress(len(cfg.expectations), "gate", "expectation", slots=getattr(executor, "slots", 1)))
        bars[0].start(exp.name)

    def done(o) -> None:
        for c in o.checks:
            if check_lines and not (skip_baseline and _is_baseline_check(c)):
                word = "SKIP" if c.skipped else c.word.upper()
                bars[0].write(f"{word}  {o.expectation.name}  {c.name}: {c.message}")
            if c.traceback:  # the ERROR line says what; the traceback where, in the log (-v prints it)
                log.info("%s %s: the renderer's traceback:\n%s", o.expectation.name, c.name, c.traceback.rstrip())
        bars[0].advance(f"{o.expectation.name} {'passed' if o.passed else 'failed'}",
                        failed=o.record.status == "failed")

    try:
        outcomes = gate_run.run_gate(cfg, on_start=start, on_done=done, scene_overrides=scene_overrides,
                                     executor=executor)
    finally:
        if bars:
            bars[0].close()
    if skip_baseline:  # this run becomes the baseline: comparing it with the old one says nothing
        outcomes = [dataclasses.replace(o, checks=[c for c in o.checks if not _is_baseline_check(c)])
                    for o in outcomes]
    return outcomes


def _is_baseline_check(c) -> bool:
    """``baseline.<metric>``, or ``baseline`` skipped (no baseline to compare with)."""
    return c.name == "baseline" or c.name.startswith("baseline.")


def _update_baseline(cfg, outcomes, force: bool) -> int:
    """Record the baseline unless a check failed (then only with ``force``); exit code 1 when refused."""
    from cornell_harness.gate import run as gate_run

    refusal = gate_run.baseline_refusal(outcomes)
    if refusal and not force:
        typer.echo(f"baseline not updated: {refusal}; fix them, or rerun with --force to record this run anyway",
                   err=True)
        return 1
    path, changes = gate_run.write_baseline(cfg, outcomes)
    for line in changes:
        info(f"baseline: {line}")
    info(f"baseline: wrote {path}" + (" (forced past failing checks)" if refusal else ""))
    return 0


def _write_ci_files(outcomes, alpha: float, out: Path, junit: Path | None, markdown: Path | None,
                    config_error: str | None = None) -> None:
    """JUnit and the Markdown summary (also appended to $GITHUB_STEP_SUMMARY)."""
    from cornell_harness.reports.ci import junit_xml, markdown_summary

    md = markdown_summary(outcomes, alpha, config_error)
    try:
        write_text_atomic(junit or out / "gate-junit.xml", junit_xml(outcomes, config_error=config_error))
        write_text_atomic(markdown or out / "gate-summary.md", md)
    except OSError as e:
        if config_error is None:
            raise
        typer.echo(f"cbox: could not write the CI files ({e})", err=True)  # the config error is what matters
    if os.environ.get("GITHUB_STEP_SUMMARY"):
        with open(os.environ["GITHUB_STEP_SUMMARY"], "a") as f:
            f.write(md)


def _write_reports(outcomes, alpha: float, out: Path, overrides=None) -> None:
    """One report per scene; with several scenes, OUT/index.html links them."""
    from cornell_harness.reports.gate import gate_index_html, gate_section

    scenes = list(dict.fromkeys(o.expectation.scene for o in outcomes))
    links = []
    for scene_name in scenes:
        mine = [o for o in outcomes if o.expectation.scene == scene_name]
        folder = out if len(scenes) == 1 else out / Path(scene_name).stem
        sc = resolve_scene(scene_name, overrides)
        report = write_compare_outputs(folder, sc, load_reference(sc), [o.record for o in mine], command_line(),
                                        sections=[("gate", "Gate", gate_section(mine, alpha))],
                                        title=f"cbox gate — {sc.name}")
        links.append((sc.name, report.relative_to(out).as_posix() if len(scenes) > 1 else report.name,
                      all(o.passed for o in mine)))
    if len(scenes) > 1:
        write_text_atomic(out / "index.html", gate_index_html(links))
        info(f"report: {out / 'index.html'}")
    elif links:
        info(f"report: {out / links[0][1]}")

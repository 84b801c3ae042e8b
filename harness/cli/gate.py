"""``cbox gate``: the CI gate, its verdict as exit code, JUnit, Markdown and the per-scene reports."""

from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path
from typing import Optional

import typer
from tqdm import tqdm

from harness.cli.common import USER_ERRORS, _command_line, app, out_folder_option
from harness.cli.run import _write_compare_outputs
from harness.gate.config import GateConfigError, load_config
from harness.scenes.library import resolve_scene
from harness.store.atomic import write_text_atomic
from harness.store.references import load_reference

# Heavy modules (SciPy, pandas, the report) are imported inside the commands that use them: `cbox gate` on
# a misspelt config, or `cbox --help`, must answer in a second.


@app.command()
def gate(
    config: Path = typer.Option(Path("gate.toml"), "--config", "-c", help="Gate config (TOML): expectations per "
                                                                        "scene, renderer and budget; see harness/gate/config.py."),
    out: Path = out_folder_option(Path("out/gate"), "Folder for report.html (index.html when "
                                                                  "there are several scenes), gate-junit.xml and "
                                                                  "gate-summary.md."),
    junit: Optional[Path] = typer.Option(None, "--junit", help="JUnit XML path (default OUT/gate-junit.xml)."),
    markdown: Optional[Path] = typer.Option(None, "--markdown", help="Markdown summary path (default "
                                                                    "OUT/gate-summary.md); also appended to "
                                                                    "$GITHUB_STEP_SUMMARY when that is set."),
    update_baseline: bool = typer.Option(False, "--update-baseline", help="Record this run's metrics as the "
                                                                          "baseline named in the config; refused "
                                                                          "when a check other than a baseline "
                                                                          "check fails."),
    force: bool = typer.Option(False, "--force", help="With --update-baseline: record the baseline even though "
                                                      "checks failed."),
) -> None:
    """CI quality gate: exit 0 if every expectation holds, 1 if one fails, 2 for a bad config or input.

    Unbiased renderers are tested for statistical agreement with the reference
    (tiled z-tests), for a reported variance that matches their residuals, and
    for single outlier pixels (family-wise false-alarm rate alpha over the
    three); others against metric
    budgets (image-wide or per named region) and, for consistent renderers
    (photon mapping, SPPM), a check that their error falls as the budget grows;
    all must have zero NaN/Inf pixels; optionally, convergence slopes
    and regressions against a recorded baseline. Each render runs in a child
    process killed at its time limit. JUnit and Markdown are written for every
    run, a config error included.
    """
    try:
        cfg = load_config(config)
        if update_baseline and cfg.baseline is None:
            raise GateConfigError(cfg.path, "baseline", "--update-baseline needs baseline = \"FILE.json\"")
        outcomes = _run_with_progress(cfg, skip_baseline=update_baseline)
    except USER_ERRORS as e:
        _write_ci_files([], 0.0, out, junit, markdown, config_error=str(e))
        raise
    code = 1 if any(not c.passed for o in outcomes for c in o.checks) else 0
    if update_baseline:
        code = max(code, _update_baseline(cfg, outcomes, force))
    _write_ci_files(outcomes, cfg.alpha, out, junit, markdown)
    _write_reports(outcomes, cfg.alpha, out)
    failed = sum(not c.passed for o in outcomes for c in o.checks)
    typer.echo(f"gate {'passed' if not failed else f'failed: {failed} check(s)'}")
    raise typer.Exit(code)


def _run_with_progress(cfg, skip_baseline: bool):
    """Run the gate; a PASS or FAIL line per check as each expectation finishes, and a moving bar.

    The bar starts with the first render, so a config error found while resolving is a clean line.
    """
    from harness.gate import run as gate_run

    bars = []

    def start(exp) -> None:
        if not bars:
            bars.append(tqdm(total=len(cfg.expectations), desc="gate", unit="expectation", file=sys.stderr,
                             dynamic_ncols=True))
        bars[0].set_postfix_str(exp.name)

    def done(o) -> None:
        for c in o.checks:
            if not (skip_baseline and c.name.startswith("baseline.")):
                word = "PASS" if c.passed else "ERROR" if c.error else "FAIL"
                tqdm.write(f"{word}  {o.expectation.name}  {c.name}: {c.message}", file=sys.stdout)
        bars[0].update(1)

    try:
        outcomes = gate_run.run_gate(cfg, on_start=start, on_done=done)
    finally:
        if bars:
            bars[0].close()
    if skip_baseline:  # this run becomes the baseline: comparing it with the old one says nothing
        outcomes = [dataclasses.replace(o, checks=[c for c in o.checks if not c.name.startswith("baseline.")])
                    for o in outcomes]
    return outcomes


def _update_baseline(cfg, outcomes, force: bool) -> int:
    """Record the baseline unless a check failed (then only with ``force``); exit code 1 when refused."""
    from harness.gate import run as gate_run

    refusal = gate_run.baseline_refusal(outcomes)
    if refusal and not force:
        typer.echo(f"baseline not updated: {refusal}; fix them, or rerun with --force to record this run anyway",
                   err=True)
        return 1
    path, changes = gate_run.write_baseline(cfg, outcomes)
    for line in changes:
        typer.echo(f"baseline: {line}", err=True)
    typer.echo(f"baseline: wrote {path}" + (" (forced past failing checks)" if refusal else ""), err=True)
    return 0


def _write_ci_files(outcomes, alpha: float, out: Path, junit: Path | None, markdown: Path | None,
                    config_error: str | None = None) -> None:
    """JUnit and the Markdown summary (also appended to $GITHUB_STEP_SUMMARY)."""
    from reports.ci import junit_xml, markdown_summary

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


def _write_reports(outcomes, alpha: float, out: Path) -> None:
    """One report per scene; with several scenes, OUT/index.html links them."""
    from reports.gate import gate_index_html, gate_section

    scenes = list(dict.fromkeys(o.expectation.scene for o in outcomes))
    links = []
    for scene_name in scenes:
        mine = [o for o in outcomes if o.expectation.scene == scene_name]
        folder = out if len(scenes) == 1 else out / Path(scene_name).stem
        sc = resolve_scene(scene_name)
        report = _write_compare_outputs(folder, sc, load_reference(sc), [o.record for o in mine], _command_line(),
                                        sections=[("gate", "Gate", gate_section(mine, alpha))],
                                        title=f"cbox gate — {sc.name}")
        links.append((sc.name, report.relative_to(out).as_posix() if len(scenes) > 1 else report.name,
                      all(o.passed for o in mine)))
    if len(scenes) > 1:
        write_text_atomic(out / "index.html", gate_index_html(links))
        typer.echo(f"report: {out / 'index.html'}", err=True)
    elif links:
        typer.echo(f"report: {out / links[0][1]}", err=True)

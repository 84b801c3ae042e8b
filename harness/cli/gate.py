"""``cbox gate``: the CI gate, its verdict as exit code, JUnit, Markdown and the per-scene reports."""

from __future__ import annotations

import dataclasses
import os
import sys
from pathlib import Path
from typing import Optional

import typer
from tqdm import tqdm

from harness.cli.common import _command_line, app
from harness.cli.run import _write_compare_outputs
from harness.gate import run as gate_run
from harness.gate.config import load_config
from harness.scenes.library import resolve_scene
from harness.store.atomic import write_text_atomic
from harness.store.references import load_reference
from reports.ci import junit_xml, markdown_summary
from reports.gate import gate_section


@app.command()
def gate(
    config: Path = typer.Option(Path("gate.toml"), "--config", "-c", help="Gate config (TOML): expectations per "
                                                                        "scene, renderer and budget; see harness/gate/config.py."),
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
    _write_outputs(outcomes, cfg.alpha, out, junit, markdown)
    for o in outcomes:
        for c in o.checks:
            typer.echo(f"{'PASS' if c.passed else 'FAIL'}  {o.expectation.name}  {c.name}: {c.message}")
    failed = sum(not c.passed for o in outcomes for c in o.checks)
    typer.echo(f"gate {'passed' if not failed else f'failed: {failed} check(s)'}")
    raise typer.Exit(1 if failed else 0)


def _write_outputs(outcomes, alpha: float, out: Path, junit: Path | None, markdown: Path | None) -> None:
    """JUnit, the Markdown summary (and $GITHUB_STEP_SUMMARY), and one report per scene."""
    md = markdown_summary(outcomes, alpha)
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
                                        sections=[("gate", "Gate", gate_section(mine, alpha))],
                                        title=f"cbox gate — {sc.name}")
        typer.echo(f"report: {report}", err=True)

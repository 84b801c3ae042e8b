"""The CLI's options and remarks about time: ``--time-repeats``, ``--time-basis``, and the one
warning line when the times were taken on a busy machine. How time is measured: docs/timing.md."""

from __future__ import annotations

from typing import Any

import typer

from cornell_harness.cli.choices import choice_callback
from cornell_harness.cli.output import info


def _checked_repeats(ctx: Any, value: int | None) -> int | None:
    if value is not None and value < 1 and not ctx.resilient_parsing:
        raise typer.BadParameter(f"{value}: give 1 or more (the number of timings of each final render)")
    return value


def time_repeats_option(default: str) -> Any:
    """``--time-repeats K`` of a command whose default is ``default`` (said in its help)."""
    return typer.Option(None, "--time-repeats", metavar="K", callback=_checked_repeats, help=(
        f"Time each final render K times ({default}), interleaved over the renderers (A B A B ...) so that a "
        "change of load hits all alike; time_s is the median, time_s_low/high its 95% interval (Student-t on "
        "log time), the timings in time_samples_s. The image and scores are the first render's (a repeat gives "
        "the same image for a renderer deterministic per seed; info_repeat_images_differ counts those that "
        "did not)."))


def _time_bases() -> tuple[str, ...]:
    from cornell_harness.evaluate.timing_stats import TIME_BASIS_CHOICES

    return TIME_BASIS_CHOICES


_checked_basis = choice_callback("--time-basis", _time_bases)


def time_basis_option(default: str | None, help: str) -> Any:
    """``--time-basis wall|cpu|auto`` (checked as it is parsed), with ``default`` and ``help``."""
    return typer.Option(default, "--time-basis", metavar="|".join(_time_bases()), callback=_checked_basis, help=help)


_BASES_HELP = ("The clock time-derived figures read (time to error, efficiency, slopes against time, equal time): "
               "wall (time_s), cpu (cpu_time_s: the process's CPU time, all threads; not inflated by other "
               "processes on a busy machine) or auto (cpu where other processes took cores from the timed renders, "
               "else wall).")
#: ``--time-basis`` of ``cbox converge`` (default wall).
TimeBasisOpt = time_basis_option("wall", _BASES_HELP + " Default wall. Recorded in experiment.json: cbox report "
                                 "redraws with it.")
#: ``--time-basis`` of ``cbox compare`` (default auto: an equal-time budget on a shared machine is CPU seconds).
CompareTimeBasisOpt = time_basis_option("auto", _BASES_HELP + " Default auto: with --time-budget, decided by the "
                                        "calibration renders, and the budget is CPU seconds when cpu. The table "
                                        "says which was used; experiment.json records it.")


def warn_contention(runs) -> None:
    """One warning line on stderr when ``runs`` (a results table) were timed on a busy machine
    (:func:`cornell_harness.evaluate.timing_quality.timing_quality`); nothing when it was quiet or nothing is known.
    ``--quiet`` drops it with the other remarks: the results alone, whatever the machine's load."""
    from cornell_harness.adapters.api import machine_cores
    from cornell_harness.evaluate.timing_quality import timing_quality

    quality = timing_quality(runs, machine_cores())
    if quality.known and not quality.ok:
        info(quality.line())

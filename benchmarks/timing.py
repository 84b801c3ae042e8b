"""Wall time against CPU time under load (issue 30): when ``--time-basis cpu`` is the better choice, measured.

Two renderers (``pathtracer`` and ``mitsuba`` by default) render ``cornell-box`` at a fixed spp through the
harness's one render path (:func:`cornell_harness.workflows.runner.run_one`, which records ``time_s``,
``cpu_time_s``, the load and the calibration kernel), interleaved A B A B for ``--rounds`` rounds, under
each condition in turn:

- **quiet**: nothing else started (the machine's own background stays);
- **N burners**: N processes ``while 1: pass`` beside the renders (N = 1 and 2 by default, on a machine
  of 2 cores: half-busy and busy).

Per condition and renderer: the medians of wall and CPU time, their spread (the interquartile range over
the median), the calibration kernel and the load; then the ratio of the two renderers' times on each
basis, and how far each ratio moved from the quiet one. An equal-time comparison buys spp in
proportion to 1/time, so a ratio that moves by x% moves the verdict of an equal-time run by x%.

``--markdown FILE`` writes the table into the file's block ``timing.py#load`` (``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/timing.py --markdown docs/timing.md`` (about a minute on 2 cores).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import markdown_blocks
from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.workflows import runner

BLOCK = "timing.py#load"
BURNER = "while 1: pass"


def _burners(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(n)]


def measure(entries, scene, spp: int, rounds: int, burners: int) -> dict[str, list[dict]]:
    """``rounds`` interleaved rounds of every renderer beside ``burners`` burning processes: each render's row."""
    procs = _burners(burners)
    try:
        time.sleep(1.0 if burners else 0.0)  # the burners running before the first render
        rows: dict[str, list[dict]] = {e.name: [] for e in entries}
        for _ in range(rounds):
            for e in entries:
                rec = runner.run_one(e, scene, spp, 0, None)
                if rec.status != "ok":
                    raise SystemExit(f"{e.name}: {rec.status}: {rec.reason}")
                rows[e.name].append(rec.row())
        return rows
    finally:
        for p in procs:
            p.kill()
            p.wait()


def _median(rows: list[dict], key: str) -> float:
    return float(statistics.median(float(r[key]) for r in rows))


def _spread(rows: list[dict], key: str) -> float:
    """Interquartile range over the median: the timing noise of one render."""
    v = np.array([float(r[key]) for r in rows])
    q1, q2, q3 = np.percentile(v, [25, 50, 75])
    return float((q3 - q1) / q2)


def table(results: dict[int, dict[str, list[dict]]], names: list[str], cores: int) -> list[str]:
    """The markdown lines of the measurement."""
    a, b = names
    out = ["| condition | renderer | wall s | wall IQR/median | CPU s | CPU IQR/median | CPU/wall | "
           "calibration ms | load after |", "|---|---|---|---|---|---|---|---|---|"]
    ratios = {}
    for burners, rows in results.items():
        cond = "quiet" if burners == 0 else f"{burners} burner{'s' * (burners > 1)}"
        for name in names:
            r = rows[name]
            wall, cpu = _median(r, "time_s"), _median(r, "cpu_time_s")
            out.append(f"| {cond} | {name} | {wall:.3f} | {_spread(r, 'time_s'):.0%} | {cpu:.3f} | "
                       f"{_spread(r, 'cpu_time_s'):.0%} | {cpu / wall:.2f} | {1e3 * _median(r, 'calibration_s'):.1f} | "
                       f"{_median(r, 'load_after'):.1f} |")
        ratios[cond] = {basis: _median(rows[a], col) / _median(rows[b], col)
                        for basis, col in (("wall", "time_s"), ("cpu", "cpu_time_s"))}
    out += ["", f"Ratio of {a}'s time to {b}'s, and its change from the quiet ratio ({cores} cores):", "",
            "| condition | wall ratio | change | CPU ratio | change |", "|---|---|---|---|---|"]
    quiet = ratios["quiet"]
    for cond, r in ratios.items():
        dw, dc = (markdown_blocks.minus(f"{r[k] / quiet[k] - 1:+.1%}") for k in ("wall", "cpu"))
        out.append(f"| {cond} | {r['wall']:.3f} | {dw} | {r['cpu']:.3f} | {dc} |")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-r", "--renderer", action="append", help="two renderers (default pathtracer, mitsuba)")
    ap.add_argument("--scene", default="cornell-box")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--rounds", type=int, default=7, help="interleaved rounds per condition")
    ap.add_argument("--burners", default="0,1,2", help="conditions: burning processes beside the renders")
    ap.add_argument("--markdown", type=Path, action="append", default=[])
    args = ap.parse_args(argv)
    names = args.renderer or ["pathtracer", "mitsuba"]
    if len(names) != 2:
        ap.error("give two renderers")
    command = markdown_blocks.command_line([sys.argv[0]] + list(sys.argv[1:] if argv is None else argv))
    scene = resolve_scene(args.scene)
    entries = resolve(names)
    for e in entries:  # warm: kernels compiled or loaded, outside every measurement
        runner.run_one(e, scene, 1, 0, None)
    t0 = time.perf_counter()
    results = {int(n): measure(entries, scene, args.spp, args.rounds, int(n)) for n in args.burners.split(",")}
    from cornell_harness.adapters.api import machine_cores

    lines = table(results, names, machine_cores())
    took = time.perf_counter() - t0
    lines += ["", f"{args.scene} at {args.spp} spp, {args.rounds} interleaved rounds per condition. "
              f"Command: `{command}` ({took / 60:.0f} min)."]
    body = "\n".join(lines)
    print(body, flush=True)
    markdown_blocks.write_blocks(args.markdown, {BLOCK: body}, command)
    return 0


if __name__ == "__main__":
    sys.exit(main())

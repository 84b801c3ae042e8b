"""The cost of ``cbox compare-image`` against idiff's on a 256² image (issue 31: within 3× idiff's, excluding a
cold interpreter start).

Each command runs as its own process, as CI runs it, interleaved over ``--rounds`` rounds (A B C A B C ...) so
that a change of load hits all alike; the figure is the median wall time. "Excluding the interpreter start"
subtracts the median of ``python -c pass`` measured in the same rounds. idiff itself is timed when OpenImageIO's
``idiff`` is on the PATH; otherwise its stand-in is OpenImageIO's Python ``ImageBufAlgo.compare`` (what idiff
calls: read both files, per-pixel differences, mean/RMS/PSNR/max and the fail/warn counts), in a Python process,
its interpreter start subtracted the same way.

The test image is a 16-spp Mitsuba render of ``cornell-box`` by ``cbox render`` (or ``--image``); the reference
is the scene's stored one (256²).

Then the same without any start-up (the warm table): one process that has imported both and run each once
times, interleaved, OpenImageIO's read-and-compare and ``cbox compare-image``'s whole command in-process
(``cornell_harness.cli.app.main``: parsing, reading, scoring, the error map, the table), medians of ``--rounds`` × 5
calls; and, for comparison, the same command with ``--all-metrics`` (what a check scored before it scored only
what it names).

``--markdown FILE`` writes the tables into the file's blocks ``compare_image.py#cost`` and
``compare_image.py#warm`` (``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/compare_image.py --markdown BENCHMARKS.md`` (about a minute on 2 cores).
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import markdown_blocks
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import REFERENCE_FILE, load_reference

BLOCK = "compare_image.py#cost"
WARM_BLOCK = "compare_image.py#warm"
ROOT = Path(__file__).resolve().parents[1]
#: idiff's stand-in: what idiff does, through OpenImageIO's Python binding.
OIIO_COMPARE = ("import sys, OpenImageIO as oiio; a, b = oiio.ImageBuf(sys.argv[1]), oiio.ImageBuf(sys.argv[2]); "
                "r = oiio.ImageBufAlgo.compare(a, b, 1e-3, 1e-6); print(r.meanerror, r.rms_error, r.PSNR, "
                "r.maxerror, r.nfail, r.nwarn)")


def _wall(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT)
    took = time.perf_counter() - t0
    if proc.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(cmd)}: exit {proc.returncode}\n{proc.stderr[-2000:]}")
    return took


def commands(image: Path, reference: Path, out: Path) -> dict[str, list[str]]:
    py, cbox = sys.executable, [sys.executable, "-m", "cornell_harness", "compare-image", str(image)]
    idiff = shutil.which("idiff")
    cmds = {"python -c pass (interpreter start)": [py, "-c", "pass"]}
    if idiff:
        cmds["idiff"] = [idiff, str(image), str(reference)]
    else:
        cmds["OpenImageIO ImageBufAlgo.compare (idiff's stand-in)"] = [py, "-c", OIIO_COMPARE, str(image),
                                                                       str(reference)]
    cmds["compare-image --reference FILE --fail delta_e2000_mean=0.1"] = [
        *cbox, "--reference", str(reference), "--fail", "delta_e2000_mean=0.1", "--out", str(out)]
    cmds["compare-image --scene cornell-box (regions, noise yardsticks)"] = [
        *cbox, "--scene", "cornell-box", "--out", str(out)]
    return cmds


def measure(cmds: dict[str, list[str]], rounds: int) -> dict[str, float]:
    for cmd in cmds.values():  # warm: the files and bytecode in the page cache, outside every measurement
        _wall(cmd)
    times: dict[str, list[float]] = {k: [] for k in cmds}
    for _ in range(rounds):
        for name, cmd in cmds.items():
            times[name].append(_wall(cmd))
    return {k: statistics.median(v) for k, v in times.items()}


#: The warm measurement, run in a child process: argv = image, reference, out, rounds; prints three medians.
WARM = """
import contextlib, io, statistics, sys, time
import OpenImageIO as oiio
from cornell_harness.cli.app import main
image, reference, out, rounds = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
args = ["compare-image", image, "--reference", reference, "--fail", "delta_e2000_mean=0.1", "--out", out]
def cbox(argv):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        try:
            main(list(argv))
        except SystemExit:
            pass
def ours():
    cbox(args)
def every():
    cbox(args + ["--all-metrics"])
def theirs():
    a, b = oiio.ImageBuf(image), oiio.ImageBuf(reference)
    oiio.ImageBufAlgo.compare(a, b, 1e-3, 1e-6)
calls = (("theirs", theirs), ("ours", ours), ("every", every))
times = {name: [] for name, _ in calls}
for _, f in calls:
    f()
for _ in range(rounds):
    for name, f in calls:
        t0 = time.perf_counter(); f(); times[name].append(time.perf_counter() - t0)
print(*(statistics.median(times[name]) for name, _ in calls))
"""


def measure_warm(image: Path, reference: Path, out: Path, rounds: int) -> tuple[float, float, float]:
    """(OpenImageIO's read and compare, compare-image's check, the same with --all-metrics) in one warm process:
    median seconds per call."""
    proc = subprocess.run([sys.executable, "-c", WARM, str(image), str(reference), str(out), str(rounds)],
                          capture_output=True, text=True, cwd=ROOT, check=True)
    theirs, ours, every = map(float, proc.stdout.split())
    return theirs, ours, every


def warm_table(theirs: float, ours: float, every: float) -> list[str]:
    return ["| in a warm process | median per call (s) | / idiff's |", "| --- | --- | --- |",
            f"| OpenImageIO ImageBufAlgo.compare, both files read (idiff's stand-in) | {theirs:.4f} | **1.0×** |",
            f"| compare-image --reference FILE --fail delta_e2000_mean=0.1 | {ours:.4f} | **{ours / theirs:.1f}×** |",
            f"| the same with --all-metrics (every metric and the noise yardsticks) | {every:.4f} | "
            f"{every / theirs:.1f}× |"]


def table(medians: dict[str, float]) -> list[str]:
    names = list(medians)
    start, baseline = medians[names[0]], names[1]
    base = medians[baseline] - start
    lines = ["| command | median wall (s) | less interpreter start (s) | / idiff's |", "| --- | --- | --- | --- |"]
    for name in names:
        net = medians[name] - start
        ratio = "" if name == names[0] else f"**{net / base:.1f}×**" if base > 0 else "n/a"
        lines.append(f"| {name} | {medians[name]:.3f} | {'' if name == names[0] else f'{net:.3f}'} | {ratio} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--image", type=Path, help="test image (default: a 16-spp Mitsuba render by cbox render)")
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds")
    ap.add_argument("--markdown", type=Path, action="append", default=[])
    args = ap.parse_args(argv)
    command = markdown_blocks.command_line([sys.argv[0]] + list(sys.argv[1:] if argv is None else argv))
    reference = load_reference(resolve_scene("cornell-box")).folder / REFERENCE_FILE
    with tempfile.TemporaryDirectory() as tmp:
        image = args.image
        if image is None:
            image = Path(tmp) / "m16.exr"
            subprocess.run([sys.executable, "-m", "cornell_harness", "render", "--scene", "cornell-box", "-r", "mitsuba",
                            "--spp", "16", "--out", str(image)], check=True, capture_output=True, cwd=ROOT)
        medians = measure(commands(image, reference, Path(tmp) / "out"), args.rounds)
        warm = measure_warm(image, reference, Path(tmp) / "warm", 5 * args.rounds)
    import os

    lines = table(medians) + ["", f"256×256 (`cornell-box`, a 16-spp Mitsuba render against the stored reference), "
                                  f"median of {args.rounds} interleaved rounds, each command a fresh process, "
                                  f"{os.cpu_count()} cores, {time.strftime('%Y-%m-%d')}. Command: `{command}`."]
    body = "\n".join(lines)
    warm_body = "\n".join(warm_table(*warm) + ["", f"The same image and reference, {5 * args.rounds} interleaved "
                                                    f"calls each, {time.strftime('%Y-%m-%d')}. Command: `{command}`."])
    print(body + "\n\n" + warm_body, flush=True)
    markdown_blocks.write_blocks(args.markdown, {BLOCK: body, WARM_BLOCK: warm_body}, command)
    return 0


if __name__ == "__main__":
    sys.exit(main())

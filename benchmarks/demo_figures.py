"""The demo's figures in the docs: runs ``cbox demo`` and takes its report's figures, unchanged but for the
image grid's resolution, into ``docs/images/`` for the docs site's gallery.

From ``OUT/figures/`` (``cornell-box``'s convergence, the demo's first section):

- the first plotted metric's convergence against spp and against wall time, and its speed/accuracy chart, and the
  bias/variance bars, each as ``docs/images/demo-<its name>.svg``;
- ``images.svg``, the image grid (renderers × image, ΔE₀₀ and FLIP maps), as ``docs/images/demo-images.png`` at
  screen resolution (the run's own PNG is 300 dpi).

Each is recorded in ``docs/images/manifest.json`` (``figure_manifest``) with this command and, as its source, the
``cbox demo`` command it came from. Options after ``--`` go to ``cbox demo`` (``-- --spp 4 -r pathtracer``: a
quick check, into folders of your choosing).

Run: ``.venv/bin/python benchmarks/demo_figures.py`` (the demo's time: about four minutes on 2 cores, numba's
caches warm).
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import figure_manifest
import markdown_blocks
from paper_outputs import FIGURE_DPI

from cornell_harness.evaluate.registry import METRICS, PLOT_METRICS

ROOT = markdown_blocks.ROOT
#: The charts taken, by their stem in ``OUT/figures/``: the first metric the report plots, and the bias bars.
CHARTS = (f"convergence-spp-{PLOT_METRICS[0]}", f"convergence-time-{PLOT_METRICS[0]}",
          f"speed-accuracy-{PLOT_METRICS[0]}", "bias-variance")
GRID = "images"
PREFIX = "demo-"
_METRIC = METRICS[PLOT_METRICS[0]].label
#: What each shows, for the gallery (no docs page shows them).
CAPTIONS = {f"{PREFIX}{CHARTS[0]}.svg": f"cornell-box: {_METRIC} against samples per pixel, every renderer",
            f"{PREFIX}{CHARTS[1]}.svg": f"cornell-box: {_METRIC} against wall time",
            f"{PREFIX}{CHARTS[2]}.svg": f"cornell-box: speed against accuracy ({_METRIC} against time)",
            f"{PREFIX}{CHARTS[3]}.svg": "cornell-box: bias² and variance of each renderer at the top spp",
            f"{PREFIX}{GRID}.png": "cornell-box: each renderer's image, its ΔE00 and FLIP maps, with crops"}


def take_figures(out: Path, images: Path) -> list[Path]:
    """Copy the demo's charts and convert its image grid from ``out/figures`` into ``images``; the files written.
    Raises FileNotFoundError, naming it, for a figure the demo did not write."""
    import cairosvg

    figures = out / "figures"
    missing = [f"{figures / stem}.svg" for stem in (*CHARTS, GRID) if not (figures / f"{stem}.svg").is_file()]
    if missing:
        raise FileNotFoundError(f"the demo wrote no {', '.join(missing)}")
    images.mkdir(parents=True, exist_ok=True)
    written = []
    for stem in CHARTS:
        written.append(shutil.copyfile(figures / f"{stem}.svg", images / f"{PREFIX}{stem}.svg"))
    grid = images / f"{PREFIX}{GRID}.png"
    cairosvg.svg2png(url=str(figures / f"{GRID}.svg"), write_to=str(grid), dpi=FIGURE_DPI)
    return [Path(p) for p in (*written, grid)]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/demo"), help="the demo's folder")
    ap.add_argument("--images", type=Path, default=ROOT / "docs" / "images", help="where the figures go")
    ap.add_argument("demo_args", nargs=argparse.REMAINDER, help="after --: options of cbox demo")
    args = ap.parse_args(argv)
    command = markdown_blocks.command_line([sys.argv[0]] + list(sys.argv[1:] if argv is None else argv))
    demo = ["demo", "--out", str(args.out), *[a for a in args.demo_args if a != "--"]]
    subprocess.run([sys.executable, "-m", "cornell_harness", *demo], check=True, cwd=ROOT)
    out = args.out if args.out.is_absolute() else ROOT / args.out
    written = take_figures(out, args.images)
    figure_manifest.record(written, command, source=f"cbox {shlex.join(demo)}", captions=CAPTIONS)
    print("\n".join(str(p) for p in written))
    return 0


if __name__ == "__main__":
    sys.exit(main())

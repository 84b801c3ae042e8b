"""The paper figure and table of docs/paper-outputs.md, made as a researcher makes them.

Runs the command of issue 31's "Done when" (``cbox converge`` on ``cornell-box-caustics``: the path
tracer with its default sampler and with ``independent`` samples, and SPPM, at 1-64 spp over 2 seeds, the
independent series labelled ``PT (independent)``) into ``--out`` (a rerun resumes it: nothing finished is
rendered again), then takes from its outputs, unchanged but for the figure's resolution:

- ``figures/images.svg`` (renderers × image, ΔE₀₀ and FLIP maps, with crops of the named regions) as
  ``docs/images/paper-images.png``, at screen resolution (the run's own PNG is 300 dpi);
- ``figures/convergence-time-rmse.svg`` as ``docs/images/paper-convergence-time-rmse.svg``;
- ``summary.tex`` as ``docs/paper-summary.tex``;
- the decisive columns of the readable ``summary.csv``, the ones ``summary.tex`` holds, as a Markdown table in
  the block ``paper_outputs.py#table`` of each ``--markdown`` file (``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/paper_outputs.py --markdown docs/paper-outputs.md`` (about a minute on 2 cores, numba's
caches warm).
"""

from __future__ import annotations

import argparse
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

import figure_manifest
import markdown_blocks

ROOT = markdown_blocks.ROOT
BLOCK = "paper_outputs.py#table"
COMMAND = ["converge", "--scene", "cornell-box-caustics", "-r", "pathtracer", "-r", "pathtracer[sampler=independent]",
           "-r", "sppm", "--spp", "1,4,16,64", "--seeds", "2",
           "--series-label", 'pathtracer[sampler="independent"]=PT (independent)']
#: The docs page's figure width in pixels (the figure is 7 in wide).
FIGURE_DPI = 110


def markdown_table(summary_csv: Path, summary: pd.DataFrame) -> list[str]:
    """The readable summary's decisive columns but those no renderer has a value in (as ``summary-wide.tex``
    holds them, where its width allows), each value with its 95% interval."""
    from cornell_harness.reports.summary_columns import decisive_columns, spec

    readable = pd.read_csv(summary_csv)
    headers = [spec(k).text for k in decisive_columns(list(summary.columns))]
    headers = [h for h in headers if h in readable.columns and readable[h].notna().any()]  # a target none reached
    lines = ["| renderer | " + " | ".join(headers) + " |", "|---" * (len(headers) + 1) + "|"]
    for _, row in readable.iterrows():
        cells = []
        for h in headers:
            v, lo, hi = row[h], row.get(f"{h} 95% low"), row.get(f"{h} 95% high")
            text = "—" if pd.isna(v) else f"{v:.3g}" if isinstance(v, float) else str(v)
            if not pd.isna(v) and lo is not None and hi is not None and not (pd.isna(lo) or pd.isna(hi)):
                text += f" ({lo:.2g}–{hi:.2g})"
            cells.append(text)
        lines.append(f"| {row['renderer']} | " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/paper"), help="the experiment folder (resumed if there)")
    ap.add_argument("--markdown", type=Path, action="append", default=[], help="file(s) holding the table block")
    args = ap.parse_args(argv)
    command = markdown_blocks.command_line([sys.argv[0]] + list(sys.argv[1:] if argv is None else argv))
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "cornell_harness", *COMMAND, "--out", str(args.out), "--quiet"], check=True, cwd=ROOT)
    took = time.perf_counter() - t0
    out = (ROOT / args.out) if not args.out.is_absolute() else args.out

    import cairosvg

    images = ROOT / "docs" / "images"
    cairosvg.svg2png(url=str(out / "figures" / "images.svg"), write_to=str(images / "paper-images.png"),
                     dpi=FIGURE_DPI)
    shutil.copyfile(out / "figures" / "convergence-time-rmse.svg", images / "paper-convergence-time-rmse.svg")
    figure_manifest.record([images / "paper-images.png", images / "paper-convergence-time-rmse.svg"], command,
                           source=f"cbox {shlex.join(COMMAND)} --out {args.out}")
    shutil.copyfile(out / "summary.tex", ROOT / "docs" / "paper-summary.tex")
    lines = markdown_table(out / "summary.csv", pd.read_parquet(out / "summary.parquet"))
    lines += ["", f"`cbox {shlex.join(COMMAND)} --out {args.out}` ({time.strftime('%Y-%m-%d')}); in brackets "
                  "the 95% intervals over the 2 seeds; a column no renderer reached (a time to a target) is left "
                  "out, as in `summary.tex`."]
    print(f"took {took / 60:.1f} min (a rerun resumes the folder: nothing finished renders again)", file=sys.stderr)
    body = "\n".join(lines)
    print(body, flush=True)
    markdown_blocks.write_blocks(args.markdown, {BLOCK: body}, command)
    return 0


if __name__ == "__main__":
    sys.exit(main())

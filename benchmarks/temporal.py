"""The table and figures of docs/temporal.md: lag, flicker, ghosting and per-frame ΔE of the real-time renderers
on the two stored animated scenes.

Runs ``cbox sequence`` (:data:`RENDERERS`: the probes at two hysteresis values, temporal accumulation, SVGF and
per-frame OIDN, at 1 spp over ``--seeds`` seeds) on ``cornell-box-moving-light`` and ``cornell-box-orbit`` into
``--out/<scene>``; a folder whose ``sequences.csv`` already holds every (renderer, seed) asked for is read, not
rendered again. Then, from each scene's ``sequences.csv``:

- the table (mean over seeds, in brackets the 95% interval's half-width) in the block ``temporal.py#table`` of each
  ``--markdown`` file (``benchmarks/markdown_blocks.py``);
- the report's lag-against-flicker plane (:func:`cornell_harness.reports.sequence.lag_flicker_plot`) of the
  moving light as ``docs/images/temporal-lag-flicker-cornell-box-moving-light.svg``, recorded in the images' manifest
  (``benchmarks/figure_manifest.py``).

Run: ``.venv/bin/python benchmarks/temporal.py --markdown docs/temporal.md`` (every renderer, both scenes: about
16 minutes for 3 seeds on 2 cores shared with other work, 14 of them the moving light's 144 frames).
"""

from __future__ import annotations

import argparse
import shlex
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

import figure_manifest
import markdown_blocks

ROOT = markdown_blocks.ROOT
BLOCK = "temporal.py#table"
SCENES = ("cornell-box-moving-light", "cornell-box-orbit")
#: The scenes whose lag/flicker plane is drawn: those with a change followed by rest (the orbit moves to its
#: last frame, so it has no lag; its table has ghosting).
LAG_SCENES = ("cornell-box-moving-light",)
RENDERERS = ("probes", "probes[hysteresis=0.9]", "pathtracer+temporal", "pathtracer+svgf", "pathtracer+oidn")
#: The table's columns: (sequences.csv column, header).
COLUMNS = (("lag", "lag (frames)"), ("flicker", "flicker"), ("ghosting", "ghosting"),
           ("delta_e2000_mean", "ΔE₀₀ per frame"), ("time_per_frame_s", "s / frame"))


def sequence_args(scene: str, seeds: int, out: Path) -> list[str]:
    """The ``cbox sequence`` arguments of one scene."""
    renderers = [a for r in RENDERERS for a in ("-r", r)]
    return ["sequence", "--scene", scene, *renderers, "--spp", "1", "--seeds", str(seeds), "--out", str(out)]


def done(folder: Path, seeds: int) -> bool:
    """Whether ``folder``'s sequences.csv holds every renderer at every seed (then it is not rendered again)."""
    path = folder / "sequences.csv"
    if not path.is_file():
        return False
    rows = pd.read_csv(path)
    return set(zip(rows["renderer"], rows["seed"])) >= {(r, s) for r in RENDERERS for s in range(seeds)}


def cell(values: pd.Series, digits: str, lag_bound=None) -> str:
    """Mean over seeds, the 95% interval's half-width in brackets (none for one seed). With ``lag_bound``, a lag:
    ``> N`` where a seed did not settle within the sequence (:func:`cornell_harness.evaluate.temporal.lag_over_seeds`),
    N the frames shown after the change."""
    from cornell_harness.evaluate.convergence import mean_ci
    from cornell_harness.evaluate.temporal import lag_over_seeds

    v = pd.to_numeric(values, errors="coerce").dropna()
    m, h = lag_over_seeds(v) if lag_bound is not None else mean_ci(v)
    if pd.isna(m):
        return "—"
    if m == float("inf"):
        return f"> {int(lag_bound)}"
    return markdown_blocks.minus(f"{m:{digits}}" + ("" if pd.isna(h) else f" (± {h:.2g})"))


def table(rows_by_scene: dict[str, pd.DataFrame]) -> list[str]:
    """One Markdown table: a row per scene and renderer, the flicker floor with each scene's first row."""
    lines = ["| scene | renderer | " + " | ".join(h for _, h in COLUMNS) + " | flicker floor |",
             "|---" * (len(COLUMNS) + 3) + "|"]
    for scene, rows in rows_by_scene.items():
        ok = rows[rows["status"] == "ok"]
        for i, name in enumerate(RENDERERS):
            g = ok[ok["renderer"] == name]
            bound = pd.to_numeric(g["lag_bound"], errors="coerce").dropna() if "lag_bound" in g else []
            cells = [cell(g[c], ".3g", bound.iloc[0] if c == "lag" and len(bound) else None) for c, _ in COLUMNS]
            floor = f"{float(rows['flicker_floor'].iloc[0]):.3g}" if i == 0 else ""
            lines.append(f"| {scene if i == 0 else ''} | `{name}` | " + " | ".join(cells) + f" | {floor} |")
    return lines


def figure(scene: str, rows: pd.DataFrame, images: Path) -> Path:
    """The report's lag/flicker plane of ``scene`` as an SVG file in ``images``."""
    from cornell_harness.reports.plots import PALETTE
    from cornell_harness.reports.sequence import lag_flicker_plot

    colours = {name: PALETTE[i % len(PALETTE)] for i, name in enumerate(RENDERERS)}
    svg = lag_flicker_plot(rows[rows["status"] == "ok"], colours)
    path = images / f"temporal-lag-flicker-{scene}.svg"
    path.write_text(svg, encoding="utf-8")
    return path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path("out/temporal"), help="folder of the runs, one per scene")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per renderer (confidence intervals over them)")
    ap.add_argument("--markdown", type=Path, action="append", default=[], help="file(s) holding the table block")
    args = ap.parse_args(argv)
    command = markdown_blocks.command_line([sys.argv[0]] + list(sys.argv[1:] if argv is None else argv))
    out = args.out if args.out.is_absolute() else ROOT / args.out
    images = ROOT / "docs" / "images"
    rows_by_scene, sources = {}, []
    for scene in SCENES:
        cli = sequence_args(scene, args.seeds, args.out / scene)
        sources.append(f"cbox {shlex.join(cli)}")
        if not done(out / scene, args.seeds):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "cornell_harness", *cli[:-1], str(out / scene), "--quiet"],
                           check=True, cwd=ROOT)
            print(f"{scene}: {(time.perf_counter() - t0) / 60:.1f} min", file=sys.stderr)
        rows = pd.read_csv(out / scene / "sequences.csv")
        rows_by_scene[scene] = rows[rows["seed"] < args.seeds]
        if scene in LAG_SCENES:
            figure_manifest.record([figure(scene, rows_by_scene[scene], images)], command, source=sources[-1])
    lines = table(rows_by_scene)
    lines += ["", f"{'; '.join(f'`{s}`' for s in sources)} ({time.strftime('%Y-%m-%d')}): mean over {args.seeds} "
                  "seeds, in brackets the 95% interval's half-width. ΔE₀₀ per frame: each frame's mean ΔE₀₀, "
                  "averaged over the frames."]
    body = "\n".join(lines)
    print(body, flush=True)
    markdown_blocks.write_blocks(args.markdown, {BLOCK: body}, command)
    return 0


if __name__ == "__main__":
    sys.exit(main())

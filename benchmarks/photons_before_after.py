"""Issue 34's photon changes, before and after, in one run: time to caustic relMSE on ``cornell-box-caustics``.

"Before" is a git worktree of the code before the change (``--before``;
by default the script makes one of commit :data:`BEFORE_COMMIT` in
``out/photons-before`` with ``git worktree add --detach``), "after" this tree. Each (version,
renderer, seed) cell runs in a child process with that tree first on
``PYTHONPATH`` (the same venv, the same harness: only ``src/cornell_harness/renderers/``
differs) through the convergence workflow
(:func:`cornell_harness.workflows.converge.run_experiment`, what ``cbox converge``
runs; resumable in ``--out``), the versions interleaved seed by seed so
that both see the same machine load. The table is the median over seeds of
the time at which each first reaches a caustic-region relMSE of 0.05 and
0.01 (:func:`cornell_harness.evaluate.convergence.time_to_target`), in CPU time
(the work: what other processes on a shared machine move least), wall time,
and spp (SPPM's iterations: what no load moves), each with after / before. What changed: SPPM's initial radius (pixel footprints at each
visible point instead of at the scene's centre) and where photons are
stored (nowhere with diffuse reflectance 0: cornell-box-caustics has no
such surface, so photonmap's images are bit-identical and its times differ
by noise only).

With ``--markdown BENCHMARKS.md`` the table goes into that file's block
``photons_before_after.py`` (``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/photons_before_after.py --seeds 3 --markdown BENCHMARKS.md``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd

import markdown_blocks

HERE = Path(__file__).resolve().parents[1]
TARGETS = (("region.caustic.rel_mse", 0.05), ("region.caustic.rel_mse", 0.01))
#: renderer -> the spp list of its run (SPPM: iterations, one progressive render).
RUNS = {"sppm": "1,2,4,...,128", "photonmap": "1,2,4,...,64"}


def cell(tree: Path, renderer: str, spp: str, seed: int, out: Path) -> None:
    """Run in the child: one renderer, one seed, from ``tree``'s package (first on sys.path). The "before" commit
    predates the one-package layout: its modules are ``harness.*`` and ``renderers``."""
    import importlib

    top, renderers = ("cornell_harness", "cornell_harness.renderers") if (tree / "src").is_dir() else ("harness", "renderers")
    resolve = importlib.import_module(f"{top}.adapters.registry").resolve
    resolve_scene = importlib.import_module(f"{top}.scenes.library").resolve_scene
    load_reference = importlib.import_module(f"{top}.store.references").load_reference
    converge = importlib.import_module(f"{top}.workflows.converge")
    run_experiment = converge.run_experiment
    spp_lists = importlib.import_module(f"{top}.workflows.spp_list") if top == "cornell_harness" else converge
    parse_spp_list = spp_lists.parse_spp_list
    package = importlib.import_module(renderers)
    assert Path(package.__file__).resolve().is_relative_to(tree.resolve()), package.__file__
    scene = resolve_scene("cornell-box-caustics")
    table = run_experiment(out, scene, load_reference(scene), resolve([renderer]), parse_spp_list(spp), [seed])
    table.to_csv(out / "table.csv", index=False)


#: The commit before issue 34's photon changes (main at the start of that work).
BEFORE_COMMIT = "c731790"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--before", type=Path, default=None,
                    help=f"a worktree of the code before the change (default: made of {BEFORE_COMMIT} in "
                         "out/photons-before)")
    ap.add_argument("--seeds", type=int, default=3, help="seeds 0 .. N-1 of each (version, renderer)")
    ap.add_argument("--out", type=Path, default=Path("out/bench-photons-before-after"),
                    help="experiment folders (resumable)")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the table into this file's block \"photons_before_after.py\" (repeatable)")
    ap.add_argument("--cell", nargs=5, metavar=("TREE", "RENDERER", "SPP", "SEED", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.cell:
        tree, renderer, spp, seed, out = args.cell
        cell(Path(tree), renderer, spp, int(seed), Path(out))
        return
    from cornell_harness.evaluate.convergence import time_to_target

    before = args.before or HERE / "out" / "photons-before"
    if args.before is None and not before.exists():
        subprocess.run(["git", "worktree", "add", "--detach", str(before), BEFORE_COMMIT], cwd=HERE, check=True)
    trees = {"before": before.resolve(), "after": HERE}
    tables: dict[tuple[str, str], list[pd.DataFrame]] = {}
    for seed in range(args.seeds):
        for renderer, spp in RUNS.items():
            for version, tree in trees.items():
                out = (args.out / f"{version}-{renderer}-seed{seed}").resolve()
                if not (out / "table.csv").exists():
                    print(f"{version} {renderer} seed {seed} ...", flush=True)
                    code = tree / "src" if (tree / "src").is_dir() else tree
                    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(code), str(HERE / "benchmarks")]))
                    subprocess.run([sys.executable, str(Path(__file__).resolve()), "--cell", str(tree), renderer, spp,
                                    str(seed), str(out)], env=env, check=True, cwd=tree)
                tables.setdefault((version, renderer), []).append(pd.read_csv(out / "table.csv"))
    # Per target: CPU time (the work: what other processes on the machine move least), wall time, and spp
    # (SPPM's iterations: what no load can move), each before / after / after ÷ before.
    measures = (("CPU time", "cpu_time_s", " s"), ("wall time", "time_s", " s"), ("spp", "spp", ""))
    lines = [f"| renderer (seeds 0-{args.seeds - 1}, medians) | target | "
             + " | ".join(f"{m}: before / after / **after ÷ before**" for m, _, _ in measures) + " |",
             "|---|---|" + "---|" * len(measures)]
    for renderer, spp in RUNS.items():
        t = {v: pd.concat(tables[(v, renderer)]) for v in trees}
        t = {v: g[g["status"] == "ok"] for v, g in t.items()}
        for metric, target in TARGETS:
            cells = []
            for _, col, unit in measures:
                b, a = (time_to_target(t[v], metric, target, time_column=col) for v in trees)
                show = [f"{x:.2f}{unit}" if np.isfinite(x) else "not reached" for x in (b, a)]
                ratio = f"{a / b:.2f}" if np.isfinite(a) and np.isfinite(b) else "–"
                cells.append(f"{show[0]} / {show[1]} / **{ratio}**")
            lines.append(f"| {renderer} (spp {spp}) | caustic relMSE ≤ {target:g} | " + " | ".join(cells) + " |")
    for renderer in RUNS:
        last = [pd.concat(tables[(v, renderer)]) for v in trees]
        last = [float(g[g["spp"] == g["spp"].max()]["region.caustic.rel_mse"].median()) for g in last]
        lines.append(f"| {renderer} | caustic relMSE at the last checkpoint | {last[0]:.4f} / {last[1]:.4f} | | |")
    print("\n".join(lines))
    markdown_blocks.write_blocks(args.markdown, {"photons_before_after.py": "\n".join(lines)})


if __name__ == "__main__":
    main()

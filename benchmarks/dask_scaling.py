"""Sweeps on Dask (issue 17): cells per minute on 1 and 2 local workers against in-process, the scheduler's
overhead per task, what a cell ships back, and what the client spends per cell.

1. **Scaling**: a fixed sweep, ``pathtracer`` on ``cornell-box`` (256², spp 1-16, seeds 0..N-1: N cells),
   through :func:`cornell_harness.workflows.converge.run_experiment` (what ``cbox converge`` runs) on each backend:
   in-process (``CBOX_THREADS`` = every core), ``--workers 1`` (one process, every core) and ``--workers
   2`` (two processes, one core each). Each run in a fresh folder, workers warmed first (renderer loaded,
   numba's cache read, one render); the three backends open at once and their runs interleaved round by
   round (the machine's other load falls on all three), medians over ``--repeats``: cells per minute, and
   the cells' own render time (the rest of a cell is scoring its five checkpoints and storing it).
2. **Overhead per task**: ``--tasks`` tasks that do nothing through
   :meth:`cornell_harness.workflows.executor.DaskExecutor.run` on 1 and 2 workers: wall time per task (ms),
   submission to result in the client, i.e. the scheduler's and the transfers' cost of a cell.
3. **Bytes**: each cell's packed result as shipped back (rows + final image, zlib;
   :func:`cornell_harness.workflows.executor.pack`) and what is sent once per worker (the scene and the reference).
4. **Client per cell**: unpacking a result and writing the cell (image, rows) and ``results.parquet``, the
   work only the client does, at the sweep's table size.

``--markdown FILE`` (repeatable) writes part 1-3's table into the file's block ``dask_scaling.py#scaling``
(``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/dask_scaling.py --markdown BENCHMARKS.md`` (not ``distributed.py``: a script of that name would
shadow the ``distributed`` package it measures); ``--seeds 4 --repeats 3``: about 8 minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import pickle
import statistics
import tempfile
import time
from pathlib import Path

import markdown_blocks
from cornell_harness.adapters.api import default_threads
from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows import cells as cells_module
from cornell_harness.workflows.converge import run_experiment
from cornell_harness.workflows.spp_list import parse_spp_list
from cornell_harness.workflows.executor import DaskExecutor, Task, open_executor, pack, unpack

SPPS = parse_spp_list("1-16")


def _noop(i: int) -> int:
    return i


def _warm(scene, reference) -> str:
    """Load the path tracer in a worker and render once: what the first cell of a sweep would pay."""
    entry = cells_module.entry_for(resolve(["pathtracer"])[0].spec, {})
    cells_module.render_cell(entry, scene, [1], 0, reference)
    return os.environ.get("CBOX_THREADS", "")


def sweep(executor, scene, ref, seeds: int) -> tuple[float, float, list[int]]:
    """One run of the sweep in a fresh folder: its wall time, the cells' median render time (their ``time_s``
    at the top spp; the rest of a cell is scoring its checkpoints and storing it), the bytes of each result."""
    sent = len(getattr(executor, "bytes_back", []))
    with tempfile.TemporaryDirectory() as out:
        t = time.perf_counter()
        table = run_experiment(Path(out), scene, ref, resolve(["pathtracer"]), SPPS, list(range(seeds)),
                               executor=executor)
        wall = time.perf_counter() - t
    assert (table["status"] == "ok").all(), table[["status", "reason"]]
    render = float(table[table["spp"] == SPPS[-1]]["time_s"].median())
    return wall, render, getattr(executor, "bytes_back", [])[sent:]


def overhead(executor: DaskExecutor, tasks: int) -> float:
    """Seconds per no-op task, submission to result (median of 3 rounds)."""
    rounds = []
    for r in range(3):
        batch = [Task(f"noop-{r}-{i}-{time.time_ns()}", "noop", _noop, (i,)) for i in range(tasks)]
        t = time.perf_counter()
        assert sum(1 for o in executor.run(batch) if o.error is None) == tasks
        rounds.append((time.perf_counter() - t) / tasks)
    return statistics.median(rounds)


def client_cost(scene, ref, cells: int, table_cells: int) -> tuple[float, float]:
    """Seconds the client spends per cell storing it (unpack, image, rows), over ``cells`` cells, and seconds
    to write ``results.parquet`` holding ``table_cells`` cells' rows."""
    import pandas as pd

    from cornell_harness.store.experiments import RESULTS_FILE, write_parquet_atomic
    from cornell_harness.workflows.cells import Cell
    from cornell_harness.workflows.converge import store_cell

    (entry,) = resolve(["pathtracer"])
    packed = pack(cells_module.render_cell_task(Cell("pathtracer__seed0", entry.spec, {}, 0, tuple(SPPS),
                                                     scene.content_hash()), scene, ref))
    with tempfile.TemporaryDirectory() as out:
        t = time.perf_counter()
        for s in range(cells):
            cell = Cell(f"pathtracer__seed{s}", entry.spec, {}, s, tuple(SPPS), scene.content_hash())
            rows = store_cell(Path(out), cell, None, *unpack(packed), SPPS)
        store = (time.perf_counter() - t) / cells
        table = pd.concat([rows] * table_cells, ignore_index=True)
        t = time.perf_counter()
        write_parquet_atomic(table, Path(out) / RESULTS_FILE)
        return store, time.perf_counter() - t


def scaling_markdown(names: list[str], runs: dict, threads: dict, per_task: dict, seeds: int,
                     load: tuple[float, float]) -> list[str]:
    """Parts 1-3 as BENCHMARKS.md tabulates them: per backend the median wall time (each run's in brackets),
    cells per minute, speed against in-process, render time per cell, ms per no-op task, kB shipped per cell."""
    base = statistics.median(r[0] for r in runs["in-process"])
    lines = [f"| run (load {load[0]:.1f} → {load[1]:.1f}) | wall s | cells/min | vs in-process | render s/cell | "
             "ms/task | kB/cell back |", "|---|---|---|---|---|---|---|"]
    for name in names:
        walls = [r[0] for r in runs[name]]
        wall = statistics.median(walls)
        sizes = [size for r in runs[name] for size in r[2]]
        if name == "in-process":
            label = f"in-process (`CBOX_THREADS` {default_threads()})"
        else:
            per = threads[name].split(",")
            label = f"`{name}` (`CBOX_THREADS` {per[0]}{' each' if len(per) > 1 else ''})"
        ratio = base / wall
        lines.append(
            f"| {label} | {wall:.1f} ({', '.join(f'{w:.1f}' for w in walls)}) | {seeds / wall * 60:.1f} | "
            f"{markdown_blocks.bold(f'{ratio:.2f}', name != 'in-process' and ratio > 1)} | "
            f"{statistics.median(r[1] for r in runs[name]):.2f} | "
            f"{f'{per_task[name] * 1e3:.1f}' if name in per_task else '—'} | "
            f"{f'{statistics.median(sizes) / 1e3:.0f}' if sizes else '—'} |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=8, help="cells in the sweep")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--tasks", type=int, default=400, help="no-op tasks per overhead round")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the table into this file's block dask_scaling.py#scaling (repeatable)")
    args = ap.parse_args()
    scene = resolve_scene("cornell-box")
    ref = load_reference(scene)
    cores = os.cpu_count() or 1
    print(f"cornell-box 256², pathtracer, spp {SPPS[0]}-{SPPS[-1]}, {args.seeds} cells, {cores} cores, "
          f"median of {args.repeats}")
    print(f"shared once per worker: scene {len(pickle.dumps(scene)) / 1e3:.0f} kB, reference "
          f"{len(pickle.dumps(ref)) / 1e6:.2f} MB")

    # Every backend open at once (idle workers cost nothing) and the runs interleaved, round by round:
    # whatever else the machine does is spread over all three, not charged to one.
    load_start = os.getloadavg()[0]
    names = ["in-process"] + [f"--workers {n}" for n in (1, 2)]
    runs: dict[str, list[tuple[float, float, list[int]]]] = {name: [] for name in names}
    with open_executor() as here, open_executor(workers=1) as one, open_executor(workers=2) as two:
        backends = dict(zip(names, (here, one, two)))
        _warm(scene, ref)
        threads = {name: ",".join(sorted(b.client.run(_warm, scene, ref).values())) for name, b in
                   backends.items() if name != "in-process"}
        for _ in range(args.repeats):
            for name, backend in backends.items():
                runs[name].append(sweep(backend, scene, ref, args.seeds))
        per_task = {name: overhead(b, args.tasks) for name, b in backends.items() if name != "in-process"}
    base = statistics.median(r[0] for r in runs["in-process"])
    print(f"{'backend':<32} {'wall s':>7} {'cells/min':>9} {'vs in-process':>13} {'render s/cell':>13} "
          f"{'ms/task':>8} {'kB/cell':>8}")
    for name in names:
        wall = statistics.median(r[0] for r in runs[name])
        render = statistics.median(r[1] for r in runs[name])
        sizes = [size for r in runs[name] for size in r[2]]
        label = name + (f" (CBOX_THREADS {threads[name]})" if name in threads else "")
        print(f"{label:<32} {wall:7.2f} {args.seeds / wall * 60:9.1f} {base / wall:13.2f} {render:13.2f} "
              f"{f'{per_task[name] * 1e3:.2f}' if name in per_task else '':>8} "
              f"{f'{statistics.median(sizes) / 1e3:.0f}' if sizes else '':>8}")
        print(f"{'':<32} walls: {', '.join(f'{r[0]:.1f}' for r in runs[name])}")
    table = scaling_markdown(names, runs, threads, per_task, args.seeds, (load_start, os.getloadavg()[0]))
    print("\n" + "\n".join(table) + "\n")
    store, results_s = client_cost(scene, ref, args.seeds, 10_000)
    print(f"client per cell: {store * 1e3:.1f} ms to unpack and store it (image, rows); results.parquet of "
          f"10,000 cells ({10_000 * len(SPPS)} rows): {results_s * 1e3:.0f} ms per write")
    markdown_blocks.write_blocks(args.markdown, {"dask_scaling.py#scaling": "\n".join(table)})


if __name__ == "__main__":
    main()

"""HDR-FLIP's map with numba and without it (numpy's kernels, evaluate/hdr_flip_numpy.py): seconds per map.

Run: ``.venv/bin/python benchmarks/flip_without_numba.py --markdown BENCHMARKS.md`` (half a minute). Each kernel
set runs in a process of its own, numba made unimportable in the second, as in a core install (no ``[ours]``);
one thread. The stored cornell-box noise batch against its reference (256²), median of ``--rounds``: once with
the reference's side computed afresh (its cache cleared), once with it cached, as scoring many images against
one reference finds it. ``--markdown FILE`` writes the table into the file's block ``flip_without_numba.py#time``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import markdown_blocks

BLOCK = "flip_without_numba.py#time"
_CHILD = "--child"


def _child(rounds: int) -> None:
    """Time the maps in this process (numba hidden first when asked) and print one JSON line."""
    if sys.argv[2] == "numpy":
        sys.modules["numba"] = None  # before anything imports it
    from cornell_harness.evaluate import flip, hdr_flip
    from cornell_harness.scenes.library import references_root
    from cornell_harness.store.exr import read_exr

    folder = references_root() / "cornell-box"
    ref, noise = read_exr(folder / "reference.exr"), read_exr(folder / "noise.exr")
    flip.flip_map(noise, ref)  # numba's compile or cache load, not timed
    fresh, cached = [], []
    for _ in range(rounds):
        hdr_flip.REFERENCE_SIDES.clear()
        t = time.perf_counter()
        flip.flip_map(noise, ref)
        fresh.append(time.perf_counter() - t)
        t = time.perf_counter()
        flip.flip_map(noise, ref)
        cached.append(time.perf_counter() - t)
    print(json.dumps({"kernels": "numba" if hdr_flip.njit is not None else "numpy",
                      "fresh": statistics.median(fresh), "cached": statistics.median(cached)}))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--markdown", type=Path, action="append", default=[])
    args = ap.parse_args()
    command = markdown_blocks.command_line()
    env = {**os.environ, "CBOX_THREADS": "1"}
    rows = [json.loads(subprocess.run([sys.executable, __file__, _CHILD, kernels, str(args.rounds)], env=env,
                                      capture_output=True, text=True, check=True).stdout)
            for kernels in ("numba", "numpy")]
    lines = ["| kernels | reference side computed (s) | reference side cached (s) |", "|---|---|---|"]
    lines += [f"| {r['kernels']} | {r['fresh']:.3f} | {r['cached']:.3f} |" for r in rows]
    body = "\n".join(lines + ["", f"256² `cornell-box` (its stored noise batch against its reference), one thread, "
                                  f"median of {args.rounds}, {os.cpu_count()} cores, load average "
                                  f"{os.getloadavg()[0]:.1f}, {time.strftime('%Y-%m-%d')}. Command: `{command}`."])
    print(body, flush=True)
    markdown_blocks.write_blocks(args.markdown, {BLOCK: body}, command)
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == [_CHILD]:
        _child(int(sys.argv[3]))
    else:
        sys.exit(main())

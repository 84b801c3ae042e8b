"""What each installed distribution costs on disk: run it with a virtual environment's own Python.

    VENV/bin/python benchmarks/install_size.py [--top N]

Sums the sizes of the files each distribution's RECORD lists (its package, its bundled libraries, its
scripts), largest first, in MB (10^6 bytes), then the total of them all and of the environment's folder
(``du``: the interpreter's links, pip and setuptools, and the ``__pycache__`` written since, included).
No import of the project: it measures any environment, the core alone or ``[all]``.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import subprocess
import sys


def sizes() -> dict[str, int]:
    """Bytes per distribution installed in this interpreter's environment."""
    out: dict[str, int] = {}
    for dist in importlib.metadata.distributions():
        total = 0
        for f in dist.files or ():
            path = f.locate()
            if path.is_file():
                total += path.stat().st_size
        name = dist.metadata["Name"]
        out[name] = out.get(name, 0) + total
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=0, help="list only the N largest (default: all)")
    args = ap.parse_args()
    found = sorted(sizes().items(), key=lambda kv: -kv[1])
    for name, size in found[:args.top or None]:
        print(f"{name:32s} {size / 1e6:8.1f}")
    print(f"{'(all distributions)':32s} {sum(s for _, s in found) / 1e6:8.1f}")
    du = subprocess.run(["du", "-sb", sys.prefix], capture_output=True, text=True).stdout.split()[0]
    print(f"{'(the environment, du -sb)':32s} {int(du) / 1e6:8.1f}")


if __name__ == "__main__":
    main()

"""Where each committed figure came from: ``manifest.json`` beside the figures, written by the script that makes them.

A script that writes figures into ``docs/images/`` (or its ``--images`` folder) records each one there::

    {"figures": [{"file": "whitted-penumbra.svg",
                  "command": ".venv/bin/python benchmarks/whitted.py",
                  "source": null,
                  "commit": "28011bf…"}, ...]}

- ``command``: the exact command that wrote the file (``markdown_blocks.command_line()``, as the markers name it);
- ``source``: the ``cbox`` command whose output the script took the figure from, if it took it from one
  (``benchmarks/paper_outputs.py`` copies ``cbox converge``'s figures), else null;
- ``commit``: the checkout the figure was made from, ``git rev-parse HEAD``, with ``-dirty`` when ``src/`` or
  ``benchmarks/`` had uncommitted changes (the first records, written by hand from the commands the docs gave,
  name the commit that added the figure);
- ``caption`` (optional): what the figure shows, for a figure no docs page shows with its own alt text.

The docs site's gallery (``scripts/docs_site.py``) reads it, so a figure's command is the producer's own record,
never a list kept by hand; ``tests/test_gallery.py`` fails on a figure of ``docs/images/`` that has none.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from cornell_harness.store.atomic import write_json_atomic

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = "manifest.json"
#: What the gallery shows: every file of the folder with one of these suffixes must be recorded.
FIGURE_SUFFIXES = (".png", ".svg")


def checkout() -> str:
    """The commit the sources are at, ``-dirty`` if ``src/`` or ``benchmarks/`` differ from it; ``unknown``
    outside a git checkout."""
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()

    try:
        head = git("rev-parse", "HEAD")
        dirty = git("status", "--porcelain", "--", "src", "benchmarks")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("-dirty" if dirty else "")


def read(folder: Path) -> dict[str, dict]:
    """The folder's records by file name (empty if it has no manifest)."""
    path = Path(folder) / MANIFEST
    if not path.is_file():
        return {}
    return {e["file"]: e for e in json.loads(path.read_text(encoding="utf-8"))["figures"]}


def record(paths: list[Path], command: str, source: str | None = None, commit: str | None = None,
           captions: dict[str, str] | None = None) -> None:
    """Record ``paths`` (figures just written) as made by ``command`` (from ``source``; ``captions`` by file name),
    each in the manifest of its own folder; the other records are kept. Raises FileNotFoundError for a path that
    is not there."""
    by_folder: dict[Path, list[Path]] = {}
    for p in map(Path, paths):
        if not p.is_file():
            raise FileNotFoundError(f"{p}: no such figure to record")
        by_folder.setdefault(p.parent, []).append(p)
    commit = commit or checkout()
    for folder, files in by_folder.items():
        entries = read(folder)
        for p in files:
            entries[p.name] = {"file": p.name, "command": command, "source": source, "commit": commit}
            if captions and p.name in captions:
                entries[p.name]["caption"] = captions[p.name]
        write_json_atomic(folder / MANIFEST, {"figures": [entries[k] for k in sorted(entries)]})

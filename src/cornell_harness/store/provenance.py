"""Provenance of a run: renderer and library versions, machine, seeds, date, what a reader needs to reproduce it."""

from __future__ import annotations

import pandas as pd

#: Libraries whose versions every report records.
LIBRARIES = ("cornell-harness", "numpy", "scipy", "pandas", "colour-science", "scikit-image", "OpenImageIO",
             "mitsuba", "drjit", "embreex", "numba", "pyrender2", "flip-evaluator")


def provenance(config: dict, runs: pd.DataFrame) -> dict:
    """Versions of renderers and libraries, machine, seeds, date: what a reader needs to reproduce."""
    import importlib.metadata as md
    import os
    import platform

    versions = {}
    for lib in LIBRARIES:
        try:
            versions[lib] = md.version(lib)
        except md.PackageNotFoundError:
            pass
    for renderer, g in runs.groupby("renderer", sort=False):
        v = g["version"].dropna()
        if len(v):
            versions[f"renderer {renderer}"] = str(v.iloc[0])
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), cpu)
    except OSError:
        pass
    seeds = sorted({int(s) for s in runs["seed"].dropna()})
    return {"versions": versions, "machine": f"{cpu}, {os.cpu_count()} CPUs, {platform.system()} {platform.release()}, "
                                             f"Python {platform.python_version()}",
            "seeds": seeds, "date": config.get("date", ""), "kind": config.get("kind", "")}

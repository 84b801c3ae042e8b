"""Our path tracer against Mitsuba 3 on cornell-box-caustics at equal spp: error image-wide and per region.

Both are unbiased path tracers with the same strategies (NEE with MIS at
diffuse vertices, delta BSDFs sampled, caustics found by BSDF sampling
alone), so at equal spp their errors should agree; this measures how far
they do, over several seeds, since a single seed's caustic RMSE moves by
±8% (147 pixels whose samples are heavy-tailed). Prints a Markdown table
of the per-seed values and their medians, and the ratio ours / Mitsuba; ``--markdown BENCHMARKS.md`` writes
it into that file's block ``caustics.py`` (``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/caustics.py --spp 256 --seeds 5 --markdown BENCHMARKS.md``
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

import markdown_blocks

from cornell_harness.adapters.registry import resolve
from cornell_harness.scenes.library import resolve_scene
from cornell_harness.store.references import load_reference
from cornell_harness.workflows.runner import run_one

#: (label, how to read it from a run record)
FIGURES = (
    ("ΔE mean", lambda r: r.metrics["delta_e2000_mean"]),
    ("RMSE", lambda r: r.metrics["rmse"]),
    ("caustic RMSE", lambda r: r.regions["caustic"]["rmse"]),
    ("glass-shadow RMSE", lambda r: r.regions["glass-shadow"]["rmse"]),
    ("mirror RMSE", lambda r: r.regions["mirror"]["rmse"]),
    ("glass RMSE", lambda r: r.regions["glass"]["rmse"]),
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spp", type=int, default=256, help="samples per pixel of every render (default 256)")
    ap.add_argument("--seeds", type=int, default=5, help="seeds 0 .. N-1 per renderer (default 5)")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the table into this file's block \"caustics.py\" (repeatable)")
    args = ap.parse_args()
    scene = resolve_scene("cornell-box-caustics")
    reference = load_reference(scene)
    values: dict[str, list[list[float]]] = {}
    for entry in resolve(["pathtracer", "mitsuba"]):
        rows = []
        for seed in range(args.seeds):
            rec = run_one(entry, scene, args.spp, seed, reference)
            assert rec.status == "ok", rec.reason
            rows.append([f(rec) for _, f in FIGURES])
        values[entry.name] = rows
    print(f"cornell-box-caustics, {args.spp} spp, seeds 0-{args.seeds - 1}\n")
    table = ["| figure | " + " | ".join(f"{n} (seeds; median)" for n in values) + " | ours / Mitsuba (medians) |",
             "|---|" + "---|" * (len(values) + 1)]
    for k, (label, _) in enumerate(FIGURES):
        med = {n: statistics.median(row[k] for row in rows) for n, rows in values.items()}
        cells = [", ".join(f"{row[k]:.4g}" for row in rows) + f"; **{med[n]:.4g}**" for n, rows in values.items()]
        table.append(f"| {label} | " + " | ".join(cells) + f" | {med['pathtracer'] / med['mitsuba']:.3f} |")
    print("\n".join(table))
    markdown_blocks.write_blocks(args.markdown, {"caustics.py": "\n".join(table)})


if __name__ == "__main__":
    main()

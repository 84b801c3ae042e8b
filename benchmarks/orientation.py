"""The orientation check's false-alarm rate on correct renders, and how often it catches a flipped or mirrored one.

``cbox compare-image`` notes "image looks flipped vertically" (or mirrored, or both) by the rule of
``src/cornell_harness/evaluate/orientation.py``. Here every stored scene is rendered by our renderers (the path
tracer; the AO renderer for an ambient-occlusion scene) at each of ``--spp`` for seeds 0 .. ``--seeds`` - 1, and
each render is checked as it is (a note is a false alarm), then flipped, mirrored and rotated 180° (any note is a
catch: on a scene symmetric under one transform, another is the same image). A transform under which the
reference itself changes by a relMSE under :data:`SYMMETRIC` leaves nothing to catch ("symmetric" in the table:
the furnaces under all three, the light panel mirrored, the two rooms flipped). Low spp is the hard case: the
most noise for the check to mistake.

``--markdown FILE`` writes the table into that file's block ``orientation.py`` (``benchmarks/markdown_blocks.py``).

Run: ``.venv/bin/python benchmarks/orientation.py --seeds 50 --markdown BENCHMARKS.md`` (a few minutes on 2 cores).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import markdown_blocks

from cornell_harness.adapters.registry import resolve
from cornell_harness.evaluate.orientation import TRANSFORMS, check_orientation
from cornell_harness.scenes.library import resolve_scene, scene_names
from cornell_harness.scenes.quantities import DEFAULT_QUANTITY
from cornell_harness.store.references import load_reference
from cornell_harness.workflows.render import render_checked

#: The relMSE of the reference transformed against itself under which a scene counts as symmetric under it.
SYMMETRIC = 1e-3

#: The renderer each quantity's scenes are rendered with.
RENDERERS = {DEFAULT_QUANTITY: "pathtracer", "ambient_occlusion": "ao"}


def tally(scene_name: str, spp: int, seeds: int) -> dict:
    """For ``seeds`` renders of the scene at ``spp``: false alarms as they are, catches per transform."""
    scene = resolve_scene(scene_name).at_frame(0)  # an animated scene: its first frame
    reference = load_reference(scene)
    (entry,) = resolve([RENDERERS[scene.quantity]])
    itself = check_orientation(reference.image, reference).transformed
    out = {"renders": 0, "false": 0, **{name: 0 if itself[name] >= SYMMETRIC else None for name in TRANSFORMS}}
    for seed in range(seeds):
        image = render_checked(entry, scene, spp, seed).image
        out["renders"] += 1
        out["false"] += check_orientation(image, reference, spp).looks is not None
        for name, transform in TRANSFORMS.items():
            if out[name] is not None:
                out[name] += check_orientation(transform(image), reference, spp).looks is not None
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spp", type=int, nargs="+", default=[1, 4, 16], help="spps to render at (default 1 4 16)")
    ap.add_argument("--seeds", type=int, default=50, help="seeds 0 .. N-1 per scene and spp (default 50)")
    ap.add_argument("--markdown", type=Path, action="append", default=[],
                    help="write the table into this file's block \"orientation.py\" (repeatable)")
    args = ap.parse_args()
    short = {name: name.split(" (")[0].replace("flipped vertically and mirrored horizontally", "both")
             for name in TRANSFORMS}
    table = ["| scene | spp | renders | false alarms | " + " | ".join(f"caught {s}" for s in short.values()) + " |",
             "|---|---|---|---|" + "---|" * len(short)]
    totals = {"renders": 0, "false": 0}
    for name in scene_names():
        for spp in args.spp:
            t = tally(name, spp, args.seeds)
            totals["renders"] += t["renders"]
            totals["false"] += t["false"]
            table.append(f"| {name} | {spp} | {t['renders']} | {t['false']} | "
                         + " | ".join("symmetric" if t[n] is None else str(t[n]) for n in TRANSFORMS) + " |")
            print(table[-1], flush=True)
    table.append(f"\nFalse alarms: {totals['false']} of {totals['renders']} correct renders.")
    print("\n".join(table))
    markdown_blocks.write_blocks(args.markdown, {"orientation.py": "\n".join(table)})


if __name__ == "__main__":
    main()

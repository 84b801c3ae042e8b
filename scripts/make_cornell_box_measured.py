"""Write src/cornell_harness/references/cornell-box-measured/scene.toml from Cornell's measured box data.

The data are ``src/cornell_harness/scenes/data/cornell-pcg.json`` (Cornell Program of Computer
Graphics, "Cornell Box Data"): geometry in millimetres, the camera, the measured
reflectance spectra of the white, green and red surfaces and the light's emission
spectrum. The scene keeps the published numbers: lengths in mm with
``length_scale = 0.001`` (:mod:`cornell_harness.scenes.units`), spectra as sampled.

What this script decides, and the header it writes says:
- every quad is wound so that its front side (our convention: counter-clockwise seen
  from the front) faces into the box, or out of a block, whatever the published order;
- the ceiling has the light's 130 × 105 mm cut-out: it is the four strips around the
  hole, and the light fills the hole at the published height y = 548.8 (so no surface
  lies on another; mi.cornell_box() and others instead lower the light 0.5 mm);
- the light's own surface reflects 0.78, flat (the data's ``light_reflectance_constant``);
- ``rgb_convention = "scene_light"`` (see RGB_CONVENTION_WHY).

Run it only to regenerate the file:

    python scripts/make_cornell_box_measured.py > src/cornell_harness/references/cornell-box-measured/scene.toml
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

DATA = Path(__file__).resolve().parents[1] / "src" / "cornell_harness" / "scenes" / "data" / "cornell-pcg.json"
#: The box's interior, for orienting the walls' normals inwards (mm).
INSIDE = np.array([278.0, 274.4, 279.6])
#: How far from a coloured wall (mm) the colour-bleeding strips reach.
STRIP_MM = 100.0
RGB_CONVENTION = "scene_light"
RGB_CONVENTION_WHY = [
    "# rgb_convention = scene_light: an RGB renderer gets reflectances white-balanced to this",
    "# warm (~3100 K) light, so a surface lit directly by it has exactly the spectral colour and",
    "# only interreflections (colour bleeding) carry the RGB error. Under illuminant_E (the",
    "# mi.cornell_box() values) a perfect white is (1.205, 0.948, 0.909), which tints the whole",
    "# image red a second time: fine for a white light, wrong for this one. Scoring renderers",
    "# against the spectral reference should measure the renderers, not that avoidable error;",
    "# benchmarks/spectral.py measures both conventions (docs/spectral.md).",
]


def fmt(x: float) -> str:
    x = round(float(x), 6) + 0.0
    return repr(int(x)) if x == int(x) else repr(x)


def vec(v) -> str:
    return "[" + ", ".join(fmt(x) for x in v) + "]"


def normal(quad: np.ndarray) -> np.ndarray:
    """The quad's normal by our winding (counter-clockwise seen from the front: (b - a) × (c - a))."""
    return np.cross(quad[1] - quad[0], quad[2] - quad[0])


def facing(quad, towards: np.ndarray | None = None, away: np.ndarray | None = None) -> np.ndarray:
    """``quad`` (4 × 3), its order reversed if its front does not face ``towards`` (or faces ``away``)."""
    q = np.asarray(quad, dtype=np.float64)
    centre = q.mean(axis=0)
    d = (towards - centre) if towards is not None else (centre - away)
    return q if normal(q) @ d > 0 else q[::-1].copy()


def ceiling_with_cutout(ceiling: np.ndarray, light: np.ndarray) -> list[np.ndarray]:
    """The ceiling rectangle less the light's rectangle: four quads around the hole, all at the ceiling's height."""
    y = float(ceiling[0, 1])
    x0, x1 = float(ceiling[:, 0].min()), float(ceiling[:, 0].max())
    z0, z1 = float(ceiling[:, 2].min()), float(ceiling[:, 2].max())
    hx0, hx1 = float(light[:, 0].min()), float(light[:, 0].max())
    hz0, hz1 = float(light[:, 2].min()), float(light[:, 2].max())
    assert np.all(ceiling[:, 1] == y) and np.all(light[:, 1] == y), "the cut-out assumes the published y = 548.8"

    def rect(a0, a1, b0, b1):
        return np.array([[a0, y, b0], [a1, y, b0], [a1, y, b1], [a0, y, b1]])

    return [rect(x0, x1, z0, hz0), rect(x0, x1, hz1, z1), rect(x0, hx0, hz0, hz1), rect(hx1, x1, hz0, hz1)]


def mesh(name: str, material: str, quads: list[np.ndarray], emitter: str | None = None) -> list[str]:
    verts = np.concatenate(quads)
    faces = [[4 * i, 4 * i + 1, 4 * i + 2, 4 * i + 3] for i in range(len(quads))]
    out = ["[[meshes]]", f'name = "{name}"', f'material = "{material}"',
           "vertices = [" + ", ".join(vec(v) for v in verts) + "]", f"faces = {faces}"]
    if emitter:
        out.append(f'emitter = {{ radiance = {{ spectrum = "{emitter}" }} }}')
    return out + [""]


def spectrum(name: str, wavelengths, values, extrapolation: str = "zero", note: str = "") -> list[str]:
    out = [f"[spectra.{name}]"] + ([f"# {note}"] if note else [])
    out += [f"wavelengths_nm = {vec(wavelengths)}", f"values = {vec(values)}"]
    if extrapolation != "zero":
        out.append(f'extrapolation = "{extrapolation}"')
    return out + [""]


def main() -> None:
    d = json.loads(DATA.read_text(encoding="utf-8"))
    q, sp, cam = d["quads"], d["spectra"], d["camera"]
    position = np.array(cam["position"], dtype=np.float64)
    out = [
        "# The real Cornell box: Cornell's measured geometry (mm), camera and spectra, from",
        "# src/cornell_harness/scenes/data/cornell-pcg.json (Cornell University Program of Computer Graphics,",
        '# "Cornell Box Data"), written by scripts/make_cornell_box_measured.py. Lengths are as',
        "# published, in mm, with length_scale = 0.001 (scene units: metres). Every quad is wound to",
        "# face into the box (out of a block); the ceiling has the light's cut-out and the light",
        "# fills it at the published y = 548.8. Seen from the camera red is on the left.",
        "# Box pixel filter and unbounded max_depth, as cornell-box.",
        *RGB_CONVENTION_WHY,
        "format = 1",
        'name = "cornell-box-measured"',
        'description = "the real Cornell box: measured geometry (mm), camera, reflectance and emission spectra"',
        'features = ["triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"]',
        "length_scale = 0.001",
        "",
        "[camera]",
        'type = "pinhole"',
        f"position = {vec(position)}",
        f"look_at = {vec(position + np.array(cam['direction'], dtype=np.float64))}",
        f"up = {vec(cam['up'])}",
        f"fov_deg = {fmt(cam['fov_deg'])}",
        'fov_axis = "smaller"',
        "resolution = [256, 256]",
        "",
        "[render]",
        "max_depth = -1",
        'pixel_filter = "box"',
        "",
        "[colour]",
        'observer = "CIE1931_2"',
        'output = "linear_srgb_d65"',
        f'rgb_convention = "{RGB_CONVENTION}"',
        'light = "light"',
        "",
    ]
    w = sp["wavelengths_nm"]
    for name in ("white", "green", "red"):
        out += spectrum(name, w, sp[f"{name}_reflectance"])
    e = sp["light_emission"]
    out += spectrum("light", e["wavelengths_nm"], e["values"], note=e["note"])
    k = float(sp["light_reflectance_constant"])
    out += spectrum("light-surface", [w[0], w[-1]], [k, k], "constant", "the light's surface: reflectance 0.78, flat")
    for name in ("white", "green", "red"):
        out += ["[materials." + name + "]", 'type = "diffuse"', f'reflectance = {{ spectrum = "{name}" }}', ""]
    out += ["[materials.light-surface]", 'type = "diffuse"', 'reflectance = { spectrum = "light-surface" }', ""]

    light = np.array(q["light"]["vertices"], dtype=np.float64)
    walls = [("floor", "floor"), ("back", "back"), ("green-wall", "right_green"), ("red-wall", "left_red")]
    for name, key in walls:
        out += mesh(name, q[key]["material"], [facing(q[key]["vertices"], towards=INSIDE)])
    ceiling = np.array(q["ceiling"]["vertices"], dtype=np.float64)
    out += mesh("ceiling", q["ceiling"]["material"],
                [facing(s, towards=INSIDE) for s in ceiling_with_cutout(ceiling, light)])
    for name, key in (("short-block", "short_block"), ("tall-block", "tall_block")):
        quads = [np.array(x, dtype=np.float64) for x in d[key]["quads"]]
        centre = np.concatenate(quads).mean(axis=0)
        out += mesh(name, d[key]["material"], [facing(x, away=centre) for x in quads])
    out += mesh("light", "light-surface", [facing(light, towards=INSIDE)], emitter="light")
    out += regions()
    print("\n".join(out).rstrip())


def regions() -> list[str]:
    red_x = 549.6  # the red wall's nearest point to the box's axis
    big = 1e4
    return [
        "# Named image regions (src/cornell_harness/evaluate/regions.py); boxes in mm, like the geometry.",
        "[regions.walls]", 'objects = ["back", "red-wall", "green-wall"]',
        'description = "the back wall and the two coloured side walls"', "",
        "[regions.blocks]", 'objects = ["short-block", "tall-block"]', 'description = "both blocks, every visible face"',
        "",
        "[regions.floor]", 'objects = ["floor"]', 'description = "the floor, including the blocks\' shadows"', "",
        "[regions.light]", 'objects = ["light"]', 'description = "the light seen directly"', "",
        "[regions.bleed-red]", 'objects = ["floor", "back", "ceiling"]',
        f"box = {{ min = [{fmt(red_x - STRIP_MM)}, {-big:g}, {-big:g}], max = [{big:g}, {big:g}, {big:g}] }}",
        f'description = "white floor, back wall and ceiling within {STRIP_MM:g} mm of the red wall: its colour '
        'bleeding"', "",
        "[regions.bleed-green]", 'objects = ["floor", "back", "ceiling"]',
        f"box = {{ min = [{-big:g}, {-big:g}, {-big:g}], max = [{fmt(STRIP_MM)}, {big:g}, {big:g}] }}",
        f'description = "white floor, back wall and ceiling within {STRIP_MM:g} mm of the green wall: its colour '
        'bleeding"',
    ]


if __name__ == "__main__":
    main()

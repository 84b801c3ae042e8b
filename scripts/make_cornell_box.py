"""Write src/cornell_harness/references/cornell-box/scene.toml from Mitsuba 3's ``mi.cornell_box()``.

Geometry, materials, light and camera are taken from Mitsuba's own scene
dictionary, so the file can be cross-checked against Mitsuba directly. Two
settings differ on purpose (see the header this writes): a box pixel filter and
unbounded ``max_depth``. Run it only to regenerate the file:

    python scripts/make_cornell_box.py > src/cornell_harness/references/cornell-box/scene.toml
"""

import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")

# Mitsuba's canonical shapes, counter-clockwise seen from their outward normal.
RECTANGLE = (np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float), [[0, 1, 2, 3]])
CUBE = (
    np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float),
    # vertex index = 4*(x>0) + 2*(y>0) + (z>0); each face wound outward
    [[0, 4, 5, 1], [2, 3, 7, 6], [4, 6, 7, 5], [0, 1, 3, 2], [1, 5, 7, 3], [0, 2, 6, 4]],
)
ORDER = ["floor", "ceiling", "back", "green-wall", "red-wall", "small-box", "large-box", "light"]


def fmt(x: float, digits: int | None = None) -> str:
    x = float(x) if digits is None else round(float(x), digits) + 0.0
    return repr(int(x)) if x == int(x) else repr(x)


def vec(v, digits: int | None = None) -> str:
    return "[" + ", ".join(fmt(x, digits) for x in v) + "]"


def point(v) -> str:
    # Mitsuba's transforms are float32: 6 decimals keep all their precision
    # and drop float32 noise such as cos(90°) = -4.4e-8.
    return vec(v, 6)


def main() -> None:
    d = mi.cornell_box()
    cam = d["sensor"]
    m = np.array(cam["to_world"].matrix, dtype=np.float64)
    origin, forward, up = m[:3, 3], m[:3, 2], m[:3, 1]
    out = [
        "# Cornell box: geometry, materials, light and camera of Mitsuba 3's mi.cornell_box(),",
        "# written by scripts/make_cornell_box.py. Two settings differ from mi.cornell_box():",
        "#  - render.pixel_filter = box (Mitsuba's is gaussian) for per-pixel comparison;",
        "#  - render.max_depth = -1 (unbounded, Russian roulette), not Mitsuba's 8: cutting paths",
        "#    at 8 segments removes about 1.7% of the red channel's energy (3% on the walls), a",
        "#    bias that would otherwise be blamed on photon mapping and probe GI.",
        "format = 1",
        'name = "cornell-box"',
        'description = "Mitsuba 3 mi.cornell_box(): RGB Cornell box, box filter, unbounded depth"',
        'features = ["triangle_mesh", "diffuse", "area_light", "pinhole_camera", "box_filter"]',
        "",
        "[camera]",
        'type = "pinhole"',
        f"position = {point(origin)}",
        f"look_at = {point(origin + forward)}",
        f"up = {point(up)}",
        f"fov_deg = {fmt(cam['fov'])}",
        f"fov_axis = \"{cam['fov_axis']}\"",
        f"resolution = [{cam['film']['width']}, {cam['film']['height']}]",
        "",
        "[render]",
        "max_depth = -1",
        'pixel_filter = "box"',
        "",
    ]
    for name in ("white", "green", "red"):
        out += [f"[materials.{name}]", 'type = "diffuse"', f"reflectance = {vec(d[name]['reflectance']['value'])}", ""]
    for name in ORDER:
        shape = d[name]
        verts, faces = RECTANGLE if shape["type"] == "rectangle" else CUBE
        m = np.array(shape["to_world"].matrix, dtype=np.float64)
        world = verts @ m[:3, :3].T + m[:3, 3]
        out += ["[[meshes]]", f'name = "{name}"', f"material = \"{shape['bsdf']['id']}\""]
        out.append("vertices = [" + ", ".join(point(v) for v in world) + "]")
        out.append("faces = " + repr(faces))
        if "emitter" in shape:
            out.append(f"emitter = {{ radiance = {vec(shape['emitter']['radiance']['value'])} }}")
        out.append("")
    out += REGIONS
    print("\n".join(out).rstrip())


#: The named regions of the stored scene (not part of its content hash).
REGIONS = [
    "# Named image regions, for per-region metrics (src/cornell_harness/evaluate/regions.py): a pixel belongs to a",
    "# region when every camera ray through it first hits one of the region's objects. Regions do not",
    "# change the image, so they are not part of the scene's content hash (the reference stays valid).",
    "[regions.walls]", 'objects = ["back", "red-wall", "green-wall"]',
    'description = "the back wall and the two coloured side walls"', "",
    "[regions.boxes]", 'objects = ["small-box", "large-box"]', 'description = "both boxes, every visible face"', "",
    "[regions.floor]", 'objects = ["floor"]', 'description = "the floor, including the boxes\' shadows"', "",
    "[regions.light]", 'objects = ["light"]', 'description = "the area light seen directly"', "",
    "[regions.back-edge]", 'objects = ["floor", "back"]', "box = { min = [-1.01, -1.01, -1.01], max = [1.01, -0.9, -0.9] }",
    'description = "where the floor meets the back wall (within 0.1): a density estimate\'s disc leaves the '
    'surface here"',
]


if __name__ == "__main__":
    main()

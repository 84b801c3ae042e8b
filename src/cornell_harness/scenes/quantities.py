"""What a scene's image means (its quantity), and the definition of ambient occlusion an AO scene pins.

A scene's top-level ``quantity`` is one of :data:`QUANTITIES`; ``radiance``
when absent. Each renderer declares the quantities it computes (an adapter's
``quantities``, ``("radiance",)`` when absent) and the runner never runs, or
scores, a renderer on a scene whose quantity it does not compute
(:func:`cornell_harness.adapters.registry.missing_features`).

Ambient occlusion
-----------------
The anchors disagree on four things (pbrt-v4's ``AOIntegrator``, Mitsuba
0.6's ``ao``, GTAO; Jimenez et al. 2016 §3), so an ``ambient_occlusion`` scene
pins all four in its ``[ambient_occlusion]`` table, and :class:`AmbientOcclusion`
holds them:

- **maximum distance**: an occluder counts only if it is nearer than this,
  ``max_distance`` in scene units or ``max_distance_relative`` as a fraction of
  the scene's size (:meth:`cornell_harness.scenes.model.Scene.extent`, its bounding
  box's diagonal); ``inf`` for no limit;
- **weighting** (:data:`AO_WEIGHTINGS`): ``cosine``, the ambient occlusion
  integral A = 1/π ∫ V(ω) cos θ dω (the fraction of a uniform sky's irradiance
  that arrives; pbrt-v4 with ``cossample``), or ``uniform``,
  A = 1/(2π) ∫ V(ω) dω (the unoccluded solid angle, Zhukov et al. 1998's
  obscurance with a step falloff);
- **normal** (:data:`AO_NORMALS`): the hemisphere is around the
  ``geometric`` or the ``shading`` normal (the same for our flat triangles and
  analytic spheres; they differ once a scene has interpolated normals); the
  hemisphere is on the side the camera sees, so a back face is not black;
- **miss value**: the pixel value where the camera ray hits nothing.

V(ω) = 1 where the ray leaves the surface without hitting anything within
the maximum distance. A pixel is the box-filtered mean of A over its
footprint, written as grey (A in all three channels of the image), so that
every image in the harness has one shape.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Every quantity a scene's image may hold, with what it means.
QUANTITIES: dict[str, str] = {
    "radiance": "linear-sRGB radiance arriving through each pixel (cornell_harness.scenes.model's units)",
    "ambient_occlusion": "ambient occlusion A in [0, 1] at the first surface each pixel sees (grey)",
}
#: The quantity of a scene that does not say.
DEFAULT_QUANTITY = "radiance"
#: What the AO integral weights directions by.
AO_WEIGHTINGS: dict[str, str] = {
    "cosine": "A = 1/pi ∫ V cos θ dω: ambient occlusion (cosine-weighted)",
    "uniform": "A = 1/(2 pi) ∫ V dω: obscurance with a step falloff (uniform over the hemisphere)",
}
AO_NORMALS = ("geometric", "shading")


def has_colour(quantity: str) -> bool:
    """Whether images of ``quantity`` are colours (radiance): then colour differences (ΔE) and a key-value
    exposure apply; an ambient-occlusion image is one value per pixel, written as grey."""
    return quantity == "radiance"


@dataclass(frozen=True)
class AmbientOcclusion:
    """The AO definition a scene pins (module docstring). ``max_distance`` is in scene units, resolved."""

    max_distance: float
    weighting: str
    normal: str
    miss_value: float

    def hash_payload(self) -> dict:
        # inf is not JSON: the content hash writes an unbounded distance as a string.
        d = self.max_distance
        return {"max_distance": d if math.isfinite(d) else "inf", "weighting": self.weighting,
                "normal": self.normal, "miss_value": self.miss_value}


def parse_ambient_occlusion(err, table: dict, size: float) -> AmbientOcclusion:
    """The ``[ambient_occlusion]`` table (checked by the scene schema); ``err(field, message)`` is the loader's
    error of the file, ``size`` the scene's."""
    given = [k for k in ("max_distance", "max_distance_relative") if k in table]
    if len(given) != 1:
        raise err("ambient_occlusion", "give exactly one of max_distance (scene units) and max_distance_relative "
                                       f"(fraction of the scene's size), got {len(given) or 'neither'}"
                  + (f": {', '.join(given)}" if given else ""))
    value = float(table[given[0]])
    distance = value if given[0] == "max_distance" else value * size
    return AmbientOcclusion(distance, table["weighting"], table["normal"], float(table["miss_value"]))

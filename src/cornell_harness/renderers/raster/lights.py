"""Area emitters as point lights, for renderers that only light with points.

A one-sided area emitter of radiance L and area A with normal n has radiant
intensity ``I(theta) = L*A*cos(theta)`` (theta from n, zero behind); cut
into small pieces, each piece is such a light at its centroid, exact as the
distance to the lit point grows.
"""

from __future__ import annotations

import math

import numpy as np

from cornell_harness.scenes.model import Scene

#: Point lights that all area emitters together are split into (about).
DEFAULT_LIGHTS = 32


def light_samples(scene: Scene, n_lights: int = DEFAULT_LIGHTS) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]:
    """The point lights standing in for the scene's area emitters.

    Returns ``(position, normal, radiance, area)`` per light: a light of
    radiant intensity ``radiance * area * max(cos(theta), 0)`` (theta from
    ``normal``). Each emitter triangle is cut into k*k congruent sub-triangles
    (k = round(sqrt(n_lights * share of the total emitter area)), at least 1)
    and gets one light at each sub-triangle's centroid.
    """
    tris = []
    for m in scene.emitters:
        for t in m.triangles:
            a, b, c = m.vertices[t]
            cross = np.cross(b - a, c - a)
            area = 0.5 * float(np.linalg.norm(cross))
            if area > 0.0:
                tris.append((a, b, c, cross / (2.0 * area), area, np.asarray(m.radiance, dtype=np.float64)))
    total = sum(t[4] for t in tris)
    out = []
    for a, b, c, normal, area, radiance in tris:
        k = max(1, int(round(math.sqrt(n_lights * area / total))))
        e1, e2 = (b - a) / k, (c - a) / k
        centres = []
        for i in range(k):
            for j in range(k - i):
                centres.append(a + (i + 1 / 3) * e1 + (j + 1 / 3) * e2)  # upward sub-triangle
                if i + j <= k - 2:
                    centres.append(a + (i + 2 / 3) * e1 + (j + 2 / 3) * e2)  # downward sub-triangle
        for p in centres:
            out.append((p, normal, radiance, area / (k * k)))
    return out

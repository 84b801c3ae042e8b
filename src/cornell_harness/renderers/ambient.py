"""Direct light plus an ambient term shadowed by ambient occlusion: the classic real-time approximation.

What real-time renderers did before (and often still do instead of) global
illumination: exact direct light, and for all indirect light one constant
**ambient radiance** La, reflected by each surface as if it arrived from
every direction of its hemisphere that is not blocked nearby. Here, per
camera sample (:func:`cornell_harness.renderers.core.visible_points.camera_visible_points`):
the camera path follows mirrors and glass to its first diffuse point x
(weight β·ρ), collecting emission seen on the way and next-event estimated
direct light at x, exactly as the path tracer's direct light in expectation;
then it adds

    β·ρ·La·A(x),   A(x) = 1/π ∫_H V(x, ω) cos θ dω,

since a Lambertian surface under uniform incident radiance La, blocked where
V = 0, reflects ρ/π ∫ La V cos θ dω = ρ·La·A. A is estimated as in
:mod:`cornell_harness.renderers.ao` (pbrt-v4's ``AOIntegrator``, :mod:`cornell_harness.renderers.core.occlusion`):
``ao_samples`` cosine-weighted directions about x's normal on the side the
path arrived, each an occlusion ray up to ``ao_max_distance`` (relative to
the scene's size, :meth:`cornell_harness.scenes.model.Scene.extent`), counting
V ∈ {0, 1} (the cosine over the pdf cos θ/π is 1: nothing to divide). So the
image estimates direct light + ρ·La·AO with a short-range AO, and what the
harness measures against the full-GI reference is the approximation itself:
``estimator = "biased"``, not converging to the reference as spp grows.

How La is chosen (setting ``ambient``)
--------------------------------------
- ``radiosity`` (default), computed from the scene alone: the ambient term of
  Cohen, Chen, Wallace and Greenberg 1988, "A Progressive Refinement Approach
  to Fast Radiosity Image Generation" (SIGGRAPH '88), §4. There the ambient
  radiosity is R·Σ_j ΔB_j·A_j/A_total: the unshot radiosities ΔB_j spread
  over the scene by the area-weighted guess of a form factor, F_*j =
  A_j/A_total, times the interreflection factor R = 1/(1 − ρ̄) with ρ̄ =
  Σ ρ_i A_i / Σ A_i the area-weighted mean reflectance. We compute direct
  light exactly, i.e. the emitters' power has been shot: the unshot energy
  left is the first reflection of it, Σ_j ΔB_j A_j, which the same
  area-weighted guess puts at ρ̄·Φ (Φ: the emitters' total power). Divided
  by π (radiosity to radiance of a Lambertian surface), per channel:

      La = ρ̄ / (1 − ρ̄) · Φ / (π · A_total),   Φ = Σ_emitters π·Le·area.

  Implemented exactly so (:mod:`cornell_harness.renderers.core.ambient_radiance`, shared
  with :mod:`cornell_harness.renderers.whitted`'s constant ambient): A_total sums every triangle's area (each
  surface once, one side) and every sphere's 4πr²; ρ per surface is the
  fraction of power it sends on: a diffuse albedo, a mirror's reflectance,
  and 1 for glass (lossless: what it does not reflect it transmits; the
  table :func:`cornell_harness.renderers.core.bsdf.material_tables` already holds 1 for it);
  emitters count with their material's reflectance; emitters are one-sided
  Lambertian, hence Φ = π·Le·area. The paper's text was not at hand when this
  was written: the form of its §4 ambient given above is as secondary
  descriptions of it state it; what is implemented is exactly the formula
  above, derived in this paragraph. It ignores where light actually goes:
  power that leaves an open scene (cornell-box's open front), occlusion
  beyond ``ao_max_distance``, and colour bleeding, which it averages away.
- ``oracle``: the one constant per channel that minimises the squared error
  against the scene's stored reference: an **oracle**, not an estimate a
  renderer could make, for measuring the most any constant ambient could buy.
  The harness fits it, not this renderer (:data:`AOAmbient.reference_fit`,
  :class:`cornell_harness.adapters.api.ReferenceFit`): least squares in closed form
  per channel, c = Σ B·(R − D) / Σ B² over all pixels
  (:mod:`cornell_harness.evaluate.reference_fit`), with D the direct-only image and B
  the image of the ambient term alone at La = 1. It costs **two renders**
  with the same seed: D (``ambient = none``) and the image at La = 1
  (``ambient = constant``), whose direct parts are then identical sample by
  sample, so B is their difference; the image is D + c·B (the render at
  La = c, up to float rounding), each checkpoint with its own c. No variance
  image is given. The reference exists at the stored scene's resolution and
  content only: another resolution or max_depth is refused before anything
  renders. Called directly (not through the harness's render path) with
  ``oracle``, this renderer refuses (ValueError).
- ``constant``: La = ``ambient_radiance`` in every channel.
- ``none``: direct light only (La = 0, no occlusion rays): what the ambient
  term buys is measured against it.

``RenderResult.info["ambient_radiance"]`` records La per channel (for a
bounded max_depth, the value at the camera's first hit, see below), and the
radiosity terms (``mean_reflectance``, ``emitted_power``, ``total_area``) or
the oracle's label.

Max depth
---------
The walk follows the scene's ``max_depth`` as the toolkit's visible points do
(the camera segment is segment 1; specular bounces count): NEE at a visible
point at depth d happens when d + 1 ≤ max_depth, so direct light needs
max_depth ≥ 2; with **max_depth 1** the image is the emission the camera
rays meet, alone (no specular bounce either), and no ambient is added. The ambient term
stands for light reflected k ≥ 1 times before reaching x, which takes
d + 1 + k ≤ max_depth segments, so at a visible point at depth d it is cut to
the K = max_depth − d − 1 bounces that fit (K = ∞ when unbounded): for
``radiosity`` La_K = Φ/(π A_total)·Σ_{k=1..K} ρ̄^k (so max_depth 2 gives
exactly the direct-only image); for ``oracle`` the constant applies where
K ≥ 1. With unbounded depth and ρ̄ = 1 in a channel the series diverges and
the render is refused (ValueError).

Random numbers, from the ``sampler`` setting's stream (:mod:`cornell_harness.renderers.core.sampler`;
default ``independent``, the sampler the gate's expectations were measured
with): the visible-point walk uses the toolkit's per-vertex layout, drawn from the pass's stream;
occlusion ray s of a sample draws its 2D sample from the sampler's block
:data:`cornell_harness.renderers.core.sampler.OCCLUSION`, far above any vertex's. The image depends on
the seed only, bit for bit, for any thread count (:func:`cornell_harness.renderers.core.schedule.render_image`);
passes double, so power-of-two checkpoints are free.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from cornell_harness.adapters.api import ReferenceFit, RenderResult, Setting, default_threads
from cornell_harness.scenes.model import Scene
from cornell_harness.renderers.core.adapter import ToolkitRenderer, warmed_geometry
from cornell_harness.renderers.core.ambient_radiance import bounces_left, radiosity_ambient, scene_surfaces
from cornell_harness.renderers.core.geometry import SceneGeometry
from cornell_harness.renderers.core.occlusion import DEFAULT_AO_MAX_DISTANCE, occlusion_segment
from cornell_harness.renderers.core.rays import add_unoccluded, head, shadow_buffer
from cornell_harness.renderers.core.sampler import (OCCLUSION, Stream, independent, occlusion_dim, path_point,
                                                    sample_2d, sampler_setting)
from cornell_harness.renderers.core.sampling import jit
from cornell_harness.renderers.core.schedule import render_image
from cornell_harness.renderers.core.settings import with_defaults
from cornell_harness.renderers.core.visible_points import camera_visible_points

#: Ways of choosing La (module docstring).
AMBIENTS = ("radiosity", "oracle", "none", "constant")


@jit
def _ambient_rays(found, vp, value, stream, first, sample, tfar, offset, occ):
    """Occlusion ray ``sample`` of each visible point ``found[j]`` (of ``vp``, path ``first + found[j]`` of
    the pass's ``stream``) carrying ``value[j]`` (skipped if all 0)."""
    k = 0
    for j in range(found.size):
        v = (value[j, 0], value[j, 1], value[j, 2])
        if v[0] == 0.0 and v[1] == 0.0 and v[2] == 0.0:
            continue  # nothing to add (a black surface, or no bounce left): no ray
        q = found[j]
        x = (vp.position[q, 0], vp.position[q, 1], vp.position[q, 2])
        n = (vp.normal[q, 0], vp.normal[q, 1], vp.normal[q, 2])
        u = sample_2d(stream, path_point(stream, first + q), occlusion_dim(sample))
        occlusion_segment(occ, k, x, n, True, u, tfar, offset, q, v)
        k += 1
    return k


class Shading:
    """One render's trace function: direct light (the toolkit's visible points) plus the ambient term."""

    def __init__(self, geom: SceneGeometry, scene: Scene, ambient, samples: int, tfar: float):
        """``ambient(depth)``: La (m, 3) or (3,) at visible points of those depths (:func:`by_depth`), or None
        for no ambient term."""
        self.geom, self.scene, self.ambient, self.samples, self.tfar = geom, scene, ambient, samples, tfar

    def trace(self, first: int, stop: int, pixels: int, stream: Stream) -> np.ndarray:
        L, vp = camera_visible_points(self.geom, self.scene, first, stop, pixels, stream)
        if self.ambient is None:
            return L
        f = np.flatnonzero(vp.found)
        # weight = β·ρ, so β·ρ·La·A is weight·La times the mean visibility of the samples.
        value = vp.weight[f] * self.ambient(vp.depth[f]) / self.samples
        occ = shadow_buffer(len(f))
        for s in range(self.samples):
            k = _ambient_rays(f, vp, value, stream, first, s, self.tfar, self.geom.offset, occ)
            seg = head(occ, k)
            add_unoccluded(L, seg, self.geom.unoccluded(seg.o, seg.d, seg.t))
        return L


def by_depth(scene: Scene, la_of_bounces):
    """depth (m,) -> La at visible points of those depths, from ``la_of_bounces`` (K (k,) -> (k, 3)).

    One value (3,) for an unbounded scene; otherwise computed once per distinct depth of a unit (a few),
    since a per-point evaluation cost more than the unit's occlusion rays.
    """
    if scene.max_depth < 0:
        la = np.asarray(la_of_bounces(np.full(1, np.inf)))[0]
        return lambda depth: la

    def at(depth: np.ndarray) -> np.ndarray:
        levels, index = np.unique(depth, return_inverse=True)
        return np.asarray(la_of_bounces(bounces_left(scene, levels)))[index]

    return at


class AOAmbient(ToolkitRenderer):
    """Direct light plus ρ·La·AO (module docstring): Embree, batched queries, multithreaded, biased."""

    name = "ambient"
    citations = (
        'Cohen, Chen, Wallace and Greenberg 1988, "A Progressive Refinement Approach to Fast Radiosity Image '
        'Generation" (SIGGRAPH), §4',
        'Pharr, Jakob and Humphreys 2023, "Physically Based Rendering", 4th ed. (pbrt-v4), AOIntegrator')
    estimator = "biased"
    approximations = ("indirect light is one constant ambient radiance per channel, shadowed by short-range "
                      "ambient occlusion: biased, it does not converge to the reference",)
    settings = (
        sampler_setting("the camera paths and the occlusion rays (one sequence per pixel)"),
        Setting("ambient", str, "radiosity", "how the ambient radiance La is chosen: radiosity (Cohen et al. "
                "1988's ambient term, from the scene alone), oracle (least squares against the stored "
                "reference by the harness: two renders), none (direct light only), constant (ambient_radiance)",
                choices=AMBIENTS),
        Setting("ambient_radiance", float, 1.0, "La in every channel for ambient = constant", low=0.0, high=1e6),
        Setting("ao_max_distance", float, DEFAULT_AO_MAX_DISTANCE, "reach of the occlusion rays, relative to "
                "the scene's size (bounding-box diagonal); the default is 0.5 scene units on cornell-box",
                low=1e-6, high=1e3),
        Setting("ao_samples", int, 1, "occlusion rays per camera sample", low=1, high=OCCLUSION.count),
    )
    #: ambient = oracle: the harness renders D (none) and D + B (constant La = 1) and fits c (module docstring).
    reference_fit = ReferenceFit("ambient", "oracle", without={"ambient": "none"},
                                 unit={"ambient": "constant", "ambient_radiance": 1.0}, record="ambient_radiance")

    def render(self, scene: Scene, spp: int, seed: int, checkpoints: Sequence[int] = (),
               settings: dict | None = None) -> RenderResult:
        s = with_defaults(self.settings, settings)
        threads = self.threads or default_threads()
        if s["ambient"] == "oracle":
            raise ValueError("ambient = oracle is fitted to the stored reference by the harness's render path "
                             "(cornell_harness.workflows.render), from this renderer's ambient = none and constant")
        tfar = s["ao_max_distance"] * scene.extent()
        geom, setup_s = warmed_geometry(scene, lambda g: Shading(g, scene, lambda depth: np.ones((len(depth), 3)),
                                                                 1, tfar).trace(0, 1, 1, independent(0)))
        terms = radiosity_ambient(scene_surfaces(geom))
        if (s["ambient"] == "radiosity" and scene.max_depth < 0
                and ((terms.power > 0.0) & (terms.mean_reflectance >= 1.0)).any()):
            raise ValueError(f"{scene.name}: the radiosity ambient diverges: mean reflectance "
                             f"{terms.mean_reflectance.tolist()} reaches 1 with unbounded max_depth")
        info = dict(s, ao_max_distance_units=tfar, setup_s=round(setup_s, 3))

        def render_with(ambient) -> RenderResult:
            shading = Shading(geom, scene, ambient, s["ao_samples"], tfar)
            return render_image(scene, spp, seed, shading.trace, checkpoints, threads, sampler=s["sampler"])

        first_hit = bounces_left(scene, np.ones(1, np.int64))
        if s["ambient"] == "none":
            result = render_with(None)
            la = np.zeros(3)
        elif s["ambient"] == "radiosity":
            result = render_with(by_depth(scene, terms.radiance))
            la = terms.radiance(first_hit)[0]
        else:
            result = render_with(by_depth(scene, lambda bounces: np.repeat((bounces >= 1.0)[:, None], 3, axis=1)
                                          * s["ambient_radiance"]))
            la = np.repeat(first_hit >= 1.0, 3) * s["ambient_radiance"]
        info.update(ambient_radiance=[float(x) for x in la], mean_reflectance=terms.mean_reflectance.tolist(),
                    emitted_power=terms.power.tolist(), total_area=terms.total_area, rays=geom.rays)
        result.info.update(info)
        return result

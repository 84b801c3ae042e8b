"""The mutant catalogue: realistic bugs in our renderers, as exact source patches (data only).

:mod:`mutants` applies them (copies of the patched modules, loaded as a
renderer the gate takes as an override) and runs the gate on them. Each
:class:`Mutant` names the renderer it is a copy of (:data:`INTEGRATORS`) and
its patches: an ``old`` snippet, which must occur exactly once in its file,
replaced by ``new``. :data:`LOW_POWER` lists the mutants below the gate's
resolution (with why, and what catches them instead), :data:`ISOLATED` those
that once hung the gate.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

ROOT = Path(__file__).resolve().parent.parent
PATHTRACER = "renderers/pathtracer.py"
PHOTONMAP = "renderers/photonmap.py"
SPPM = "renderers/sppm.py"
AO = "renderers/ao.py"
AMBIENT = "renderers/ambient.py"
PROBES = "renderers/probes.py"
DDGI = "renderers/ddgi.py"  # the probes' algorithm (not an integrator: its mutants get a copy, as core modules do)
OIDN = "renderers/oidn.py"  # the denoise stage; its PathTracerOIDN wraps the unmutated path tracer
SOURCE = ROOT / PATHTRACER
CORE = "renderers/core"
#: The renderers mutants are made of: registered name -> (integrator module, adapter class).
INTEGRATORS = {"pathtracer": (PATHTRACER, "PathTracer"), "photonmap": (PHOTONMAP, "PhotonMapper"),
               "sppm": (SPPM, "SPPM"), "ao": (AO, "AORenderer"), "ambient": (AMBIENT, "AOAmbient"),
               "probes": (PROBES, "IrradianceProbes"), "pathtracer+oidn": (OIDN, "PathTracerOIDN")}


class Patch(NamedTuple):
    old: str  # occurs exactly once in ``file``
    new: str
    file: str = PATHTRACER  # relative to the repository root


@dataclass(frozen=True)
class Mutant:
    name: str
    description: str  # the bug, as a developer would make it
    patches: tuple[Patch, ...]  # a patch without a file patches renderers/pathtracer.py
    renderer: str = "pathtracer"  # the registered renderer it is a copy of (INTEGRATORS)

    def __post_init__(self):
        object.__setattr__(self, "patches", tuple(Patch(*p) for p in self.patches))


MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "nee_missing_cos_x",
        "NEE geometry term written cos θ_y / r² (the receiver's cos θ_x dropped)",
        (("g = cos_x * cos_y / dist2 * w / pe", "g = cos_y / dist2 * w / pe", f"{CORE}/direct.py"),),
    ),
    Mutant(
        "light_pdf_2pct",
        "light pdf 2% too high where NEE reads it (pe = light_pdf_area[e] * 1.02, e.g. a stale area table)",
        (("    y, ny, e, pe = sample_emitter(u[0], u[1], u[2], geo)\n",
          "    y, ny, e, pe = sample_emitter(u[0], u[1], u[2], geo)\n"
          "    pe = pe * 1.02\n", f"{CORE}/direct.py"),),
    ),
    Mutant(
        "rr_no_compensation",
        "Russian roulette kills paths but survivors are not divided by the survival probability",
        (("        b0, b1, b2 = b0 / survive, b1 / survive, b2 / survive\n", "", f"{CORE}/roulette.py"),),
    ),
    Mutant(
        "mis_emitter_double",
        "emission found by BSDF-sampled rays weighted 1 instead of its MIS weight (emitter counted twice)",
        (("return 1.0 if pdf_bsdf == 0.0 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))",
          "return 1.0"),),
    ),
    Mutant(
        "camera_half_pixel",
        "pixel jitter recentred to [-0.5, 0.5) though camera_ray adds it to the pixel corner: "
        "image shifted half a pixel",
        (("camera_ray(basis, width, height, j % pixels, u, v)",
          "camera_ray(basis, width, height, j % pixels, u - 0.5, v - 0.5)", f"{CORE}/camera.py"),),
    ),
    Mutant(
        "swap_rb",
        "radiance returned in BGR order (as OpenCV wants) instead of RGB: red and blue swapped",
        (("        depth += 1\n    return (L, aux) if aovs else L\n",
          "        depth += 1\n    L = L[:, ::-1].copy()\n    return (L, aux) if aovs else L\n"),),
    ),
    Mutant(
        "energy_loss_1pct",
        "an 'energy-conserving' fudge: the BSDF-sampled throughput multiplied by 0.99 at every bounce "
        "(indirect light only; the camera-visible direct light is untouched)",
        (("b0, b1, b2 = beta[0] * f[0], beta[1] * f[1], beta[2] * f[2]",
          "b0, b1, b2 = 0.99 * beta[0] * f[0], 0.99 * beta[1] * f[1], 0.99 * beta[2] * f[2]", f"{CORE}/roulette.py"),),
    ),
    Mutant(
        "nan_one_pixel",
        "lens-distortion weight r'/r applied to each path's radiance, from the pixel's offset to the principal "
        "point: 0/0 = NaN at that one pixel",
        (("        depth += 1\n    return (L, aux) if aovs else L\n",
          "        depth += 1\n"
          "    # Lens-distortion weight r'/r of each path's pixel, r its offset from the principal point.\n"
          "    pix = (first + np.arange(m)) % pixels\n"
          "    r = np.hypot(pix % cam.width - cam.width // 2, pix // cam.width - cam.height // 2)\n"
          "    k1 = 0.0  # no radial distortion\n"
          "    L = L * (r * (1.0 + k1 * r * r) / r)[:, None]\n"
          "    return (L, aux) if aovs else L\n"),),
    ),
    Mutant(
        "nan_throughput",
        "the same lens-distortion weight r'/r folded into the camera ray's throughput: a NaN throughput at "
        "the principal-point pixel, which Russian roulette never ends (u >= NaN is false)",
        (("        set_path(rays, i, i, (1.0, 1.0, 1.0), 0.0)\n",
          "        px = j % pixels\n"
          "        r = math.hypot(px % width - width // 2, px // width - height // 2)\n"
          "        k1 = 0.0  # no radial distortion\n"
          "        weight = r * (1.0 + k1 * r * r) / r\n"
          "        set_path(rays, i, i, (weight, weight, weight), 0.0)\n", f"{CORE}/camera.py"),),
    ),
    Mutant(
        "shadow_tfar_past_light",
        "shadow-ray tfar lengthened (sl * (1 + 1e-3), a sign slip) so it reaches the emitter: "
        "the light occludes itself",
        (("sl * SHADOW_TFAR_REL, sl", "sl * (1.0 + 1e-3), sl", f"{CORE}/rays.py"),),
    ),
    Mutant(
        "mis_pdf_area_measure",
        "MIS weight of BSDF-found emission compares the cosine pdf (solid angle) with the light pdf "
        "left in area measure (no r²/cos θ_y conversion)",
        (("power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))", "power_heuristic(pdf_bsdf, pa)"),),
    ),
    Mutant(
        "offset_minus_n",
        "continuation-ray origin offset along −n instead of +n: the ray starts behind the surface "
        "and hits it from the back (self-intersection ends every path)",
        (("set_ray(out.nxt, nn, offset_origin(x, side, geo.offset), wi)",
          "set_ray(out.nxt, nn, offset_origin(x, side, -geo.offset), wi)"),),
    ),
    Mutant(
        "cosine_pdf_mismatch",
        "continuation ray's pdf recorded as uniform-hemisphere 1/(2π) though it is sampled cosine-weighted "
        "(MIS weights no longer sum to 1)",
        (("return True, (b0, b1, b2), bsdf_pdf(mat, cos_w)", "return True, (b0, b1, b2), 0.5 / 3.141592653589793",
          f"{CORE}/roulette.py"),),
    ),
    Mutant(
        "two_sided_emitter",
        "the one-sided area light made two-sided: emission found on its back side counted (and |cos θ_y| in "
        "NEE)",
        (("        if not faces(mat, cos_o):\n            continue  # back side",
          "        if not faces(mat, cos_o):\n"
          "            if geo.light_pdf_area[p] > 0.0:  # area lights emit on both sides; NEE never samples the back\n"
          "                for c in range(3):\n"
          "                    out.L[rays.path[i], c] += rays.beta[i, c] * geo.radiance[p, c]\n"
          "            continue  # back side"),
         ("return -(ny[0] * w[0] + ny[1] * w[1] + ny[2] * w[2])",
          "return abs(ny[0] * w[0] + ny[1] * w[1] + ny[2] * w[2])", f"{CORE}/lights.py")),
    ),
    # -- specular materials (mirror, glass) ------------------------------------------
    Mutant(
        "fresnel_schlick",
        "Schlick's approximation R0 + (1 - R0)(1 - cos θi)^5 in place of the exact Fresnel equations, with "
        "cos θi taken on whichever side the ray arrives (exact inside the glass needs cos θt)",
        (("        a_s = (eta_it * ct - ci) / (eta_it * ct + ci)\n"
          "        a_p = (eta_it * ci - ct) / (eta_it * ci + ct)\n"
          "        r = 0.5 * (a_s * a_s + a_p * a_p)\n",
          "        r0 = ((eta - 1.0) / (eta + 1.0)) ** 2\n"
          "        r = r0 + (1.0 - r0) * (1.0 - ci) ** 5 if cos_t_sqr > 0.0 else 1.0\n", f"{CORE}/bsdf.py"),),
    ),
    Mutant(
        "ior2_missing",
        "refracted radiance not scaled by (η_i/η_t)² (the weight of a transmission left at 1, as in "
        "importance transport)",
        (("return refract(wo, n, cos_o, cos_t, eta_ti), cos_t, eta_ti * eta_ti, True",
          "return refract(wo, n, cos_o, cos_t, eta_ti), cos_t, 1.0, True", f"{CORE}/bsdf.py"),),
    ),
    Mutant(
        "tir_absorbed",
        "total internal reflection treated as absorption: no refracted direction exists, so the sample is "
        "declared invalid and the path ends",
        (("    r, cos_t, eta_it, eta_ti = fresnel_dielectric(cos_o, eta)\n",
          "    r, cos_t, eta_it, eta_ti = fresnel_dielectric(cos_o, eta)\n"
          "    if cos_t == 0.0:\n"
          "        return (0.0, 0.0, 1.0), 0.0, 0.0, False  # no refracted ray\n", f"{CORE}/bsdf.py"),),
    ),
    Mutant(
        "nee_at_delta_vertex",
        "next-event estimation at every vertex, mirrors and glass included, with the BSDF evaluated as "
        "Lambertian whatever the material (delta lobes get direct light twice over)",
        (("if geo.emitter_ids.size > 0 and not is_delta(mat):", "if geo.emitter_ids.size > 0:"),
         ("    if material == LAMBERT:\n        return lambert_eval(rho, cos)\n    return 0.0\n",
          "    return lambert_eval(rho, cos)\n", f"{CORE}/bsdf.py"),
         ("    if material == LAMBERT:\n        return lambert_pdf(cos)\n    return 0.0\n",
          "    return lambert_pdf(cos)\n", f"{CORE}/bsdf.py")),
    ),
    Mutant(
        "mirror_reflectance_ignored",
        "the mirror's specular reflectance ignored: a perfect reflector (weight 1) whatever the scene says",
        (("return reflect(wo, n, cos_o), cos_o, rho, cos_o > 0.0",
          "return reflect(wo, n, cos_o), cos_o, (1.0, 1.0, 1.0), cos_o > 0.0", f"{CORE}/bsdf.py"),),
    ),
    Mutant(
        "delta_emission_mis_weighted",
        "emission found after a mirror or glass bounce MIS-weighted against light sampling that was never "
        "done there (the weight is 1 only for camera rays): caustics and mirrored lights vanish",
        (("return 1.0 if pdf_bsdf == 0.0 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))",
          "return 1.0 if depth == 1 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))"),
         ("def _emission_weight(pdf_bsdf, pa, t, cos_o) -> float:",
          "def _emission_weight(pdf_bsdf, pa, t, cos_o, depth) -> float:"),
         ("w = _emission_weight(rays.pdf[i], pa, t, cos_o)", "w = _emission_weight(rays.pdf[i], pa, t, cos_o, depth)")),
    ),
    # -- photon mapping (photonmap, sppm) ------------------------------------------------
    Mutant(
        "photon_power_not_divided",
        "photon flux not divided by the number of photons emitted (each photon carries the light's whole "
        "power)",
        (("    photons.power[:] /= max(emitted, 1)\n", "", f"{CORE}/photons.py"),),
        "photonmap",
    ),
    Mutant(
        "double_cosine",
        "density estimate weighted by the cosine of each photon's incidence, which its flux already counts",
        (("            w = kernel_weight(kernel, dist[i, a], r)\n",
          "            w = kernel_weight(kernel, dist[i, a], r) * cos_in\n", f"{CORE}/photon_map.py"),),
        "photonmap",
    ),
    Mutant(
        "caustic_photon_on_specular_surface",
        "caustic photons stored where they leave the last specular surface (the ray's origin) instead of "
        "where they land",
        (("                _store(out.photons, ns, x, power, d, n, depth, caustic)\n",
          "                o = (rays.o[i, 0], rays.o[i, 1], rays.o[i, 2])\n"
          "                _store(out.photons, ns, o if mode == STORE_CAUSTIC else x, power, d, n, depth, caustic)\n",
          f"{CORE}/photons.py"),),
        "photonmap",
    ),
    Mutant(
        "photon_direction_reuses_point_dims",
        "a photon's emitted direction drawn from the sample dimensions of its point on the emitter (EMIT_U for "
        "both decisions): where a photon leaves the light decides where it goes",
        (("        w = sample_2d(stream, pt, EMIT_DIR_U)\n", "        w = sample_2d(stream, pt, EMIT_U)\n",
          f"{CORE}/photons.py"),),
        "photonmap",
    ),
    Mutant(
        "no_normal_test",
        "no normal test in the density estimate: photons on a wall count on the floor at their corner",
        (("    if cos_n < NORMAL_COS_MIN:\n        return 0.0\n", "", f"{CORE}/photon_map.py"),),
        "photonmap",
    ),
    Mutant(
        "no_radius_shrinking",
        "SPPM's α left out of the photon-count update (N' = N + M): the radius never shrinks, and the image "
        "converges to a blurred one",
        (("        n_new = self.n[hit] + alpha * m[hit]\n", "        n_new = self.n[hit] + m[hit]\n", SPPM),),
        "sppm",
    ),
    Mutant(
        "sppm_power_not_divided",
        "SPPM's gathered flux not divided by the iteration's photon count",
        (("            phi /= photons\n", "", SPPM),),
        "sppm",
    ),
    # -- ambient occlusion (ao) ------------------------------------------------------------------------
    Mutant(
        "ao_uniform_as_cosine",
        "cosine-weighted AO sampled with uniform hemisphere directions but each still counted as V (the pdf "
        "1/(2π) taken for cos θ/π): the image is the uniform obscurance, too dark beside walls",
        (("        d = cosine_hemisphere(n[0], n[1], n[2], u1, u2)\n",
          "        d = uniform_hemisphere(n[0], n[1], n[2], u1, u2)\n", f"{CORE}/occlusion.py"),),
        "ao",
    ),
    Mutant(
        "ao_max_distance_ignored",
        "the occlusion ray's tfar left at infinity: occluders beyond max_distance count",
        (("    tfar = ao.max_distance  #", '    tfar = float("inf")  #', AO),),
        "ao",
    ),
    Mutant(
        "ao_normal_flipped",
        "FaceForward's test the wrong way round: the hemisphere is on the far side of every surface, so the "
        "rays look into walls and boxes (or the void behind them) instead of the room",
        (("    return n if cos_o >= 0.0 else (-n[0], -n[1], -n[2])\n",
          "    return (-n[0], -n[1], -n[2]) if cos_o >= 0.0 else n\n", f"{CORE}/occlusion.py"),),
        "ao",
    ),
    # -- the AO-ambient approximation (ambient) --------------------------------------------------------
    Mutant(
        "ambient_not_occluded",
        "the ambient term added without its occlusion rays' verdict (AO taken as 1): corners and the floor "
        "round the boxes as bright as open walls",
        (("            add_unoccluded(L, seg, self.geom.unoccluded(seg.o, seg.d, seg.t))\n",
          "            add_unoccluded(L, seg, np.ones(k, bool))\n", AMBIENT),),
        "ambient",
    ),
    # -- DDGI irradiance probes (probes; the algorithm is renderers/ddgi.py) ----------------------------
    Mutant(
        "chebyshev_inverted",
        "Chebyshev visibility test written the wrong way round (r < μ): probes are darkened where they see "
        "the point and trusted where a wall hides it (light leaks)",
        (("                if r > mean:  # farther than the surfaces the probe saw this way: maybe hidden\n",
          "                if r < mean:  # farther than the surfaces the probe saw this way: maybe hidden\n", DDGI),),
        "probes",
    ),
    Mutant(
        "irradiance_not_cosine_weighted",
        "an irradiance texel's ray weight max(0, n·ω) replaced by 1 on the texel's hemisphere (as for a "
        "radiance average): a uniform hemisphere mean instead of the cosine-weighted irradiance",
        (("                    w = max(0.0, texels[a, b, 0] * directions[r, 0] + texels[a, b, 1] * directions[r, 1]\n"
          "                            + texels[a, b, 2] * directions[r, 2])\n",
          "                    w = 1.0 if texels[a, b, 0] * directions[r, 0] + texels[a, b, 1] * directions[r, 1] \\\n"
          "                        + texels[a, b, 2] * directions[r, 2] > 0.0 else 0.0\n", DDGI),),
        "probes",
    ),
    Mutant(
        "probe_index_off_by_one",
        "a lookup's base probe one cell too far along x (floor(...) + 1, clamped to the grid): every point "
        "reads the probes of the next cell over",
        (("    gx = min(max(int(math.floor((bx - vol.origin[0]) / vol.spacing[0])), 0), nx - 1)\n",
          "    gx = min(max(int(math.floor((bx - vol.origin[0]) / vol.spacing[0])) + 1, 0), nx - 1)\n", DDGI),),
        "probes",
    ),
    # -- denoised path tracing (pathtracer+oidn; renderers/oidn.py) ------------------------------------------
    Mutant(
        "oidn_ldr",
        "the beauty filtered as LDR (hdr off: pyoidn.denoise's default), so radiance above 1 is clipped",
        (('    _filter(device, images, quality, hdr=True, cleanAux=aux == "prefiltered")\n',
          '    _filter(device, images, quality, hdr=False, cleanAux=aux == "prefiltered")\n', OIDN),),
        "pathtracer+oidn",
    ),
    Mutant(
        "oidn_aux_not_prefiltered",
        "albedo and normal flagged clean (cleanAux) but passed as rendered, never prefiltered: what "
        "pyoidn.denoise(clean_aux=True) does; the glass sphere's noisy auxiliary images are kept as detail",
        (('            _filter(device, {"albedo": albedo, "output": albedo}, quality)\n'
          '            _filter(device, {"normal": normal, "output": normal}, quality)\n',
          '            pass  # the auxiliary images as rendered\n', OIDN),),
        "pathtracer+oidn",
    ),
    Mutant(
        "oidn_checkpoints_not_denoised",
        "only the final image denoised: the checkpoints below it keep the path tracer's noisy image",
        (("            shots.append(Checkpoint(c.spp, image, c.time_s + dt, c.aovs))\n",
          "            shots.append(Checkpoint(c.spp, image if c.spp == spp else c.image, c.time_s + dt, c.aovs))\n",
          OIDN),),
        "pathtracer+oidn",
    ),
)

BY_NAME = {m.name: m for m in MUTANTS}
assert len(BY_NAME) == len(MUTANTS), "mutant names must be unique"

#: Mutants the gate cannot fail: a bias too small at its CI budget (power < 99% over seeds, as measured by
#: ``benchmarks/gate_power.py``, docs/gate-detection.md), or a change that does not take the image away from
#: the reference: name -> why, and what catches them instead.
#: None of the path tracer's since gate.toml has the furnace and light-panel expectations; before them, the
#: Cornell box alone missed cosine_pdf_mismatch (0.85 sd) and had power 0.2 on mis_pdf_area_measure.
LOW_POWER: dict[str, str] = {
    "no_normal_test": "it moves images towards the reference, so no check that scores agreement can fail it "
                      "without asserting a bias. Jensen's estimate divides by the area of a disc that a corner "
                      "cuts, so with the normal test concave corners read dark; without it, the other face's "
                      "photons fill the cut part, which is right wherever the two faces' irradiance is alike "
                      "(the incoming-side test still stops thin surfaces). cornell-box without gathering, "
                      "seeds 0-2, 8x8 tiles against Mitsuba at the ceiling's right edge: -52% to -54% clean, -28% "
                      "to -36% mutated; with k = 200, 1M photons, max_radius 0.05, -22% to -24% clean and +2% to +5% "
                      "mutated; of 1024 tiles, four had a larger error than every clean seed, by at most 1.7 "
                      "points (small box's top front edge: +10% to +17% against +2% to +9%). Three corner-caustic "
                      "scenes (docs/photon-mapping.md) changed no pixel beyond 18%. Caught by "
                      "tests/renderers/test_photons.py::test_normal_test_keeps_wall_photons_off_the_floor",
}
assert set(LOW_POWER) <= set(BY_NAME)

#: Mutants that once made a gate run never end (a NaN throughput survived Russian roulette, so in the
#: closed furnace the path bounced forever): tests and the benchmark run them in a child process with a
#: time limit, so a regression fails instead of hanging the suite.
ISOLATED = {"nan_throughput"}
assert ISOLATED <= set(BY_NAME)

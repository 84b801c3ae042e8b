"""The path tracer's mutants (src/cornell_harness/renderers/pathtracer.py and the toolkit it is built on: direct light, roulette, camera,
rays, lights, BSDFs)."""

from __future__ import annotations

from tests.mutants.model import CORE, Edit, Mutant, Replace, Wrap

DIRECT, ROULETTE, CAMERA, RAYS, LIGHTS, BSDF = (f"{CORE}/{m}.py" for m in ("direct", "roulette", "camera", "rays", "lights", "bsdf"))

MUTANTS: tuple[Mutant, ...] = (
    Mutant(
        "nee_missing_cos_x",
        "NEE geometry term written cos θ_y / r² (the receiver's cos θ_x dropped)",
        (Edit("light_sample", "g = cos_x * cos_y / dist2 * w / pe", "g = cos_y / dist2 * w / pe", DIRECT),),
    ),
    Mutant(
        "light_pdf_2pct",
        "light pdf 2% too high where NEE reads it (pe = light_pdf_area[e] * 1.02, e.g. a stale area table)",
        (Edit("light_sample", "y, ny, e, pe = sample_emitter(u[0], u[1], u[2], geo)",
              "y, ny, e, pe = sample_emitter(u[0], u[1], u[2], geo)\npe = pe * 1.02", DIRECT),),
    ),
    Mutant(
        "rr_no_compensation",
        "Russian roulette kills paths but survivors are not divided by the survival probability",
        (Edit("continue_path", "b0, b1, b2 = b0 / survive, b1 / survive, b2 / survive", "", ROULETTE),),
    ),
    Mutant(
        "mis_emitter_double",
        "emission found by BSDF-sampled rays weighted 1 instead of its MIS weight (emitter counted twice)",
        (Edit("emission_weight",
              "1.0 if pdf_bsdf == 0.0 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))", "1.0",
              DIRECT),),
    ),
    Mutant(
        "camera_half_pixel",
        "pixel jitter recentred to [-0.5, 0.5) though camera_ray adds it to the pixel corner: "
        "image shifted half a pixel",
        (Edit("camera_rays", "camera_ray(basis, width, height, j % pixels, u, v)",
              "camera_ray(basis, width, height, j % pixels, u - 0.5, v - 0.5)", CAMERA),),
    ),
    Mutant(
        "swap_rb",
        "radiance returned in BGR order (as OpenCV wants) instead of RGB: red and blue swapped",
        (Edit("trace_paths", "return (L, aux) if aovs else L",
              "L = L[:, ::-1].copy()\nreturn (L, aux) if aovs else L"),),
    ),
    Mutant(
        "energy_loss_1pct",
        "an 'energy-conserving' fudge: the BSDF-sampled throughput multiplied by 0.99 at every bounce "
        "(indirect light only; the camera-visible direct light is untouched)",
        (Edit("continue_path", "b0, b1, b2 = beta[0] * f[0], beta[1] * f[1], beta[2] * f[2]",
              "b0, b1, b2 = 0.99 * beta[0] * f[0], 0.99 * beta[1] * f[1], 0.99 * beta[2] * f[2]", ROULETTE),),
    ),
    Mutant(
        "nan_one_pixel",
        "lens-distortion weight r'/r applied to each path's radiance, from the pixel's offset to the principal "
        "point: 0/0 = NaN at that one pixel",
        (Edit("trace_paths", "return (L, aux) if aovs else L", """
              pix = (first + np.arange(m)) % pixels  # each path's pixel; r its offset from the principal point
              r = np.hypot(pix % cam.width - cam.width // 2, pix // cam.width - cam.height // 2)
              k1 = 0.0  # no radial distortion
              L = L * (r * (1.0 + k1 * r * r) / r)[:, None]
              return (L, aux) if aovs else L"""),),
    ),
    Mutant(
        "nan_throughput",
        "the same lens-distortion weight r'/r folded into the camera ray's throughput: a NaN throughput at "
        "the principal-point pixel, which Russian roulette never ends (u >= NaN is false)",
        (Edit("camera_rays", "set_path(rays, i, i, (1.0, 1.0, 1.0), 0.0)", """
              px = j % pixels
              r = math.hypot(px % width - width // 2, px // width - height // 2)
              k1 = 0.0  # no radial distortion
              weight = r * (1.0 + k1 * r * r) / r
              set_path(rays, i, i, (weight, weight, weight), 0.0)""", CAMERA),),
    ),
    Mutant(
        "shadow_tfar_past_light",
        "shadow-ray tfar lengthened (sl * (1 + 1e-3), a sign slip) so it reaches the emitter: "
        "the light occludes itself",
        (Edit("shadow_segment", "sl * SHADOW_TFAR_REL", "sl * (1.0 + 1e-3)", RAYS),),
    ),
    Mutant(
        "mis_pdf_area_measure",
        "MIS weight of BSDF-found emission compares the cosine pdf (solid angle) with the light pdf "
        "left in area measure (no r²/cos θ_y conversion)",
        (Edit("emission_weight", "power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))",
              "power_heuristic(pdf_bsdf, pa)", DIRECT),),
    ),
    Mutant(
        "offset_minus_n",
        "continuation-ray origin offset along −n instead of +n: the ray starts behind the surface "
        "and hits it from the back (self-intersection ends every path)",
        (Edit("_shade", "offset_origin(x, side, geo.offset)", "offset_origin(x, side, -geo.offset)"),),
    ),
    Mutant(
        "cosine_pdf_mismatch",
        "continuation ray's pdf recorded as uniform-hemisphere 1/(2π) though it is sampled cosine-weighted "
        "(MIS weights no longer sum to 1)",
        (Edit("continue_path", "return True, (b0, b1, b2), bsdf_pdf(mat, cos_w)",
              "return True, (b0, b1, b2), 0.5 / 3.141592653589793", ROULETTE),),
    ),
    Mutant(
        "two_sided_emitter",
        "the one-sided area light made two-sided: emission found on its back side counted (and |cos θ_y| in "
        "NEE)",
        (Edit("_shade", """
              if not faces(mat, cos_o):
                  continue""", """
              if not faces(mat, cos_o):
                  if geo.light_pdf_area[p] > 0.0:  # area lights emit on both sides; NEE never samples the back
                      for c in range(3):
                          paths.L[rays.path[i], c] += rays.beta[i, c] * geo.radiance[p, c]
                  continue"""),
         Edit("emitter_cos", "-(ny[0] * w[0] + ny[1] * w[1] + ny[2] * w[2])",
              "abs(ny[0] * w[0] + ny[1] * w[1] + ny[2] * w[2])", LIGHTS)),
    ),
    # -- specular materials (mirror, glass) ------------------------------------------
    Mutant(
        "fresnel_schlick",
        "Schlick's approximation R0 + (1 - R0)(1 - cos θi)^5 in place of the exact Fresnel equations, with "
        "cos θi taken on whichever side the ray arrives (exact inside the glass needs cos θt)",
        (Edit("fresnel_dielectric", """
              a_s = (eta_it * ct - ci) / (eta_it * ct + ci)
              a_p = (eta_it * ci - ct) / (eta_it * ci + ct)
              r = 0.5 * (a_s * a_s + a_p * a_p)""", """
              r0 = ((eta - 1.0) / (eta + 1.0)) ** 2
              r = r0 + (1.0 - r0) * (1.0 - ci) ** 5 if cos_t_sqr > 0.0 else 1.0""", BSDF),),
    ),
    Mutant(
        "ior2_missing",
        "refracted radiance not scaled by (η_i/η_t)² (the weight of a transmission left at 1, as in "
        "importance transport)",
        (Edit("dielectric_sample", "return refract(wo, n, cos_o, cos_t, eta_ti), cos_t, eta_ti * eta_ti, True",
              "return refract(wo, n, cos_o, cos_t, eta_ti), cos_t, 1.0, True", BSDF),),
    ),
    Mutant(
        "tir_absorbed",
        "total internal reflection treated as absorption: no refracted direction exists, so the sample is "
        "declared invalid and the path ends",
        (Edit("dielectric_sample", "r, cos_t, eta_it, eta_ti = fresnel_dielectric(cos_o, eta)", """
              r, cos_t, eta_it, eta_ti = fresnel_dielectric(cos_o, eta)
              if cos_t == 0.0:
                  return (0.0, 0.0, 1.0), 0.0, 0.0, False  # no refracted ray""", BSDF),),
    ),
    Mutant(
        "nee_at_delta_vertex",
        "next-event estimation at every vertex, mirrors and glass included, with the BSDF evaluated as "
        "Lambertian whatever the material (delta lobes get direct light twice over)",
        (Edit("_shade", "geo.emitter_ids.size > 0 and not is_delta(mat)", "geo.emitter_ids.size > 0"),
         Edit("bsdf_eval", """
              if material == LAMBERT:
                  return lambert_eval(rho, cos)
              return 0.0""", "return lambert_eval(rho, cos)", BSDF),
         Edit("bsdf_pdf", """
              if material == LAMBERT:
                  return lambert_pdf(cos)
              return 0.0""", "return lambert_pdf(cos)", BSDF)),
    ),
    Mutant(
        "mirror_reflectance_ignored",
        "the mirror's specular reflectance ignored: a perfect reflector (weight 1) whatever the scene says",
        (Edit("bsdf_sample", "return reflect(wo, n, cos_o), cos_o, rho, cos_o > 0.0",
              "return reflect(wo, n, cos_o), cos_o, (1.0, 1.0, 1.0), cos_o > 0.0", BSDF),),
    ),
    Mutant(
        "delta_emission_mis_weighted",
        "emission found after a mirror or glass bounce MIS-weighted against light sampling that was never "
        "done there (the weight is 1 only for camera rays): caustics and mirrored lights vanish",
        (Replace("emission_weight", """
                 def emission_weight(pdf_bsdf, pa, t, cos_o, depth) -> float:
                     return 1.0 if depth == 1 else power_heuristic(pdf_bsdf, solid_angle_pdf_along(pa, t, cos_o))""",
                 DIRECT),
         Edit("_shade", "emission_weight(rays.pdf[i], pa, t, cos_o)", "emission_weight(rays.pdf[i], pa, t, cos_o, depth)")),
    ),
    Mutant(
        "caustic_95",
        "a 'caustic damping' constant meant to tame fireflies, left in: emission found by a mirror- or glass-sampled "
        "ray from the third path segment on (taken to be a caustic: a diffuse bounce, then the specular chain to the "
        "light) weighted 0.95. The caustic (L S+ D) comes out 5% dark, and so does the light seen through both "
        "faces of the glass; the light's image in the mirror (second segment) is untouched",
        (Edit("_shade", "w = emission_weight(rays.pdf[i], pa, t, cos_o)", """
              w = emission_weight(rays.pdf[i], pa, t, cos_o)
              if rays.pdf[i] == 0.0 and depth > 2:  # a caustic: damp its fireflies
                  w *= 0.95"""),),
    ),
    Mutant(
        "variance_understated_4x",
        "the reported variance of the mean 4 times too small (e.g. a divisor applied twice): every z, confidence "
        "interval and bias/variance split shown to users twice too narrow",
        (Wrap("PathTracer.render", """
              def wrap(render):
                  def understated(*args, **kwargs):
                      result = render(*args, **kwargs)
                      result.variance = result.variance / 4
                      return result
                  return understated"""),),
    ),
    Mutant(
        "variance_overstated_4x",
        "the reported variance of the mean multiplied by 4 (e.g. the variance of one sample over n/4): "
        "errors up to twice the noise pass every z-test",
        (Wrap("PathTracer.render", """
              def wrap(render):
                  def overstated(*args, **kwargs):
                      result = render(*args, **kwargs)
                      result.variance = result.variance * 4
                      return result
                  return overstated"""),),
    ),
)

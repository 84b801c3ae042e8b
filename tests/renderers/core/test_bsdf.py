"""Smooth mirror and glass BSDFs, and ray-sphere intersection, against closed forms written here.

The references are independent of the code under test: Fresnel reflectance
from the angles (Snell's law, then Fresnel's sine and tangent laws), the
transmittance from the transmitted amplitudes, and sphere hits from exact
rational arithmetic. Everything here is deterministic (no Monte Carlo): the
tolerances are float64 rounding, stated at each assertion.
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext
from fractions import Fraction

import numpy as np
import pytest

from cornell_harness.scenes.loader import load_scene
from cornell_harness.renderers.core.bsdf import (DIELECTRIC, LAMBERT, MIRROR, bsdf_eval, bsdf_pdf, bsdf_sample, dielectric_sample,
                                 fresnel_dielectric, is_delta, material_tables, reflect, two_sided)
from cornell_harness.renderers.core.geometry import OFFSET_REL, sphere_hit

from tests.conftest import ROOT

CAUSTICS = ROOT / "src" / "cornell_harness" / "references" / "cornell-box-caustics" / "scene.toml"
ETAS = (1.5, 1 / 1.5)
ANGLES_DEG = (0.0, 5.0, 20.0, 35.0, 40.0, 45.0, 56.31, 60.0, 75.0, 85.0, 89.5)
#: float64 rounding of the closed forms (a few ulps of numbers of order 1, through acos/asin/tan).
TOL = 1e-12


# --- independent closed forms -------------------------------------------------------

def media(cos_i: float, eta: float) -> tuple[float, float]:
    """(n_incident, n_transmitted) for a direction at ``cos_i`` with the front normal; eta = n_int/n_ext, n_ext = 1."""
    return (1.0, eta) if cos_i >= 0.0 else (eta, 1.0)


def fresnel_from_angles(cos_i: float, eta: float) -> float:
    """Unpolarised reflectance from θi, θt (Snell: n1 sin θi = n2 sin θt) and Fresnel's laws.

    r_s = -sin(θi - θt) / sin(θi + θt), r_p = tan(θi - θt) / tan(θi + θt)
    (Born & Wolf §1.5.2); normal incidence ((n1 - n2)/(n1 + n2))²; past the
    critical angle 1.
    """
    n1, n2 = media(cos_i, eta)
    ti = math.acos(min(1.0, abs(cos_i)))
    s = n1 / n2 * math.sin(ti)
    if s >= 1.0:
        return 1.0
    tt = math.asin(s)
    if ti == 0.0:
        return ((n1 - n2) / (n1 + n2)) ** 2
    rs = -math.sin(ti - tt) / math.sin(ti + tt)
    rp = math.tan(ti - tt) / math.tan(ti + tt)
    return 0.5 * (rs * rs + rp * rp)


def transmittance_from_angles(cos_i: float, eta: float) -> float:
    """Unpolarised power transmittance (n2 cos θt)/(n1 cos θi)·(t_s² + t_p²)/2 from the transmitted amplitudes.

    t_s = 2 sin θt cos θi / sin(θi + θt), t_p = t_s / cos(θi - θt) (Born & Wolf
    §1.5.2); normal incidence 4 n1 n2 / (n1 + n2)²; past the critical angle 0.
    """
    n1, n2 = media(cos_i, eta)
    ti = math.acos(min(1.0, abs(cos_i)))
    s = n1 / n2 * math.sin(ti)
    if s >= 1.0:
        return 0.0
    tt = math.asin(s)
    if ti == 0.0:
        return 4 * n1 * n2 / (n1 + n2) ** 2
    ts = 2 * math.sin(tt) * math.cos(ti) / math.sin(ti + tt)
    tp = ts / math.cos(ti - tt)
    return (n2 * math.cos(tt)) / (n1 * math.cos(ti)) * 0.5 * (ts * ts + tp * tp)


def frame(theta_deg: float, phi: float = 0.7, inside: bool = False):
    """A tilted normal n and a unit ``wo`` at angle θ to it (to -n when ``inside``); cos_o = wo·n."""
    n = np.array([0.3, -0.5, 0.8])
    n /= np.linalg.norm(n)
    t = np.cross(n, [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    b = np.cross(n, t)
    th = math.radians(theta_deg)
    wo = math.sin(th) * (math.cos(phi) * t + math.sin(phi) * b) + math.cos(th) * (-n if inside else n)
    return tuple(n), tuple(wo), float(np.dot(wo, n))


def cases():
    for eta in ETAS:
        for deg in ANGLES_DEG:
            for inside in (False, True):
                yield eta, deg, inside


CASES = list(cases())
IDS = [f"eta={e:.3g}-{d:g}deg-{'in' if i else 'out'}" for e, d, i in CASES]


# --- Fresnel ------------------------------------------------------------------------

def test_closed_forms_conserve_energy():
    """The two references agree with each other: R + T = 1 from the amplitudes (a check of the checks)."""
    for eta, deg, inside in CASES:
        _, _, cos = frame(deg, inside=inside)
        assert fresnel_from_angles(cos, eta) + transmittance_from_angles(cos, eta) == pytest.approx(1.0, abs=TOL)


@pytest.mark.parametrize("eta, deg, inside", CASES, ids=IDS)
def test_fresnel_reflectance_matches_fresnels_equations(eta, deg, inside):
    """R from the code equals R from the angles, and 1 - R the transmittance from the amplitudes (R + T = 1)."""
    _, _, cos = frame(deg, inside=inside)
    r, cos_t, eta_it, eta_ti = fresnel_dielectric(cos, eta)
    assert r == pytest.approx(fresnel_from_angles(cos, eta), abs=TOL)
    assert 1.0 - r == pytest.approx(transmittance_from_angles(cos, eta), abs=TOL)
    n1, n2 = media(cos, eta)
    assert eta_it == pytest.approx(n2 / n1, rel=1e-15) and eta_ti == pytest.approx(n1 / n2, rel=1e-15)
    if r < 1.0:  # cos θt from Snell, on the far side of the surface
        sin_t = n1 / n2 * math.sqrt(max(0.0, 1.0 - cos * cos))
        assert abs(cos_t) == pytest.approx(math.sqrt(1.0 - sin_t * sin_t), abs=TOL)
        assert math.copysign(1.0, cos_t) == -math.copysign(1.0, cos)


@pytest.mark.parametrize("eta", ETAS + (2.42, 1.0001))
@pytest.mark.parametrize("side", (1.0, -1.0))
def test_normal_incidence(eta, side):
    r, cos_t, _, _ = fresnel_dielectric(side, eta)
    assert r == pytest.approx(((eta - 1) / (eta + 1)) ** 2, rel=1e-14)
    assert cos_t == -side


@pytest.mark.parametrize("cos", (1.0, 0.7, 0.01, -0.01, -0.7, -1.0))
def test_index_matched_interface_is_invisible(cos):
    """η = 1: no reflection, and the refracted ray goes straight on with weight 1."""
    n, wo, c = frame(math.degrees(math.acos(abs(cos))), inside=cos < 0)
    r, cos_t, eta_it, eta_ti = fresnel_dielectric(c, 1.0)
    assert r == 0.0 and eta_it == eta_ti == 1.0
    for u in (0.0, 0.5, 1 - 2**-53):
        wi, ci, w, ok = dielectric_sample(wo, n, c, 1.0, u)
        assert ok and w == 1.0
        np.testing.assert_allclose(wi, -np.asarray(wo), atol=1e-15)
        assert ci == pytest.approx(-c, abs=1e-15)


def test_grazing_incidence_reflects_everything():
    assert fresnel_dielectric(0.0, 1.5)[0] == 1.0


# --- dielectric sampling --------------------------------------------------------------

@pytest.mark.parametrize("eta, deg, inside", CASES, ids=IDS)
def test_sample_chooses_by_fresnel_with_radiance_weights(eta, deg, inside):
    """Reflect for u < R (weight 1), refract otherwise (weight η_ti², radiance transport), never absorbed.

    The boundary is checked on both sides of u = R, and the mean weight over
    4000 stratified u against E[w] = R + (1 - R)·η_ti² (exact up to the
    stratification, |error| <= max(1, η_ti²)/4000).
    """
    n, wo, cos = frame(deg, inside=inside)
    r_ref = fresnel_from_angles(cos, eta)
    n1, n2 = media(cos, eta)
    eta_ti2 = (n1 / n2) ** 2
    r = fresnel_dielectric(cos, eta)[0]
    below, above = math.nextafter(r, 0.0), r
    if r > 0.0:
        wi, ci, w, ok = dielectric_sample(wo, n, cos, eta, below)
        assert ok and w == 1.0 and ci == cos  # reflected: same side
    if r < 1.0:
        wi, ci, w, ok = dielectric_sample(wo, n, cos, eta, above)
        assert ok and w == pytest.approx(eta_ti2, rel=1e-15) and ci * cos < 0.0  # refracted: other side
    k = 4000
    weights = []
    for j in range(k):
        wi, ci, w, ok = dielectric_sample(wo, n, cos, eta, (j + 0.5) / k)
        assert ok, "a dielectric never absorbs"
        weights.append(w)
    expected = r_ref + (1.0 - r_ref) * eta_ti2
    assert np.mean(weights) == pytest.approx(expected, abs=max(1.0, eta_ti2) / k)


@pytest.mark.parametrize("eta", ETAS)
def test_refraction_obeys_snell(eta):
    """Refracted ω: unit, coplanar with ωo and n, other side, |n × ωt| = η_ti·|n × ωo|, tangent reversed."""
    rng = np.random.default_rng(20240610)
    checked = 0
    for _ in range(200):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        wo = rng.normal(size=3)
        wo /= np.linalg.norm(wo)
        cos = float(wo @ n)
        r, cos_t, _, eta_ti = fresnel_dielectric(cos, eta)
        if r >= 1.0:
            continue
        wt, ci, w, ok = dielectric_sample(tuple(wo), tuple(n), cos, eta, 1.0 - 1e-12)
        wt = np.asarray(wt)
        assert ok and ci == cos_t
        assert np.linalg.norm(wt) == pytest.approx(1.0, abs=1e-14)
        assert wt @ n == pytest.approx(ci, abs=1e-14) and ci * cos < 0.0
        assert np.linalg.det(np.stack([wo, n, wt])) == pytest.approx(0.0, abs=1e-14)
        assert np.linalg.norm(np.cross(n, wt)) == pytest.approx(eta_ti * np.linalg.norm(np.cross(n, wo)), abs=1e-14)
        np.testing.assert_allclose(wt - (wt @ n) * n, -eta_ti * (wo - cos * n), atol=1e-14)
        checked += 1
    assert checked > 100


def test_reflection_direction():
    rng = np.random.default_rng(3)
    for _ in range(50):
        n = rng.normal(size=3)
        n /= np.linalg.norm(n)
        wo = rng.normal(size=3)
        wo /= np.linalg.norm(wo)
        cos = float(wo @ n)
        wr = np.asarray(reflect(tuple(wo), tuple(n), cos))
        assert np.linalg.norm(wr) == pytest.approx(1.0, abs=1e-14)
        assert wr @ n == pytest.approx(cos, abs=1e-14)
        np.testing.assert_allclose(wr - cos * n, -(wo - cos * n), atol=1e-14)


@pytest.mark.parametrize("eta", ETAS)
def test_round_trip_through_a_slab_has_weight_one(eta):
    """In through one face of a slab, out through the parallel one: weight η_ti²·η_it² = 1, direction restored."""
    for deg in (0.0, 10.0, 30.0, 45.0, 70.0, 85.0):
        n, wo, cos = frame(deg)
        if fresnel_dielectric(cos, eta)[0] >= 1.0:
            continue  # eta < 1: total reflection from outside past its critical angle
        wt, ct, w_in, ok = dielectric_sample(wo, n, cos, eta, 1.0 - 1e-12)
        assert ok and ct < 0.0
        back = tuple(-x for x in n)  # the far face's front normal points out of the slab, i.e. along -n
        wo2 = tuple(-x for x in wt)  # at the far face, ωo points back along the ray: into the slab
        cos2 = float(np.dot(wo2, back))  # negative: from inside
        assert cos2 < 0.0
        wt2, _, w_out, ok = dielectric_sample(wo2, back, cos2, eta, 1.0 - 1e-12)
        assert ok
        assert w_in * w_out == pytest.approx(1.0, rel=1e-14)
        np.testing.assert_allclose(wt2, -np.asarray(wo), atol=1e-14)


@pytest.mark.parametrize("eta, inside", [(1.5, True), (1 / 1.5, False)])
def test_total_internal_reflection(eta, inside):
    """Past the critical angle (sin θc = n2/n1): R = 1, every u reflects with weight 1; nothing absorbed.

    Just inside the critical angle some light is still transmitted.
    """
    crit = math.degrees(math.asin(1 / 1.5))
    for deg in (crit + 0.01, 50.0, 70.0, 89.9):
        n, wo, cos = frame(deg, inside=inside)
        r, cos_t, _, _ = fresnel_dielectric(cos, eta)
        assert r == 1.0 and cos_t == 0.0
        for u in (0.0, 0.5, 0.999, 1 - 2**-53):
            wi, ci, w, ok = dielectric_sample(wo, n, cos, eta, u)
            assert ok and w == 1.0 and ci == cos
            np.testing.assert_allclose(wi, reflect(wo, n, cos), atol=0)
    n, wo, cos = frame(crit - 0.01, inside=inside)
    r = fresnel_dielectric(cos, eta)[0]
    assert 0.5 < r < 1.0
    assert dielectric_sample(wo, n, cos, eta, 1 - 2**-53)[1] * cos < 0.0  # refracted


# --- the dispatchers and the mirror ---------------------------------------------------

def test_mirror_sample_weight_is_its_reflectance_and_front_side_only():
    rho = (0.9, 0.5, 0.2)
    n, wo, cos = frame(30.0)
    wi, ci, w, ok = bsdf_sample(MIRROR, n, wo, cos, rho, 1.0, 0.3, 0.8)
    assert ok and w == rho and ci == cos
    np.testing.assert_allclose(wi, reflect(wo, n, cos), atol=0)
    n, wo, cos = frame(30.0, inside=True)
    assert bsdf_sample(MIRROR, n, wo, cos, rho, 1.0, 0.3, 0.8)[3] is False  # from behind: the path ends


def test_dielectric_dispatch_is_grey_and_delta_flags():
    n, wo, cos = frame(40.0)
    wi, ci, w, ok = bsdf_sample(DIELECTRIC, n, wo, cos, (1.0, 1.0, 1.0), 1.5, 0.99, 0.1)
    assert ok and w[0] == w[1] == w[2] == pytest.approx(1 / 1.5**2, rel=1e-15)
    assert [is_delta(m) for m in (LAMBERT, MIRROR, DIELECTRIC)] == [False, True, True]
    assert [two_sided(m) for m in (LAMBERT, MIRROR, DIELECTRIC)] == [False, False, True]
    for m in (MIRROR, DIELECTRIC):  # a delta BSDF cannot be evaluated or hit by light sampling
        assert bsdf_eval(m, 1.0, 0.5) == 0.0 and bsdf_pdf(m, 0.5) == 0.0


def test_material_tables_of_the_caustics_scene():
    scene = load_scene(CAUSTICS)
    ids, rho, eta = material_tables(scene)
    names = [o.name for o in scene.meshes + scene.spheres]
    by_name = {name: (int(i), tuple(r), float(e)) for name, i, r, e in zip(names, ids, rho, eta)}
    assert by_name["mirror-sphere"] == (MIRROR, (0.95, 0.95, 0.95), 1.0)
    assert by_name["glass-sphere"] == (DIELECTRIC, (1.0, 1.0, 1.0), 1.5)
    assert by_name["floor"][0] == LAMBERT and by_name["floor"][1] == scene.materials["white"].reflectance


# --- ray-sphere intersection ----------------------------------------------------------

def exact_hits(c, r, o, d) -> tuple[Decimal, Decimal] | None:
    """Both roots of |o + t·d - c|² = r² for the float inputs taken as exact rationals (60 digits)."""
    c, o, d = ([Fraction(x) for x in v] for v in (c, o, d))
    r = Fraction(r)
    f = [oi - ci for oi, ci in zip(o, c)]
    a = sum(x * x for x in d)
    b = sum(x * y for x, y in zip(f, d))
    disc = b * b - a * (sum(x * x for x in f) - r * r)
    if disc < 0:
        return None
    with localcontext() as ctx:
        ctx.prec = 60
        root = (Decimal(disc.numerator) / Decimal(disc.denominator)).sqrt()
        bb, aa = Decimal(b.numerator) / Decimal(b.denominator), Decimal(a.numerator) / Decimal(a.denominator)
        return (-bb - root) / aa, (-bb + root) / aa


def unit(v) -> tuple[float, float, float]:
    v = np.asarray(v, dtype=np.float64)
    return tuple(v / np.linalg.norm(v))


def test_sphere_hit_from_outside_inside_and_misses():
    c, r = (1.0, 2.0, 3.0), 0.5
    o, d = (1.0, 2.0, 0.0), (0.0, 0.0, 1.0)
    assert sphere_hit(*c, r, o, d, math.inf) == 2.5  # near root
    assert sphere_hit(*c, r, c, d, math.inf) == 0.5  # from the centre: the far root
    o_in = (1.1, 2.0, 2.9)
    t = sphere_hit(*c, r, o_in, d, math.inf)
    assert t == pytest.approx(float(exact_hits(c, r, o_in, d)[1]), rel=1e-15)  # from inside: the far root
    assert sphere_hit(*c, r, (1.0, 2.6, 0.0), d, math.inf) == math.inf  # passes beside
    assert sphere_hit(*c, r, (1.0, 2.0, 4.0), d, math.inf) == math.inf  # sphere behind the origin
    assert sphere_hit(*c, r, o, d, 2.4) == math.inf  # tmax before the sphere
    assert sphere_hit(*c, r, o, d, 2.6) == 2.5
    assert sphere_hit(*c, r, c, d, 0.49) == math.inf  # from inside, tmax before the wall


def test_ray_leaving_the_surface_does_not_hit_it_again():
    """A ray offset off the surface as the renderers offset it (OFFSET_REL of the scene), heading away: no hit.

    Outward at any angle above the tangent plane, from spheres near and far
    from the origin; and inward from just inside (a refracted ray), which
    must hit the far side, not the surface it left.
    """
    rng = np.random.default_rng(11)
    for c, r in [((0.0, 0.0, 0.0), 1.0), ((1e3, -2e3, 5e2), 0.25), ((0.3, 0.1, -0.2), 1e-4)]:
        eps = OFFSET_REL * max(2 * r, max(abs(x) for x in c) + r)
        for _ in range(200):
            nrm = np.asarray(unit(rng.normal(size=3)))
            x = np.asarray(c) + r * nrm
            d = rng.normal(size=3)
            d -= (d @ nrm) * nrm
            d = unit(d / np.linalg.norm(d) + rng.uniform(0.001, 3.0) * nrm)  # above the tangent plane
            assert sphere_hit(*c, r, tuple(x + eps * nrm), d, math.inf) == math.inf
            d_in = tuple(-np.asarray(d))
            o_in = tuple(x - eps * nrm)
            near, far = exact_hits(c, r, o_in, d_in)
            assert near < 0 < far  # the origin is inside: the hit is the far side
            assert sphere_hit(*c, r, o_in, d_in, math.inf) == pytest.approx(float(far), rel=1e-9, abs=1e-12 * r)


def test_small_sphere_far_away_is_hit_precisely():
    """A 1 mm sphere 10⁶ units away: the hit distance within 1e-6 of the radius of the exact one.

    The textbook discriminant b² - c cancels catastrophically here (b² ≈ 10¹²,
    b² - c ≈ 10⁻⁷; float64 keeps ~10⁻⁴ of it) and this case shows it: the
    naive formula, also computed below, is off by far more than the bound
    or misses. Grazing (0.99 r off-axis) and near-miss (1.01 r) rays too.
    """
    c, r = (6e5, -4e5, 7e5), 1e-3
    o = (0.25, -0.5, 0.125)
    axis = np.subtract(c, o)
    dist = np.linalg.norm(axis)
    side = unit(np.cross(axis, [0.0, 0.0, 1.0]))
    worst_naive = 0.0
    for frac in (0.0, 0.3, 0.7, 0.95, 0.99):
        d = unit(np.subtract(c, o) + frac * r * np.asarray(side))
        exact = exact_hits(c, r, o, d)
        assert exact is not None
        t = sphere_hit(*c, r, o, d, math.inf)
        assert abs(t - float(exact[0])) <= 1e-6 * r, (frac, t, exact[0])
        f = np.subtract(o, c)
        b = f @ d
        disc = b * b - (f @ f - r * r)
        naive = -b - math.sqrt(disc) if disc >= 0 else math.inf
        worst_naive = max(worst_naive, abs(naive - float(exact[0])))
    assert worst_naive > 1e-6 * r  # the case is hard: the textbook form fails it
    for frac in (1.01, 1.5):
        d = unit(np.subtract(c, o) + frac * r * np.asarray(side))
        assert exact_hits(c, r, o, d) is None
        assert sphere_hit(*c, r, o, d, math.inf) == math.inf
    assert dist > 1e6

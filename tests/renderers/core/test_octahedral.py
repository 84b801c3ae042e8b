"""The toolkit's parts for probe GI, against closed forms: octahedral maps, spherical Fibonacci, random rotations.

:mod:`cornell_harness.renderers.core.octahedral` and the point sets of :mod:`cornell_harness.renderers.core.sampling`
are deterministic: each check is exact to float64 rounding or within a
quadrature error that was measured (each tolerance says how). The probes that
use them are tested in ``tests/renderers/test_probes.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cornell_harness.renderers.core.octahedral import bilinear_texels, octahedral_direction, octahedral_uv, texel_directions, \
    with_borders
from cornell_harness.renderers.core.sampling import random_rotation, spherical_fibonacci


def unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# -- octahedral maps -------------------------------------------------------------------------------

def test_octahedral_round_trip():
    """``octahedral_direction(octahedral_uv(d)) == d`` (to 1e-15) for 20 000 random unit directions, the
    six axes and directions with zero components on both hemispheres (the sign-of-zero cases of the fold); the
    upper hemisphere lands in the diamond |u| + |v| ≤ 1, the lower one outside it, all inside [-1, 1]². And the
    other way: (u, v) → direction → (u, v) for random points of the square (off its edges, which the fold glues)."""
    gen = np.random.default_rng(1)
    dirs = [unit(gen.normal(size=(20_000, 3)))]
    special = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    special += [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 1e-300, 1) if (x, y) != (0, 0)]
    special += [(1e-300, -1.0, -1.0), (-0.0, 1.0, -1.0), (1.0, -0.0, -1.0), (-0.0, -0.0, -1.0)]
    dirs.append(unit(np.array(special, np.float64)))
    for d in np.concatenate(dirs):
        u, v = octahedral_uv(*d)
        assert -1.0 <= u <= 1.0 and -1.0 <= v <= 1.0, (d, u, v)
        assert (abs(u) + abs(v) <= 1.0 + 1e-15) == (d[2] >= 0.0) or abs(d[2]) < 1e-15, (d, u, v)
        assert np.allclose(octahedral_direction(u, v), d, rtol=0.0, atol=1e-15), (d, u, v)
    for u, v in gen.uniform(-0.999, 0.999, (5000, 2)):
        back = octahedral_uv(*octahedral_direction(u, v))
        assert np.allclose(back, (u, v), rtol=0.0, atol=1e-14), (u, v, back)


@pytest.mark.parametrize("n", [2, 6, 14])
def test_texel_directions(n):
    """``texel_directions(n)``: unit vectors; texel (row i, column j) is the direction of the centre
    (u_j, v_i) = ((j + ½)·2/n − 1, (i + ½)·2/n − 1) (rows are v, columns u, as the lookup reads them); for even n
    the set is symmetric under z → −z (the fold maps the diamond's texel centres onto the corners'), so the two
    hemispheres have equally many texels, and it sums to the zero vector (symmetric under x → −x and y → −y)."""
    t = texel_directions(n)
    assert t.shape == (n, n, 3)
    assert np.allclose(np.linalg.norm(t, axis=-1), 1.0, rtol=0.0, atol=1e-15)
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    for i in range(n):
        for j in range(n):
            assert np.allclose(octahedral_uv(*t[i, j]), (c[j], c[i]), rtol=0.0, atol=1e-14), (i, j)
    flat = t.reshape(-1, 3)
    up, down = (flat[:, 2] > 1e-12).sum(), (flat[:, 2] < -1e-12).sum()
    assert up == down and (up > 0) == (n > 2)  # n = 2: all four centres are on the equator
    key = np.round(flat, 12)
    mirrored = key * np.array([1.0, 1.0, -1.0]) + 0.0  # + 0.0: -0.0 and 0.0 sort alike
    assert np.array_equal(key[np.lexsort(key.T)], mirrored[np.lexsort(mirrored.T)])
    assert np.allclose(flat.sum(axis=0), 0.0, atol=1e-12)


def _fold(u: float, v: float) -> tuple[float, float]:
    """A point of the square extended by a border, folded back inside: across the edge v = -1, (u, -1 - e) is
    the direction of (-u, -1 + e) (the fold glues (u, -1) to (-u, -1)), and likewise for each edge; a corner
    point is folded across both edges (the -z pole's four corners)."""
    if v < -1.0:
        u, v = -u, -2.0 - v
    elif v > 1.0:
        u, v = -u, 2.0 - v
    if u < -1.0:
        u, v = -2.0 - u, -v
    elif u > 1.0:
        u, v = 2.0 - u, -v
    return u, v


def _border_lookups(n: int, count: int, gen) -> dict[str, list[tuple[float, float]]]:
    """(u, v) points near the square's edges (within one texel, on every edge), near its corners (within one
    texel of each), and inside it at least one texel from every edge."""
    h = 2.0 / n
    pts: dict[str, list] = {"edge": [], "corner": [], "interior": []}
    for _ in range(count):
        t, e = gen.uniform(-1.0, 1.0), gen.uniform(0.0, h)
        pts["edge"].append([(t, -1 + e), (t, 1 - e), (-1 + e, t), (1 - e, t)][gen.integers(4)])
        su, sv = gen.choice([-1.0, 1.0], 2)
        pts["corner"].append((su * (1 - gen.uniform(0.0, h)), sv * (1 - gen.uniform(0.0, h))))
        pts["interior"].append(tuple(gen.uniform(-1.0 + h, 1.0 - h, 2)))
    return pts


#: Largest |bilinear lookup − f(d)| of a linear f(d) = a·d + b (a = A_BORDER, a unit vector) over 3000 lookups of
#: each kind: the octahedral map's own interpolation error (d(u, v) is not linear in u, v, and has kinks on the
#: axes and the diamond), as large near the edges as inside. Measured (edge, corner, interior): n = 6: 0.156,
#: 0.129, 0.160; n = 14: 0.065, 0.022, 0.066. The tolerance is the interior's largest error times 1.25; a border
#: copied without its mirror makes edge lookups jump to 0.233 (n = 6) and 0.097 (n = 14), 1.45 times it. (A wrong
#: corner moves corner lookups by less than that: the exact check of the test catches it.)
A_BORDER = unit(np.array([0.3, -0.7, 0.5]))
SMOOTH_MARGIN = 1.25


@pytest.mark.parametrize("n", [6, 14])
def test_octahedral_borders_make_bilinear_lookups_continuous(n):
    """A linear function of direction f(d) = a·d + b stored per texel (``with_borders``) and read bilinearly
    (``bilinear_texels`` and the 4 texels it names) near and across the square's edges and corners:

    - the lookup is *exactly* (1e-12) the bilinear blend of f at the directions of the 4 texel centres, a centre
      outside the square taken at its folded point (:func:`_fold`): every border texel holds the value of the
      direction it stands for (a border copied unmirrored, from the wrong row, or a wrong corner fails this);
    - the lookup's coordinates are those of the point: u = centre(column) + fc·2/n, likewise v, weights in [0, 1];
    - its error against f(d) is no larger near the edges and corners than inside the square (times
      :data:`SMOOTH_MARGIN`): a wrong border makes it jump (see :data:`A_BORDER`)."""
    gen = np.random.default_rng(n)
    a, b = A_BORDER, 0.25
    texels = texel_directions(n)
    maps = with_borders((texels @ a + b)[..., None])[..., 0]
    assert maps.shape == (n + 2, n + 2)
    h = 2.0 / n

    def centre(k: int) -> float:  # bordered index k is centred at (k - ½)·h - 1
        return (k - 0.5) * h - 1.0

    worst = {}
    for kind, points in _border_lookups(n, 3000, gen).items():
        errors = []
        for u0, v0 in points:
            d = np.array(octahedral_direction(u0, v0))
            u, v = octahedral_uv(*d)
            r, c, fr, fc = bilinear_texels(n, u, v)
            assert 0 <= r <= n and 0 <= c <= n and 0.0 <= fr <= 1.0 and 0.0 <= fc <= 1.0, (u, v, r, c, fr, fc)
            assert centre(c) + fc * h == pytest.approx(u, abs=1e-12)
            assert centre(r) + fr * h == pytest.approx(v, abs=1e-12)
            value = ((1 - fr) * ((1 - fc) * maps[r, c] + fc * maps[r, c + 1])
                     + fr * ((1 - fc) * maps[r + 1, c] + fc * maps[r + 1, c + 1]))
            want = 0.0
            for rr, wr in ((r, 1 - fr), (r + 1, fr)):
                for cc, wc in ((c, 1 - fc), (c + 1, fc)):
                    want += wr * wc * (a @ np.array(octahedral_direction(*_fold(centre(cc), centre(rr)))) + b)
            assert value == pytest.approx(want, abs=1e-12), (kind, u0, v0, r, c)
            errors.append(abs(value - (a @ d + b)))
        worst[kind] = max(errors)
    tolerance = SMOOTH_MARGIN * worst["interior"]
    assert worst["edge"] <= tolerance and worst["corner"] <= tolerance, worst


# -- spherical Fibonacci and random rotations ------------------------------------------------------

@pytest.mark.parametrize("n", [8, 256, 1001, 4096])
def test_spherical_fibonacci(n):
    """``spherical_fibonacci(n)``: unit vectors; z in equal steps 2/n from 1 − 1/n (equal-area bands: Σz = 0
    exactly and, for even n, exactly half have z > 0); the mean vector ≈ 0 (x and y: measured |mean| 5.6e-3,
    1.9e-4, 2.0e-5 and 3.1e-6 for n = 8, 256, 1001, 4096; tolerance 2/n^1.5, at least 2.6 times those); and each
    point stands for 4π/n of solid angle: (4π/n) Σ max(0, m·d) = ∫ max(0, m·ω) dω = π for any unit m, measured
    over 2000 random m to 19%, 0.27%, 0.046% and 0.0071% (tolerance 6/n^1.2, at least 2.6 times those; points
    spread by a wrong angle step fail it)."""
    d = spherical_fibonacci(n)
    assert d.shape == (n, 3)
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, rtol=0.0, atol=1e-15)
    assert np.allclose(d[:, 2], 1.0 - (2.0 * np.arange(n) + 1.0) / n, rtol=0.0, atol=1e-15)
    assert abs(d[:, 2].sum()) < 1e-12
    if n % 2 == 0:
        assert (d[:, 2] > 0.0).sum() == n // 2
    assert np.abs(d[:, :2].mean(axis=0)).max() <= 2.0 / n ** 1.5
    m = unit(np.random.default_rng(n).normal(size=(2000, 3)))
    cosine = 4.0 * math.pi / n * np.maximum(0.0, m @ d.T).sum(axis=1)
    assert np.abs(cosine / math.pi - 1.0).max() <= 6.0 / n ** 1.2


def test_random_rotation():
    """``random_rotation(u1, u2, u3)`` is a rotation (RᵀR = I and det R = +1, to 1e-12) for random and extreme
    inputs; and uniform over SO(3): over 20 000 draws every entry of R averages 0 (its variance is 1/3, so the
    mean's standard deviation is 0.0041; tolerance 5 of them: 0.0204) and R_zz² averages 1/3 (its variance is
    4/45, standard deviation of the mean 0.0021; tolerance 0.0106). The identity, or a rotation about one fixed
    axis, fails both."""
    gen = np.random.default_rng(3)
    us = np.concatenate([gen.random((20_000, 3)), [[0, 0, 0], [1, 1, 1], [0, 0.5, 1], [1, 0.25, 0]]])
    rs = np.array([random_rotation(*u) for u in us])
    assert np.allclose(np.einsum("kji,kjl->kil", rs, rs), np.eye(3), rtol=0.0, atol=1e-12)
    assert np.allclose(np.linalg.det(rs), 1.0, rtol=0.0, atol=1e-12)
    draws = rs[:20_000]
    assert np.abs(draws.mean(axis=0)).max() <= 5.0 * math.sqrt(1.0 / 3.0 / len(draws))
    assert abs((draws[:, 2, 2] ** 2).mean() - 1.0 / 3.0) <= 5.0 * math.sqrt(4.0 / 45.0 / len(draws))

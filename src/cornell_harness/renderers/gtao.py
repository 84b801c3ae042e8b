"""Ground-truth-based ambient occlusion (GTAO), the ``gtao`` variant of :mod:`cornell_harness.renderers.ssao`.

Jimenez, Wu, Pesce and Jarabo 2016, "Practical Realtime Strategies for Accurate Indirect Occlusion" (Activision
technical memo ATVI-TR-16-01, §4 and its Algorithm 1): per pixel, the hemisphere is cut into slices through the
view vector; in each, depth-buffer samples give the two horizon angles, and the cosine-weighted visible arc
between them is integrated in closed form. What the variant estimates, and its screen-space approximations, are
the docstring of :mod:`cornell_harness.renderers.ssao`; its kernels read the G-buffer and share the screen
helpers of :mod:`cornell_harness.renderers.core.screen_space` with the other two passes.
"""

from __future__ import annotations

import math

import numpy as np

from cornell_harness.renderers.core.sampling import jit, orthonormal_basis
from cornell_harness.renderers.core.screen_space import on_screen, plane_depth, ray_through, to_edge


@jit
def slice_frame(p, v, n, o, fx, fy):
    """The slice through v and o (unit, ⊥ v) at view-space point p with normal n (Algorithm 1 lines 5-15).

    Returns the screen direction (du, dv) of the slice's +side o (unit, pixels:
    the projection's derivative along o at p), the projected normal's length
    ‖n_p‖, and γ, its signed angle from v (positive towards o), with cos γ and sin γ.
    """
    du = (o[0] * p[2] - p[0] * o[2]) * fx
    dv = -(o[1] * p[2] - p[1] * o[2]) * fy
    dl = math.sqrt(du * du + dv * dv)
    a = (o[1] * v[2] - o[2] * v[1], o[2] * v[0] - o[0] * v[2], o[0] * v[1] - o[1] * v[0])  # the slice's normal
    na = n[0] * a[0] + n[1] * a[1] + n[2] * a[2]
    npx, npy, npz = n[0] - na * a[0], n[1] - na * a[1], n[2] - na * a[2]
    length = math.sqrt(npx * npx + npy * npy + npz * npz)
    if not length > 1e-12:  # n along the slice's normal (a grazing view): the slice has no cosine weight
        return du / dl, dv / dl, 0.0, 0.0, 1.0, 0.0
    cos_g = min(1.0, (npx * v[0] + npy * v[1] + npz * v[2]) / length)
    sign = 1.0 if npx * o[0] + npy * o[1] + npz * o[2] >= 0.0 else -1.0
    return du / dl, dv / dl, length, sign * math.acos(cos_g), cos_g, sign * math.sqrt(max(0.0, 1.0 - cos_g * cos_g))


@jit
def arc(side, hc, lowest, gamma, cos_g, sin_g):
    """¼(−cos(2h − γ) + cos γ + 2h sin γ) for the horizon h = side·acos(hc) (Algorithm 1 line 27).

    cos(2h − γ) is expanded with cos h = hc, sin h = side·√(1 − hc²), so the
    only transcendental is acos, skipped when the horizon is the tangent
    (hc = ``lowest``: h = γ + side·π/2), as on any open surface.
    """
    h = gamma + side * 0.5 * math.pi if hc == lowest else side * math.acos(min(1.0, hc))
    sin_h = side * math.sqrt(max(0.0, 1.0 - hc * hc))
    cos_2h_g = (2.0 * hc * hc - 1.0) * cos_g + 2.0 * hc * sin_h * sin_g
    return 0.25 * (-cos_2h_g + cos_g + 2.0 * h * sin_g)


@jit
def gtao_pass(gb, radius, thickness, slices, steps, cosine, screen, row0, row1, out):
    """Jimenez et al. 2016, Algorithm 1: horizons per slice, the visible arc in closed form; rows ``row0`` ..
    ``row1 - 1`` of ``out``, NaN where the pixel saw nothing (:func:`cornell_harness.renderers.ssao.screen_space_pass`'s
    contract)."""
    width, height, tx, ty = screen
    fx, fy = width / (2.0 * tx), height / (2.0 * ty)  # pixels per image-plane unit at depth 1
    r2 = radius * radius
    ax, ay = 2.0 * tx / width, 2.0 * ty / height
    cos_phi = np.cos(np.pi * (np.arange(slices) + 0.5) / slices)
    sin_phi = np.sin(np.pi * (np.arange(slices) + 0.5) / slices)
    for row in range(row0, row1):
        for col in range(width):
            pz = gb[row, col, 2]
            if not pz < np.inf:
                out[row, col] = np.nan
                continue
            p = (gb[row, col, 0], gb[row, col, 1], pz)
            n = (gb[row, col, 3], gb[row, col, 4], gb[row, col, 5])
            inv = 1.0 / math.sqrt(p[0] * p[0] + p[1] * p[1] + pz * pz)
            v = (-p[0] * inv, -p[1] * inv, -pz * inv)  # towards the camera
            e1, e2 = orthonormal_basis(v[0], v[1], v[2])
            r_px = radius * fx / pz  # the radius's length on screen at p's depth
            visible, unoccluded = 0.0, 0.0
            for k in range(slices):
                c, s = cos_phi[k], sin_phi[k]
                o = (c * e1[0] + s * e2[0], c * e1[1] + s * e2[1], c * e1[2] + s * e2[2])
                du, dv, length, gamma, cos_g, sin_g = slice_frame(p, v, n, o, fx, fy)
                for si in range(2):
                    side = 1.0 - 2.0 * si
                    # Horizon search (lines 17-24): samples at r_px·j/steps pixels along the slice's side,
                    # from the tangent γ ± π/2 (cos ∓ sin γ: Algorithm 1's clamp to the hemisphere) up.
                    lowest = -side * sin_g
                    hc = lowest
                    # The steps spread over the on-screen part of the segment: the screen shows nothing
                    # beyond its edge, so occluders there are missed whatever the radius.
                    dt = side * min(r_px, to_edge(col + 0.5, row + 0.5, side * du, side * dv, width, height)) / steps
                    for j in range(1, steps + 1):
                        t = dt * j
                        su, sv = col + 0.5 + t * du, row + 0.5 + t * dv
                        if not on_screen(su, sv, width, height):
                            break
                        dx, dy = ray_through(su, sv, ax, ay, tx, ty)
                        i, jj = int(sv), int(su)
                        zb = plane_depth(gb[i, jj, 0], gb[i, jj, 1], gb[i, jj, 2], gb[i, jj, 3], gb[i, jj, 4],
                                          gb[i, jj, 5], dx, dy)
                        wx, wy, wz = zb * dx - p[0], zb * dy - p[1], zb - pz
                        d2 = wx * wx + wy * wy + wz * wz
                        # Beyond the radius (a step falloff: the scene's max distance), or (thickness) too far
                        # in front of p to be a slab that reaches back to it, a sample does not count.
                        if not (0.0 < d2 <= r2) or (thickness > 0.0 and pz - zb > thickness):
                            continue
                        dist = math.sqrt(d2)
                        dot = wx * v[0] + wy * v[1] + wz * v[2]
                        if dot > hc * dist:  # raises the horizon: only then pay for the division
                            hc = dot / dist
                    if cosine:  # the inner integral in closed form
                        visible += length * arc(side, hc, lowest, gamma, cos_g, sin_g)
                    else:  # uniform: ½∫ |sin θ| dθ from 0 to h = ½(1 − cos h)
                        visible += 0.5 * (1.0 - hc)
                # The same with both horizons at the tangent: its mean over φ is exactly 1 (the whole hemisphere).
                unoccluded += length * (cos_g + gamma * sin_g) if cosine else 1.0
            out[row, col] = min(1.0, max(0.0, visible / unoccluded)) if unoccluded > 0.0 else 1.0

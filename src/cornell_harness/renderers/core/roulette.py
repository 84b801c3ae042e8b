"""Russian roulette: how a path's throughput goes on after a BSDF sample, or ends without bias.

Every integrator of ours that follows camera paths (the path tracer; the
camera passes of the photon mappers) continues a path through
:func:`continue_path`. From the ``rr_depth``-th vertex on (default
:data:`RR_DEPTH`) a path goes on with probability
``q = min(max_c β_c / s, Q_MAX)`` and its throughput is divided by ``q``, so
the estimate stays unbiased (pbrt-v4 §13.1.5 uses the same rule; Mitsuba 3
too, with 0.95).

- Capping ``q`` at ``Q_MAX < 1`` ends every path with probability 1 even
  when every albedo is 1: the expected length past ``rr_depth`` is at most
  ``1 / (1 - Q_MAX)`` = 100 vertices. 0.99, not Mitsuba's 0.95: with 0.95
  a furnace of albedo above 0.975 has infinite variance (found by the
  ρ = 0.99 furnace test).
- ``s`` is the radiance scaling (η_i/η_t)² of the path's refractions, which
  β contains (:func:`cornell_harness.renderers.core.bsdf.refraction_scale`): without it a
  path inside glass (β/2.25) would be ended more often for no reason, as
  Mitsuba 3's ``path`` also avoids (it uses β·η²).
"""

from __future__ import annotations

from cornell_harness.renderers.core.bsdf import bsdf_pdf
from cornell_harness.renderers.core.sampling import jit

RR_DEPTH = 5
Q_MAX = 0.99


@jit
def survival_probability(bmax, scale) -> float:
    """The probability ``q`` that a path of largest throughput component ``bmax`` goes on (module docstring)."""
    return min(bmax / scale, Q_MAX)


@jit
def continue_path(mat, valid, cos_w, f, beta, scale, u_rr, roulette):
    """Throughput after a BSDF sample at cosine ``cos_w`` with weight ``f``: (alive, β', pdf of the sample).

    Russian roulette with the vertex's number ``u_rr`` when ``roulette``, on
    β without the refraction scaling ``scale`` it contains.
    """
    if not valid:
        return False, beta, 0.0  # zero-pdf direction
    b0, b1, b2 = beta[0] * f[0], beta[1] * f[1], beta[2] * f[2]
    bmax = max(b0, b1, b2)
    if bmax <= 0.0:
        return False, beta, 0.0
    if roulette:
        survive = survival_probability(bmax, scale)
        # Written so a NaN throughput ends the path (NaN < x is false): its NaN
        # has already reached L, where the NaN count reports it.
        if not u_rr < survive:
            return False, beta, 0.0
        b0, b1, b2 = b0 / survive, b1 / survive, b2 / survive
    return True, (b0, b1, b2), bsdf_pdf(mat, cos_w)


@jit
def continue_spectral_path(mat, valid, cos_w, f, beta, scale, u_rr, roulette):
    """:func:`continue_path` for a throughput of 4 wavelengths (4-tuples ``f`` and ``beta``; the hero-wavelength
    path tracer, :mod:`cornell_harness.renderers.hero_wavelength`): the same rule on the largest of the four."""
    if not valid:
        return False, beta, 0.0
    b0, b1, b2, b3 = beta[0] * f[0], beta[1] * f[1], beta[2] * f[2], beta[3] * f[3]
    bmax = max(max(b0, b1), max(b2, b3))
    if bmax <= 0.0:
        return False, beta, 0.0
    if roulette:
        survive = survival_probability(bmax, scale)
        if not u_rr < survive:  # a NaN throughput ends the path, as in continue_path
            return False, beta, 0.0
        b0, b1, b2, b3 = b0 / survive, b1 / survive, b2 / survive, b3 / survive
    return True, (b0, b1, b2, b3), bsdf_pdf(mat, cos_w)
